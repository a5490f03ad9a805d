/* Unit test of the MPC driver (templates/c/runtime/ncgen_mpc.h) alone, on a hand-written
 * "iteration" whose iterate is known in closed form: X_sol = X + x (node by node, the state
 * added), U_sol = U + 1 + t.  Checked: the start's guess and its adopted iterations, the
 * shift of the solution into the next guess, u_out; non-finite or null measurements refused
 * before any work; a failed iteration and a non-finite iterate (in the second of two
 * iterations, after the first succeeded) leave the guess exactly as it was, so the next good
 * step answers as if the bad ones never happened. */
#include <math.h>
#include <stdio.h>
#include <string.h>

typedef double casadi_real;

static int failures, checks;

/* Counts a check; prints the failing condition with a message. */
#define CHECK(cond, ...)                                                    \
  do {                                                                      \
    ++checks;                                                               \
    if (!(cond)) {                                                          \
      ++failures;                                                           \
      fprintf(stderr, "%s:%d: FAILED %s: ", __FILE__, __LINE__, #cond);     \
      fprintf(stderr, __VA_ARGS__);                                         \
      fputc('\n', stderr);                                                  \
    }                                                                       \
  } while (0)

#define NCGEN_MPC_NX 2
#define NCGEN_MPC_NU 1
#define NCGEN_MPC_N 3
#define NCGEN_MPC_ITERATIONS 2

static int calls, fail_at, nan_at;   /* the fake's call count; the call that fails / gives NaN (0: none) */

static int ncgen_mpc_iteration(void *m, const casadi_real *x, casadi_real t, const casadi_real *X,
                               const casadi_real *U, casadi_real *X_sol, casadi_real *U_sol) {
  int k, i;
  (void)m;
  ++calls;
  if (calls == fail_at) return 1;
  for (k = 0; k <= NCGEN_MPC_N; ++k)
    for (i = 0; i < NCGEN_MPC_NX; ++i) X_sol[k * NCGEN_MPC_NX + i] = X[k * NCGEN_MPC_NX + i] + x[i];
  for (k = 0; k < NCGEN_MPC_N * NCGEN_MPC_NU; ++k) U_sol[k] = U[k] + 1 + t;
  if (calls == nan_at) X_sol[NCGEN_MPC_NX * NCGEN_MPC_N] = NAN;
  return 0;
}

#include "ncgen_mpc.h"

typedef struct {
  casadi_real X[NCGEN_MPC_NXS], U[NCGEN_MPC_NUS], X_it[NCGEN_MPC_NXS], U_it[NCGEN_MPC_NUS];
  casadi_real X_sol[NCGEN_MPC_NXS], U_sol[NCGEN_MPC_NUS];
} controller;

static ncgen_mpc_arrays arrays(controller *c) {
  ncgen_mpc_arrays a;
  a.X = c->X;
  a.U = c->U;
  a.X_it = c->X_it;
  a.U_it = c->U_it;
  a.X_sol = c->X_sol;
  a.U_sol = c->U_sol;
  return a;
}

static int same_guess(const controller *a, const controller *b) {
  return !memcmp(a->X, b->X, sizeof a->X) && !memcmp(a->U, b->U, sizeof a->U);
}

int main(void) {
  static controller c, saved;
  const casadi_real x[2] = {0.5, -2.0}, rest[1] = {0.25}, specials[3] = {NAN, INFINITY, -INFINITY};
  casadi_real bad[2], u = 99.0;
  ncgen_mpc_arrays a = arrays(&c);
  int k, s;

  /* start: refused arguments change nothing */
  memset(&c, 0, sizeof c);
  for (s = 0; s < 3; ++s) {
    bad[0] = x[0];
    bad[1] = specials[s];
    CHECK(ncgen_mpc_start(&c, &a, bad, 0.0, 1, rest) == NCGEN_MPC_BAD_INPUT, "non-finite x");
    CHECK(ncgen_mpc_start(&c, &a, x, specials[s], 1, rest) == NCGEN_MPC_BAD_INPUT, "non-finite t");
  }
  CHECK(ncgen_mpc_start(&c, &a, NULL, 0.0, 1, rest) == NCGEN_MPC_BAD_INPUT, "null x");
  CHECK(ncgen_mpc_start(&c, &a, x, 0.0, -1, rest) == NCGEN_MPC_BAD_INPUT, "iterations < 0");
  CHECK(calls == 0 && c.X[0] == 0 && c.U[0] == 0, "a refused start does no work");

  /* start with one adopted solve (two iterations): X = x held + 2 x = 3 x, U = rest + 2 (1 + t) */
  CHECK(ncgen_mpc_start(&c, &a, x, 0.5, 1, rest) == NCGEN_MPC_OK, "start");
  for (k = 0; k <= NCGEN_MPC_N; ++k)
    CHECK(c.X[2 * k] == 1.5 && c.X[2 * k + 1] == -6.0, "node %d: %g %g", k, c.X[2 * k], c.X[2 * k + 1]);
  for (k = 0; k < NCGEN_MPC_N; ++k) CHECK(c.U[k] == 0.25 + 3.0, "interval %d: %g", k, c.U[k]);
  CHECK(calls == 2, "two iterations per solve: %d", calls);

  /* a step: node k of the solution is 3x + 2x = 5x (the guess shifted: same, all equal), u = U + 2 (1 + t) */
  CHECK(ncgen_mpc_advance(&c, &a, x, 1.0, &u) == NCGEN_MPC_OK && u == 3.25 + 4.0, "step: u = %g", u);
  CHECK(c.X[0] == 2.5 && c.X[2 * NCGEN_MPC_N] == 2.5 && c.U[NCGEN_MPC_N - 1] == 7.25, "the shifted guess");

  /* refused measurements and outputs: nothing changes, no work */
  saved = c;
  calls = 0;
  for (s = 0; s < 3; ++s) {
    bad[0] = specials[s];
    bad[1] = x[1];
    u = 99.0;
    CHECK(ncgen_mpc_advance(&c, &a, bad, 1.0, &u) == NCGEN_MPC_BAD_INPUT && u == 99.0, "non-finite x");
    CHECK(ncgen_mpc_advance(&c, &a, x, specials[s], &u) == NCGEN_MPC_BAD_INPUT && u == 99.0, "non-finite t");
  }
  CHECK(ncgen_mpc_advance(&c, &a, x, 1.0, NULL) == NCGEN_MPC_BAD_INPUT, "null u_out");
  CHECK(ncgen_mpc_advance(&c, &a, NULL, 1.0, &u) == NCGEN_MPC_BAD_INPUT, "null x");
  CHECK(calls == 0 && same_guess(&c, &saved), "refused steps do no work and keep the guess");

  /* a failing iteration, then a NaN iterate after a good first iteration: the guess is kept */
  fail_at = 1;
  CHECK(ncgen_mpc_advance(&c, &a, x, 1.0, &u) == NCGEN_MPC_FAILED && u == 99.0, "failed iteration");
  CHECK(same_guess(&c, &saved), "the guess after a failed iteration");
  calls = 0;
  fail_at = 0;
  nan_at = 2;
  CHECK(ncgen_mpc_advance(&c, &a, x, 1.0, &u) == NCGEN_MPC_FAILED && u == 99.0, "NaN iterate");
  CHECK(same_guess(&c, &saved), "the guess after a NaN in the second iteration");
  nan_at = 0;

  /* the next good step answers as from the saved controller */
  CHECK(ncgen_mpc_advance(&c, &a, x, 1.0, &u) == NCGEN_MPC_OK, "good step after the failures");
  {
    ncgen_mpc_arrays b = arrays(&saved);
    casadi_real u_ref = 0;
    CHECK(ncgen_mpc_advance(&saved, &b, x, 1.0, &u_ref) == NCGEN_MPC_OK && u == u_ref, "u %g vs %g", u, u_ref);
    CHECK(same_guess(&c, &saved), "the same guess as without the failures");
  }
  if (failures) {
    fprintf(stderr, "test_mpc: %d of %d checks failed\n", failures, checks);
    return 1;
  }
  printf("test_mpc: all %d checks passed\n", checks);
  return 0;
}

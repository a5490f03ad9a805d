/* The model-predictive controller's driver (ncgen.export_mpc): the real-time-iteration loop
 * around one SQP iteration, with its input checks.  Plain C99, model-independent; the
 * package's <name>_mpc.c defines before including it:
 *
 *   NCGEN_MPC_NX, NCGEN_MPC_NU, NCGEN_MPC_N   state and input sizes, intervals of the horizon;
 *   NCGEN_MPC_ITERATIONS                      SQP iterations per control step (>= 1);
 *   static int ncgen_mpc_iteration(void *m, const casadi_real *x, casadi_real t,
 *                                  const casadi_real *X, const casadi_real *U,
 *                                  casadi_real *X_sol, casadi_real *U_sol);
 *       one SQP iteration at the measured state x (NX values) and time t (s) from the guess
 *       (X: NX (N + 1) states node by node, U: NU N inputs) into (X_sol, U_sol); 0 on success.
 *
 * Guarantees (tests/c/test_mpc.c): a non-finite or null argument is refused with
 * NCGEN_MPC_BAD_INPUT before any work; a failed iteration or a non-finite iterate leaves the
 * guess as it was (NCGEN_MPC_FAILED), so neither a bad measurement nor a failed solve poisons
 * later steps; u_out is written only on success. */
#define NCGEN_MPC_OK 0
#define NCGEN_MPC_FAILED 1
#define NCGEN_MPC_BAD_INPUT 2
#define NCGEN_MPC_NXS (NCGEN_MPC_NX * (NCGEN_MPC_N + 1))
#define NCGEN_MPC_NUS (NCGEN_MPC_NU * NCGEN_MPC_N)

/* The controller's arrays (owned by the caller's struct): the guess (X, U), the guess of
 * the current iteration (X_it, U_it) and the last iterate (X_sol, U_sol). */
typedef struct {
  casadi_real *X, *U, *X_it, *U_it, *X_sol, *U_sol;
} ncgen_mpc_arrays;

/* 1 when the n values at v are all finite (n = 0: vacuously). */
static int ncgen_all_finite(const casadi_real *v, int n) {
  int i;
  for (i = 0; i < n; ++i)
    if (!isfinite(v[i])) return 0;
  return 1;
}

/* 1 when x (NX values) and t are a measurement the controller takes. */
static int ncgen_mpc_measurement(const casadi_real *x, casadi_real t) {
  return x && isfinite(t) && ncgen_all_finite(x, NCGEN_MPC_NX);
}

/* NCGEN_MPC_ITERATIONS iterations at (x, t) from the guess into (X_sol, U_sol); the guess
 * itself is not changed. */
static int ncgen_mpc_solve(void *m, const ncgen_mpc_arrays *a, const casadi_real *x, casadi_real t) {
  int i;
  memcpy(a->X_it, a->X, NCGEN_MPC_NXS * sizeof(casadi_real));
  memcpy(a->U_it, a->U, NCGEN_MPC_NUS * sizeof(casadi_real));
  for (i = 0; i < NCGEN_MPC_ITERATIONS; ++i) {
    if (ncgen_mpc_iteration(m, x, t, a->X_it, a->U_it, a->X_sol, a->U_sol)) return NCGEN_MPC_FAILED;
    if (!ncgen_all_finite(a->X_sol, NCGEN_MPC_NXS) || !ncgen_all_finite(a->U_sol, NCGEN_MPC_NUS))
      return NCGEN_MPC_FAILED;
    memcpy(a->X_it, a->X_sol, NCGEN_MPC_NXS * sizeof(casadi_real));
    memcpy(a->U_it, a->U_sol, NCGEN_MPC_NUS * sizeof(casadi_real));
  }
  return NCGEN_MPC_OK;
}

/* The guess set to x held at every node and u_rest on every interval, then `iterations`
 * solves at (x, t), each adopted as the next guess. */
static int ncgen_mpc_start(void *m, const ncgen_mpc_arrays *a, const casadi_real *x, casadi_real t, int iterations,
                           const casadi_real *u_rest) {
  int k, status;
  if (!ncgen_mpc_measurement(x, t) || iterations < 0) return NCGEN_MPC_BAD_INPUT;
  for (k = 0; k <= NCGEN_MPC_N; ++k) memcpy(a->X + k * NCGEN_MPC_NX, x, NCGEN_MPC_NX * sizeof(casadi_real));
  for (k = 0; k < NCGEN_MPC_N; ++k) memcpy(a->U + k * NCGEN_MPC_NU, u_rest, NCGEN_MPC_NU * sizeof(casadi_real));
  for (k = 0; k < iterations; ++k) {
    if ((status = ncgen_mpc_solve(m, a, x, t)) != NCGEN_MPC_OK) return status;
    memcpy(a->X, a->X_sol, NCGEN_MPC_NXS * sizeof(casadi_real));
    memcpy(a->U, a->U_sol, NCGEN_MPC_NUS * sizeof(casadi_real));
  }
  return NCGEN_MPC_OK;
}

/* One control step: u_out (NU values) from the measurement (x, t); the solution shifted by
 * one interval (its last node and input repeated) becomes the guess. */
static int ncgen_mpc_advance(void *m, const ncgen_mpc_arrays *a, const casadi_real *x, casadi_real t,
                             casadi_real *u_out) {
  const int nx = NCGEN_MPC_NX, nu = NCGEN_MPC_NU, n = NCGEN_MPC_N;
  int status;
  if (!u_out || !ncgen_mpc_measurement(x, t)) return NCGEN_MPC_BAD_INPUT;
  if ((status = ncgen_mpc_solve(m, a, x, t)) != NCGEN_MPC_OK) return status;
  memcpy(u_out, a->U_sol, nu * sizeof(casadi_real));
  memcpy(a->X, a->X_sol + nx, nx * n * sizeof(casadi_real));
  memcpy(a->X + nx * n, a->X_sol + nx * n, nx * sizeof(casadi_real));
  memcpy(a->U, a->U_sol + nu, nu * (n - 1) * sizeof(casadi_real));
  memcpy(a->U + nu * (n - 1), a->U_sol + nu * (n - 1), nu * sizeof(casadi_real));
  return NCGEN_MPC_OK;
}

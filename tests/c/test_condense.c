/* Unit tests of the SQP controller's condensing (ncgen_condense.h) against the problem it
 * condenses, evaluated directly: random blocks (A_k, B_k, shooting gaps d, symmetric cost blocks
 * Q_k with zero entries, cross terms M_k != 0, symmetric R_k, gradients g_x, g_u); the states
 * X(U) by the recursion x_0 = d_0, x_{k+1} = A_k x_k + B_k u_k + d_{k+1}, the cost
 *     J(U) = sum_k 1/2 x_k' Q_k x_k + g_x,k' x_k  +  sum_{k<N} x_k' M_k u_k + 1/2 u_k' R_k u_k + g_u,k' u_k.
 * X is affine and J quadratic in U, so s = X(0), S's columns X(e_c) - X(0), g = (J(e_c) - J(-e_c)) / 2
 * and H_cd = J(e_c + e_d) - J(e_c) - J(e_d) + J(0) hold exactly up to round-off.  The cables' rows
 * (ncgen_condense_taut) against the linearised pulls evaluated on that recursion: with random
 * P_k, P_a,k, P_b,k, P_u,k, the rows' value (A U - lb)_k must be
 * P_k + P_a,k x_k(U) + P_b,k x_{k+1}(U) + P_u,k u_k - T_min at U = 0 and every e_c (the rows are
 * affine in U), the rows above r0 untouched.  Built and run by tests/test_stepper_runtime_c.py
 * under AddressSanitizer and UndefinedBehaviorSanitizer. */
#include "check.h"

typedef double casadi_real;
#define NCGEN_MPC_NX 5
#define NCGEN_MPC_NU 2
#define NCGEN_MPC_N 4
#define NXS (NCGEN_MPC_NX * (NCGEN_MPC_N + 1))
#define NUS (NCGEN_MPC_NU * NCGEN_MPC_N)
#define NCGEN_MPC_PULLS 3
#include "ncgen_condense.h"

#define NX NCGEN_MPC_NX
#define NU NCGEN_MPC_NU
#define NN NCGEN_MPC_N

static double A[NN * NX * NX], B[NN * NX * NU], d[NXS], Q[(NN + 1) * NX * NX], M[NN * NX * NU],
    R[NN * NU * NU], g_x[NXS], g_u[NUS];

static double uniform(void) { return 2.0 * rand() / (double)RAND_MAX - 1.0; }

/* The blocks: Q_k symmetric with about a third of its entries zero, R_k symmetric. */
static void blocks(void) {
  int i, j, k;
  for (i = 0; i < NN * NX * NX; ++i) A[i] = 0.6 * uniform();
  for (i = 0; i < NN * NX * NU; ++i) B[i] = uniform(), M[i] = 0.3 * uniform();
  for (i = 0; i < NXS; ++i) d[i] = uniform(), g_x[i] = uniform();
  for (i = 0; i < NUS; ++i) g_u[i] = uniform();
  for (k = 0; k <= NN; ++k)
    for (j = 0; j < NX; ++j)
      for (i = j; i < NX; ++i) {
        double q = (i == j) ? 2.0 + uniform() : (rand() % 3 ? 0.0 : 0.5 * uniform());
        Q[k * NX * NX + i + j * NX] = Q[k * NX * NX + j + i * NX] = q;
      }
  for (k = 0; k < NN; ++k)
    for (j = 0; j < NU; ++j)
      for (i = j; i < NU; ++i)
        R[k * NU * NU + i + j * NU] = R[k * NU * NU + j + i * NU] = (i == j) ? 1.0 + uniform() : 0.2 * uniform();
}

/* X(U) (NXS values) and J(U). */
static double cost(const double *U, double *X) {
  double J = 0.0;
  int i, j, k;
  for (i = 0; i < NX; ++i) X[i] = d[i];
  for (k = 0; k < NN; ++k)
    for (i = 0; i < NX; ++i) {
      double x = d[(k + 1) * NX + i];
      for (j = 0; j < NX; ++j) x += A[k * NX * NX + i + j * NX] * X[k * NX + j];
      for (j = 0; j < NU; ++j) x += B[(k * NU + j) * NX + i] * U[k * NU + j];
      X[(k + 1) * NX + i] = x;
    }
  for (k = 0; k <= NN; ++k)
    for (i = 0; i < NX; ++i) {
      J += g_x[k * NX + i] * X[k * NX + i];
      for (j = 0; j < NX; ++j) J += 0.5 * X[k * NX + i] * Q[k * NX * NX + i + j * NX] * X[k * NX + j];
      if (k < NN)
        for (j = 0; j < NU; ++j) J += X[k * NX + i] * M[(k * NU + j) * NX + i] * U[k * NU + j];
    }
  for (k = 0; k < NN; ++k)
    for (i = 0; i < NU; ++i) {
      J += g_u[k * NU + i] * U[k * NU + i];
      for (j = 0; j < NU; ++j) J += 0.5 * U[k * NU + i] * R[k * NU * NU + i + j * NU] * U[k * NU + j];
    }
  return J;
}

#define NP NCGEN_MPC_PULLS
#define R0 2          /* rows before the cables' (the state bounds') */
#define NR (R0 + NP * NN)

static double P[NP * NN], Pa[NP * NX * NN], Pb[NP * NX * NN], Pu[NP * NU * NN];

/* The cables' rows on the blocks: the worst error of A U - lb against the pulls by the recursion. */
static double taut_rows(const double *S, const double *s) {
  const double T_min = 0.7;
  double A_t[NR * NUS], lb[NR], U[NUS], X[NXS], worst = 0.0;
  int i, j, k, c;
  for (i = 0; i < NP * NN; ++i) P[i] = uniform();
  for (i = 0; i < NP * NX * NN; ++i) Pa[i] = uniform(), Pb[i] = uniform();
  for (i = 0; i < NP * NU * NN; ++i) Pu[i] = uniform();
  for (i = 0; i < NR * NUS; ++i) A_t[i] = 42.0;
  lb[0] = lb[1] = 42.0;
  ncgen_condense_taut(P, Pa, Pb, Pu, T_min, S, s, NR, R0, A_t, lb);
  for (c = 0; c < NUS; ++c) worst = fmax(worst, fabs(A_t[c * NR] - 42.0) + fabs(A_t[1 + c * NR] - 42.0));
  worst = fmax(worst, fabs(lb[0] - 42.0) + fabs(lb[1] - 42.0));
  for (c = -1; c < NUS; ++c) {                     /* U = 0, then U = e_c */
    memset(U, 0, sizeof U);
    if (c >= 0) U[c] = 1.0;
    cost(U, X);
    for (k = 0; k < NN; ++k)
      for (i = 0; i < NP; ++i) {
        const int row = R0 + k * NP + i;
        double want = P[k * NP + i] - T_min, got = -lb[row];
        for (j = 0; j < NX; ++j)
          want += Pa[(k * NX + j) * NP + i] * X[k * NX + j] + Pb[(k * NX + j) * NP + i] * X[(k + 1) * NX + j];
        for (j = 0; j < NU; ++j) want += Pu[(k * NU + j) * NP + i] * U[k * NU + j];
        for (j = 0; j < NUS; ++j) got += A_t[row + NR * j] * U[j];
        worst = fmax(worst, fabs(got - want));
      }
  }
  return worst;
}

int main(void) {
  double S[NXS * NUS], s[NXS], H[NUS * NUS], g[NUS], T[NX * NUS];
  double U[NUS], X0[NXS], X[NXS], J0, Jc[NUS];
  int trial, i, c, e;
  ncgen_qp_blocks b = {A, B, d, Q, M, R, g_x, g_u};
  srand(7);
  for (trial = 0; trial < 20; ++trial) {
    double worst_S = 0.0, worst_g = 0.0, worst_H = 0.0, asym = 0.0;
    blocks();
    ncgen_condense(&b, S, s, H, g, T);
    memset(U, 0, sizeof U);
    J0 = cost(U, X0);
    for (i = 0; i < NXS; ++i) worst_S = fmax(worst_S, fabs(s[i] - X0[i]));
    for (c = 0; c < NUS; ++c) {
      double Jm;
      U[c] = 1.0;
      Jc[c] = cost(U, X);
      for (i = 0; i < NXS; ++i) worst_S = fmax(worst_S, fabs(S[c * NXS + i] - (X[i] - X0[i])));
      U[c] = -1.0;
      Jm = cost(U, X);
      worst_g = fmax(worst_g, fabs(g[c] - 0.5 * (Jc[c] - Jm)));
      U[c] = 0.0;
    }
    for (c = 0; c < NUS; ++c)
      for (e = 0; e < NUS; ++e) {
        double Jce;
        U[c] += 1.0;
        U[e] += 1.0;
        Jce = cost(U, X);
        U[c] = U[e] = 0.0;
        worst_H = fmax(worst_H, fabs(H[c + e * NUS] - (Jce - Jc[c] - Jc[e] + J0)));
        asym = fmax(asym, fabs(H[c + e * NUS] - H[e + c * NUS]));
      }
    CHECK(worst_S < 1e-12, "trial %d: S, s against the recursion: %.3g", trial, worst_S);
    CHECK(worst_g < 1e-11, "trial %d: g against the cost's differences: %.3g", trial, worst_g);
    CHECK(worst_H < 1e-11, "trial %d: H against the cost's second differences: %.3g", trial, worst_H);
    CHECK(asym == 0.0, "trial %d: H not symmetric: %.3g", trial, asym);
    worst_S = taut_rows(S, s);
    CHECK(worst_S < 1e-12, "trial %d: the cables' rows against the pulls on the recursion: %.3g", trial, worst_S);
  }
  return report("test_condense");
}

/* Unit tests of the semismooth Newton contact solver (ncgen_cone_newton.h) on hand-made
 * Delassus matrices of three contacts in 3D (DC = 3: a normal and two tangents each): its
 * generalised Jacobian against central differences of the Alart-Curnier function in the
 * sticking, slipping and open regimes, and its solutions against ones worked by hand
 * (one contact slipping, one sticking, one opening; a redundant pair), from zero and from a
 * warm start.  Only the workspace fields the solver reads are defined here: it needs no
 * model.  Compiled by tests/test_stepper_runtime_c.py under the sanitizers. */
#include "check.h"
#include "stepper_decls.h"

#define NK 3
#define DC 3
#define ND (NK * DC)

typedef struct {
  casadi_real *G, *U, *P, *Um, *S, *S2, *cn;
  casadi_int *act, *gp, *gi, *cni;
  int fm;
} workspace;

static casadi_real mu[NK] = {0.5, 0.5, 0.5};
static const casadi_real restitution[NK] = {0, 0, 0};

static casadi_real nan_max(casadi_real m, casadi_real a) {
  return isnan(m) || a <= m ? m : a;
}

#include "ncgen_cone_newton.h"

static casadi_real G_[ND * ND], U_[ND], P_[ND], Um_[2 * ND], S_[2 * ND * ND], cn_[8 * ND];
static casadi_int act_[NK], gp_[ND + 1], gi_[ND * ND], cni_[2 * ND];
static const int first[NK + 1] = {0, 3, 6, 9};
static const casadi_real bias[NK] = {0, 0, 0};

static workspace make(const casadi_real *G, const casadi_real *U0) {
  workspace ws;
  int a, r, k = 0;
  ws.G = G_, ws.U = U_, ws.P = P_, ws.Um = Um_, ws.S = S_, ws.S2 = S_ + ND * ND, ws.cn = cn_;
  ws.act = act_, ws.gp = gp_, ws.gi = gi_, ws.cni = cni_, ws.fm = 0;
  memcpy(G_, G, sizeof G_);
  memcpy(U_, U0, sizeof U_);
  memset(P_, 0, sizeof P_);
  memset(Um_, 0, sizeof Um_);
  for (a = 0; a < NK; ++a) act_[a] = a;
  for (r = 0; r < ND; ++r) { /* the pattern of G by columns, as g_pattern() gives it */
    gp_[r] = k;
    for (a = 0; a < ND; ++a)
      if (G[a + r * ND] != 0) gi_[k++] = a;
  }
  gp_[ND] = k;
  return ws;
}

/* G = I with the normal rows of contacts 0 and 1 coupled by 1/2. */
static void coupled(casadi_real *G) {
  int i;
  memset(G, 0, ND * ND * sizeof(casadi_real));
  for (i = 0; i < ND; ++i) G[i + i * ND] = 1;
  G[0 + 3 * ND] = G[3 + 0 * ND] = 0.5;
}

/* dphi/dP against central differences at points of each regime (away from the kinks). */
static void test_jacobian(void) {
  casadi_real G[ND * ND], J[ND * ND], rho[ND], phi_p[ND], phi_m[ND], Pp[ND], Up[ND], Pm[ND], Um[ND];
  const casadi_real U0[ND] = {-1.0, 0.3, -0.2, -0.5, 0.01, 0.02, 0.4, 0.1, 0.0};
  const casadi_real P0[ND] = {1.0, 0.2, -0.1, 0.7, 0.05, -0.02, 0.1, 0.0, 0.0};
  const casadi_real eps = 1e-7;
  workspace ws;
  int i, j, k;
  coupled(G);
  for (i = 0; i < ND; ++i) /* a full symmetric coupling, diagonally dominant */
    for (j = 0; j < i; ++j) G[i + j * ND] = G[j + i * ND] += 0.05 * sin(1.0 + i + 2.0 * j);
  ws = make(G, U0);
  memcpy(ws.P, P0, sizeof P0);
  for (i = 0; i < ND; ++i)
    for (j = 0; j < ND; ++j) ws.U[i] += G[i + j * ND] * P0[j];
  cone_scales(&ws, NK, first, rho);
  cone_phi(&ws, NK, first, bias, rho, ws.P, ws.U, phi_p, J);
  for (j = 0; j < ND; ++j) {
    for (i = 0; i < ND; ++i) {
      Pp[i] = ws.P[i] + eps * (i == j);
      Pm[i] = ws.P[i] - eps * (i == j);
      Up[i] = ws.U[i] + eps * G[i + j * ND];
      Um[i] = ws.U[i] - eps * G[i + j * ND];
    }
    cone_phi(&ws, NK, first, bias, rho, Pp, Up, phi_p, 0);
    cone_phi(&ws, NK, first, bias, rho, Pm, Um, phi_m, 0);
    for (k = 0; k < ND; ++k) {
      const casadi_real fd = (phi_p[k] - phi_m[k]) / (2 * eps);
      CHECK(fabs(J[k * ND + j] - fd) < 1e-7, "dphi_%d/dP_%d = %.12g, differences %.12g", k, j, J[k * ND + j], fd);
    }
  }
}

/* Contact 0 slips, contact 1 sticks, contact 2 opens (G of coupled()):
 * P_N = (4/3, 4/3, 0) from the coupled normal rows, P_T0 = -mu P_N0 u with u the direction
 * of U0_T0 (G_TT = I: the slip keeps its direction), P_T1 = -U0_T1, P_2 = 0. */
static void test_solution(void) {
  casadi_real G[ND * ND], res, slip = sqrt(5.0), P[ND];
  const casadi_real U0[ND] = {-2, 2, 1, -2, 0.1, -0.05, 1, 0.3, 0.3};
  workspace ws;
  int i, start;
  coupled(G);
  for (i = 0; i < ND; ++i) P[i] = 0;
  P[0] = P[3] = 4.0 / 3;
  P[1] = -0.5 * P[0] * 2 / slip, P[2] = -0.5 * P[0] / slip;
  P[4] = -0.1, P[5] = 0.05;
  for (start = 0; start < 2; ++start) { /* from zero, then warm from a nearby point */
    ws = make(G, U0);
    if (start)
      for (i = 0; i < ND; ++i) {
        int j;
        ws.P[i] = P[i] * 1.1 + 0.01;
        for (j = 0; j < ND; ++j) ws.U[j] += G[j + i * ND] * ws.P[i];
      }
    CHECK(cone_newton(&ws, NK, first, bias, 1e-13, &res), "not converged from start %d: residual %g", start, res);
    CHECK(ws.fm == -1, "lcp_newton's factor not marked stale");
    for (i = 0; i < ND; ++i) CHECK(fabs(ws.P[i] - P[i]) < 1e-12, "P[%d] = %.15g, expected %.15g", i, ws.P[i], P[i]);
    CHECK(cone_residual(&ws, NK, first, bias) < 1e-13, "residual %g", cone_residual(&ws, NK, first, bias));
    CHECK(fabs(ws.U[0]) < 1e-12 && fabs(ws.U[3]) < 1e-12 && fabs(ws.U[6] - 1) < 1e-12, "normal velocities");
    CHECK(fabs(ws.U[1] - 2 * (1 - 0.5 * P[0] / slip)) < 1e-12, "slip velocity %.15g", ws.U[1]);
  }
}

/* Contacts 0 and 1 on the same rows (G's blocks all equal, singular): any split of the
 * impulse that stops the shared velocity; the dropped pivots leave a consistent solution. */
static void test_redundant(void) {
  casadi_real G[ND * ND], res;
  const casadi_real U0[ND] = {-1, 0.2, 0.1, -1, 0.2, 0.1, 1, 0, 0};
  workspace ws;
  int i, a, b;
  memset(G, 0, sizeof G);
  for (a = 0; a < 2; ++a)
    for (b = 0; b < 2; ++b)
      for (i = 0; i < 3; ++i) G[(3 * a + i) + (3 * b + i) * ND] = 1;
  for (i = 6; i < ND; ++i) G[i + i * ND] = 1;
  ws = make(G, U0);
  CHECK(cone_newton(&ws, NK, first, bias, 1e-13, &res), "redundant pair: residual %g", res);
  for (i = 0; i < 6; ++i) CHECK(fabs(ws.U[i]) < 1e-12, "U[%d] = %g", i, ws.U[i]);
  CHECK(fabs(ws.P[0] + ws.P[3] - 1) < 1e-12 && ws.P[0] >= -1e-15 && ws.P[3] >= -1e-15, "P_N = %g, %g", ws.P[0], ws.P[3]);
  CHECK(hypot(ws.P[1], ws.P[2]) <= 0.5 * ws.P[0] + 1e-12 && hypot(ws.P[4], ws.P[5]) <= 0.5 * ws.P[3] + 1e-12,
        "outside the cone");
}

/* The redundant pair of test_redundant() sticking, solved from an uneven warm start: its
 * solutions are P_0 + P_1 = the impulse that stops the shared velocity, and the one of least
 * norm splits it evenly (each contact P_N = 1/2, P_T = -U0_T / 2). */
static void test_min_norm(void) {
  casadi_real G[ND * ND], res;
  const casadi_real U0[ND] = {-1, 0.2, 0.1, -1, 0.2, 0.1, 1, 0, 0};
  const casadi_real warm[6] = {0.9, -0.3, 0.05, 0.1, 0.02, -0.03};
  workspace ws;
  int i, j, a, b;
  memset(G, 0, sizeof G);
  for (a = 0; a < 2; ++a)
    for (b = 0; b < 2; ++b)
      for (i = 0; i < 3; ++i) G[(3 * a + i) + (3 * b + i) * ND] = 1;
  for (i = 6; i < ND; ++i) G[i + i * ND] = 1;
  ws = make(G, U0);
  for (i = 0; i < 6; ++i) {
    ws.P[i] = warm[i];
    for (j = 0; j < ND; ++j) ws.U[j] += G[j + i * ND] * warm[i];
  }
  CHECK(cone_newton(&ws, NK, first, bias, 1e-13, &res), "redundant pair: residual %g", res);
  cone_min_norm(&ws, NK, first, bias, 1e-13);
  CHECK(ws.fm == -1, "lcp_newton's factor not marked stale");
  for (a = 0; a < 2; ++a) {
    CHECK(fabs(ws.P[3 * a] - 0.5) < 1e-14, "P_N%d = %.17g, expected 1/2", a, ws.P[3 * a]);
    CHECK(fabs(ws.P[3 * a + 1] + 0.1) < 1e-14 && fabs(ws.P[3 * a + 2] + 0.05) < 1e-14, "P_T%d = (%.17g, %.17g)", a,
          ws.P[3 * a + 1], ws.P[3 * a + 2]);
  }
  for (i = 0; i < 6; ++i) CHECK(fabs(ws.U[i]) < 1e-13, "U[%d] = %g", i, ws.U[i]);
  CHECK(cone_residual(&ws, NK, first, bias) < 1e-13, "residual %g", cone_residual(&ws, NK, first, bias));
}

/* The redundant pair of test_redundant() after a solve that left contact 1 touching with no
 * impulse (contact 0 alone stops the shared velocity, U = 0 on both): the laws let contact 1
 * carry a share, so the least-norm move takes it in and splits the impulse evenly. */
static void test_min_norm_touching(void) {
  casadi_real G[ND * ND];
  const casadi_real U0[ND] = {-1, 0.2, 0.1, -1, 0.2, 0.1, 1, 0, 0};
  const casadi_real solved[3] = {1, -0.2, -0.1};
  workspace ws;
  int i, j, a, b;
  memset(G, 0, sizeof G);
  for (a = 0; a < 2; ++a)
    for (b = 0; b < 2; ++b)
      for (i = 0; i < 3; ++i) G[(3 * a + i) + (3 * b + i) * ND] = 1;
  for (i = 6; i < ND; ++i) G[i + i * ND] = 1;
  ws = make(G, U0);
  for (i = 0; i < 3; ++i) {
    ws.P[i] = solved[i];
    for (j = 0; j < ND; ++j) ws.U[j] += G[j + i * ND] * solved[i];
  }
  cone_min_norm(&ws, NK, first, bias, 1e-13);
  for (a = 0; a < 2; ++a) {
    CHECK(fabs(ws.P[3 * a] - 0.5) < 1e-14, "P_N%d = %.17g, expected 1/2", a, ws.P[3 * a]);
    CHECK(fabs(ws.P[3 * a + 1] + 0.1) < 1e-14 && fabs(ws.P[3 * a + 2] + 0.05) < 1e-14, "P_T%d = (%.17g, %.17g)", a,
          ws.P[3 * a + 1], ws.P[3 * a + 2]);
  }
  for (i = 0; i < 6; ++i) CHECK(fabs(ws.U[i]) < 1e-13, "U[%d] = %g", i, ws.U[i]);
  /* again with a speck of impulse outside contact 1's cone (P_N = -1e-18, P_T = 1e-18, as
   * Newton's steps leave): it counts as none */
  ws = make(G, U0);
  for (i = 0; i < 3; ++i) {
    ws.P[i] = solved[i];
    for (j = 0; j < ND; ++j) ws.U[j] += G[j + i * ND] * solved[i];
  }
  ws.P[3] = -1e-18;
  ws.P[4] = 1e-18;
  cone_min_norm(&ws, NK, first, bias, 1e-13);
  for (a = 0; a < 2; ++a) CHECK(fabs(ws.P[3 * a] - 0.5) < 1e-14, "speck: P_N%d = %.17g, expected 1/2", a, ws.P[3 * a]);
}

/* Contacts 0 and 1 on opposite sides of one normal row (G_NN blocks [1 -1; -1 1]: a member
 * pressed between two stops), contact 1 touching with no impulse: the family's least-norm
 * member would pull contact 1 (-1/2), so the move falls back to the contacts with an
 * impulse (contact 0 alone: nothing to move) and the impulses stay as solved. */
static void test_min_norm_touching_pulled(void) {
  casadi_real G[ND * ND];
  const casadi_real U0[ND] = {-1, 0, 0, 1, 0, 0, 1, 0, 0};
  workspace ws;
  int i;
  memset(G, 0, sizeof G);
  for (i = 0; i < ND; ++i) G[i + i * ND] = 1;
  G[0 + 3 * ND] = G[3 + 0 * ND] = -1;
  ws = make(G, U0);
  ws.P[0] = 1;
  ws.U[0] = 0;
  ws.U[3] = 0;
  cone_min_norm(&ws, NK, first, bias, 1e-13);
  CHECK(ws.P[0] == 1 && ws.P[3] == 0, "P_N = %.17g, %.17g, expected 1, 0", ws.P[0], ws.P[3]);
  for (i = 0; i < ND; ++i) CHECK(ws.P[i] == (i == 0), "P[%d] = %g", i, ws.P[i]);
}

/* The redundant pair of test_redundant() sticking with an uneven split (0.7 / 0.3), and contact 2, not
 * coupled to it, slipping (P_N = 1, P_T = -mu P_N along U_T = (1, 0)): the slip fixes
 * contact 2's impulse but not the pair's, so the pair's group still moves to the even split
 * and contact 2 keeps its impulse (one least-norm move for the whole problem stopped at the
 * slipping contact and left 0.9 / 0.1). */
static void test_min_norm_per_group(void) {
  casadi_real G[ND * ND];
  const casadi_real U0[ND] = {-1, 0.2, 0.1, -1, 0.2, 0.1, -1, 1.5, 0};
  const casadi_real P[ND] = {0.7, -0.15, -0.07, 0.3, -0.05, -0.03, 1, -0.5, 0};
  workspace ws;
  int i, j, a, b;
  memset(G, 0, sizeof G);
  for (a = 0; a < 2; ++a)
    for (b = 0; b < 2; ++b)
      for (i = 0; i < 3; ++i) G[(3 * a + i) + (3 * b + i) * ND] = 1;
  for (i = 6; i < ND; ++i) G[i + i * ND] = 1;
  ws = make(G, U0);
  for (i = 0; i < ND; ++i) {
    ws.P[i] = P[i];
    for (j = 0; j < ND; ++j) ws.U[j] += G[j + i * ND] * P[i];
  }
  CHECK(cone_residual(&ws, NK, first, bias) < 1e-15, "not a solution: residual %g", cone_residual(&ws, NK, first, bias));
  cone_min_norm(&ws, NK, first, bias, 1e-13);
  for (a = 0; a < 2; ++a) {
    CHECK(fabs(ws.P[3 * a] - 0.5) < 1e-14, "P_N%d = %.17g, expected 1/2", a, ws.P[3 * a]);
    CHECK(fabs(ws.P[3 * a + 1] + 0.1) < 1e-14 && fabs(ws.P[3 * a + 2] + 0.05) < 1e-14, "P_T%d = (%.17g, %.17g)", a,
          ws.P[3 * a + 1], ws.P[3 * a + 2]);
  }
  for (i = 6; i < ND; ++i) CHECK(ws.P[i] == P[i], "slipping contact: P[%d] = %.17g, was %.17g", i, ws.P[i], P[i]);
  CHECK(fabs(ws.U[7] - 1) < 1e-15, "slip velocity %.17g", ws.U[7]);
  CHECK(cone_residual(&ws, NK, first, bias) < 1e-13, "residual %g", cone_residual(&ws, NK, first, bias));
}

/* Three contacts on a rank-4 Delassus matrix G = B B^T (B: 9 x 4, every contact coupled to
 * every other, five null directions: more than one dropped pivot, so the move's QR and
 * its reflections all take part), sticking (U = 0): from P = P* + n, P* in range(B) inside
 * the cones and n in null(B^T), the least-norm member of P + null(G) is P* (the reference:
 * n made orthogonal to B's columns by Gram-Schmidt here, independently of the solver). */
static void test_min_norm_rank_deficient(void) {
  const casadi_real Ps[ND] = {1, 0.1, -0.2, 0.8, -0.15, 0.05, 1.2, 0.3, 0.1};
  casadi_real B[4][ND], E[4][ND], n[ND] = {0.3, -0.7, 0.2, 0.5, 0.1, -0.4, 0.6, -0.2, 0.9}, G[ND * ND], s;
  workspace ws;
  int i, j, a, b;
  for (i = 0; i < ND; ++i) { /* B = [P*, three fixed columns] */
    B[0][i] = Ps[i];
    B[1][i] = sin(1.0 + 3 * i);
    B[2][i] = cos(0.5 + 2 * i * i);
    B[3][i] = 0.1 * i - 0.4;
  }
  for (a = 0; a < 4; ++a) { /* E: orthonormal columns spanning range(B) */
    memcpy(E[a], B[a], sizeof E[a]);
    for (b = 0; b < a; ++b) {
      for (s = 0, i = 0; i < ND; ++i) s += E[b][i] * E[a][i];
      for (i = 0; i < ND; ++i) E[a][i] -= s * E[b][i];
    }
    for (s = 0, i = 0; i < ND; ++i) s += E[a][i] * E[a][i];
    for (i = 0; i < ND; ++i) E[a][i] /= sqrt(s);
  }
  for (a = 0; a < 4; ++a) { /* n -= E E^T n, then |n| = 0.05 */
    for (s = 0, i = 0; i < ND; ++i) s += E[a][i] * n[i];
    for (i = 0; i < ND; ++i) n[i] -= s * E[a][i];
  }
  for (s = 0, i = 0; i < ND; ++i) s += n[i] * n[i];
  for (i = 0; i < ND; ++i) n[i] *= 0.05 / sqrt(s);
  for (i = 0; i < ND; ++i)
    for (j = 0; j < ND; ++j) {
      for (s = 0, a = 0; a < 4; ++a) s += B[a][i] * B[a][j];
      G[i + j * ND] = s;
    }
  ws = make(G, (const casadi_real[ND]){0});
  for (i = 0; i < ND; ++i) ws.P[i] = Ps[i] + n[i];
  cone_min_norm(&ws, NK, first, bias, 1e-13);
  for (i = 0; i < ND; ++i) CHECK(fabs(ws.P[i] - Ps[i]) < 1e-13, "P[%d] = %.17g, expected %.17g", i, ws.P[i], Ps[i]);
  for (i = 0; i < ND; ++i) CHECK(fabs(ws.U[i]) < 1e-13, "U[%d] = %g", i, ws.U[i]);
}

/* cone_qr() on a 9 x 7 lower-trapezoidal matrix (the kept columns of a Cholesky factor: column
 * j zero above row j + j/3) takes its columns four at a time and then one by one: Q R gives
 * the matrix back (Q applied as the product of its reflections), R is upper triangular and
 * Q keeps lengths (orthogonal), to round-off. */
static void test_qr(void) {
  enum { M = 9, R = 7 };
  casadi_real C[M * R], C0[M * R], beta[R], x[M], y[M], nx = 0, ny = 0;
  int i, j;
  for (j = 0; j < R; ++j)
    for (i = 0; i < M; ++i) C0[i + j * M] = i < j + j / 3 ? 0 : 1 + sin(3.0 * i + 7.0 * j) / (1 + i - j);
  memcpy(C, C0, sizeof C);
  cone_qr(C, M, R, beta);
  for (j = 0; j < R; ++j) {
    for (i = 0; i < M; ++i) x[i] = i <= j ? C[i + j * M] : 0; /* column j of R */
    for (i = R - 1; i >= 0; --i) cone_reflect(C, M, i, beta[i], x); /* Q R_j = H_0 ... H_{R-1} R_j */
    for (i = 0; i < M; ++i)
      CHECK(fabs(x[i] - C0[i + j * M]) < 1e-14, "(Q R)[%d][%d] = %.17g, expected %.17g", i, j, x[i], C0[i + j * M]);
  }
  for (i = 0; i < M; ++i) {
    y[i] = x[i] = cos(1.0 + i);
    nx += x[i] * x[i];
  }
  for (i = R - 1; i >= 0; --i) cone_reflect(C, M, i, beta[i], y);
  for (i = 0; i < M; ++i) ny += y[i] * y[i];
  CHECK(fabs(sqrt(ny) - sqrt(nx)) < 1e-14 * sqrt(nx), "|Q x| = %.17g, |x| = %.17g", sqrt(ny), sqrt(nx));
}

/* cone_lm() with a J of two decoupled blocks (rows and columns 0-3 and 4-8: H = J^T J is
 * block diagonal, and its Cholesky factor's rows start at their block) against the equations
 * it solves, (J^T J + |phi| I) dP = -J^T phi, formed densely here. */
static void test_lm(void) {
  enum { M = 9 };
  casadi_real J[M * M], H[M * M], g[M], dP[M], phi[M], lambda = 0;
  casadi_int cols[M], start[M];
  int i, j, k;
  for (i = 0; i < M; ++i) {
    phi[i] = 0.3 - 0.1 * i;
    lambda += phi[i] * phi[i];
    for (j = 0; j < M; ++j)
      J[i * M + j] = (i < 4) == (j < 4) && (i == j || (i + j) % 3 == 0) ? 1 + 0.25 * sin(1.0 + i + 2.0 * j) : 0;
  }
  lambda = sqrt(lambda);
  CHECK(cone_lm(J, phi, H, g, dP, M, cols, start), "no step");
  for (i = 4; i < M; ++i) CHECK(start[i] >= 4, "row %d of the factor starts at %d, in the other block", i, (int) start[i]);
  for (i = 0; i < M; ++i) {
    casadi_real r = lambda * dP[i];
    for (k = 0; k < M; ++k) { /* (J^T J dP)_i + (J^T phi)_i */
      casadi_real jdp = 0;
      for (j = 0; j < M; ++j) jdp += J[k * M + j] * dP[j];
      r += J[k * M + i] * (jdp + phi[k]);
    }
    CHECK(fabs(r) < 1e-14, "residual of row %d: %g", i, r);
  }
}

int main(void) {
  test_jacobian();
  test_solution();
  test_redundant();
  test_min_norm();
  test_min_norm_touching();
  test_min_norm_touching_pulled();
  test_min_norm_per_group();
  test_min_norm_rank_deficient();
  test_qr();
  test_lm();
  return report("test_cone_newton");
}

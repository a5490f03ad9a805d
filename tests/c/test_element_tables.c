/* Unit tests of the table loops (ncgen_element_tables.h) on hand-written kernels of a tiny
 * planar model, q = (q0, q1, q2, q3):
 *
 *   member 0, a bar (kind BAR): ends r1 = (1, 0) (a ground point: columns -1) and r2 = (q0, q1);
 *       Φ_0 = |r2 − r1|² − L²;  M_I = m/3 [[2I, I], [I, 2I]] (uniform bar, coordinates r1, r2)
 *   member 1, a point (kind POINT): p = (q2, q3), no constraint; M_I = m I
 *   joint element 0, DISTANCE(f0 = r2, f1 = p; D):  Φ_1 = |f1 − f0|² − D²
 *   joint element 1, COINCIDENCE(f2 = (q2/2 + q0/2, q3), f3 = (0, 2)): Φ_2 = q2/2 + q0/2, its
 *       second output left out of the model (row -1)
 *
 * A and M are stored dense in column-major order as their "CSC" pattern (every entry), so the
 * expected positions are (column · rows + row).  Checked: Φ, A and M against the closed forms,
 * A against central differences of Φ, γ against those of A v, Φ_t = 0, the checks of inconsistent tables, a failing
 * kernel.  Built and run by tests/test_stepper_runtime_c.py under AddressSanitizer and
 * UndefinedBehaviorSanitizer. */
#include "check.h"
#include "ncgen_element_tables.h"

#define L 1.5
#define D 0.7
#define MASS 2.0
#define MASS_POINT 0.3

static int fail_kernel = 0;

/* Joint kind 0: distance (2D): x = (f0, f1, D) -> phi, J = dphi/d(f0, f1) (1 x 4). */
static int k_distance(const double **arg, double **res, long long *iw, double *w, int mem) {
  const double *x = arg[0];
  double dx = x[2] - x[0], dy = x[3] - x[1];
  (void)iw; (void)w; (void)mem;
  if (fail_kernel) return 1;
  res[0][0] = dx * dx + dy * dy - x[4] * x[4];
  res[1][0] = -2 * dx; res[1][1] = -2 * dy; res[1][2] = 2 * dx; res[1][3] = 2 * dy;
  return 0;
}

/* Its Hessian-vector products: (x, fdot) -> 2 |fdot1 - fdot0|². */
static int k_distance_hvv(const double **arg, double **res, long long *iw, double *w, int mem) {
  const double *fd = arg[1];
  (void)iw; (void)w; (void)mem;
  res[0][0] = 2 * ((fd[2] - fd[0]) * (fd[2] - fd[0]) + (fd[3] - fd[1]) * (fd[3] - fd[1]));
  return 0;
}

/* Joint kind 1: coincidence (2D): x = (f0, f1) -> phi = f0 - f1 (2), J (2 x 4, column-major). */
static int k_coincidence(const double **arg, double **res, long long *iw, double *w, int mem) {
  const double *x = arg[0];
  int i;
  (void)iw; (void)w; (void)mem;
  res[0][0] = x[0] - x[2];
  res[0][1] = x[1] - x[3];
  for (i = 0; i < 8; ++i) res[1][i] = 0;
  res[1][0] = 1; res[1][3] = 1; res[1][4] = -1; res[1][7] = -1;
  return 0;
}

static int k_coincidence_hvv(const double **arg, double **res, long long *iw, double *w, int mem) {
  (void)arg; (void)iw; (void)w; (void)mem;
  res[0][0] = res[0][1] = 0;
  return 0;
}

/* Member kind 0: bar (rr, 2D): (q_I, c = (L, m)) -> phi, J (1 x 4); (q̇_I, c) -> 2 |ṙ2 − ṙ1|²;
 * c -> M_I (4 x 4). */
static int k_bar_hvv(const double **arg, double **res, long long *iw, double *w, int mem) {
  const double *v = arg[0];
  (void)iw; (void)w; (void)mem;
  res[0][0] = 2 * ((v[2] - v[0]) * (v[2] - v[0]) + (v[3] - v[1]) * (v[3] - v[1]));
  return 0;
}

static int k_bar_phi(const double **arg, double **res, long long *iw, double *w, int mem) {
  const double *q = arg[0], *c = arg[1];
  double dx = q[2] - q[0], dy = q[3] - q[1];
  (void)iw; (void)w; (void)mem;
  res[0][0] = dx * dx + dy * dy - c[0] * c[0];
  res[1][0] = -2 * dx; res[1][1] = -2 * dy; res[1][2] = 2 * dx; res[1][3] = 2 * dy;
  return 0;
}

static int k_bar_mass(const double **arg, double **res, long long *iw, double *w, int mem) {
  double m = arg[0][1];
  int i, j;
  (void)iw; (void)w; (void)mem;
  for (j = 0; j < 4; ++j)
    for (i = 0; i < 4; ++i)
      res[0][j * 4 + i] = (i % 2 == j % 2) ? m / 3 * (i / 2 == j / 2 ? 2 : 1) : 0;
  return 0;
}

/* Member kind 1: point (2D): c = (m) -> M_I = m I. */
static int k_point_mass(const double **arg, double **res, long long *iw, double *w, int mem) {
  (void)iw; (void)w; (void)mem;
  res[0][0] = res[0][3] = arg[0][0];
  res[0][1] = res[0][2] = 0;
  return 0;
}

static const ncgen_joint_kind JOINTS[2] = {{k_distance, k_distance_hvv, 2, 2, 1, 1},
                                           {k_coincidence, k_coincidence_hvv, 2, 2, 0, 2}};
static const ncgen_member_kind MEMBERS[2] = {{k_bar_phi, k_bar_hvv, k_bar_mass, 4, 2, 1},
                                             {0, 0, k_point_mass, 2, 1, 0}};
static const ncgen_kinds KINDS = {JOINTS, 2, MEMBERS, 2, 1};

#define NQ 4
#define NC 3

/* features: f0 = r2 = (q0, q1), f1 = p = (q2, q3), f2 = (q2/2 + q0/2, q3), f3 = (0, 2) */
static int feat_ptr[] = {0, 2, 4, 7, 7};
static int feat_row[] = {0, 1, 0, 1, 0, 0, 1};
static int feat_col[] = {0, 1, 2, 3, 2, 0, 3};
static double feat_coef[] = {1, 1, 1, 1, 0.5, 0.5, 1};
static double feat_const[] = {0, 0, 0, 0, 0, 0, 0, 2};
static int el_kind[] = {0, 1}, el_arg_ptr[] = {0, 2, 4}, el_arg[] = {0, 1, 2, 3}, el_sc_ptr[] = {0, 1, 1};
static double el_sc[] = {D};
static int el_row_ptr[] = {0, 1, 3}, el_row[] = {1, 2, -1};
/* row 1: f0 (col 0, 1), f1 (col 2, 3); row 2: f2 (col 2, 0, 3) */
static int el_apos_ptr[] = {0, 4, 7}, el_apos[] = {0 * NC + 1, 1 * NC + 1, 2 * NC + 1, 3 * NC + 1,
                                                    2 * NC + 2, 0 * NC + 2, 3 * NC + 2};
static int mem_kind[] = {0, 1}, mem_q_ptr[] = {0, 4, 6}, mem_q_col[] = {-1, -1, 0, 1, 2, 3};
static double mem_q_const[] = {1, 0, 0, 0, 0, 0};
static int mem_c_ptr[] = {0, 2, 3};
static double mem_c[] = {L, MASS, MASS_POINT};
static int mem_row_ptr[] = {0, 1, 1}, mem_row[] = {0};
static int mem_apos_ptr[] = {0, 2, 2}, mem_apos[] = {0 * NC + 0, 1 * NC + 0};
static int mem_mpos_ptr[] = {0, 4, 8}, mem_mpos[] = {0 * NQ + 0, 0 * NQ + 1, 1 * NQ + 0, 1 * NQ + 1,
                                                     2 * NQ + 2, 2 * NQ + 3, 3 * NQ + 2, 3 * NQ + 3};

static ncgen_tables tables(void) {
  ncgen_tables T = {NQ, NC, 2, NC * NQ, NQ * NQ, 4, feat_ptr, feat_row, feat_col, feat_coef, feat_const,
                    2, el_kind, el_arg_ptr, el_arg, el_sc_ptr, el_sc, el_row_ptr, el_row, el_apos_ptr, el_apos,
                    2, mem_kind, mem_q_ptr, mem_q_col, mem_q_const, mem_c_ptr, mem_c, mem_row_ptr, mem_row,
                    mem_apos_ptr, mem_apos, mem_mpos_ptr, mem_mpos};
  return T;
}

static void expected(const double *q, double *phi, double *A) {
  int i;
  phi[0] = (q[0] - 1) * (q[0] - 1) + q[1] * q[1] - L * L;
  phi[1] = (q[2] - q[0]) * (q[2] - q[0]) + (q[3] - q[1]) * (q[3] - q[1]) - D * D;
  phi[2] = 0.5 * q[2] + 0.5 * q[0];
  for (i = 0; i < NC * NQ; ++i) A[i] = 0;
  A[0 * NC + 0] = 2 * (q[0] - 1); A[1 * NC + 0] = 2 * q[1];
  A[0 * NC + 1] = -2 * (q[2] - q[0]); A[1 * NC + 1] = -2 * (q[3] - q[1]);
  A[2 * NC + 1] = 2 * (q[2] - q[0]); A[3 * NC + 1] = 2 * (q[3] - q[1]);
  A[0 * NC + 2] = 0.5; A[2 * NC + 2] = 0.5;
}

static void test_values(void) {
  ncgen_tables T = tables();
  double q[NQ] = {0.3, -1.2, 0.9, 0.4}, phi[NC], A[NC * NQ], M[NQ * NQ], phi_t[NC];
  double phi_x[NC], A_x[NC * NQ], fd[NC], p1[NC], p2[NC], work[64];
  int i, j;
  CHECK(ncgen_tables_check(&KINDS, &T) == 0, "consistent tables");
  CHECK(ncgen_tables_work_size(&KINDS, &T) <= 64, "work size %ld", ncgen_tables_work_size(&KINDS, &T));
  CHECK(ncgen_tables_phi(&KINDS, &T, q, phi, work) == 0, "phi");
  CHECK(ncgen_tables_jacobian(&KINDS, &T, q, A, work) == 0, "A");
  expected(q, phi_x, A_x);
  for (i = 0; i < NC; ++i) CHECK(fabs(phi[i] - phi_x[i]) < 1e-15, "phi[%d] = %g, expected %g", i, phi[i], phi_x[i]);
  for (i = 0; i < NC * NQ; ++i) CHECK(fabs(A[i] - A_x[i]) < 1e-15, "A nz %d = %g, expected %g", i, A[i], A_x[i]);
  for (j = 0; j < NQ; ++j) {       /* A against central differences of phi */
    double h = 1e-6, qp[NQ], qm[NQ];
    memcpy(qp, q, sizeof q); memcpy(qm, q, sizeof q);
    qp[j] += h; qm[j] -= h;
    ncgen_tables_phi(&KINDS, &T, qp, p1, work);
    ncgen_tables_phi(&KINDS, &T, qm, p2, work);
    for (i = 0; i < NC; ++i) {
      fd[i] = (p1[i] - p2[i]) / (2 * h);
      CHECK(fabs(fd[i] - A[j * NC + i]) < 1e-8, "dphi_%d/dq_%d = %g by differences, A: %g", i, j, fd[i], A[j * NC + i]);
    }
  }
  {                                /* γ = −(∂(A v)/∂q) v by central differences of A v */
    double v[NQ] = {0.7, -0.2, 0.5, 1.1}, g[NC], h = 1e-6, qp[NQ], qm[NQ], Ap[NC * NQ], Am[NC * NQ];
    CHECK(ncgen_tables_gamma(&KINDS, &T, q, v, g, work) == 0, "gamma");
    for (j = 0; j < NQ; ++j) { qp[j] = q[j] + h * v[j]; qm[j] = q[j] - h * v[j]; }
    ncgen_tables_jacobian(&KINDS, &T, qp, Ap, work);
    ncgen_tables_jacobian(&KINDS, &T, qm, Am, work);
    for (i = 0; i < NC; ++i) {
      double d = 0;
      for (j = 0; j < NQ; ++j) d += (Ap[j * NC + i] - Am[j * NC + i]) / (2 * h) * v[j];
      CHECK(fabs(g[i] + d) < 1e-8, "gamma[%d] = %g, -(dA/dq v) v = %g", i, g[i], -d);
    }
    CHECK(fabs(g[0] + 2 * (v[0] * v[0] + v[1] * v[1])) < 1e-14, "the bar's gamma in closed form: %g", g[0]);
  }
  CHECK(ncgen_tables_phi_t(&T, phi_t) == 0, "phi_t");
  for (i = 0; i < NC; ++i) CHECK(phi_t[i] == 0, "phi_t[%d] = %g", i, phi_t[i]);
  CHECK(ncgen_tables_mass(&KINDS, &T, M, work) == 0, "mass");
  CHECK(fabs(M[0] - 2 * MASS / 3) < 1e-15 && fabs(M[5] - 2 * MASS / 3) < 1e-15, "bar's free end: 2m/3, got %g %g",
        M[0], M[5]);
  CHECK(M[1] == 0 && M[4] == 0, "no coupling of x and y");
  CHECK(M[10] == MASS_POINT && M[15] == MASS_POINT && M[11] == 0 && M[14] == 0, "the point's m I");
  for (i = 0; i < 2; ++i)
    for (j = 2; j < 4; ++j) CHECK(M[j * NQ + i] == 0 && M[i * NQ + j] == 0, "no coupling of bar and point");
}

static void test_checks_and_failures(void) {
  ncgen_tables T = tables();
  double q[NQ] = {0, 0, 0, 0}, phi[NC], work[64];
  int bad_col[] = {0, 1, 2, 4, 2, 0, 3};           /* column 4 of nq = 4 */
  int bad_sc_ptr[] = {0, 0, 0};                     /* the distance element without its scalar */
  int bad_apos[] = {0 * NC + 1, 1 * NC + 1, 2 * NC + 1, 3 * NC + 1, 2 * NC + 2, 0 * NC + 2, NC * NQ};
  int bad_kind[] = {0, 2};
  int bad_row[] = {1, 3, -1};                       /* row 3 of nc = 3 */
  int bad_mpos_ptr[] = {0, 4, 7};                   /* the point's M_I with 3 entries */
  T.feat_col = bad_col;
  CHECK(ncgen_tables_check(&KINDS, &T) == NCGEN_TABLES_BAD, "column out of range");
  T = tables(); T.el_sc_ptr = bad_sc_ptr;
  CHECK(ncgen_tables_check(&KINDS, &T) == NCGEN_TABLES_BAD, "scalars of an element");
  T = tables(); T.el_apos = bad_apos;
  CHECK(ncgen_tables_check(&KINDS, &T) == NCGEN_TABLES_BAD, "position beyond the nonzeros of A");
  T = tables(); T.el_kind = bad_kind;
  CHECK(ncgen_tables_check(&KINDS, &T) == NCGEN_TABLES_BAD, "unknown kind");
  T = tables(); T.el_row = bad_row;
  CHECK(ncgen_tables_check(&KINDS, &T) == NCGEN_TABLES_BAD, "row out of range");
  T = tables(); T.mem_mpos_ptr = bad_mpos_ptr;
  CHECK(ncgen_tables_check(&KINDS, &T) == NCGEN_TABLES_BAD, "mass positions of a member");
  T = tables(); T.dim = 3;
  CHECK(ncgen_tables_check(&KINDS, &T) == NCGEN_TABLES_BAD, "kinds of another dimension");
  T = tables();
  fail_kernel = 1;
  CHECK(ncgen_tables_phi(&KINDS, &T, q, phi, work) == NCGEN_TABLES_KERNEL, "a failing kernel is reported");
  fail_kernel = 0;
}

int main(void) {
  test_values();
  test_checks_and_failures();
  return report("test_element_tables");
}

/* Unit tests of the table-driven stepper (ncgen_table_stepper.h, with the RATTLE runtime it
 * includes) on hand-written kernels and tables of a tiny planar model, q = p = (q0, q1):
 *
 *   member 0, a point of mass MASS (kind POINT): M = MASS I, no constraint;
 *   joint element 0, DISTANCE(f1 = the origin, f0 = p; L):  Φ = |p|² − L²  (a pendulum);
 *   gravity: f_gravity = (0, −MASS G);
 *   one spring-damper from the ground point f2 = ANCHOR to p (k, l0, c), marker p;
 *   with c > 0 also a drag −(c/2) ṗ (a force element over the feature p), a constant force
 *   (c/4, 0) and a tangential push (c/8)(−p1, p0) (a torque element on member 0).
 *
 * Checked: the element loops on these tables; the Newton matrix K of step_newton against central differences of its
 * residual r (the damper's and the drag's ∂F/∂v in it); undamped, 2000 RATTLE steps keep Φ ≤ 1e-9
 * and the energy to 1e-6; damped, the energy lost equals the work of the damper, drag, force and
 * push that the stepper integrates (step_power, to 1e-4), and the energy decreases; one step, and an error-controlled run on the constraint;
 * all of it with the QR alone and with the sparse LU (ncgen_sparse_lu.h), the two runs equal
 * to round-off with the same Newton iterations; a singular K (at q = 0, A = 0) reported as
 * STEP_NOT_FINITE.  Built and run
 * by tests/test_stepper_runtime_c.py under AddressSanitizer and UndefinedBehaviorSanitizer. */
#include "check.h"
#include "stepper_decls.h"

#include "ncgen_element_tables.h"

#define L 0.9
#define MASS 1.7
#define G 9.81

/* Joint kind 0: distance (2D): x = (f0, f1, L) -> phi = |f1 - f0|² - L², J (1 x 4). */
static int k_distance(const double **arg, double **res, long long *iw, double *w, int mem) {
  const double *x = arg[0];
  double dx = x[2] - x[0], dy = x[3] - x[1];
  (void)iw; (void)w; (void)mem;
  res[0][0] = dx * dx + dy * dy - x[4] * x[4];
  res[1][0] = -2 * dx; res[1][1] = -2 * dy; res[1][2] = 2 * dx; res[1][3] = 2 * dy;
  return 0;
}

static int k_distance_hvv(const double **arg, double **res, long long *iw, double *w, int mem) {
  const double *fd = arg[1];
  (void)iw; (void)w; (void)mem;
  res[0][0] = 2 * ((fd[2] - fd[0]) * (fd[2] - fd[0]) + (fd[3] - fd[1]) * (fd[3] - fd[1]));
  return 0;
}

/* Member kind 0: a planar point, c = (m,) -> M_I = m I. */
static int k_point_mass(const double **arg, double **res, long long *iw, double *w, int mem) {
  (void)iw; (void)w; (void)mem;
  res[0][0] = res[0][3] = arg[0][0];
  res[0][1] = res[0][2] = 0;
  return 0;
}

/* The spring kernel (2D): x = (r_a, r_b, v_a, v_b, k, l0, c) -> y = (f, V, P), J = df/d(r_a, r_b,
 * v_a, v_b) (2 x 8, column-major): f = -(k (l - l0) + c l') d / l, d = r_b - r_a. */
static int k_spring(const double **arg, double **res, long long *iw, double *w, int mem) {
  const double *x = arg[0];
  double d[2], dv[2], l, rate, T, k = x[8], l0 = x[9], c = x[10], *J = res[1];
  int i, j;
  (void)iw; (void)w; (void)mem;
  for (i = 0; i < 2; ++i) {
    d[i] = x[2 + i] - x[i];
    dv[i] = x[6 + i] - x[4 + i];
  }
  l = sqrt(d[0] * d[0] + d[1] * d[1]);
  rate = (d[0] * dv[0] + d[1] * dv[1]) / l;
  T = k * (l - l0) + c * rate;
  for (i = 0; i < 2; ++i) res[0][i] = -T * d[i] / l;
  res[0][2] = 0.5 * k * (l - l0) * (l - l0);
  res[0][3] = -c * rate * rate;
  for (i = 0; i < 2; ++i)          /* f_i = -T d_i / l */
    for (j = 0; j < 2; ++j) {
      double dl = d[j] / l, drate = dv[j] / l - rate * d[j] / (l * l);
      double dT_dd = k * dl + c * drate, dfi_dd = -dT_dd * d[i] / l - T * ((i == j) / l - d[i] * d[j] / (l * l * l));
      double dfi_ddv = -c * (d[j] / l) * d[i] / l;
      J[i + 2 * j] = -dfi_dd;           /* d/dr_a = -d/dd */
      J[i + 2 * (2 + j)] = dfi_dd;
      J[i + 2 * (4 + j)] = -dfi_ddv;
      J[i + 2 * (6 + j)] = dfi_ddv;
    }
  return 0;
}

static const ncgen_joint_kind JOINT_KINDS[1] = {{k_distance, k_distance_hvv, 2, 2, 1, 1}};
static const ncgen_member_kind MEMBER_KINDS[1] = {{0, 0, k_point_mass, 2, 1, 0}};
static const ncgen_kinds KINDS = {JOINT_KINDS, 1, MEMBER_KINDS, 1, 0};

/* Force kind over features 0: a viscous drag on one point, x = (r, ṙ, c) -> y = (g = −c ṙ, V = 0,
 * P = ṙ·g), J = ∂g/∂ṙ = −c I. */
static int k_drag(const double **arg, double **res, long long *iw, double *w, int mem) {
  const double *x = arg[0];
  (void)iw; (void)w; (void)mem;
  res[0][0] = -x[4] * x[2];
  res[0][1] = -x[4] * x[3];
  res[0][2] = 0;
  res[0][3] = x[2] * res[0][0] + x[3] * res[0][1];
  res[1][0] = res[1][3] = -x[4];
  res[1][1] = res[1][2] = 0;
  return 0;
}

/* Torque kind of member kind 0 (a stand-in: a point has no W): x = (q_I, τ) -> Q = τ (−q1, q0),
 * a tangential push about the origin. */
static int k_twist(const double **arg, double **res, long long *iw, double *w, int mem) {
  const double *x = arg[0];
  (void)iw; (void)w; (void)mem;
  res[0][0] = -x[2] * x[1];
  res[0][1] = x[2] * x[0];
  return 0;
}

static const ncgen_feature_force_kind FEATURE_FORCE_KINDS[1] = {{k_drag, 2, 1, 1}};
static const ncgen_torque_kind TORQUE_KINDS[1] = {{k_twist, 0}};

#define TAB_KINDS (&KINDS)
#define TAB_SPRING_3D k_spring
#define TAB_SPRING_2D k_spring
#define TAB_FEATURE_FORCES FEATURE_FORCE_KINDS
#define TAB_TORQUES TORQUE_KINDS
#define TAB_FF_IN 5
#define TAB_FF_OUT 8
#define MAX_HALVINGS 10
#define NSTATS 12

#include "ncgen_table_stepper.h"

/* The model's tables (see the top of the file). */
static const int feat_ptr[] = {0, 2, 2, 2}, feat_row[] = {0, 1}, feat_col[] = {0, 1};
static const double feat_coef[] = {1, 1}, feat_const[] = {0, 0, 0, 0, 0.5, 0.3};
static const int el_kind[] = {0}, el_arg_ptr[] = {0, 2}, el_arg[] = {1, 0}, el_sc_ptr[] = {0, 1};
static const double el_sc[] = {L};
static const int el_row_ptr[] = {0, 1}, el_row[] = {0}, el_apos_ptr[] = {0, 2}, el_apos[] = {0, 1};
static const int mem_kind[] = {0}, mem_q_ptr[] = {0, 2}, mem_q_col[] = {0, 1};
static const double mem_q_const[] = {0, 0};
static const int mem_c_ptr[] = {0, 1};
static const double mem_c[] = {MASS};
static const int mem_row_ptr[] = {0, 0}, mem_row[] = {-1}, mem_apos_ptr[] = {0, 0}, mem_apos[] = {0},
                 mem_mpos_ptr[] = {0, 4}, mem_mpos[] = {0, 1, 2, 3};
/* K (3 x 3) dense in CSC: entry (r, c) is nonzero c * 3 + r; V lower and R upper triangles. */
static const int k_colind[] = {0, 3, 6, 9}, k_row[] = {0, 1, 2, 0, 1, 2, 0, 1, 2};
static const int v_colind[] = {0, 3, 5, 6}, v_row[] = {0, 1, 2, 1, 2, 2};
static const int r_colind[] = {0, 1, 3, 6}, r_row[] = {0, 0, 1, 0, 1, 2};
static const int perm[] = {0, 1, 2};
/* The LU's analysis of the same K in identity order (the multiplier after both coordinates):
 * L and U whole strict triangles, U(k, c) = L(c, k). */
static const int l_colind[] = {0, 2, 3, 3}, l_row[] = {1, 2, 2}, u_colind[] = {0, 0, 1, 3}, u_row[] = {0, 0, 1},
                 u_lpos[] = {0, 1, 2};
static int with_lu;                /* whether make_tables gives the LU's analysis (else QR only) */
static const int a_colind[] = {0, 1, 2}, a_row[] = {0, 0}, m_colind[] = {0, 2, 4}, m_row[] = {0, 1, 0, 1};
static const double m_val[] = {MASS, 0, 0, MASS}, f_gravity[] = {0, -MASS * G};
static const int spr_feat[] = {2, 0}, spr_kpos_ptr[] = {0, 4}, spr_kpos[] = {0, 3, 1, 4}, marker_feat[] = {0};
/* the damper's products: J = ∂f/∂[r_a; r_b; ṙ_a; ṙ_b] (2 x 8), ∂f_i/∂ṙ_b,j at i + 2 (6 + j) */
static const int spr_kj[] = {12, 14, 13, 15};
static const double spr_kcoef[] = {1, 1, 1, 1};
static const int k_mpos[] = {0, 1, 3, 4}, k_apos[] = {2, 5}, k_atpos[] = {6, 7};
static double f_const[2], ff_par[1], tq_val[1];
static const int ff_kind[] = {0}, ff_feat_ptr[] = {0, 1}, ff_feat[] = {0}, ff_par_ptr[] = {0, 1};
static const int ff_kpos_ptr[] = {0, 4}, ff_kpos[] = {0, 3, 1, 4}, tq_member[] = {0}, tq_c_ptr[] = {0, 0};
static const int ff_kj[] = {0, 2, 1, 3};   /* J = ∂g/∂ḟ (2 x 2), column-major */

static ncgen_tables T;
static ncgen_stepper_tables S;

static void make_tables(double k, double l0, double c, double *par) {
  T.nq = 2; T.nc = 1; T.dim = 2; T.a_nnz = 2; T.m_nnz = 4; T.nf = 3;
  T.feat_ptr = feat_ptr; T.feat_row = feat_row; T.feat_col = feat_col; T.feat_coef = feat_coef;
  T.feat_const = feat_const;
  T.ne = 1; T.el_kind = el_kind; T.el_arg_ptr = el_arg_ptr; T.el_arg = el_arg; T.el_sc_ptr = el_sc_ptr;
  T.el_sc = el_sc; T.el_row_ptr = el_row_ptr; T.el_row = el_row; T.el_apos_ptr = el_apos_ptr; T.el_apos = el_apos;
  T.nm = 1; T.mem_kind = mem_kind; T.mem_q_ptr = mem_q_ptr; T.mem_q_col = mem_q_col; T.mem_q_const = mem_q_const;
  T.mem_c_ptr = mem_c_ptr; T.mem_c = mem_c; T.mem_row_ptr = mem_row_ptr; T.mem_row = mem_row;
  T.mem_apos_ptr = mem_apos_ptr; T.mem_apos = mem_apos; T.mem_mpos_ptr = mem_mpos_ptr; T.mem_mpos = mem_mpos;
  par[0] = k; par[1] = l0; par[2] = c;
  S.T = &T; S.nu = 0; S.np = 0; S.n_markers = 1; S.n_spring = 1; S.mass_scale = MASS; S.m_nnz = 4;
  S.a_colind = a_colind; S.a_row = a_row; S.m_colind = m_colind; S.m_row = m_row; S.m_val = m_val;
  S.f_gravity = f_gravity; S.v_gravity = 0; S.spr_feat = spr_feat; S.spr_par = par;
  S.spr_kpos_ptr = spr_kpos_ptr; S.spr_kpos = spr_kpos; S.spr_kcoef = spr_kcoef; S.spr_kj = spr_kj; S.marker_feat = marker_feat;
  S.nnz_k = 9; S.nnz_v = 6; S.nnz_r = 6; S.k_mpos = k_mpos; S.k_apos = k_apos; S.k_atpos = k_atpos;
  f_const[0] = c / 4; f_const[1] = 0; ff_par[0] = c / 2; tq_val[0] = c / 8;   /* c = 0: conservative */
  S.f_const = f_const; S.n_ff = 1; S.ff_kind = ff_kind; S.ff_feat_ptr = ff_feat_ptr; S.ff_feat = ff_feat;
  S.ff_par_ptr = ff_par_ptr; S.ff_par = ff_par; S.ff_kpos_ptr = ff_kpos_ptr; S.ff_kpos = ff_kpos; S.ff_kcoef = spr_kcoef; S.ff_kj = ff_kj;
  S.n_torque = 1; S.tq_member = tq_member; S.tq_c_ptr = tq_c_ptr; S.tq_c = ff_par; S.tq_val = tq_val;
  S.qr.n = 3; S.qr.k_colind = k_colind; S.qr.k_row = k_row; S.qr.v_colind = v_colind; S.qr.v_row = v_row;
  S.qr.r_colind = r_colind; S.qr.r_row = r_row; S.qr.prinv = perm; S.qr.pc = perm;
  S.lu.n = with_lu ? 3 : 0; S.lu.nnz_l = 3; S.lu.k_colind = k_colind; S.lu.k_prow = k_row; S.lu.p = perm;
  S.lu.pinv = perm; S.lu.l_colind = l_colind; S.lu.l_row = l_row; S.lu.u_colind = u_colind; S.lu.u_row = u_row;
  S.lu.u_lpos = u_lpos;
}

/* The element loops on these tables: Φ = |q|² − L², A = 2 qᵀ, γ = −2 |v|², Φ_t = 0, M. */
static void test_tables(void) {
  double par[3], w[4096], q[2] = {0.5, -0.72}, v[2] = {0.3, 0.2}, phi, A[2], g, pt, M[4];
  make_tables(30.0, 0.4, 0.6, par);
  CHECK(ncgen_tables_work_size(&KINDS, &T) <= 4096, "work fits");
  CHECK(ncgen_tables_phi(&KINDS, &T, q, &phi, w) == 0 && fabs(phi - (q[0] * q[0] + q[1] * q[1] - L * L)) < 1e-15,
        "phi %g", phi);
  CHECK(ncgen_tables_jacobian(&KINDS, &T, q, A, w) == 0 && A[0] == 2 * q[0] && A[1] == 2 * q[1], "A");
  CHECK(ncgen_tables_gamma(&KINDS, &T, q, v, &g, w) == 0 && fabs(g + 2 * (v[0] * v[0] + v[1] * v[1])) < 1e-15,
        "gamma %g", g);
  CHECK(ncgen_tables_phi_t(&T, &pt) == 0 && pt == 0, "phi_t");
  CHECK(ncgen_tables_mass(&KINDS, &T, M, w) == 0 && M[0] == MASS && M[1] == 0 && M[2] == 0 && M[3] == MASS, "M");
}

/* K of step_newton against central differences of its r in [w; ν]. */
static void test_newton_matrix(void) {
  double par[3], w[4096], K[9], Kp[9], r[3], rp[3], rm[3], x[3] = {0.4, -0.7, 0.05};
  double q[2] = {0.5, -0.72}, v[2] = {0.3, 0.2}, t = 0, h = 0.01, e = 1e-6;
  const double *arg[8];
  double *res[2];
  int i, j;
  make_tables(30.0, 0.4, 0.6, par);
  CHECK(ncgen_tables_check(&KINDS, &T) == 0, "the tables are consistent");
  CHECK(!tab_begin(&S), "run started");
  CHECK(tab_work_size(&S) <= 4096, "work fits: %ld", tab_work_size(&S));
  arg[0] = &t; arg[1] = q; arg[2] = v; arg[3] = 0; arg[4] = 0; arg[5] = &h; arg[6] = x; arg[7] = x + 2;
  res[0] = r; res[1] = K;
  CHECK(tab_newton(arg, res, 0, w, 0) == 0, "newton");
  for (j = 0; j < 3; ++j) {
    double xs = x[j];
    res[1] = Kp;
    x[j] = xs + e; res[0] = rp; tab_newton(arg, res, 0, w, 0);
    x[j] = xs - e; res[0] = rm; tab_newton(arg, res, 0, w, 0);
    x[j] = xs;
    for (i = 0; i < 3; ++i)
      CHECK(fabs(K[j * 3 + i] - (rp[i] - rm[i]) / (2 * e)) < 1e-6 * (1 + fabs(K[j * 3 + i])),
            "K[%d, %d] = %g, central differences %g", i, j, K[j * 3 + i], (rp[i] - rm[i]) / (2 * e));
  }
  tab_end();
}

/* 2000 RATTLE steps of 1 ms from rest at 0.5 rad; the energy and its balance. */
static void run(double c) {
  double par[3], q0[2] = {L * sin(0.5), -L * cos(0.5)}, v0[2] = {0, 0}, lam0[1] = {0};
  double q[2 * 10], v[2 * 10], lam[10], stats[NSTATS * 10], y[14], *y0 = y, *y1 = y + 7, tt[2] = {0, 2};
  double qa[2 * 5], va[2 * 5], la[5], sa[NSTATS * 5], qn[2], vn[2], h_next = 0;
  long rows = 0;
  int iters = 0;
  double qq[4], vv[4], ll[2] = {0, 0};
  step_options o = DEFAULT_OPTIONS();
  long done = 0, splits = 0;
  int status;
  make_tables(30.0, 0.4, c, par);
  CHECK(!tab_begin(&S), "run started");
  status = run_fixed(q0, v0, lam0, 0, 1e-3, 2000, 200, 0, 0, 0, q, v, lam, 0, stats, &o, &FIXED_RUN(0, 1), &done,
                     &splits, 0);
  CHECK(status == STEP_OK && done == 2000, "c = %g: status %d after %ld steps", c, status, done);
  qq[0] = q0[0]; qq[1] = q0[1]; qq[2] = q[18]; qq[3] = q[19];
  vv[0] = v0[0]; vv[1] = v0[1]; vv[2] = v[18]; vv[3] = v[19];
  CHECK(stepper_outputs(2, tt, qq, vv, ll, 0, 0, 0, y) == 0, "outputs");
  CHECK(y1[2] < 1e-9 && y1[3] < 1e-9, "c = %g: constraints %g, %g", c, y1[2], y1[3]);
  CHECK(y1[5] == q[18] && y1[6] == q[19], "the marker is p");
  if (c == 0) {
    CHECK(fabs(y1[0] + y1[1] - y0[0] - y0[1]) < 1e-6 * fabs(y0[1]), "energy kept: %.12g -> %.12g", y0[0] + y0[1], y1[0] + y1[1]);
  } else {
    double work = stats[9 * NSTATS + 5], lost = y1[0] + y1[1] - y0[0] - y0[1];
    CHECK(lost < -1e-3, "the damper takes energy: %g", lost);
    CHECK(fabs(lost - work) < 1e-4 * fabs(lost), "energy lost %.9g = damper work %.9g", lost, work);
  }
  status = stepper_step(q0, v0, 0, 0, 0, 1e-3, qn, vn, la, &iters, &o, 0, 0);
  CHECK(status == STEP_OK && iters >= 1, "one step: status %d", status);
  status = simulate_adaptive(q0, v0, lam0, 0, 0.02, 5, 0, 0, 0, &RUN_OPTIONS(1e-6, 1e-6, 1e-3, 1, 10000, 1),
                             qa, va, la, sa, &o, &rows, &h_next);
  CHECK(status == STEP_OK && rows == 5, "error control: status %d, %ld rows", status, rows);
  CHECK(fabs(qa[8] * qa[8] + qa[9] * qa[9] - L * L) < 1e-9, "error control keeps the constraint");
  tab_end();
}

/* 300 damped steps with the LU and with the QR alone: the same iterations, the same states to
 * round-off (two exact solves of the same Newton systems). */
static void test_lu_against_qr(void) {
  double par[3], q0[2] = {L * sin(0.5), -L * cos(0.5)}, v0[2] = {0.4, 0.3}, lam0[1] = {0};
  double q[2][2 * 3], v[2][2 * 3], lam[2][3], stats[2][NSTATS * 3];
  step_options o = DEFAULT_OPTIONS();
  long done = 0, splits = 0;
  int k, i, status;
  for (k = 0; k < 2; ++k) {
    with_lu = k;
    make_tables(30.0, 0.4, 0.8, par);
    CHECK(!tab_begin(&S), "run started");
    status = run_fixed(q0, v0, lam0, 0, 1e-3, 300, 100, 0, 0, 0, q[k], v[k], lam[k], 0, stats[k], &o, 0, &done,
                       &splits, 0);
    CHECK(status == STEP_OK && done == 300, "%s: status %d", k ? "LU" : "QR", status);
    tab_end();
  }
  with_lu = 1;
  for (i = 0; i < 6; ++i) {
    CHECK(fabs(q[0][i] - q[1][i]) < 1e-13 && fabs(v[0][i] - v[1][i]) < 1e-12, "LU vs QR: q %.17g %.17g, v %.17g %.17g",
          q[0][i], q[1][i], v[0][i], v[1][i]);
  }
  for (i = 0; i < 3; ++i)
    CHECK(stats[0][i * NSTATS + 1] == stats[1][i * NSTATS + 1], "LU vs QR: Newton iterations %g, %g",
          stats[0][i * NSTATS + 1], stats[1][i * NSTATS + 1]);
}

/* At q = 0 the constraint's gradient A = 2 qᵀ vanishes: K is singular, the LU refuses it, the
 * QR finds a zero diagonal, and the step reports STEP_NOT_FINITE (no NaN state returned). */
static void test_singular_reported(void) {
  double par[3], q0[2] = {0, 0}, v0[2] = {0.1, 0}, qn[2] = {7, 7}, vn[2] = {7, 7}, la[1];
  step_options o = DEFAULT_OPTIONS();
  int iters = 0, status;
  make_tables(30.0, 0.4, 0.8, par);
  CHECK(!tab_begin(&S), "run started");
  status = stepper_step(q0, v0, 0, 0, 0, 1e-3, qn, vn, la, &iters, &o, 0, 0);
  CHECK(status == STEP_NOT_FINITE, "singular K: status %d", status);
  tab_end();
}

int main(void) {
  with_lu = 0;                  /* the QR alone, then the LU (QR where it refuses) */
  test_tables();
  test_newton_matrix();
  run(0.0);
  run(0.8);
  with_lu = 1;
  test_newton_matrix();
  run(0.0);
  run(0.8);
  test_lu_against_qr();
  test_singular_reported();
  return report("test_table_stepper");
}

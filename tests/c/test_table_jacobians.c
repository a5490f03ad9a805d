/* Unit tests of the step Jacobians of the table-driven stepper (ncgen_table_jacobians.h) on
 * the tiny planar model of test_table_stepper.c (a point p = (q0, q1) of mass MASS on a
 * pendulum constraint |p|² = L², gravity, a spring-damper from a ground point), with inputs
 * u = (u0, u1, u2):
 *
 *   an input force   Q = B_u u, B_u = [[1, 0, 0], [0.5, 0, 0]] (u0 pushes p);
 *   actuator 0       an angle θ = atan2(y, x), x = 1 + q0 + 0.3 q0 q1, y = q1 + 0.2 q0²,
 *                    effort τ = 0.7 u1 − 0.2 u0;
 *   actuator 1       a slider s = 0.5 q0² + q1 − 0.1 q1², effort τ = u2.
 *
 * Checked: the input forces against τ ∇θ by central differences of θ; the step of
 * tab_step_jacobians against the stepper's own (stepper_step); ∂x⁺/∂x and ∂x⁺/∂u against
 * central differences of the step, with and without the damper; the polished residual at
 * the rounding floor; all of it with the stages factored by the sparse QR and by the sparse LU
 * (its transposed solve in the reverse passes), the two equal to 1e-12.  Built and run by tests/test_stepper_runtime_c.py under
 * AddressSanitizer and UndefinedBehaviorSanitizer. */
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

/* No force elements over features and no torques here (n_ff = n_torque = 0): empty kinds. */
static const ncgen_feature_force_kind FEATURE_FORCE_KINDS[1] = {{0, 0, 0, 0}};
static const ncgen_torque_kind TORQUE_KINDS[1] = {{0, 0}};

#define TAB_KINDS (&KINDS)
#define TAB_SPRING_3D k_spring
#define TAB_SPRING_2D k_spring
#define TAB_FEATURE_FORCES FEATURE_FORCE_KINDS
#define TAB_TORQUES TORQUE_KINDS
#define TAB_FF_IN 1
#define TAB_FF_OUT 1
#define MAX_HALVINGS 10
#define NSTATS 12

#include "ncgen_table_stepper.h"
#include "ncgen_table_jacobians.h"

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
/* The LU's analysis of the same K in identity order (the multiplier after both coordinates). */
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
  S.qr.n = 3; S.qr.k_colind = k_colind; S.qr.k_row = k_row; S.qr.v_colind = v_colind; S.qr.v_row = v_row;
  S.qr.r_colind = r_colind; S.qr.r_row = r_row; S.qr.prinv = perm; S.qr.pc = perm;
  S.lu.n = with_lu ? 3 : 0; S.lu.nnz_l = 3; S.lu.k_colind = k_colind; S.lu.k_prow = k_row; S.lu.p = perm;
  S.lu.pinv = perm; S.lu.l_colind = l_colind; S.lu.l_row = l_row; S.lu.u_colind = u_colind; S.lu.u_row = u_row;
  S.lu.u_lpos = u_lpos;
}


/* D of the pendulum constraint: A = 2 qᵀ, so A(e_i) − A(0) = 2 e_iᵀ. */
static const int d_colind[] = {0, 1, 2}, d_row[] = {0, 1};
static const double d_val[] = {2, 2};
/* The inputs' tables (see the top of the file). */
static const int bu_colind[] = {0, 2, 2, 2}, bu_row[] = {0, 1};
static const double bu_val[] = {1, 0.5};
static const int act_kind[] = {1, 0}, act_ptr[] = {0, 2, 4}, act_col[] = {0, 1, 0, 1}, act_form_ptr[] = {0, 14, 21};
/* [c0; g; H (column-major)]: x, y of actuator 0, s of actuator 1 */
static const double act_form[] = {1, 1, 0, 0, 0.3, 0.3, 0,   0, 0, 1, 0.4, 0, 0, 0,   0, 0, 1, 1, 0, 0, -0.2};
static const double act_tau[] = {-0.2, 0.7, 0, 0, 0, 1};

/* D against A(e_i) − A(0) from the element loops. */
static void test_hessian(void) {
  double par[3], w[4096], A0[2], Ai[2], e[2];
  int i, k;
  make_tables(30.0, 0.4, 0.6, par);
  CHECK(ncgen_tables_check(&KINDS, &T) == 0, "the tables are consistent");
  e[0] = e[1] = 0;
  CHECK(ncgen_tables_jacobian(&KINDS, &T, e, A0, w) == 0, "A(0)");
  for (i = 0; i < 2; ++i) {
    e[0] = e[1] = 0;
    e[i] = 1;
    CHECK(ncgen_tables_jacobian(&KINDS, &T, e, Ai, w) == 0, "A(e_i)");
    for (k = 0; k < 2; ++k) {
      double expect = 0;
      int m;
      for (m = d_colind[i]; m < d_colind[i + 1]; ++m)
        if (d_row[m] == k) expect = d_val[m];
      CHECK(Ai[k] - A0[k] == expect, "D[%d, %d] = %g, A(e_i) − A(0) = %g", k, i, expect, Ai[k] - A0[k]);
    }
  }
}

static void with_inputs(void) {
  S.nu = 3;
  S.bu_colind = bu_colind; S.bu_row = bu_row; S.bu_val = bu_val;
  S.n_act = 2; S.act_kind = act_kind; S.act_ptr = act_ptr; S.act_col = act_col; S.act_form_ptr = act_form_ptr;
  S.act_form = act_form; S.act_tau = act_tau;
}

static double theta(const double *q) {
  return atan2(q[1] + 0.2 * q[0] * q[0], 1 + q[0] + 0.3 * q[0] * q[1]);
}

static double slide(const double *q) { return 0.5 * q[0] * q[0] + q[1] - 0.1 * q[1] * q[1]; }

/* The input forces at q against B_u u + τ0 ∇θ + τ1 ∇s, the gradients by central differences. */
static void test_input_forces(void) {
  double par[3], q[2] = {0.5, -0.72}, u[3] = {0.8, -1.3, 0.6}, F[2] = {0, 0}, e = 1e-6, tau0 = 0.7 * u[1] - 0.2 * u[0];
  int i;
  make_tables(30.0, 0.4, 0.6, par);
  with_inputs();
  CHECK(!tab_begin(&S), "run started");
  tab_input_forces(q, u, F);
  for (i = 0; i < 2; ++i) {
    double qp[2] = {q[0], q[1]}, qm[2] = {q[0], q[1]}, expect;
    qp[i] += e;
    qm[i] -= e;
    expect = bu_val[i] * u[0] + tau0 * (theta(qp) - theta(qm)) / (2 * e) + u[2] * (slide(qp) - slide(qm)) / (2 * e);
    CHECK(fabs(F[i] - expect) < 1e-8, "F[%d] = %.12g, expected %.12g", i, F[i], expect);
  }
  tab_end();
}

/* One step: x⁺ by tab_step_jacobians with and without its Jacobians and by stepper_step. */
static void one_step(const double *x, const double *u, double h, double *x1, double *Jx, double *Ju, double *res) {
  step_options o = DEFAULT_OPTIONS();
  tab_jac_hessian D;
  int it = 0, status;
  o.tol = 1e-12;
  o.max_iter = 20;
  D.colind = d_colind; D.row = d_row; D.val = d_val;
  CHECK(!tab_begin(&S), "run started");
  status = tab_step_jacobians(x, x + 2, 0, u, 0, h, &o, &D, x1, x1 + 2, Jx, Ju, res, &it);
  CHECK(status == STEP_OK && it >= 1, "step: status %d after %d iterations", status, it);
  tab_end();
}

/* ∂x⁺/∂x and ∂x⁺/∂u against central differences of the step (and into Jx, Ju). */
static void test_jacobians(double c, double *Jx, double *Ju) {
  double par[3], x[4] = {0.5, -sqrt(L * L - 0.25), 0.9, 0.6}, u[3] = {0.8, -1.3, 0.6}, h = 0.01, e = 1e-6;
  double x1[4], x1n[4], xs[4], qn[2], vn[2], lam[1], res, res2, worst = 0;
  step_options o = DEFAULT_OPTIONS();
  int i, j, it, status;
  make_tables(30.0, 0.4, c, par);
  with_inputs();
  one_step(x, u, h, x1, Jx, Ju, &res);
  CHECK(res < 1e-13, "c = %g: residual at the rounding floor: %g", c, res);
  one_step(x, u, h, x1n, 0, 0, &res2);
  for (i = 0; i < 4; ++i) CHECK(x1n[i] == x1[i], "the step without Jacobians is the same step");
  o.tol = 1e-13;
  CHECK(!tab_begin(&S), "run started");
  status = stepper_step(x, x + 2, 0, u, 0, h, qn, vn, lam, &it, &o, 0, 0);
  tab_end();
  CHECK(status == STEP_OK, "stepper_step: status %d", status);
  for (i = 0; i < 2; ++i)
    CHECK(fabs(qn[i] - x1[i]) < 1e-12 && fabs(vn[i] - x1[2 + i]) < 1e-10, "c = %g: the stepper's own step: %g %g",
          c, qn[i] - x1[i], vn[i] - x1[2 + i]);
  for (j = 0; j < 7; ++j) {
    double xp[4], xm[4], up[3], um[3];
    for (i = 0; i < 4; ++i) xs[i] = x[i];
    memcpy(up, u, sizeof up);
    memcpy(um, u, sizeof um);
    if (j < 4) {
      xs[j] += e;
      one_step(xs, u, h, xp, 0, 0, &res2);
      xs[j] -= 2 * e;
      one_step(xs, u, h, xm, 0, 0, &res2);
    } else {
      up[j - 4] += e;
      um[j - 4] -= e;
      one_step(x, up, h, xp, 0, 0, &res2);
      one_step(x, um, h, xm, 0, 0, &res2);
    }
    for (i = 0; i < 4; ++i) {
      double fd = (xp[i] - xm[i]) / (2 * e), J = j < 4 ? Jx[j * 4 + i] : Ju[(j - 4) * 4 + i];
      worst = fabs(J - fd) > worst ? fabs(J - fd) : worst;
      CHECK(fabs(J - fd) < 1e-6 * (1 + fabs(fd)), "c = %g: d x1[%d] / d y[%d] = %.10g, central differences %.10g",
            c, i, j, J, fd);
    }
  }
  CHECK(fabs(Jx[0]) > 0.5 && fabs(Ju[4 * 1 + 2]) > 1e-4, "the Jacobians are not trivial");
  printf("c = %g, %s: largest difference to central differences %.2e\n", c, with_lu ? "LU" : "QR", worst);
}

int main(void) {
  double Jx[2][32], Ju[2][24];
  int i;
  (void)run_fixed;                  /* the runtime's loops, tested by test_table_stepper.c */
  (void)stepper_outputs;
  (void)simulate_adaptive;
  (void)ncgen_tables_phi;
  (void)ncgen_tables_gamma;
  (void)ncgen_tables_phi_t;
  (void)ncgen_tables_mass;
  test_hessian();
  test_input_forces();
  for (with_lu = 0; with_lu < 2; ++with_lu) {    /* the stages by the QR, then by the LU */
    test_jacobians(0.0, Jx[with_lu], Ju[with_lu]);
    test_jacobians(0.8, Jx[with_lu] + 16, Ju[with_lu] + 12);
  }
  for (i = 0; i < 32; ++i)
    CHECK(fabs(Jx[0][i] - Jx[1][i]) < 1e-12 * (1 + fabs(Jx[0][i])), "Jx by the LU and the QR: %g", Jx[1][i] - Jx[0][i]);
  for (i = 0; i < 24; ++i)
    CHECK(fabs(Ju[0][i] - Ju[1][i]) < 1e-12 * (1 + fabs(Ju[0][i])), "Ju by the LU and the QR: %g", Ju[1][i] - Ju[0][i]);
  return report("test_table_jacobians");
}

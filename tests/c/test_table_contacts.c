/* Unit tests of nonsmooth contacts on the stepper tables (ncgen_table_contacts.h: the contact
 * runtime reading the run's contact tables, the element rows from a pair kind on canonical
 * coordinates) on hand-written tables of a planar point of mass MASS (member kind 0, no
 * constraint) and one frictional floor contact (a hand-written pair kind: a point of radius RADIUS
 * over the ground line y = 0, g = q1 − RADIUS, W = [[0, 1], [1, 0]]).
 *
 * Checked: tab_pair_eval against the hand-made rows for a non-identity canonical map B
 * (g = (B q)_1 − RADIUS, W_local = W_c B); tab_contacts_check refuses a bad kind, a map entry
 * out of range and M⁻¹'s nonzeros out of range; a drop from y0 with a sideways speed u0 (e = 0, μ): it lands at
 * t = √(2 (y0 − RADIUS)/g), where the impact's friction impulse (≤ μ m v_land) stops the slide
 * (μ v_land ≥ u0 here), and rests on the floor (gap within 1e-8 m, velocity below 1e-9 m/s) at
 * x = u0 t_land (to u0 h, the landing step), each resting step's impulse m g h; energy only
 * lost; the QR, the sparse LU (kept per K) and the Schur complement of M⁻¹ (schur = 1: the
 * Delassus matrix from M⁻¹ = I / MASS instead of KKT solves) runs equal.
 * Built and run by tests/test_stepper_runtime_c.py under AddressSanitizer and
 * UndefinedBehaviorSanitizer. */
#include "check.h"
#include "stepper_decls.h"

#pragma GCC diagnostic ignored "-Wunused-function"  /* the runtime's functions not used here */
#include "ncgen_element_tables.h"

#define MASS 0.8
#define GRAV 9.81
#define RADIUS 0.1
#define FRICTION 0.5

/* Member kind 0: a planar point, c = (m,) -> M_I = m I. */
static int k_point_mass(const double **arg, double **res, long long *iw, double *w, int mem) {
  (void)iw; (void)w; (void)mem;
  res[0][0] = res[0][3] = arg[0][0];
  res[0][1] = res[0][2] = 0;
  return 0;
}

/* Not called (no spring, force element or torque in these tables). */
static int k_none(const double **arg, double **res, long long *iw, double *w, int mem) {
  (void)arg; (void)res; (void)iw; (void)w; (void)mem;
  return 1;
}

/* Pair kind 0: q = (x, y) of the point (canonical type r), c = (RADIUS,) -> g = y − RADIUS, W (2 x 2,
 * column-major): the normal row (0, 1), the tangent row (1, 0). */
static int k_floor(const double **arg, double **res, long long *iw, double *w, int mem) {
  (void)iw; (void)w; (void)mem;
  res[0][0] = arg[0][1] - arg[1][0];
  res[1][0] = 0; res[1][1] = 1; res[1][2] = 1; res[1][3] = 0;
  return 0;
}

static const ncgen_member_kind MEMBER_KINDS[1] = {{0, 0, k_point_mass, 2, 1, 0}};
static const ncgen_kinds KINDS = {0, 0, MEMBER_KINDS, 1, 0};
static const ncgen_feature_force_kind FEATURE_FORCE_KINDS[1] = {{k_none, 2, 1, 1}};
static const ncgen_torque_kind TORQUE_KINDS[1] = {{0, 0}};
static const ncgen_pair_kind PAIR_KINDS[1] = {{k_floor, 2, 2, 0, 1}};

#define TAB_KINDS (&KINDS)
#define TAB_SPRING_3D k_none
#define TAB_SPRING_2D k_none
#define TAB_FEATURE_FORCES FEATURE_FORCE_KINDS
#define TAB_TORQUES TORQUE_KINDS
#define TAB_FF_IN 5
#define TAB_FF_OUT 8
#define MAX_HALVINGS 10
#define NSTATS 16
#define NCGEN_CONTACTS
#define TAB_PAIR_KINDS PAIR_KINDS
#define N_PAIR_KINDS 1
#define TAB_PAIR_W 0
#define TAB_PAIR_QC 2
#define PGS_MAX_ITER 300
#define PGS_TOL 1e-12
#define CONTACT_REFINE_MAX 10
#define CONTACT_REFINE_TOL 1e-8
#define PENETRATION_TOL 1e-8
#define GAP_REACH 2.0
#define REPEAT_TOL 1e-12

#include "ncgen_table_stepper.h"
#include "ncgen_table_contacts.h"  /* (already in, through ncgen_table_stepper.h with NCGEN_CONTACTS) */
/* The runtime is compiled: the contact tables' field names, which ncgen_table_contacts.h defines
 * as macros for it, are plain names again here. */
#undef wt_colind
#undef wt_row
#undef pair_int
#undef pair_qidx
#undef pair_qconst
#undef pair_wpos
#undef pair_side
#undef pair_bdata
#undef pair_bound
#undef pair_sid
#undef pair_srep
#undef mu
#undef restitution
#undef minv
#undef minv_colind
#undef minv_row

/* The model's tables: no feature, no joint element, the member's M = MASS I (its two nonzero
 * entries), K = M (2 x 2 diagonal: V, RADIUS, L and U trivial). */
static const int zero[] = {0}, none[] = {-1}, one_two[] = {0, 1, 2}, ident[] = {0, 1};
static const double nothing[] = {0}, mem_c[] = {MASS}, m_val[] = {MASS, MASS}, f_gravity[] = {0, -MASS * GRAV};
static const int mem_q_ptr[] = {0, 2}, mem_mpos_ptr[] = {0, 4}, mem_mpos[] = {0, 1, 2, 3}, mem_c_ptr[] = {0, 1};
static const int m_colind_all[] = {0, 0, 0};

/* The contact tables (ncgen/codegen/contact_tables.py's layout): one element, the point (side 0,
 * its coordinates q0, q1) over the ground half-space y ≥ 0 (side 1). */
static const int wt_colind[] = {0, 2, 4}, wt_row[] = {0, 1, 0, 1};
static const int pair_int[] = {0, 0, 1, 2, 0, 0, 0, 1}, pair_wpos[] = {0, 2, 1, 3};
static const int pair_side[] = {1, 0, 0, 3, 0, 6}, pair_sid[] = {0, -1}, pair_srep[] = {0, 0};
static const double pair_bdata[] = {1, 0, 0, 1, RADIUS, 0, 0, 0, 0, 1}, pair_bound[] = {1, 0, 1e300};
static const int pk_kind[] = {0}, pk_swap[] = {0}, pk_c_ptr[] = {0, 1}, cm_ptr[] = {0, 2, 2}, cm_n[] = {2, 0};
static const double mu_[] = {FRICTION}, e_[] = {0}, pk_c[] = {RADIUS}, cm_identity[] = {1, 1};
/* M⁻¹ = I / MASS (column-major) and its nonzeros by columns */
static const double minv_[] = {1 / MASS, 0, 0, 1 / MASS};

static ncgen_tables T;
static ncgen_stepper_tables S;
static struct ncgen_contact_tables C;

static void make_tables(int with_lu, int schur) {
  T.nq = 2; T.nc = 0; T.dim = 2; T.a_nnz = 0; T.m_nnz = 4; T.nf = 0;
  T.feat_ptr = zero; T.feat_row = zero; T.feat_col = zero; T.feat_coef = nothing; T.feat_const = nothing;
  T.ne = 0; T.el_kind = zero; T.el_arg_ptr = zero; T.el_arg = zero; T.el_sc_ptr = zero; T.el_sc = nothing;
  T.el_row_ptr = zero; T.el_row = zero; T.el_apos_ptr = zero; T.el_apos = zero;
  T.nm = 1; T.mem_kind = zero; T.mem_q_ptr = mem_q_ptr; T.mem_q_col = ident; T.mem_q_const = nothing + 0;
  T.mem_c_ptr = mem_c_ptr; T.mem_c = mem_c; T.mem_row_ptr = zero; T.mem_row = none; T.mem_apos_ptr = zero;
  T.mem_apos = zero; T.mem_mpos_ptr = mem_mpos_ptr; T.mem_mpos = mem_mpos;
  memset(&S, 0, sizeof S);
  S.T = &T; S.mass_scale = MASS; S.m_nnz = 2;
  S.a_colind = m_colind_all; S.a_row = zero; S.m_colind = one_two; S.m_row = ident; S.m_val = m_val;
  S.f_gravity = f_gravity; S.spr_kpos_ptr = zero; S.marker_feat = zero;
  S.nnz_k = 2; S.nnz_v = 2; S.nnz_r = 2; S.k_mpos = ident; S.k_apos = zero; S.k_atpos = zero;
  S.ff_feat_ptr = zero; S.ff_par_ptr = zero; S.ff_kpos_ptr = zero; S.tq_c_ptr = zero;
  S.qr.n = 2; S.qr.k_colind = one_two; S.qr.k_row = ident; S.qr.v_colind = one_two; S.qr.v_row = ident;
  S.qr.r_colind = one_two; S.qr.r_row = ident; S.qr.prinv = ident; S.qr.pc = ident;
  S.lu.n = with_lu ? 2 : 0; S.lu.nnz_l = 0; S.lu.k_colind = one_two; S.lu.k_prow = ident; S.lu.p = ident;
  S.lu.pinv = ident; S.lu.l_colind = m_colind_all; S.lu.l_row = zero; S.lu.u_colind = m_colind_all;
  S.lu.u_row = zero; S.lu.u_lpos = zero;
  C.nk = 1; C.ne = 1; C.ns = 1; C.max_q = 2; C.max_g = 1; C.max_w = 4; C.nnz_w = 4; C.gravity_norm = GRAV;
  C.wt_colind = wt_colind; C.wt_row = wt_row; C.pair_int = pair_int; C.pair_qidx = ident; C.pair_wpos = pair_wpos;
  C.pair_side = pair_side; C.pair_sid = pair_sid; C.pair_srep = pair_srep; C.pk_kind = pk_kind; C.pk_swap = pk_swap;
  C.pk_c_ptr = pk_c_ptr; C.cm_ptr = cm_ptr; C.cm_n = cm_n; C.mu = mu_; C.restitution = e_;
  C.pair_qconst = nothing; C.pair_bdata = pair_bdata; C.pair_bound = pair_bound; C.pk_c = pk_c; C.cm = cm_identity;
  C.cm_row = ident; C.cm_col = ident;
  C.schur = schur; C.minv = minv_; C.minv_colind = one_two; C.minv_row = ident; C.a_col = zero;
  S.ct = &C;
}

/* tab_pair_eval with the map B = [[2, 1], [0.5, 3]] (nonzeros by columns 2, 0.5, 1, 3): g = (B q)_1 −
 * RADIUS, W_local = W_c B (normal row (0, 1) B, tangent row (1, 0) B); the check's refusals. */
static void test_pair_eval(void) {
  static const double B[] = {2, 0.5, 1, 3};
  static const int b_ptr[] = {0, 4, 4}, b_row[] = {0, 1, 0, 1}, b_col[] = {0, 0, 1, 1};
  double q[2] = {0.3, 0.2}, g, W[4], w[64];
  const double *arg[2];
  double *res[2];
  make_tables(0, 1);
  C.cm = B;
  C.cm_ptr = b_ptr;
  C.cm_row = b_row;
  C.cm_col = b_col;
  tab_cur = &S;
  arg[0] = q; arg[1] = q + 2;
  res[0] = &g; res[1] = W;
  CHECK(tab_contacts_check(&S) == 0, "the contact tables are consistent");
  CHECK(tab_pair_eval(arg, res, w, 0, 1) == 0, "pair eval");
  CHECK(fabs(g - (0.5 * q[0] + 3 * q[1] - RADIUS)) < 1e-15, "g %g", g);
  /* rows: normal (0.5, 3), tangent (2, 1); W column-major (2 rows) */
  CHECK(W[0] == 0.5 && W[2] == 3 && W[1] == 2 && W[3] == 1, "W %g %g %g %g", W[0], W[1], W[2], W[3]);
  C.mu = e_;                         /* frictionless: the tangent row is zero */
  CHECK(tab_pair_eval(arg, res, w, 0, 1) == 0 && W[1] == 0 && W[3] == 0 && W[0] == 0.5, "frictionless rows");
  C.mu = mu_;
  C.pk_kind = pk_swap + 0;           /* kind 0 still; then a bad kind */
  {
    static const int bad[] = {1}, bad_row[] = {0, 2, 0, 1}, bad_minv_row[] = {0, 2};
    C.pk_kind = bad;
    CHECK(tab_contacts_check(&S) != 0, "a kind out of range refused");
    C.pk_kind = pk_kind;
    C.cm_row = bad_row;
    CHECK(tab_contacts_check(&S) != 0, "a map entry out of range refused");
    C.cm_row = b_row;
    C.minv_row = bad_minv_row;
    CHECK(tab_contacts_check(&S) != 0, "M⁻¹'s nonzero out of range refused");
    C.schur = 0;
    CHECK(tab_contacts_check(&S) == 0, "M⁻¹ not read without the Schur complement");
  }
  tab_cur = 0;
}

/* The drop (top of the file), with the QR alone or the LU, the Delassus matrix by KKT solves or
 * (schur) from M⁻¹; returns the final x. */
static double drop(int with_lu, int schur, double *impulse_last) {
  enum { N = 600, EVERY = 1 };
  const double h = 1e-3, y0 = 0.3, u0 = 0.2;
  static double q[2 * N], v[2 * N], lam[1], P[2 * N];
  double q0[2] = {0, y0}, v0[2] = {u0, 0}, E0 = MASS * (GRAV * y0 + u0 * u0 / 2), E;
  long iters[N], done = 0, splits = 0;
  step_options o = DEFAULT_OPTIONS();
  /* the impact's friction impulse (≤ μ m v_land) stops the slide at once if μ v_land ≥ u0, else
   * the point slides on, decelerated by μ g */
  double t_land = sqrt(2 * (y0 - RADIUS) / GRAV), v_land = GRAV * t_land;
  double slide = FRICTION * v_land >= u0 ? 0 : (u0 - FRICTION * v_land) / (FRICTION * GRAV);
  double t_stop = t_land + slide, x_end = u0 * t_land + (u0 - FRICTION * v_land) * slide / 2;
  int status, k, resting = 0;
  make_tables(with_lu, schur);
  CHECK(tab_contacts_check(&S) == 0, "tables");
  CHECK(!tab_begin(&S), "run started");
  status = run_fixed(q0, v0, 0, 0, h, N, EVERY, 0, 0, 0, q, v, lam, iters, 0, &o, 0, &done, &splits, P);
  tab_end();
  CHECK(status == STEP_OK && done == N, "run: status %d, %ld steps", status, done);
  for (k = 0; k < N; ++k) {
    double t = (k + 1) * h, gap = q[2 * k + 1] - RADIUS;
    E = MASS * (GRAV * q[2 * k + 1] + (v[2 * k] * v[2 * k] + v[2 * k + 1] * v[2 * k + 1]) / 2);
    CHECK(E <= E0 * (1 + 1e-12), "energy created at step %d: %g > %g", k, E, E0);
    CHECK(gap > -1e-8, "penetration %g at step %d", gap, k);
    if (t < t_land - 2 * h) CHECK(P[2 * k] == 0, "no impulse in flight at t = %g", t);
    if (t > t_stop + 0.05) {         /* (a contact about to close may stop it just above the floor:
                                        it then falls that far again, ≈ 0.013 s here) */
      ++resting;
      CHECK(fabs(gap) < 1e-8 && fabs(v[2 * k]) < 1e-9 && fabs(v[2 * k + 1]) < 1e-9,
            "at rest at t = %g: gap %g, v (%g, %g)", t, gap, v[2 * k], v[2 * k + 1]);
      CHECK(fabs(P[2 * k] - MASS * GRAV * h) < 1e-12 && fabs(P[2 * k + 1]) < 1e-12, "resting impulse (%g, %g), m g h %g",
            P[2 * k], P[2 * k + 1], MASS * GRAV * h);
    }
  }
  CHECK(resting > 300, "rest reached");
  CHECK(fabs(q[2 * (N - 1)] - x_end) < 2 * u0 * h, "stopped at x = %g, closed form %g", q[2 * (N - 1)], x_end);
  *impulse_last = P[2 * (N - 1)];
  return q[2 * (N - 1)];
}

int main(void) {
  double p_qr, p_lu, p_schur, x_qr, x_lu, x_schur;
  test_pair_eval();
  x_qr = drop(0, 0, &p_qr);
  x_lu = drop(1, 0, &p_lu);
  x_schur = drop(1, 1, &p_schur);
  CHECK(fabs(x_qr - x_lu) < 1e-14 && fabs(p_qr - p_lu) < 1e-15, "QR and LU runs: x %g, %g", x_qr, x_lu);
  CHECK(fabs(x_schur - x_lu) < 1e-14 && fabs(p_schur - p_lu) < 1e-15, "Schur and KKT runs: x %g, %g", x_schur, x_lu);
  return report("test_table_contacts");
}

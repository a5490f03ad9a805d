/* Unit tests of the tree loops (ncgen_tree_tables.h) on hand-written kernels of a tiny tree of
 * sliders (pure translations, so every kernel has a short closed form):
 *
 *   body 0 slides along e_x on the ground (q0), body 1 along e_y on body 0 (q1), body 2 along
 *   e_x on body 1 (q2), a mimic follower of q0: q2 = 2 q0 + 0.1, v2 = 2 v0; independent rates
 *   (v0, v1); masses m0, m1, m2 with centres of mass off the joint frames; gravity −g e_y.
 *
 *   Velocities: body 0 (v0, 0), body 1 (v0, v1), body 2 (3 v0, v1), so
 *   M_i = diag(m0 + m1 + 9 m2, m1 + m2), the bias is (0, (m1 + m2) g) at every (q, v), and
 *   τ_i = M_i a_i + bias, a_i = M_i⁻¹ (τ_i − bias), ∂τ/∂q = ∂τ/∂v = 0, ∂a/∂τ = M_i⁻¹.
 *
 * Checked: RNEA, CRBA, forward dynamics (both ways: the articulated-body algorithm, which
 * NCGEN_TREE_DENSE_NV 0 makes ncgen_tree_aba's, and Cholesky of M_i, ncgen_tree_dense_aba),
 * both derivatives and the joint-space ODE against these closed forms, the mimic map, the pivot
 * check, the checks of inconsistent tables, a failing kernel.  Built and run by
 * tests/test_stepper_runtime_c.py under AddressSanitizer and UndefinedBehaviorSanitizer. */
#include "check.h"
#define NCGEN_TREE_DENSE_NV 0
#include "ncgen_tree_tables.h"

#define GRAV 9.81

static int fail_kernel = 0;

/* Slider along the unit axis e (its numbers), for a parent with R_p = 1 and ω_p = 0:
 * [R_p; p_p; T_p; q; w; e] -> [R_c = R_p; p_c = p_p + q e; S_g = [0; e]; c_g = 0]. */
static int k_slide(const double **arg, double **res, long long *iw, double *w, int mem) {
  const double *x = arg[0], *e = x + 20;
  double *y = res[0];
  int i;
  (void)iw; (void)w; (void)mem;
  if (fail_kernel) return 1;
  for (i = 0; i < 9; ++i) y[i] = x[i];
  for (i = 0; i < 3; ++i) y[9 + i] = x[9 + i] + x[18] * e[i];
  for (i = 0; i < 3; ++i) y[12 + i] = 0.0, y[15 + i] = e[i];
  for (i = 0; i < 6; ++i) y[18 + i] = 0.0;
  return 0;
}

/* Its tangent: [x (23); dR_p; dp_p; dT_p; δ; dw] -> [dR_p; dp_p + δ e; 0; 0]. */
static int k_slide_fwd(const double **arg, double **res, long long *iw, double *w, int mem) {
  const double *x = arg[0], *e = x + 20, *dRp = x + 23, *dpp = x + 32, delta = x[41];
  double *y = res[0];
  int i;
  (void)iw; (void)w; (void)mem;
  for (i = 0; i < 9; ++i) y[i] = dRp[i];
  for (i = 0; i < 3; ++i) y[9 + i] = dpp[i] + delta * e[i];
  for (i = 12; i < 24; ++i) y[i] = 0.0;
  return 0;
}

/* Its position rate: [q; w] -> q̇ = w. */
static int k_slide_qdot(const double **arg, double **res, long long *iw, double *w, int mem) {
  (void)iw; (void)w; (void)mem;
  res[0][0] = arg[0][1];
  return 0;
}

/* M_g (6 x 6, column-major) of mass m with centre c (in g), no rotational inertia about it:
 * [[m(|c|² 1 − c cᵀ), m ĉ], [m ĉᵀ, m 1]]; its derivative along dc when d is not NULL. */
static void mass_g(double m, const double *c, const double *dc, double *M) {
  int i, j;
  double cc = 0.0;
  for (i = 0; i < 3; ++i) cc += (dc ? 2 * c[i] * dc[i] : c[i] * c[i]);
  for (i = 0; i < 36; ++i) M[i] = 0.0;
  for (i = 0; i < 3; ++i)
    for (j = 0; j < 3; ++j)
      M[i + 6 * j] = m * ((i == j ? cc : 0.0) - (dc ? dc[i] * c[j] + c[i] * dc[j] : c[i] * c[j]));
  {
    const double *u = dc ? dc : c;   /* m ĉ (top right), m ĉᵀ (bottom left) */
    double h[9] = {0, u[2], -u[1], -u[2], 0, u[0], u[1], -u[0], 0};
    for (i = 0; i < 3; ++i)
      for (j = 0; j < 3; ++j) {
        M[i + 6 * (3 + j)] = m * h[i + 3 * j];
        M[3 + i + 6 * j] = m * h[j + 3 * i];
      }
  }
  if (!dc)
    for (i = 3; i < 6; ++i) M[i + 6 * i] = m;
}

/* Body of a tree of translations (ω = 0, α = 0): [R = 1; p; T; dT; m; c; I_c = 0] ->
 * [M_g; W = M_g dT] (the bias −ad(T)ᵀ M_g T vanishes without rotation). */
static int k_body(const double **arg, double **res, long long *iw, double *w, int mem) {
  const double *x = arg[0], *dT = x + 18, m = x[24];
  double c[3], *y = res[0];
  int i, j;
  (void)iw; (void)w; (void)mem;
  for (i = 0; i < 3; ++i) c[i] = x[9 + i] + x[25 + i];
  mass_g(m, c, 0, y);
  for (i = 0; i < 6; ++i) {
    y[36 + i] = 0.0;
    for (j = 0; j < 6; ++j) y[36 + i] += y[i + 6 * j] * dT[j];
  }
  return 0;
}

/* Its tangent along [dR; dp; dT; ddT]: [dM_g; dM_g dT + M_g ddT]. */
static int k_body_fwd(const double **arg, double **res, long long *iw, double *w, int mem) {
  const double *x = arg[0], *dT = x + 18, m = x[24], *dp = x + 37 + 9, *ddT = x + 37 + 18;
  double c[3], M[36], *y = res[0];
  int i, j;
  (void)iw; (void)w; (void)mem;
  for (i = 0; i < 3; ++i) c[i] = x[9 + i] + x[25 + i];
  mass_g(m, c, 0, M);
  mass_g(m, c, dp, y);
  for (i = 0; i < 6; ++i) {
    y[36 + i] = 0.0;
    for (j = 0; j < 6; ++j) y[36 + i] += y[i + 6 * j] * dT[j] + M[i + 6 * j] * ddT[j];
  }
  return 0;
}

/* Its local motion for RNEA, CRBA and ABA (mode 0): [q; w; e] -> [R_J = 1; p_J = q e; S = [0; e]; c_J = 0]. */
static int k_slide_local(const double **arg, double **res, long long *iw, double *w, int mem) {
  const double *x = arg[0], *e = x + 2;
  double *y = res[0];
  int i;
  (void)iw; (void)w; (void)mem;
  if (fail_kernel) return 1;
  for (i = 0; i < 9; ++i) y[i] = i % 4 == 0 ? 1.0 : 0.0;
  for (i = 0; i < 3; ++i) y[9 + i] = x[0] * e[i];
  for (i = 0; i < 3; ++i) y[12 + i] = 0.0, y[15 + i] = e[i];
  for (i = 0; i < 6; ++i) y[18 + i] = 0.0;
  return 0;
}

/* Kind 0 through its kernels; kind 1 the same slider as the loops' own prismatic joint along z
 * (mode 2), used with placements that turn z onto the slider's axis. */
static const ncgen_tree_joint_kind JOINT_KINDS[2] = {{k_slide, k_slide_fwd, k_slide_qdot, k_slide_local, 1, 1, 3, 0},
                                                     {k_slide, k_slide_fwd, k_slide_qdot, 0, 1, 1, 3, 2}};
static const ncgen_tree_kinds KINDS = {JOINT_KINDS, 2, k_body, k_body_fwd, 0};

static const double MASS[3] = {1.5, 0.7, 0.4};

static int parent[3] = {-1, 0, 1}, kind[3] = {0, 0, 0}, q_at[3] = {0, 1, 2}, v_at[3] = {0, 1, 2};
static int num_ptr[4] = {0, 3, 6, 9};
static const double num[9] = {1, 0, 0, 0, 1, 0, 1, 0, 0};
static const double body[39] = {1.5, 0.1, 0.2, 0.0, 0, 0, 0, 0, 0, 0, 0, 0, 0,
                                0.7, -0.3, 0.1, 0.2, 0, 0, 0, 0, 0, 0, 0, 0, 0,
                                0.4, 0.2, 0.0, -0.1, 0, 0, 0, 0, 0, 0, 0, 0, 0};
static const double gravity[3] = {0.0, -GRAV, 0.0};
/* xin: identity placements (kind 0); for kind 1 the rotations taking z onto e_x, e_y, e_x */
static const double xin[36] = {1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0,
                               1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0};
static const double xin_z[36] = {0, 1, 0, 0, 0, 1, 1, 0, 0, 0, 0, 0,
                                 0, 1, 0, 0, 0, 1, 1, 0, 0, 0, 0, 0,
                                 0, 0, 1, 1, 0, 0, 0, 1, 0, 0, 0, 0};
static double inertia[39], inertia_z[39];

/* [m; m c; I_o = −m ĉ ĉ] of a point mass m at c, in the frame f_b (c turned by Rᵀ for kind 1:
 * the body frames of a chain of turned frames, each f_b = f_p R since p_in = 0). */
static void point_inertia(double m, const double *c, double *I) {
  int i, j;
  double cc = c[0] * c[0] + c[1] * c[1] + c[2] * c[2];
  I[0] = m;
  for (i = 0; i < 3; ++i) I[1 + i] = m * c[i];
  for (i = 0; i < 3; ++i)
    for (j = 0; j < 3; ++j) I[4 + i + 3 * j] = m * ((i == j ? cc : 0.0) - c[i] * c[j]);
}
static const int rate_src[3] = {0, 1, 0}, rate_col[3] = {0, 1, 0};
static const double rate_coef[3] = {1.0, 1.0, 2.0};
static const int q_src[3] = {-1, -1, 0};
static const double q_coef[3] = {1.0, 1.0, 2.0}, q_off[3] = {0.0, 0.0, 0.1};

static double close_to(double a, double b) { return fabs(a - b) <= 1e-12 * (1.0 + fabs(b)); }

static ncgen_tree tree(void) {
  ncgen_tree T;
  T.nb = 3; T.nq = 3; T.nv = 3; T.ni = 2;
  T.parent = parent; T.kind = kind; T.q_at = q_at; T.v_at = v_at; T.num_ptr = num_ptr;
  T.num = num; T.body = body; T.gravity = gravity;
  T.rate_src = rate_src; T.rate_col = rate_col; T.rate_coef = rate_coef;
  T.q_src = q_src; T.q_coef = q_coef; T.q_off = q_off;
  T.xin = xin; T.inertia = inertia;
  return T;
}

/* The body numbers in f_b of both kinds: kind 0's f_b has the world's axes; kind 1's f_b of
 * body b is turned by R_0 ⋯ R_b (xin_z), so its centre is (R_0 ⋯ R_b)ᵀ c. */
static void make_inertias(void) {
  double Racc[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  int b, i, j, k;
  for (b = 0; b < 3; ++b) {
    const double *m = body + 13 * b, *R = xin_z + 12 * b;
    double N[9], c[3];
    point_inertia(m[0], m + 1, inertia + 13 * b);
    for (i = 0; i < 3; ++i)
      for (j = 0; j < 3; ++j) {
        double t = 0.0;
        for (k = 0; k < 3; ++k) t += Racc[i + 3 * k] * R[k + 3 * j];
        N[i + 3 * j] = t;
      }
    memcpy(Racc, N, sizeof N);
    for (i = 0; i < 3; ++i) c[i] = Racc[3 * i] * m[1] + Racc[3 * i + 1] * m[2] + Racc[3 * i + 2] * m[3];
    point_inertia(m[0], c, inertia_z + 13 * b);
  }
}

/* Forward dynamics by Cholesky of M_i (ncgen_tree_aba's way for trees of at most NCGEN_TREE_DENSE_NV rates). */
static int factored_aba(const ncgen_tree *T, const double *q, const double *v, const double *t_in, double *aj,
                        double *check, double *work) {
  ncgen_tree_work s;
  ncgen_tree_layout(&KINDS, T, work, &s);
  return ncgen_tree_dense_aba(&KINDS, T, &s, q, v, t_in, aj, check);
}

/* The tree without its mimic map (three independent sliders): M = [[m0 + m1 + m2, 0, m2],
 * [0, m1 + m2, 0], [m2, 0, m2]], bias (0, (m1 + m2) g, 0): the articulated-body algorithm. */
static void check_articulated(ncgen_tree *T) {
  static const int src[3] = {0, 1, 2}, no_q[3] = {-1, -1, -1};
  static const double one[3] = {1, 1, 1}, zero[3] = {0, 0, 0};
  ncgen_tree U = *T;
  double q[3] = {0.3, -0.2, 0.4}, v[3] = {0.7, -1.1, 0.2}, t_in[3] = {1.2, -0.4, 0.5}, aj[3], check[2], tau[3];
  double m0 = MASS[0], m1 = MASS[1], m2 = MASS[2], a0, a2, det;
  double *work;
  int way;
  U.ni = 3; U.rate_src = src; U.rate_col = src; U.rate_coef = one; U.q_src = no_q; U.q_coef = one; U.q_off = zero;
  work = (double *)malloc((size_t)ncgen_tree_work_size(&KINDS, &U) * sizeof(double));
  if (!work) return;
  det = (m0 + m1 + m2) * m2 - m2 * m2;
  a0 = (m2 * t_in[0] - m2 * t_in[2]) / det;
  a2 = (-m2 * t_in[0] + (m0 + m1 + m2) * t_in[2]) / det;
  for (way = 0; way < 2; ++way) {               /* the articulated-body algorithm, Cholesky of M */
    CHECK((way ? factored_aba(&U, q, v, t_in, aj, check, work) : ncgen_tree_aba(&KINDS, &U, q, v, t_in, aj, check,
                                                                                 work)) == 0, "aba %d failed", way);
    CHECK(close_to(aj[0], a0) && close_to(aj[1], (t_in[1] - (m1 + m2) * GRAV) / (m1 + m2)) && close_to(aj[2], a2),
          "unmapped %d: aj = (%g, %g, %g), expected (%g, %g, %g)", way, aj[0], aj[1], aj[2], a0,
          (t_in[1] - (m1 + m2) * GRAV) / (m1 + m2), a2);
    CHECK(check[0] > 0.0 && check[0] <= 1.0 && close_to(check[1], aj[0] + aj[1] + aj[2]), "unmapped %d: check (%g, %g)",
          way, check[0], check[1]);
    CHECK(ncgen_tree_rnea(&KINDS, &U, q, v, aj, tau, work) == 0 && close_to(tau[0], t_in[0]) &&
          close_to(tau[1], t_in[1]) && close_to(tau[2], t_in[2]), "rnea(aba(τ)) = (%g, %g, %g)", tau[0], tau[1], tau[2]);
  }
  free(work);
}


int main(void) {
  ncgen_tree T = tree();
  double *work, q[3] = {0.3, -0.2, 5.0}, v[3] = {0.7, -1.1, 9.0}, a[3] = {0.4, 2.0, -7.0};
  double tau[2], M[4], aj[3], check[2], dq[4], dv[4], Minv[4], t_in[2] = {1.2, -0.4};
  double M0 = MASS[0] + MASS[1] + 9 * MASS[2], M1 = MASS[1] + MASS[2], bias1 = (MASS[1] + MASS[2]) * GRAV;
  long n = ncgen_tree_work_size(&KINDS, &T);
  int i;
  CHECK(ncgen_tree_check(&KINDS, &T) == 0, "consistent tables refused");
  work = (double *)malloc((size_t)n * sizeof(double));
  if (!work) return 1;
  make_inertias();

  {
    static int kind_z[3] = {1, 1, 1};
    int pass, way;
    for (pass = 0; pass < 2; ++pass) {          /* kind 0 (kernels), then kind 1 (z sliders turned) */
      if (pass) {
        T.kind = kind_z;
        T.xin = xin_z;
        T.inertia = inertia_z;
      }
      CHECK(ncgen_tree_rnea(&KINDS, &T, q, v, a, tau, work) == 0, "rnea failed");
      CHECK(close_to(tau[0], M0 * a[0]), "pass %d: tau0 = %.17g, expected %.17g", pass, tau[0], M0 * a[0]);
      CHECK(close_to(tau[1], M1 * a[1] + bias1), "pass %d: tau1 = %.17g, expected %.17g", pass, tau[1],
            M1 * a[1] + bias1);

      CHECK(ncgen_tree_crba(&KINDS, &T, q, M, work) == 0, "crba failed");
      CHECK(close_to(M[0], M0) && close_to(M[3], M1) && fabs(M[1]) < 1e-14 && fabs(M[2]) < 1e-14,
            "pass %d: M = [%g %g; %g %g]", pass, M[0], M[2], M[1], M[3]);

      for (way = 0; way < 2; ++way) {           /* the constrained articulated-body algorithm, Cholesky of M_i */
        CHECK((way ? factored_aba(&T, q, v, t_in, aj, check, work) : ncgen_tree_aba(&KINDS, &T, q, v, t_in, aj, check,
                                                                                     work)) == 0, "aba %d failed", way);
        CHECK(close_to(aj[0], t_in[0] / M0) && close_to(aj[1], (t_in[1] - bias1) / M1) && close_to(aj[2], 2 * aj[0]),
              "pass %d, way %d: aj = (%g, %g, %g)", pass, way, aj[0], aj[1], aj[2]);
        CHECK(check[0] > 0.0 && check[0] <= 1.0 && close_to(check[1], aj[0] + aj[1] + aj[2]), "check = (%g, %g)",
              check[0], check[1]);
      }
      check_articulated(&T);
    }
    T.kind = kind;
    T.xin = xin;
    T.inertia = inertia;
  }

  CHECK(ncgen_tree_rnea_derivatives(&KINDS, &T, q, v, a, tau, dq, dv, M, work) == 0, "rnea derivatives failed");
  for (i = 0; i < 4; ++i) CHECK(fabs(dq[i]) < 1e-12 && fabs(dv[i]) < 1e-12, "dtau[%d]: %g, %g", i, dq[i], dv[i]);
  CHECK(close_to(M[0], M0) && close_to(M[3], M1), "dtau/da");
  CHECK(close_to(tau[1], M1 * a[1] + bias1), "tau of the derivatives");

  CHECK(ncgen_tree_aba_derivatives(&KINDS, &T, q, v, t_in, aj, dq, dv, Minv, check, work) == 0,
        "aba derivatives failed");
  for (i = 0; i < 4; ++i) CHECK(fabs(dq[i]) < 1e-12 && fabs(dv[i]) < 1e-12, "da[%d]: %g, %g", i, dq[i], dv[i]);
  CHECK(close_to(Minv[0], 1 / M0) && close_to(Minv[3], 1 / M1) && fabs(Minv[1]) < 1e-14, "M^-1");
  CHECK(close_to(aj[1], (t_in[1] - bias1) / M1), "a of the derivatives");

  /* the ODE: ẋ = [v; a(q, v, E w)] with E = [[1, 0], [0, 2]] (ni × nu, column-major) */
  {
    double x[6] = {0.3, -0.2, 0.7, 0.7, -1.1, 1.4}, xd[6], E[4] = {1.0, 0.0, 0.0, 2.0}, u[2] = {1.2, -0.2};
    ncgen_tree_work s;
    ncgen_tree_layout(&KINDS, &T, work, &s);
    CHECK(ncgen_tree_ode_at(&KINDS, &T, &s, E, 2, x, u, xd, check) == 0, "ode failed");
    CHECK(close_to(xd[0], 0.7) && close_to(xd[1], -1.1) && close_to(xd[2], 1.4), "q̇ = v");
    CHECK(close_to(xd[3], 1.2 / M0) && close_to(xd[4], (-0.4 - bias1) / M1) && close_to(xd[5], 2 * xd[3]),
          "a = (%g, %g, %g)", xd[3], xd[4], xd[5]);
  }

  /* the follower's position and rate are set from its leader: the given q2, v2, a2 do not matter */
  q[2] = -3.0; v[2] = 1.0; a[2] = 100.0;
  CHECK(ncgen_tree_rnea(&KINDS, &T, q, v, a, tau, work) == 0 && close_to(tau[0], M0 * a[0]), "mimic map");

  /* a singular mass matrix: a massless leaf body alone on its rate */
  {
    double massless[39];
    int k;
    memcpy(massless, inertia, sizeof massless);
    for (k = 13; k < 39; ++k) massless[k] = 0.0;
    T.inertia = massless;
    CHECK(ncgen_tree_aba(&KINDS, &T, q, v, t_in, aj, check, work) == 0 && !(check[0] > 1e-12),
          "pivot %g of a singular M", check[0]);
    CHECK(factored_aba(&T, q, v, t_in, aj, check, work) == 0 && !(check[0] > 1e-12),
          "Cholesky pivot %g of a singular M", check[0]);
    T.inertia = inertia;
  }

  fail_kernel = 1;
  CHECK(ncgen_tree_rnea(&KINDS, &T, q, v, a, tau, work) == NCGEN_TREE_KERNEL, "failing kernel not reported");
  fail_kernel = 0;

  parent[1] = 1;
  CHECK(ncgen_tree_check(&KINDS, &T) == NCGEN_TREE_BAD, "a body its own parent accepted");
  parent[1] = 0;
  num_ptr[2] = 5;
  CHECK(ncgen_tree_check(&KINDS, &T) == NCGEN_TREE_BAD, "wrong numbers accepted");
  num_ptr[2] = 6;
  v_at[2] = 3;
  CHECK(ncgen_tree_check(&KINDS, &T) == NCGEN_TREE_BAD, "rate out of range accepted");
  v_at[2] = 2;
  kind[0] = 2;
  CHECK(ncgen_tree_check(&KINDS, &T) == NCGEN_TREE_BAD, "unknown kind accepted");
  kind[0] = 0;
  CHECK(ncgen_tree_check(&KINDS, &T) == 0, "restored tables refused");
  free(work);
  return report("test_tree_tables");
}

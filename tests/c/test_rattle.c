/* Unit tests of the RATTLE stepper's plain C (ncgen_rattle.h, ncgen_fixed.h,
 * ncgen_adaptive.h) on a hand-written model: a planar pendulum in Cartesian coordinates,
 * a point of mass M_P on a massless rod of length L_P from the origin, gravity -G_P along y,
 * and a horizontal force u (the one input) on the point.
 *
 *   q = (x, y), Phi = (x^2 + y^2 - L^2) / 2, A = (x, y), Phi_t = 0, F = (u, -m g)
 *
 * The reference motion is independent of the stepper: the angle theta from the downward
 * vertical obeys m L theta'' = u cos(theta) - m g sin(theta), integrated by classical
 * Runge-Kutta with a step 100 times smaller.  Built and run by tests/test_stepper_runtime_c.py
 * under AddressSanitizer and UndefinedBehaviorSanitizer. */
#include "harness.h"

#define M_P 2.0
#define L_P 1.0
#define G_P 9.81

#define NQ 2
#define NC 1
#define NU 1
#define NNZ_K 9
#define MASS_SCALE M_P
#define MAX_HALVINGS 10
#define NSTATS 12
#define NOUT 5

static casadi_real phi(const casadi_real *q) {
  return (q[0] * q[0] + q[1] * q[1] - L_P * L_P) / 2;
}

/* Column-major dense 3 x 3 KKT matrix [m I, a^T; b, 0]. */
static void kkt(casadi_real *K, const casadi_real *a, const casadi_real *b) {
  K[0] = M_P, K[1] = 0, K[2] = b[0];
  K[3] = 0, K[4] = M_P, K[5] = b[1];
  K[6] = a[0], K[7] = a[1], K[8] = 0;
}

/* r = [m (w - v) - h/2 F + A(q)^T lam_h; Phi(q + h w) / h], K = dr/d[w; lam_h]. */
static int k_newton(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem) {
  const casadi_real *q = arg[1], h = *arg[5], u = at(arg[3], 0), lh = at(arg[7], 0);
  casadi_real wv[2], qp[2];
  int i;
  (void) iw, (void) w, (void) mem;
  for (i = 0; i < 2; ++i) {
    wv[i] = at(arg[6], i);
    qp[i] = q[i] + h * wv[i];
  }
  res[0][0] = M_P * (wv[0] - at(arg[2], 0)) - h / 2 * u + q[0] * lh;
  res[0][1] = M_P * (wv[1] - at(arg[2], 1)) + h / 2 * M_P * G_P + q[1] * lh;
  res[0][2] = phi(qp) / h;
  kkt(res[1], q, qp);
  return 0;
}

/* b = [m w + h/2 F; -Phi_t], K = [m I, A^T; A, 0] at q. */
static int k_velocity(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem) {
  const casadi_real *q = arg[1], h = *arg[5];
  (void) iw, (void) w, (void) mem;
  res[0][0] = M_P * at(arg[2], 0) + h / 2 * at(arg[3], 0);
  res[0][1] = M_P * at(arg[2], 1) - h / 2 * M_P * G_P;
  res[0][2] = 0;
  kkt(res[1], q, q);
  return 0;
}

static int k_check(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem) {
  const casadi_real *q = arg[1], *v = arg[2];
  (void) iw, (void) w, (void) mem;
  *res[0] = fabs(phi(q));
  *res[1] = fabs(q[0] * v[0] + q[1] * v[1]);
  return 0;
}

/* x = K^-1 r, Gaussian elimination with partial pivoting (3 x 3, column-major K). */
static int k_solve(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem) {
  casadi_real a[3][4];
  int i, j, k;
  (void) iw, (void) w, (void) mem;
  for (i = 0; i < 3; ++i) {
    for (j = 0; j < 3; ++j) a[i][j] = arg[0][i + 3 * j];
    a[i][3] = arg[1][i];
  }
  for (k = 0; k < 3; ++k) {
    int p = k;
    for (i = k + 1; i < 3; ++i)
      if (fabs(a[i][k]) > fabs(a[p][k])) p = i;
    for (j = 0; j < 4; ++j) {
      casadi_real s = a[k][j];
      a[k][j] = a[p][j];
      a[p][j] = s;
    }
    for (i = k + 1; i < 3; ++i) {
      casadi_real f = a[i][k] / a[k][k];
      for (j = k; j < 4; ++j) a[i][j] -= f * a[k][j];
    }
  }
  for (i = 2; i >= 0; --i) {
    casadi_real s = a[i][3];
    for (j = i + 1; j < 3; ++j) s -= a[i][j] * res[0][j];
    res[0][i] = s / a[i][i];
  }
  return 0;
}

/* K = [m I, A^T; A, 0], Phi, A v + Phi_t (v NULL: zeros; an output NULL: not wanted). */
static int k_project(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem) {
  const casadi_real *q = arg[1];
  (void) iw, (void) w, (void) mem;
  if (res[0]) kkt(res[0], q, q);
  if (res[1]) res[1][0] = phi(q);
  if (res[2]) res[2][0] = q[0] * at(arg[2], 0) + q[1] * at(arg[2], 1);
  return 0;
}

/* Power of the non-conservative force u: u x'. */
static int k_power(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem) {
  (void) iw, (void) w, (void) mem;
  int i;
  for (i = 0; i < 5; ++i) res[0][i] = 0;
  res[0][0] = res[0][3] = at(arg[4], 0) * arg[2][0]; /* P, all of it the input's */
  return 0;
}

/* T, V, |Phi|, |A v|, P. */
static int k_outputs(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem) {
  const casadi_real *q = arg[1], *v = arg[2];
  (void) iw, (void) w, (void) mem;
  res[0][0] = M_P * (v[0] * v[0] + v[1] * v[1]) / 2;
  res[0][1] = M_P * G_P * q[1];
  res[0][2] = fabs(phi(q));
  res[0][3] = fabs(q[0] * v[0] + q[1] * v[1]);
  res[0][4] = at(arg[4], 0) * v[0];
  return 0;
}

#define KERNEL_NEWTON k_newton
#define KERNEL_VELOCITY k_velocity
#define KERNEL_CHECK k_check
#define KERNEL_SOLVE k_solve
#define KERNEL_PROJECT k_project
#define KERNEL_POWER k_power
#define KERNEL_OUTPUTS k_outputs

#include "ncgen_rattle.h"
#include "ncgen_fixed.h"
#include "ncgen_adaptive.h"

/* ---------------------------------------------------------------- reference motion */

static void rates(casadi_real u, const casadi_real *y, casadi_real *dy) {
  dy[0] = y[1];
  dy[1] = (u * cos(y[0]) - M_P * G_P * sin(y[0])) / (M_P * L_P);
}

/* theta, theta' after t from (theta0, 0) under constant u: RK4 with n steps. */
static void reference(casadi_real theta0, casadi_real u, casadi_real t, long n, casadi_real *y) {
  casadi_real h = t / n, k1[2], k2[2], k3[2], k4[2], z[2];
  long s;
  int i;
  y[0] = theta0;
  y[1] = 0;
  for (s = 0; s < n; ++s) {
    rates(u, y, k1);
    for (i = 0; i < 2; ++i) z[i] = y[i] + h / 2 * k1[i];
    rates(u, z, k2);
    for (i = 0; i < 2; ++i) z[i] = y[i] + h / 2 * k2[i];
    rates(u, z, k3);
    for (i = 0; i < 2; ++i) z[i] = y[i] + h * k3[i];
    rates(u, z, k4);
    for (i = 0; i < 2; ++i) y[i] += h / 6 * (k1[i] + 2 * k2[i] + 2 * k3[i] + k4[i]);
  }
}

/* Cartesian state of angle theta and rate omega. */
static void cartesian(casadi_real theta, casadi_real omega, casadi_real *q, casadi_real *v) {
  q[0] = L_P * sin(theta);
  q[1] = -L_P * cos(theta);
  v[0] = L_P * omega * cos(theta);
  v[1] = L_P * omega * sin(theta);
}

/* max |q - q_ref| at t from theta0 at rest. */
static casadi_real position_error(const casadi_real *q, casadi_real theta0, casadi_real u, casadi_real t) {
  casadi_real y[2], qr[2], vr[2];
  reference(theta0, u, t, 20000, y);
  cartesian(y[0], y[1], qr, vr);
  return fmax(fabs(q[0] - qr[0]), fabs(q[1] - qr[1]));
}

/* ---------------------------------------------------------------- tests */

/* One step by Newton's method: converged in a few iterations, both constraint levels hold,
 * and the step is within its O(h^3) local error of the reference. */
static void test_newton_step(void) {
  casadi_real q[2], v[2], q1[2], v1[2], lam[1], u = 0, h = 1e-3;
  int it = -1, status;
  cartesian(0.5, 0, q, v);
  status = stepper_step(q, v, 0, &u, 0, h, q1, v1, lam, &it, 0, 0, 0);
  CHECK(status == STEP_OK, "status %d", status);
  CHECK(it >= 1 && it <= 4, "%d Newton iterations", it);
  CHECK(fabs(phi(q1)) <= 1e-10, "Phi = %g", phi(q1));
  CHECK(fabs(q1[0] * v1[0] + q1[1] * v1[1]) <= 1e-10, "A v = %g", q1[0] * v1[0] + q1[1] * v1[1]);
  CHECK(position_error(q1, 0.5, 0, h) < 1e-8, "error %g after one step", position_error(q1, 0.5, 0, h));
  /* the multiplier is the rod's tension over L: m g cos(theta) at rest (first order in h) */
  CHECK(fabs(lam[0] - M_P * G_P * cos(0.5) / L_P) < 1e-2 * M_P * G_P, "lambda = %g", lam[0]);
}

/* Fixed steps: second order (the error falls 4 times with h / 2), energy balance with the
 * work of u, and the shadow run's error estimate of the size of the true error. */
static void test_fixed_order_work_estimate(void) {
  const casadi_real theta0 = 0.8, u = 0.7, T = 1.0;
  casadi_real q0[2], v0[2], q[2 * 400], v[2 * 400], lam[400], stats[NSTATS * 400], err[2];
  step_options o = DEFAULT_OPTIONS();
  long done = -1, splits = -1;
  int k, status;
  cartesian(theta0, 0, q0, v0);
  for (k = 0; k < 2; ++k) {
    long n = k ? 400 : 200;
    casadi_real h = T / n, *qe = q + 2 * (n - 1), *ve = v + 2 * (n - 1), *s = stats + NSTATS * (n - 1);
    casadi_real e0 = -M_P * G_P * L_P * cos(theta0), e1, est;
    status = run_fixed(q0, v0, 0, 0, h, n, 1, &u, 0, 0, q, v, lam, 0, stats, &o, &FIXED_RUN(ESTIMATE_SHADOW, 1), &done,
                       &splits, 0);
    CHECK(status == STEP_OK && done == n && splits == 0, "status %d, %ld steps, %ld splits", status, done, splits);
    err[k] = position_error(qe, theta0, u, T);
    e1 = M_P * (ve[0] * ve[0] + ve[1] * ve[1]) / 2 + M_P * G_P * qe[1];
    CHECK(fabs(e1 - e0 - s[5]) < 1e-3 * fabs(e0), "energy change %g, work %g", e1 - e0, s[5]);
    CHECK(s[0] == 1 && s[2] == 0 && s[1] >= 1, "stats row %g %g %g", s[0], s[1], s[2]);
    est = s[3];
    CHECK(est > 0.3 * err[k] && est < 3 * err[k], "estimate %g for an error %g", est, err[k]);
  }
  CHECK(err[0] / err[1] > 3.5 && err[0] / err[1] < 4.5, "errors %g, %g: not second order", err[0], err[1]);
}

/* The fourth-order composition (scheme SCHEME_RATTLE4): fourth order (the error falls 16
 * times with h / 2), both constraint levels held, the shadow run's estimate (now / 15) of
 * the size of the true error, and the local estimate (ESTIMATE_LOCAL) of its magnitude: on
 * this driven pendulum RATTLE's errors grow faster than the composition's and the local
 * estimate comes out about 20 times the true error (documented in stepper_checks.py). */
static void test_rattle4_order_estimate(void) {
  const casadi_real theta0 = 0.8, u = 0.7, T = 1.0;
  casadi_real q0[2], v0[2], q[2 * 50], v[2 * 50], stats[NSTATS * 50], err[2];
  step_options o = DEFAULT_OPTIONS();
  long done = -1;
  int k, status;
  o.scheme = SCHEME_RATTLE4;
  cartesian(theta0, 0, q0, v0);
  for (k = 0; k < 2; ++k) {
    long n = k ? 50 : 25;
    casadi_real h = T / n, *qe = q + 2 * (n - 1), *ve = v + 2 * (n - 1), est;
    status = run_fixed(q0, v0, 0, 0, h, n, 1, &u, 0, 0, q, v, 0, 0, stats, &o, &FIXED_RUN(ESTIMATE_SHADOW, 0), &done,
                       0, 0);
    CHECK(status == STEP_OK && done == n, "status %d, %ld steps", status, done);
    err[k] = position_error(qe, theta0, u, T);
    est = stats[NSTATS * (n - 1) + 3];
    CHECK(fabs(phi(qe)) <= 1e-10 && fabs(qe[0] * ve[0] + qe[1] * ve[1]) <= 1e-10, "constraints");
    CHECK(est > 0.3 * err[k] && est < 3 * err[k], "estimate %g for an error %g", est, err[k]);
    status = run_fixed(q0, v0, 0, 0, h, n, 1, &u, 0, 0, q, v, 0, 0, stats, &o, &FIXED_RUN(ESTIMATE_LOCAL, 0), &done,
                       0, 0);
    est = stats[NSTATS * (n - 1) + 3];
    CHECK(status == STEP_OK && est > 0.1 * err[k] && est < 30 * err[k], "local estimate %g for an error %g", est,
          err[k]);
  }
  CHECK(err[0] / err[1] > 14 && err[0] / err[1] < 18, "errors %g, %g: not fourth order", err[0], err[1]);
  /* a scheme beyond the composition is refused; a backward step is internal only */
  o.scheme = SCHEME_RATTLE4 + 1;
  status = simulate_adaptive(q0, v0, 0, 0, 0.1, 1, 0, 0, 0, &RUN_OPTIONS(1e-6, 1e-6, 0, 1, 100, 0),
                             q, v, 0, 0, &o, 0, 0);
  CHECK(status == STEP_BAD_INPUT, "adaptive with scheme %d: status %d", o.scheme, status);
  o.scheme = SCHEME_RATTLE4;
  status = stepper_step(q0, v0, 0, &u, 0, -1e-3, q, v, 0, 0, &o, 0, 0);
  CHECK(status == STEP_BAD_INPUT, "h < 0: status %d", status);
}

/* A step too long for Newton within max_iter is split into halves (counted), and fails
 * with max_halvings = 0; bad inputs are refused. */
static void test_split_and_bad_input(void) {
  casadi_real q[2], v[2], q1[2], v1[2], u = 0;
  step_options o = DEFAULT_OPTIONS();
  long splits = 0;
  int it = 0, status;
  workspace ws;
  char *block = malloc(step_work_bytes());
  layout(&ws, block);
  cartesian(1.2, 0, q, v);
  o.max_iter = 2;
  status = step_split(q, v, 0, &u, 0, 0.3, q1, v1, 0, &it, &splits, &o, 0, &ws, 0);
  CHECK(status == STEP_OK, "status %d", status);
  CHECK(splits >= 1, "%ld splits", splits);
  CHECK(fabs(phi(q1)) <= o.tol, "Phi = %g", phi(q1));
  CHECK(position_error(q1, 1.2, 0, 0.3) < 5e-3, "error %g", position_error(q1, 1.2, 0, 0.3));
  o.max_halvings = 0;
  splits = 0;
  status = step_split(q, v, 0, &u, 0, 0.3, q1, v1, 0, &it, &splits, &o, 0, &ws, 0);
  CHECK(status == STEP_NO_CONVERGENCE && splits == 0, "status %d, %ld splits", status, splits);
  o = DEFAULT_OPTIONS();
  CHECK(stepper_step(q, v, 0, &u, 0, 0, q1, v1, 0, 0, &o, 0, 0) == STEP_BAD_INPUT, "h = 0");
  CHECK(stepper_step(q, v, 0, &u, 0, NAN, q1, v1, 0, 0, &o, 0, 0) == STEP_BAD_INPUT, "h = NaN");
  CHECK(stepper_step(q, v, INFINITY, &u, 0, 1e-3, q1, v1, 0, 0, &o, 0, 0) == STEP_BAD_INPUT, "t = inf");
  o.max_halvings = MAX_HALVINGS + 1;
  CHECK(stepper_step(q, v, 0, &u, 0, 1e-3, q1, v1, 0, 0, &o, block, 0) == STEP_BAD_INPUT, "max_halvings");
  o = DEFAULT_OPTIONS();
  o.tol = 0;
  CHECK(stepper_step(q, v, 0, &u, 0, 1e-3, q1, v1, 0, 0, &o, block, 0) == STEP_BAD_INPUT, "tol = 0");
  CHECK(run_fixed(q, v, 0, 0, 1e-3, 10, 3, 0, 0, 0, 0, 0, 0, 0, 0, &o, 0, 0, 0, 0) == STEP_BAD_INPUT,
        "n_steps not a multiple of every");
  CHECK(run_fixed(q, v, 0, 0, 1e-3, 10, 5, 0, 0, 0, 0, 0, 0, 0, 0, &o, &FIXED_RUN(ESTIMATE_SHADOW + 1, 0), 0, 0, 0)
        == STEP_BAD_INPUT, "estimate out of range");
  free(block);
}

/* The error controller's step-size rule and its local error measure, by hand. */
static void test_error_controller(void) {
  const casadi_real y[4] = {1, -2, 0, 0.5}, fine[4] = {1, -2.5, 0, 0.5};
  const casadi_real diff[4] = {3e-6, 0, -6e-9, 3e-7};
  casadi_real eq, ev, e;
  CHECK(step_factor_order(1, 2) == 0.9, "factor(1) = %g", step_factor_order(1, 2));
  CHECK(fabs(step_factor_order(8, 2) - 0.45) < 1e-15, "factor(8) = %g", step_factor_order(8, 2));
  CHECK(fabs(step_factor_order(0.125, 2) - 1.8) < 1e-15, "factor(1/8) = %g", step_factor_order(0.125, 2));
  CHECK(step_factor_order(0, 2) == 4 && step_factor_order(1e-12, 2) == 4, "largest growth 4");
  CHECK(step_factor_order(1e6, 2) == 0.2 && step_factor_order(INFINITY, 2) == 0.2, "largest cut 0.2");
  CHECK(step_factor_order(NAN, 2) == 4, "factor(NaN) = %g (the caller rejects the step)", step_factor_order(NAN, 2));
  CHECK(fabs(step_factor_order(32, 4) - 0.45) < 1e-15, "order 4: factor(32) = %g", step_factor_order(32, 4));
  /* |diff| / 3 against atol + rtol max(|y_i|, |fine_i|), rtol = 1e-3, atol = 1e-6: the
   * third component (2e-9 against 1e-6) is the largest relative one */
  e = local_error(y, diff, fine, 1e-3, 1e-6, 3, &eq, &ev);
  CHECK(fabs(eq - 1e-6) < 1e-21 && fabs(ev - 1e-7) < 1e-22, "errors %g in q, %g in v", eq, ev);
  CHECK(fabs(e - 2e-3) < 1e-15, "relative error %g", e);
  e = local_error(y, (const casadi_real[4]) {0, NAN, 0, 1}, fine, 1e-3, 1e-6, 3, &eq, &ev);
  CHECK(isnan(e) && isnan(eq) && ev > 0, "NaN propagates past later components: %g, %g, %g", e, eq, ev);
  CHECK(isnan(norm_inf((const casadi_real[3]) {1, NAN, 2}, 3)), "norm_inf of a NaN");
  CHECK(norm_inf((const casadi_real[3]) {1, -3, 2}, 3) == 3, "norm_inf");
}

/* Error-controlled run: every row reached, the error near the tolerance and smaller for a
 * tighter one (with fewer steps for a looser one), the projection onto the constraints. */
static void test_adaptive(void) {
  const casadi_real theta0 = 1.0, T = 1.0, uu[11] = {0};
  casadi_real q0[2], v0[2], q[2 * 10], v[2 * 10], stats[NSTATS * 10], h_next = 0, err[2];
  long rows = -1, steps[2] = {0, 0};
  int k, r, status;
  cartesian(theta0, 0, q0, v0);
  for (k = 0; k < 2; ++k) {
    casadi_real rtol = k ? 1e-8 : 1e-5;
    status = simulate_adaptive(q0, v0, 0, 0, T / 10, 10, uu, 1, 0, &RUN_OPTIONS(rtol, rtol, 0, 1, 1000, 1),
                               q, v, 0, stats, 0, &rows, &h_next);
    CHECK(status == STEP_OK && rows == 10, "status %d, %ld rows", status, rows);
    CHECK(h_next > 0, "next step %g", h_next);
    for (r = 0; r < 10; ++r) steps[k] += (long) stats[NSTATS * r];
    err[k] = position_error(q + 18, theta0, 0, T);
    CHECK(err[k] < 300 * rtol, "error %g for rtol %g", err[k], rtol);
    CHECK(fabs(phi(q + 18)) <= 1e-10, "Phi = %g", phi(q + 18));
  }
  CHECK(err[1] < err[0] / 5, "errors %g, %g", err[0], err[1]);
  CHECK(steps[1] > 3 * steps[0], "steps %ld, %ld", steps[0], steps[1]);
  status = simulate_adaptive(q0, v0, 0, 0, T, 1, 0, 0, 0, &RUN_OPTIONS(1e-10, 1e-10, T, 0, 2, 0),
                             q, v, 0, 0, 0, &rows, 0);
  CHECK(status == STEP_TOO_MANY_STEPS && rows == 0, "status %d, %ld rows", status, rows);
  status = simulate_adaptive(q0, v0, 0, 0, T, 1, 0, 0, 0, &RUN_OPTIONS(0, 1e-8, 0, 0, 10, 0),
                             q, v, 0, 0, 0, &rows, 0);
  CHECK(status == STEP_BAD_INPUT, "rtol = 0: status %d", status);
}

/* Error control of the fourth-order composition (scheme SCHEME_RATTLE4): every row reached,
 * both constraint levels held, the error near the tolerance and falling with it, the step
 * count growing as rtol^(-1/5) (order 4: 10^(3/5) ~ 4 for rtol / 1000) and far below
 * RATTLE's at the tight tolerance; the local error columns sum to about the true error. */
static void test_adaptive_rattle4(void) {
  const casadi_real theta0 = 1.0, T = 1.0, uu[11] = {0};
  casadi_real q0[2], v0[2], q[2 * 10], v[2 * 10], stats[NSTATS * 10], err[2];
  step_options o = DEFAULT_OPTIONS();
  long rows = -1, steps[2] = {0, 0}, steps_rattle = 0;
  int k, r, status;
  cartesian(theta0, 0, q0, v0);
  o.scheme = SCHEME_RATTLE4;
  for (k = 0; k < 2; ++k) {
    casadi_real rtol = k ? 1e-9 : 1e-6;
    status = simulate_adaptive(q0, v0, 0, 0, T / 10, 10, uu, 1, 0, &RUN_OPTIONS(rtol, rtol, 0, 0, 1000, 0),
                               q, v, 0, stats, &o, &rows, 0);
    CHECK(status == STEP_OK && rows == 10, "status %d, %ld rows", status, rows);
    for (r = 0; r < 10; ++r) steps[k] += (long) stats[NSTATS * r];
    err[k] = position_error(q + 18, theta0, 0, T);
    CHECK(err[k] < 100 * rtol && err[k] > 1e-3 * rtol, "error %g for rtol %g", err[k], rtol);
    CHECK(fabs(phi(q + 18)) <= 1e-10 && fabs(q[18] * v[18] + q[19] * v[19]) <= 1e-9, "constraints");
  }
  CHECK(err[1] < err[0] / 30, "errors %g, %g", err[0], err[1]);
  CHECK(steps[1] > 2.5 * steps[0] && steps[1] < 7 * steps[0], "steps %ld, %ld: not order 4", steps[0], steps[1]);
  o.scheme = 0;
  status = simulate_adaptive(q0, v0, 0, 0, T / 10, 10, uu, 1, 0, &RUN_OPTIONS(1e-9, 1e-9, 0, 0, 100000, 0),
                             q, v, 0, stats, &o, &rows, 0);
  for (r = 0; r < 10; ++r) steps_rattle += (long) stats[NSTATS * r];
  CHECK(status == STEP_OK && steps_rattle > 5 * steps[1], "RATTLE %ld steps, the composition %ld", steps_rattle,
        steps[1]);
}

/* The projection of a state off both constraint levels: radially back onto the circle (the
 * mass metric is a multiple of the identity), the radial part of the velocity removed. */
static void test_project_and_outputs(void) {
  casadi_real q[2] = {0.6 * 1.01, -0.8 * 1.01}, v[2] = {1.0, 0.5}, phidot[1], y[NOUT], t = 0;
  casadi_real vt = 1.0 * 0.8 + 0.5 * 0.6; /* tangential speed along (0.8, 0.6) */
  step_options o = DEFAULT_OPTIONS();
  workspace ws;
  char *block = malloc(step_work_bytes());
  layout(&ws, block);
  CHECK(project(&ws, 0, q, v, 0, &o, phidot) == STEP_OK, "status");
  CHECK(fabs(q[0] - 0.6) < 1e-10 && fabs(q[1] + 0.8) < 1e-10, "q = (%g, %g)", q[0], q[1]);
  CHECK(fabs(v[0] - 0.8 * vt) < 1e-9 && fabs(v[1] - 0.6 * vt) < 1e-9, "v = (%g, %g)", v[0], v[1]);
  free(block);
  CHECK(stepper_outputs(1, &t, q, v, 0, 0, 0, 0, y) == STEP_OK, "outputs");
  CHECK(fabs(y[0] - M_P * vt * vt / 2) < 1e-9 && fabs(y[1] + M_P * G_P * 0.8) < 1e-9, "T = %g, V = %g", y[0], y[1]);
}

/* A stop request (options->stop set) ends both loops before their next step with
 * STEP_INTERRUPTED and the rows done so far. */
static void test_stop_request(void) {
  casadi_real q0[2] = {0.6, -0.8}, v0[2] = {0.8, 0.6}, q[4], v[4];
  volatile int stop = 1;
  step_options o = DEFAULT_OPTIONS();
  long done = -1, rows = -1;
  int status;
  o.stop = &stop;
  status = run_fixed(q0, v0, 0, 0, 1e-3, 4, 2, 0, 0, 0, q, v, 0, 0, 0, &o, &FIXED_RUN(ESTIMATE_LOCAL, 0), &done, 0, 0);
  CHECK(status == STEP_INTERRUPTED && done == 0, "fixed: status %d, %ld steps", status, done);
  status = simulate_adaptive(q0, v0, 0, 0, 0.1, 2, 0, 0, 0, &RUN_OPTIONS(1e-6, 1e-6, 0, 1, 100, 0),
                             q, v, 0, 0, &o, &rows, 0);
  CHECK(status == STEP_INTERRUPTED && rows == 0, "adaptive: status %d, %ld rows", status, rows);
  stop = 0;
  status = run_fixed(q0, v0, 0, 0, 1e-3, 4, 2, 0, 0, 0, q, v, 0, 0, 0, &o, &FIXED_RUN(ESTIMATE_LOCAL, 0), &done, 0, 0);
  CHECK(status == STEP_OK && done == 4, "fixed, not stopped: status %d, %ld steps", status, done);
}

int main(void) {
  test_newton_step();
  test_fixed_order_work_estimate();
  test_rattle4_order_estimate();
  test_split_and_bad_input();
  test_error_controller();
  test_adaptive();
  test_adaptive_rattle4();
  test_project_and_outputs();
  test_stop_request();
  return report("test_rattle");
}

/* Unit tests of the joint-space loop's plain C (ncgen_joint_loop.h) on a hand-written ODE
 * with a closed-form solution, x = (a, b, y, z, q0, q1, q2, q3):
 *
 *   a' = b, b' = -OMEGA^2 a                harmonic oscillator: a = cos(OMEGA t), b = -OMEGA sin(OMEGA t)
 *   y' = -LAMBDA y  (blow_up: y' = y^2)    exponential decay e^(-LAMBDA t)  (blow_up: 1 / (1 - t))
 *   z' = w(t) = W[k] + (t - t_k) S[k]      the input of output interval k, integrated exactly
 *   q' = q (x) (0, 0, 0, SPIN) / 2         a unit quaternion turning about z at SPIN rad/s:
 *                                          q = (cos(SPIN t / 2), 0, 0, sin(SPIN t / 2))
 *
 * from a = 1, b = 0, y = 1, z = 0, q = (1, 0, 0, 0) at t = 0.  Checked: RK4's order (the error
 * falls 16-fold per halving of the step), its evaluation count, the inputs of each output
 * interval; Dormand-Prince's error against its tolerance, its step count against tol^(-1/5),
 * its dense output on a non-uniform grid, restarts at the outputs; the renormalised
 * quaternion; the failure paths (non-finite state, a blow-up: too many steps, step size
 * underflow; the stop flag).  Built and run by tests/test_stepper_runtime_c.py under
 * AddressSanitizer and UndefinedBehaviorSanitizer. */
#include "check.h"

#define OMEGA 3.0
#define LAMBDA 0.7
#define SPIN 2.0
#define NX 8
#define MAX_OUT 64

typedef struct {
    const double *W, *S;
    int blow_up;
    long evaluations;
} test_model;

/* Nonzero where x or x' is not finite, as the generated ODE's checks. */
static int test_ode(test_model *m, int k, double t_k, double t, const double *x, double *f) {
    int i;
    ++m->evaluations;
    f[0] = x[1];
    f[1] = -OMEGA * OMEGA * x[0];
    f[2] = m->blow_up ? x[2] * x[2] : -LAMBDA * x[2];
    f[3] = m->W ? m->W[k] + (m->S ? (t - t_k) * m->S[k] : 0.0) : 0.0;
    f[4] = -0.5 * SPIN * x[7];
    f[5] = 0.5 * SPIN * x[6];
    f[6] = -0.5 * SPIN * x[5];
    f[7] = 0.5 * SPIN * x[4];
    for (i = 0; i < NX; ++i)
        if (!isfinite(x[i]) || !isfinite(f[i])) return 1;
    return 0;
}

#define JOINT_MODEL test_model
#define JOINT_ODE test_ode
#include "ncgen_joint_loop.h"

static const int QUAT[1] = {4};

static void exact(double t, double z, double *x) {
    x[0] = cos(OMEGA * t);
    x[1] = -OMEGA * sin(OMEGA * t);
    x[2] = exp(-LAMBDA * t);
    x[3] = z;
    x[4] = cos(0.5 * SPIN * t);
    x[5] = 0.0;
    x[6] = 0.0;
    x[7] = sin(0.5 * SPIN * t);
}

static void start(double *X) {
    exact(0.0, 0.0, X);
}

/* The integral of the piecewise-linear input over [t_0, t_n], interval by interval. */
static double input_integral(const double *t, const double *W, const double *S, int n) {
    double z = 0.0;
    int k;
    for (k = 0; k < n; ++k) {
        double h = t[k + 1] - t[k];
        z += W[k] * h + (S ? 0.5 * S[k] * h * h : 0.0);
    }
    return z;
}

/* max_i |x_i - exact_i| / (atol + rtol |exact_i|) over the rows 1..n of X. */
static double scaled_error(const double *t, const double *X, const double *W, const double *S, int n,
                           double rtol, double atol) {
    double worst = 0.0, ref[NX];
    int k, i;
    for (k = 1; k <= n; ++k) {
        exact(t[k], W ? input_integral(t, W, S, k) : 0.0, ref);
        for (i = 0; i < NX; ++i) {
            double r = fabs(X[k * NX + i] - ref[i]) / (atol + rtol * fabs(ref[i]));
            if (r > worst) worst = r;
        }
    }
    return worst;
}

static double quaternion_norm_error(const double *X, int n) {
    double worst = 0.0;
    int k;
    for (k = 0; k <= n; ++k) {
        const double *q = X + k * NX + 4;
        double e = fabs(sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]) - 1.0);
        if (e > worst) worst = e;
    }
    return worst;
}

static void grid(double *t, int n, double T) {
    int k;
    for (k = 0; k <= n; ++k) t[k] = T * k / n;
}

static int run(test_model *m, int method, int n, const double *t, double *X, int nquat, double rtol,
               double atol, int substeps, long max_steps, int stop_at_outputs, double *stats, int *k_done,
               volatile int *stop) {
    memset(stats, 0, 5 * sizeof(double));
    m->evaluations = 0;
    start(X);
    ncgen_joint_options o;
    o.method = method;
    o.rtol = rtol;
    o.atol = atol;
    o.substeps = substeps;
    o.max_steps = max_steps;
    o.stop_at_outputs = stop_at_outputs;
    o.stop = stop;
    return joint_run(m, &o, n, t, X, nquat, QUAT, stats, k_done);
}

/* RK4: the error of the final state falls by 2^4 per halving of the step; each step costs
 * four evaluations; the piecewise-linear input is integrated exactly on its own interval. */
static void test_rk4_order(void) {
    double t[5], X[5 * NX], stats[5], W[4] = {1.0, -2.0, 0.5, 3.0}, S[4] = {0.4, 1.0, -3.0, 2.0};
    double err[4], z;
    int j, k_done, status;
    test_model m = {W, S, 0, 0};
    grid(t, 4, 2.0);
    for (j = 0; j < 4; ++j) {
        int substeps = 8 << j;
        double ref[NX];
        int i;
        status = run(&m, 0, 4, t, X, 1, 0, 0, substeps, 0, 1, stats, &k_done, 0);
        CHECK(status == JOINT_OK && k_done == 4, "status %d, k_done %d", status, k_done);
        CHECK(stats[0] == 4.0 * substeps && stats[2] == 16.0 * substeps && (long)stats[2] == m.evaluations,
              "steps %g, evaluations %g (counted %ld) for %d substeps", stats[0], stats[2], m.evaluations, substeps);
        z = input_integral(t, W, S, 4);
        CHECK(fabs(X[4 * NX + 3] - z) < 1e-13, "z(2) = %.17g, exact %.17g", X[4 * NX + 3], z);
        exact(t[4], z, ref);
        err[j] = 0.0;
        for (i = 0; i < NX; ++i)
            if (fabs(X[4 * NX + i] - ref[i]) > err[j]) err[j] = fabs(X[4 * NX + i] - ref[i]);
        CHECK(quaternion_norm_error(X, 4) < 1e-15, "|q| - 1 = %g with renormalisation", quaternion_norm_error(X, 4));
    }
    for (j = 1; j < 4; ++j)
        CHECK(err[j - 1] / err[j] > 14.0 && err[j - 1] / err[j] < 18.0, "RK4 error ratio %g at %d substeps (%g / %g)",
              err[j - 1] / err[j], 8 << j, err[j - 1], err[j]);
    CHECK(err[3] < 1e-6 && err[3] > 1e-12, "RK4 error %g at 64 substeps", err[3]);
}

/* Without renormalisation RK4 leaves the unit sphere (|R(i z)| < 1 for its stability
 * function); with it the quaternion keeps unit length to rounding. */
static void test_renormalisation(void) {
    double t[5], X[5 * NX], stats[5];
    int k_done;
    test_model m = {0, 0, 0, 0};
    grid(t, 4, 2.0);
    run(&m, 0, 4, t, X, 0, 0, 0, 2, 0, 1, stats, &k_done, 0);
    CHECK(quaternion_norm_error(X, 4) > 1e-6, "|q| - 1 = %g without renormalisation", quaternion_norm_error(X, 4));
    run(&m, 0, 4, t, X, 1, 0, 0, 2, 0, 1, stats, &k_done, 0);
    CHECK(quaternion_norm_error(X, 4) < 1e-15, "|q| - 1 = %g with renormalisation", quaternion_norm_error(X, 4));
}

/* Dormand-Prince: the error at every output stays within a small multiple of the tolerance
 * (the control bounds the local error; the global one adds up over the steps) and falls
 * with it; the steps grow as tol^(-1/5); evaluations: 6 per step tried (rejections before
 * the first accepted step are not counted as rejected), plus the first stage of each of the
 * 8 restarted intervals and one for the initial step estimate. */
static void test_dopri5_tolerance(void) {
    double t[9], X[9 * NX], stats[5], steps[2], tol[2] = {1e-6, 1e-9}, worst[2];
    double W[8] = {1.0, -1.0, 2.0, 0.0, 0.5, -0.5, 1.5, 3.0}, S[8] = {1.0, 0.0, -2.0, 4.0, 0.0, 1.0, -1.0, 0.5};
    int j, k_done, status;
    test_model m = {W, S, 0, 0};
    grid(t, 8, 3.0);
    for (j = 0; j < 2; ++j) {
        status = run(&m, 1, 8, t, X, 1, tol[j], tol[j], 0, 100000, 1, stats, &k_done, 0);
        CHECK(status == JOINT_OK && k_done == 8, "status %d, k_done %d", status, k_done);
        worst[j] = scaled_error(t, X, W, S, 8, tol[j], tol[j]);
        CHECK(worst[j] < 20.0, "scaled error %g at tol %g", worst[j], tol[j]);
        CHECK((long)stats[2] == m.evaluations, "evaluations %g, counted %ld", stats[2], m.evaluations);
        CHECK(stats[2] >= 9.0 + 6.0 * (stats[0] + stats[1]) && fmod(stats[2] - 9.0, 6.0) == 0.0,
              "evaluations %g for %g steps, %g rejected", stats[2], stats[0], stats[1]);
        CHECK(stats[3] > 0.0, "next step %g", stats[3]);
        CHECK(quaternion_norm_error(X, 8) < 1e-15, "|q| - 1 = %g", quaternion_norm_error(X, 8));
        steps[j] = stats[0];
    }
    CHECK(steps[1] / steps[0] > 2.5 && steps[1] / steps[0] < 6.5, "steps %g at 1e-6, %g at 1e-9 (expected ~4x)",
          steps[0], steps[1]);
    CHECK(worst[0] * tol[0] > 30.0 * worst[1] * tol[1], "absolute errors %g at 1e-6, %g at 1e-9",
          worst[0] * tol[0], worst[1] * tol[1]);
}

/* Dense output: without restarts at the outputs (held inputs) a run over a fine, non-uniform
 * grid takes fewer steps than there are outputs, and its 4th-order interpolant meets the
 * tolerance at every output; with restarts every interval takes at least one step. */
static void test_dense_output(void) {
    double t[MAX_OUT + 1], X[(MAX_OUT + 1) * NX], stats[5], W[MAX_OUT], worst;
    int k, k_done, status, n = MAX_OUT;
    test_model m = {W, 0, 0, 0};
    for (k = 0; k <= n; ++k) t[k] = 2.0 * (double)k * k / ((double)n * n);
    for (k = 0; k < n; ++k) W[k] = 1.5;
    status = run(&m, 1, n, t, X, 1, 1e-8, 1e-8, 0, 1000, 0, stats, &k_done, 0);
    CHECK(status == JOINT_OK && k_done == n, "status %d, k_done %d", status, k_done);
    CHECK(stats[0] < n, "%g steps for %d outputs: not interpolated", stats[0], n);
    worst = scaled_error(t, X, W, 0, n, 1e-8, 1e-8);
    CHECK(worst < 20.0, "scaled error %g of the dense output", worst);
    CHECK(quaternion_norm_error(X, n) < 1e-15, "|q| - 1 = %g at the dense outputs", quaternion_norm_error(X, n));
    status = run(&m, 1, n, t, X, 1, 1e-8, 1e-8, 0, 1000, 1, stats, &k_done, 0);
    CHECK(status == JOINT_OK && k_done == n && stats[0] >= n, "status %d, %g steps for %d outputs with restarts",
          status, stats[0], n);
    worst = scaled_error(t, X, W, 0, n, 1e-8, 1e-8);
    CHECK(worst < 20.0, "scaled error %g with restarts", worst);
}

/* A non-finite initial state: both methods stop at once, nothing written past row 0. */
static void test_non_finite_state(void) {
    double t[5], X[5 * NX], stats[5];
    int method, k_done, status;
    test_model m = {0, 0, 0, 0};
    grid(t, 4, 1.0);
    for (method = 0; method < 2; ++method) {
        memset(stats, 0, sizeof stats);
        m.evaluations = 0;
        start(X);
        X[1] = NAN;
        X[NX] = 12345.0;
        k_done = -1;
        ncgen_joint_options o = {0, 1e-8, 1e-8, 4, 1000, 1, NULL};
        o.method = method;
        status = joint_run(&m, &o, 4, t, X, 1, QUAT, stats, &k_done);
        CHECK(status == JOINT_SINGULAR && k_done == 0 && stats[4] == 0.0 && stats[0] == 0.0,
              "method %d: status %d, k_done %d, failed at t = %g after %g steps", method, status, k_done, stats[4],
              stats[0]);
        CHECK(stats[2] == 1.0 && X[NX] == 12345.0, "method %d: %g evaluations, row 1 %g", method, stats[2], X[NX]);
    }
}

/* y' = y^2 from y = 1 blows up at t = 1, inside output interval 1 of (0, 2/3, 4/3, 2): RK4
 * overflows past it (a non-finite state), Dormand-Prince runs out of steps (max_steps per
 * interval), or with enough steps shrinks its step to underflow within 1e-6 of t = 1; the rows
 * before are accurate. */
static void test_blow_up(void) {
    double t[4], X[4 * NX], stats[5];
    int k_done, status, k;
    test_model m = {0, 0, 1, 0};
    grid(t, 3, 2.0);
    status = run(&m, 0, 3, t, X, 1, 0, 0, 10, 0, 1, stats, &k_done, 0);
    CHECK(status == JOINT_SINGULAR && k_done >= 1 && k_done < 3 && stats[4] >= t[k_done] && stats[4] < t[k_done + 1],
          "RK4: status %d, k_done %d, failed at t = %g", status, k_done, stats[4]);
    for (k = 0; k <= k_done; ++k)
        CHECK(isfinite(X[k * NX + 2]), "RK4: row %d not finite", k);
    status = run(&m, 1, 3, t, X, 1, 1e-8, 1e-8, 0, 50, 1, stats, &k_done, 0);
    CHECK(status == JOINT_TOO_MANY_STEPS && k_done == 1 && stats[4] > t[1] && stats[4] < 1.0,
          "DOPRI5, 50 steps: status %d, k_done %d, failed at t = %g after %g steps", status, k_done, stats[4],
          stats[0]);
    status = run(&m, 1, 3, t, X, 1, 1e-8, 1e-8, 0, 1000000, 1, stats, &k_done, 0);
    CHECK(status == JOINT_STEP_UNDERFLOW && k_done == 1 && fabs(stats[4] - 1.0) < 1e-6,
          "DOPRI5: status %d, k_done %d, failed at t = %.17g", status, k_done, stats[4]);
    CHECK(fabs(X[NX + 2] - 3.0) < 1e-6, "y(2/3) = %.17g, exact 3", X[NX + 2]);
}

/* The stop flag, read before every step: a set flag stops both methods at once. */
static void test_stop(void) {
    double t[5], X[5 * NX], stats[5];
    volatile int stop = 1;
    int method, k_done, status;
    test_model m = {0, 0, 0, 0};
    grid(t, 4, 1.0);
    for (method = 0; method < 2; ++method) {
        status = run(&m, method, 4, t, X, 1, 1e-8, 1e-8, 4, 1000, 1, stats, &k_done, &stop);
        CHECK(status == JOINT_STOPPED && k_done == 0 && stats[0] == 0.0, "method %d: status %d, k_done %d, %g steps",
              method, status, k_done, stats[0]);
    }
}

int main(void) {
    test_rk4_order();
    test_renormalisation();
    test_dopri5_tolerance();
    test_dense_output();
    test_non_finite_state();
    test_blow_up();
    test_stop();
    return report("test_joint_loop");
}

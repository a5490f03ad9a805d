/* The joint-space integration loop: x' = f(t, x) integrated over a grid of output times by
 * classical RK4 or by Dormand-Prince 5(4) with error control and dense output.  Plain C99,
 * model-independent: the model's glue (<model>_joint_loop.c, from
 * templates/c/joint_loop.c.j2) defines the data below, then includes this file; every
 * function here is static.  Times in the unit of t_out (s), states as the ODE defines them.
 *
 * What the including file defines first:
 *   NX            the size of the state x
 *   JOINT_MODEL   the type of the model's data (passed through to JOINT_ODE)
 *   JOINT_ODE     a function int JOINT_ODE(JOINT_MODEL *m, int k, double t_k, double t,
 *                 const double *x, double *f) writing f = x'(t) on output interval k, which
 *                 starts at t_k = t_out[k] (the model interpolates its inputs from them);
 *                 nonzero when the dynamics are singular or not finite at (t, x)
 *
 * joint_run() integrates from t_out[0] over the n_out output intervals and writes the state
 * at every output time into X (row-major, (n_out + 1) x NX; row 0 is the initial state on
 * entry), as its options (ncgen_joint_options, below: simulate(method="joint")'s option
 * group, passed whole) say.
 *   method 0: classical RK4, `substeps` equal steps per output interval;
 *   method 1: Dormand-Prince 5(4) (error per step: sqrt(mean((e_i / (atol + rtol max(|y0_i|,
 *             |y1_i|)))^2)) <= 1; step control as Hairer's DOPRI5), outputs by its
 *             4th-order dense output, restarted at every output time when stop_at_outputs
 *             (otherwise one segment over the whole grid, on output interval k = 0's data);
 *             at most max_steps steps per output interval.
 * After every step the unit quaternions (starts quat[0..nquat-1] in x) are renormalised.
 * stats (in/out): [0] steps, [1] rejected steps, [2] ODE evaluations, [3] next step size
 * (in: first step to try, 0 = estimate), [4] time reached when failing.
 * stop: NULL, or a flag read before every step; nonzero stops the run.
 * Returns one of the JOINT_* status codes below; *k_done = output intervals completed. */
#include <float.h>
#include <math.h>
#include <string.h>

#define JOINT_OK 0
#define JOINT_SINGULAR 1        /* singular or non-finite dynamics */
#define JOINT_TOO_MANY_STEPS 2  /* more than max_steps steps per output interval */
#define JOINT_STEP_UNDERFLOW 3  /* step size underflow */
/* 4 is not used: no glue allocates (the code once said out of memory; the others keep their numbers) */
#define JOINT_STOPPED 5         /* stopped through *stop */

/* The joint loop's options (fields as described at the top of this file). */
typedef struct {
    int method;
    double rtol;
    double atol;
    int substeps;
    long max_steps;
    int stop_at_outputs;
    volatile int *stop;
} ncgen_joint_options;

typedef struct {
    JOINT_MODEL *model;
    int k;          /* output interval of the current segment */
    double t_k;     /* its start t_out[k] */
    double nfev;    /* ODE evaluations */
} joint_loop;

static int joint_rhs(joint_loop *c, double t, const double *x, double *f) {
    c->nfev += 1.0;
    return JOINT_ODE(c->model, c->k, c->t_k, t, x, f);
}

static void renormalise(double *x, int nquat, const int *quat) {
    int i, j;
    for (i = 0; i < nquat; ++i) {
        double *q = x + quat[i], n = 0.0;
        for (j = 0; j < 4; ++j) n += q[j] * q[j];
        n = sqrt(n);
        if (n > 0.0)
            for (j = 0; j < 4; ++j) q[j] /= n;
    }
}

static double err_norm(const double *y0, const double *y1, const double *e, double rtol, double atol) {
    double s = 0.0;
    int i;
    for (i = 0; i < NX; ++i) {
        double a = fabs(y0[i]), b = fabs(y1[i]);
        double sk = atol + rtol * (a > b ? a : b);
        double r = e[i] / sk;
        s += r * r;
    }
    return sqrt(s / NX);
}

static int run_rk4(joint_loop *c, int n_out, const double *t_out, double *X, int substeps,
                   int nquat, const int *quat, double *stats, int *k_done, volatile int *stop) {
    double k1[NX], k2[NX], k3[NX], k4[NX], y[NX], tmp[NX];
    int k, s, i;
    for (k = 0; k < n_out; ++k) {
        double t = t_out[k], h = (t_out[k + 1] - t_out[k]) / substeps;
        c->k = k;
        c->t_k = t_out[k];
        memcpy(y, X + (size_t)k * NX, sizeof y);
        if (stop && *stop) {
            *k_done = k;
            return JOINT_STOPPED;
        }
        for (s = 0; s < substeps; ++s) {
            if (joint_rhs(c, t, y, k1)) goto fail;
            for (i = 0; i < NX; ++i) tmp[i] = y[i] + 0.5 * h * k1[i];
            if (joint_rhs(c, t + 0.5 * h, tmp, k2)) goto fail;
            for (i = 0; i < NX; ++i) tmp[i] = y[i] + 0.5 * h * k2[i];
            if (joint_rhs(c, t + 0.5 * h, tmp, k3)) goto fail;
            for (i = 0; i < NX; ++i) tmp[i] = y[i] + h * k3[i];
            if (joint_rhs(c, t + h, tmp, k4)) goto fail;
            for (i = 0; i < NX; ++i) y[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
            renormalise(y, nquat, quat);
            t = (s + 1 == substeps) ? t_out[k + 1] : t + h;
            stats[0] += 1.0;
            continue;
        fail:
            stats[4] = t;
            *k_done = k;
            return JOINT_SINGULAR;
        }
        memcpy(X + (size_t)(k + 1) * NX, y, sizeof y);
    }
    *k_done = n_out;
    return JOINT_OK;
}

/* Dormand-Prince 5(4) coefficients, and Hairer's dense output (DOPRI5, contd5). */
#define C2 (1.0 / 5)
#define C3 (3.0 / 10)
#define C4 (4.0 / 5)
#define C5 (8.0 / 9)
#define A21 (1.0 / 5)
#define A31 (3.0 / 40)
#define A32 (9.0 / 40)
#define A41 (44.0 / 45)
#define A42 (-56.0 / 15)
#define A43 (32.0 / 9)
#define A51 (19372.0 / 6561)
#define A52 (-25360.0 / 2187)
#define A53 (64448.0 / 6561)
#define A54 (-212.0 / 729)
#define A61 (9017.0 / 3168)
#define A62 (-355.0 / 33)
#define A63 (46732.0 / 5247)
#define A64 (49.0 / 176)
#define A65 (-5103.0 / 18656)
#define A71 (35.0 / 384)
#define A73 (500.0 / 1113)
#define A74 (125.0 / 192)
#define A75 (-2187.0 / 6784)
#define A76 (11.0 / 84)
#define E1 (71.0 / 57600)
#define E3 (-71.0 / 16695)
#define E4 (71.0 / 1920)
#define E5 (-17253.0 / 339200)
#define E6 (22.0 / 525)
#define E7 (-1.0 / 40)
#define D1 (-12715105075.0 / 11282082432)
#define D3 (87487479700.0 / 32700410799)
#define D4 (-10690763975.0 / 1880347072)
#define D5 (701980252875.0 / 199316789632)
#define D6 (-1453857185.0 / 822651844)
#define D7 (69997945.0 / 29380423)

/* Hairer's initial step (hinit) for order 5. */
static int first_step(joint_loop *c, double t, const double *y, const double *f0, double span,
                      double rtol, double atol, double *h) {
    double y1[NX], f1[NX], d0 = 0, d1 = 0, d2 = 0, h0, h1, dm;
    int i;
    for (i = 0; i < NX; ++i) {
        double sk = atol + rtol * fabs(y[i]);
        d0 += (y[i] / sk) * (y[i] / sk);
        d1 += (f0[i] / sk) * (f0[i] / sk);
    }
    d0 = sqrt(d0 / NX);
    d1 = sqrt(d1 / NX);
    h0 = (d0 < 1e-5 || d1 < 1e-5) ? 1e-6 : 0.01 * d0 / d1;
    if (h0 > span) h0 = span;
    for (i = 0; i < NX; ++i) y1[i] = y[i] + h0 * f0[i];
    if (joint_rhs(c, t + h0, y1, f1)) return 1;
    for (i = 0; i < NX; ++i) {
        double sk = atol + rtol * fabs(y[i]);
        d2 += ((f1[i] - f0[i]) / sk) * ((f1[i] - f0[i]) / sk);
    }
    d2 = sqrt(d2 / NX) / h0;
    dm = d1 > d2 ? d1 : d2;
    h1 = dm <= 1e-15 ? (h0 * 1e-3 > 1e-6 ? h0 * 1e-3 : 1e-6) : pow(0.01 / dm, 0.2);
    *h = 100.0 * h0 < h1 ? 100.0 * h0 : h1;
    if (*h > span) *h = span;
    return 0;
}

static int run_dopri5(joint_loop *c, int n_out, const double *t_out, double *X, double rtol,
                      double atol, long max_steps, int stop_at_outputs, int nquat,
                      const int *quat, double *stats, int *k_done, volatile int *stop) {
    double y[NX], y1[NX], yt[NX], k1[NX], k2[NX], k3[NX], k4[NX], k5[NX], k6[NX], k7[NX];
    double e[NX], r1[NX], r2[NX], r3[NX], r4[NX], r5[NX];
    const double safe = 0.9, facl = 0.2, facr = 10.0, beta = 0.04, expo1 = 0.2 - 0.04 * 0.75;
    double facold = 1e-4, h = stats[3];
    int k = 0, seg_end, i, status = JOINT_OK;
    memcpy(y, X, sizeof y);
    while (k < n_out) {
        /* one segment: [t_out[k], t_out[seg_end]] without restarting the method */
        double t = t_out[k], t_end;
        long steps = 0, budget;
        int last = 0, reject = 0;
        seg_end = stop_at_outputs ? k + 1 : n_out;
        t_end = t_out[seg_end];
        budget = max_steps * (long)(seg_end - k);
        c->k = k;
        c->t_k = t_out[k];
        if (joint_rhs(c, t, y, k1)) { status = JOINT_SINGULAR; goto fail; }
        if (!(h > 0.0)) {
            if (first_step(c, t, y, k1, t_end - t, rtol, atol, &h)) { status = JOINT_SINGULAR; goto fail; }
        }
        while (k < seg_end) {
            double err, fac11, fac, hnew, tn;
            if (stop && *stop) { status = JOINT_STOPPED; goto fail; }
            if (steps++ >= budget) { status = JOINT_TOO_MANY_STEPS; goto fail; }
            if (!(fabs(h) > 10.0 * DBL_EPSILON * fabs(t) && fabs(h) > 1e-300)) { status = JOINT_STEP_UNDERFLOW; goto fail; }
            if (t + 1.01 * h >= t_end) { h = t_end - t; last = 1; } else last = 0;
            for (i = 0; i < NX; ++i) yt[i] = y[i] + h * A21 * k1[i];
            if (joint_rhs(c, t + C2 * h, yt, k2)) { status = JOINT_SINGULAR; goto fail; }
            for (i = 0; i < NX; ++i) yt[i] = y[i] + h * (A31 * k1[i] + A32 * k2[i]);
            if (joint_rhs(c, t + C3 * h, yt, k3)) { status = JOINT_SINGULAR; goto fail; }
            for (i = 0; i < NX; ++i) yt[i] = y[i] + h * (A41 * k1[i] + A42 * k2[i] + A43 * k3[i]);
            if (joint_rhs(c, t + C4 * h, yt, k4)) { status = JOINT_SINGULAR; goto fail; }
            for (i = 0; i < NX; ++i)
                yt[i] = y[i] + h * (A51 * k1[i] + A52 * k2[i] + A53 * k3[i] + A54 * k4[i]);
            if (joint_rhs(c, t + C5 * h, yt, k5)) { status = JOINT_SINGULAR; goto fail; }
            for (i = 0; i < NX; ++i)
                yt[i] = y[i] + h * (A61 * k1[i] + A62 * k2[i] + A63 * k3[i] + A64 * k4[i] + A65 * k5[i]);
            tn = last ? t_end : t + h;
            if (joint_rhs(c, tn, yt, k6)) { status = JOINT_SINGULAR; goto fail; }
            for (i = 0; i < NX; ++i)
                y1[i] = y[i] + h * (A71 * k1[i] + A73 * k3[i] + A74 * k4[i] + A75 * k5[i] + A76 * k6[i]);
            if (joint_rhs(c, tn, y1, k7)) { status = JOINT_SINGULAR; goto fail; }
            for (i = 0; i < NX; ++i)
                e[i] = h * (E1 * k1[i] + E3 * k3[i] + E4 * k4[i] + E5 * k5[i] + E6 * k6[i] + E7 * k7[i]);
            err = err_norm(y, y1, e, rtol, atol);
            if (!(err == err)) err = 1e10;
            fac11 = pow(err, expo1);
            fac = fac11 / pow(facold, beta);
            fac = fac / safe;
            if (fac < 1.0 / facr) fac = 1.0 / facr;
            if (fac > 1.0 / facl) fac = 1.0 / facl;
            hnew = h / fac;
            if (err <= 1.0) {
                facold = err > 1e-4 ? err : 1e-4;
                stats[0] += 1.0;
                /* dense output of the step [t, tn] for the output times inside it */
                if (k + 1 < seg_end && t_out[k + 1] < tn) {
                    for (i = 0; i < NX; ++i) {
                        double ydiff = y1[i] - y[i], bspl = h * k1[i] - ydiff;
                        r1[i] = y[i];
                        r2[i] = ydiff;
                        r3[i] = bspl;
                        r4[i] = ydiff - h * k7[i] - bspl;
                        r5[i] = h * (D1 * k1[i] + D3 * k3[i] + D4 * k4[i] + D5 * k5[i] + D6 * k6[i] + D7 * k7[i]);
                    }
                    while (k + 1 < seg_end && t_out[k + 1] < tn) {
                        double th = (t_out[k + 1] - t) / h, th1 = 1.0 - th;
                        double *out = X + (size_t)(k + 1) * NX;
                        for (i = 0; i < NX; ++i)
                            out[i] = r1[i] + th * (r2[i] + th1 * (r3[i] + th * (r4[i] + th1 * r5[i])));
                        renormalise(out, nquat, quat);
                        ++k;
                    }
                }
                memcpy(y, y1, sizeof y);
                renormalise(y, nquat, quat);
                memcpy(k1, k7, sizeof k1);
                t = tn;
                if (last) {
                    memcpy(X + (size_t)seg_end * NX, y, sizeof y);
                    k = seg_end;
                    if (!reject || hnew < h) h = hnew;
                    if (h <= 0) h = stats[3];
                    break;
                }
                if (reject && hnew > h) hnew = h;
                reject = 0;
                h = hnew;
                stats[3] = h;
            } else {
                hnew = h / (1.0 / facl < fac11 / safe ? 1.0 / facl : fac11 / safe);
                reject = 1;
                if (stats[0] >= 1.0) stats[1] += 1.0;
                h = hnew;
            }
        }
        stats[3] = h;
        continue;
    fail:
        stats[4] = t;
        *k_done = k;
        return status;
    }
    *k_done = n_out;
    return JOINT_OK;
}

/* The run described at the top of this file, on the model's data `model`. */
static int joint_run(JOINT_MODEL *model, const ncgen_joint_options *o, int n_out, const double *t_out, double *X,
                     int nquat, const int *quat, double *stats, int *k_done) {
    joint_loop c;
    int status;
    c.model = model;
    c.k = 0;
    c.t_k = t_out[0];
    c.nfev = 0.0;
    if (o->method == 0)
        status = run_rk4(&c, n_out, t_out, X, o->substeps, nquat, quat, stats, k_done, o->stop);
    else
        status = run_dopri5(&c, n_out, t_out, X, o->rtol, o->atol, o->max_steps, o->stop_at_outputs, nquat, quat,
                            stats, k_done, o->stop);
    stats[2] += c.nfev;
    return status;
}

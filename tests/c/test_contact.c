/* Unit tests of the stepper's contact solver (ncgen_contact.h) on a hand-written model: two
 * point masses in the plane (q = (x1, y1, x2, y2), no bilateral constraint), gravity -G_P
 * along y, each with a contact against the floor y = 0 (a sphere of radius R_P: the gap is
 * y_k - R_P, the normal row of the contact Jacobian is dy_k, the tangent row dx_k).
 *
 * Projected Gauss-Seidel is tested on hand-made Delassus matrices with known solutions
 * (friction: sliding and sticking; frictionless and redundant: the Newton steps), the
 * contact step on closed forms: a mass sliding with Coulomb friction decelerates by mu g
 * and stops, a mass dropped with restitution e rebounds to e^2 its height.  Compiled twice
 * by tests/test_stepper_runtime_c.py: as is (the Delassus matrix by KKT solves, one per
 * row) and with -DSCHUR_FACTORED (from the constant M^-1, and the KKT matrix factored once);
 * and a third time with -DPAIRS: the contact rows by element kernels with the broad phase
 * of ncgen_contact_pairs.h (each mass and the floor one element, one kernel for both). */
#include "harness.h"

#define M_P 0.5
#define G_P 9.81
#define R_P 0.05

#define NQ 4
#define NC 0
#define NU 0
#define NNZ_K 4
#define MASS_SCALE M_P
#define MAX_HALVINGS 10
#define NSTATS 16
#define NOUT 5

#define NCGEN_CONTACTS
#define NK 2
#define DC 2
#define PGS_MAX_ITER 300
#define PGS_TOL 1e-12
#define CONTACT_REFINE_MAX 10
#define CONTACT_REFINE_TOL 1e-8
#define GRAVITY_NORM G_P
#define PENETRATION_TOL 1e-8
#define GAP_REACH 2.0
#define REPEAT_TOL 1e-12
#define ANY_RESTITUTION
/* the tests set them per case */
static casadi_real mu[NK] = {0.5, 0.0};
static casadi_real restitution[NK] = {0.0, 0.5};
#ifdef PAIRS
/* W by rows: each row over its element's coordinates (x_k, y_k) */
#define NNZ_W 8
static const int wt_colind[NK * DC + 1] = {0, 2, 4, 6, 8};
static const int wt_row[NNZ_W] = {0, 1, 0, 1, 2, 3, 2, 3};
#define CONTACT_PAIRS
#define NE 2
#define PAIR_MAX_Q 2
#define PAIR_MAX_G 1
#define PAIR_MAX_W 4
/* kernel, first contact, contacts, na, nb, coordinate offset, W map offset, rates bounded */
static const int pair_int[NE * 8] = {0, 0, 1, 2, 0, 0, 0, 1, 0, 1, 1, 2, 0, 2, 4, 1};
static const int pair_qidx[4] = {0, 1, 2, 3};
static const casadi_real pair_qconst[4] = {0, 0, 0, 0};
/* the dense W (rows normal, tangent; columns x, y) into W's nonzeros */
static const int pair_wpos[8] = {0, 2, 1, 3, 4, 6, 5, 7};
/* side a: a member sphere (data at 0), side b: the floor half-space (data at 6) */
static const int pair_side[NE * 6] = {1, 0, 0, 3, 0, 6, 1, 0, 0, 3, 0, 6};
/* centre = the point (2 x 2 identity), radius R_P, |G| = 0; the floor's point and normal */
static const casadi_real pair_bdata[10] = {1, 0, 0, 1, R_P, 0, 0, 0, 0, 1};
static const casadi_real pair_bound[NE * 3] = {1, 0, 1e300, 1, 0, 1e300};
/* two distinct member sides (the points), each the side a of its element */
#define PAIR_NS 2
static const int pair_sid[NE * 2] = {0, -1, 1, -1};
static const int pair_srep[PAIR_NS * 2] = {0, 0, 1, 0};
/* gap y - R_P; W rows dy (normal) and dx (tangent), column-major over (x, y); the calls
 * counted (test_pair_cache) */
static int n_pair_gap, n_pair_rows;
static int k_pair_gap(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem) {
  (void) iw, (void) w, (void) mem;
  ++n_pair_gap;
  res[0][0] = arg[0][1] - R_P;
  return 0;
}
static int k_pair_rows(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem) {
  (void) iw, (void) w, (void) mem;
  ++n_pair_rows;
  res[0][0] = arg[0][1] - R_P;
  res[1][0] = 0, res[1][1] = 1, res[1][2] = 1, res[1][3] = 0;
  return 0;
}
static int (*const pair_gap_fn[1])(const casadi_real **, casadi_real **, casadi_int *, casadi_real *, int) = {
    k_pair_gap};
static int (*const pair_rows_fn[1])(const casadi_real **, casadi_real **, casadi_int *, casadi_real *, int) = {
    k_pair_rows};
#else
/* W by rows: normal 1 (dy1), tangent 1 (dx1), normal 2 (dy2), tangent 2 (dx2) */
#define NNZ_W 4
static const int wt_colind[NK * DC + 1] = {0, 1, 2, 3, 4};
static const int wt_row[NNZ_W] = {1, 0, 3, 2};
#endif

#ifdef SCHUR_FACTORED
#define CONTACT_FACTORED
#define NNZ_V 0
#define NNZ_R 4
#define N_BETA 0
#define CONTACT_SCHUR
static const casadi_real minv[NQ * NQ] = {1 / M_P, 0, 0, 0, 0, 1 / M_P, 0, 0, 0, 0, 1 / M_P, 0, 0, 0, 0, 1 / M_P};
static const int minv_colind[NQ + 1] = {0, 1, 2, 3, 4};
static const int minv_row[NQ] = {0, 1, 2, 3};
#define NNZ_A 0
#endif

/* r = m (w - v) - h/2 F - j/2 (F = gravity), K = m I (its diagonal). */
static int k_newton(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem) {
  const casadi_real h = *arg[5];
  int i;
  (void) iw, (void) w, (void) mem;
  for (i = 0; i < NQ; ++i) {
    res[0][i] = M_P * (at(arg[6], i) - at(arg[2], i)) + (i % 2 ? h / 2 * M_P * G_P : 0) - at(arg[8], i) / 2;
    res[1][i] = M_P;
  }
  return 0;
}

/* b = m w + h/2 F + j/2, K = m I. */
static int k_velocity(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem) {
  const casadi_real h = *arg[5];
  int i;
  (void) iw, (void) w, (void) mem;
  for (i = 0; i < NQ; ++i) {
    res[0][i] = M_P * at(arg[2], i) - (i % 2 ? h / 2 * M_P * G_P : 0) + at(arg[6], i) / 2;
    res[1][i] = M_P;
  }
  return 0;
}

static int k_check(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem) {
  (void) arg, (void) iw, (void) w, (void) mem;
  *res[0] = 0;
  *res[1] = 0;
  return 0;
}

/* x = K^-1 r for the diagonal K. */
static int k_solve(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem) {
  int i;
  (void) iw, (void) w, (void) mem;
  for (i = 0; i < NQ; ++i) res[0][i] = arg[1][i] / arg[0][i];
  return 0;
}

static int k_project(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem) {
  int i;
  (void) arg, (void) iw, (void) w, (void) mem;
  if (res[0])
    for (i = 0; i < NQ; ++i) res[0][i] = M_P;
  return 0;
}

static int k_power(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem) {
  int i;
  (void) arg, (void) iw, (void) w, (void) mem;
  for (i = 0; i < 5; ++i) res[0][i] = 0;
  return 0;
}

static int k_outputs(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem) {
  const casadi_real *q = arg[1], *v = arg[2];
  int i;
  (void) iw, (void) w, (void) mem;
  for (i = 0; i < NOUT; ++i) res[0][i] = 0;
  for (i = 0; i < NQ; ++i) res[0][0] += M_P * v[i] * v[i] / 2;
  res[0][1] = M_P * G_P * (q[1] + q[3]);
  return 0;
}

#ifndef PAIRS
static int k_gap(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem) {
  (void) iw, (void) w, (void) mem;
  res[0][0] = arg[0][1] - R_P;
  res[0][1] = arg[0][3] - R_P;
  return 0;
}

/* gaps, W's nonzeros (all 1), contact velocities W v = (y1', x1', y2', x2'). */
static int k_contact(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem) {
  const casadi_real *q = arg[0];
  int r;
  (void) iw, (void) w, (void) mem;
  if (res[0]) {
    res[0][0] = q[1] - R_P;
    res[0][1] = q[3] - R_P;
  }
  if (res[1])
    for (r = 0; r < NNZ_W; ++r) res[1][r] = 1;
  if (res[2])
    for (r = 0; r < NK * DC; ++r) res[2][r] = at(arg[1], wt_row[r]);
  return 0;
}
#endif

#ifdef SCHUR_FACTORED
/* The "factors" of the diagonal K: R = its diagonal. */
static int k_factor(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem) {
  int i;
  (void) iw, (void) w, (void) mem;
  for (i = 0; i < NQ; ++i) res[1][i] = arg[0][i];
  return 0;
}

static int k_backsolve(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem) {
  int i;
  (void) iw, (void) w, (void) mem;
  for (i = 0; i < NQ; ++i) res[0][i] = arg[3][i] / arg[1][i];
  return 0;
}
#define KERNEL_FACTOR k_factor
#define KERNEL_BACKSOLVE k_backsolve
#endif

#define KERNEL_NEWTON k_newton
#define KERNEL_VELOCITY k_velocity
#define KERNEL_CHECK k_check
#define KERNEL_SOLVE k_solve
#define KERNEL_PROJECT k_project
#define KERNEL_POWER k_power
#define KERNEL_OUTPUTS k_outputs
#ifndef PAIRS
#define KERNEL_GAP k_gap
#define KERNEL_CONTACT k_contact
#endif

#include "ncgen_rattle.h"
#include "ncgen_cone_newton.h"
#include "ncgen_contact_pairs.h"
#include "ncgen_contact.h"
#include "ncgen_fixed.h"

/* ---------------------------------------------------------------- tests */

/* Sets up ws for pgs() on the na = 2 contacts (rows in first[]) with the nr x nr Delassus
 * matrix G (column-major) and the free contact velocities U0. */
static void pgs_problem(workspace *ws, int nr, const casadi_real *G, const casadi_real *U0) {
  int a;
  CHECK(contact_reserve(ws, nr) == 0 && ws->ncap >= nr, "room for %d rows", nr);
  memcpy(ws->G, G, (size_t) (nr * nr) * sizeof(casadi_real));
  memcpy(ws->U, U0, (size_t) nr * sizeof(casadi_real));
  memset(ws->Um, 0, ND * sizeof(casadi_real));
  for (a = 0; a < nr; ++a) ws->P[a] = 0;
  ws->act[0] = 0;
  ws->act[1] = 1;
  ws->fm = -1;
  g_pattern(ws, nr);
}

/* Two contacts with friction, normal rows coupled: contact 1 slides (its tangential impulse
 * on the cone's edge, against the slip), contact 2 sticks.  Solution by hand:
 *   P_N = G_NN^-1 (-U0_N) = (4/3, 4/3), P_T1 = -mu P_N1 = -2/3, P_T2 = -U0_T2 = -0.1. */
static void test_pgs_friction(void) {
  const casadi_real G[16] = {1, 0, 0.5, 0, 0, 1, 0, 0, 0.5, 0, 1, 0, 0, 0, 0, 1};
  const casadi_real U0[4] = {-2, 2, -2, 0.1}, P[4] = {4.0 / 3, -2.0 / 3, 4.0 / 3, -0.1};
  const casadi_real U[4] = {0, 4.0 / 3, 0, 0}, bias[2] = {0, 0};
  const int first[3] = {0, 2, 4};
  workspace ws;
  char *block = malloc(step_work_bytes());
  int a, converged;
  layout(&ws, block);
  mu[0] = mu[1] = 0.5;
  restitution[0] = restitution[1] = 0;
  pgs_problem(&ws, 4, G, U0);
  converged = pgs(&ws, 2, first, bias);
  CHECK(converged, "%d sweeps, last change %g", ws.pgs_sweeps, ws.pgs_last);
  for (a = 0; a < 4; ++a) {
    CHECK(fabs(ws.P[a] - P[a]) < 1e-10, "P[%d] = %.15g, expected %.15g", a, ws.P[a], P[a]);
    CHECK(fabs(ws.U[a] - U[a]) < 1e-10, "U[%d] = %.15g, expected %.15g", a, ws.U[a], U[a]);
  }
  workspace_free(&ws);
  free(block);
}

/* Two frictionless contacts on the same direction (redundant: G singular): any P >= 0 with
 * P_1 + P_2 = 1 solves it; the Newton steps of lcp_newton() finish what the sweeps crawl on.
 * With a separating velocity on one, only the other takes an impulse. */
static void test_pgs_frictionless_redundant(void) {
  const casadi_real G[4] = {1, 1, 1, 1}, U0[2] = {-1, -1}, bias[2] = {0, 0};
  const casadi_real G2[4] = {2, 1, 1, 2}, U2[2] = {-1, 3};
  const int first[3] = {0, 1, 2};
  workspace ws;
  char *block = malloc(step_work_bytes());
  layout(&ws, block);
  mu[0] = mu[1] = 0;
  pgs_problem(&ws, 2, G, U0);
  CHECK(pgs(&ws, 2, first, bias), "%d sweeps, last change %g", ws.pgs_sweeps, ws.pgs_last);
  CHECK(ws.P[0] >= 0 && ws.P[1] >= 0 && fabs(ws.P[0] + ws.P[1] - 1) < 1e-12, "P = (%g, %g)", ws.P[0], ws.P[1]);
  CHECK(fabs(ws.U[0]) < 1e-12 && fabs(ws.U[1]) < 1e-12, "U = (%g, %g)", ws.U[0], ws.U[1]);
  pgs_problem(&ws, 2, G2, U2);
  CHECK(pgs(&ws, 2, first, bias), "%d sweeps", ws.pgs_sweeps);
  CHECK(fabs(ws.P[0] - 0.5) < 1e-12 && ws.P[1] == 0, "P = (%g, %g)", ws.P[0], ws.P[1]);
  CHECK(fabs(ws.U[0]) < 1e-12 && fabs(ws.U[1] - 3.5) < 1e-12, "U = (%g, %g)", ws.U[0], ws.U[1]);
  workspace_free(&ws);
  free(block);
}

/* Mass 1 slides on the floor (mu = 0.5) from 1 m/s: x' = v0 - mu g t until it stops at
 * v0 / (mu g), x = v0 t - mu g t^2 / 2 (RATTLE is exact for a constant acceleration), resting
 * on the floor with the normal impulse m g per second.  Mass 2 (frictionless, e = 0.5)
 * dropped from 0.1 m above the floor rebounds to e^2 0.1 m. */
static void test_contact_steps(void) {
  enum { N = 6000 };
  const casadi_real h = 1e-4, v0 = 1.0, drop = 0.1, t_slide = 0.1;
  const casadi_real q0[NQ] = {0, R_P, 0, R_P + drop}, vel0[NQ] = {v0, 0, 0, 0};
  casadi_real *q = malloc(N * NQ * sizeof(casadi_real)), *v = malloc(N * NQ * sizeof(casadi_real));
  casadi_real *imp = malloc(N * ND * sizeof(casadi_real)), *stats = malloc(N * NSTATS * sizeof(casadi_real));
  casadi_real apex = 0, pn = 0, pt = 0, deepest = 0;
  long done = 0, splits = 0, k, unconverged = 0, bounced = 0;
  step_options o = DEFAULT_OPTIONS();
  int status;
  mu[0] = 0.5, mu[1] = 0;
  restitution[0] = 0, restitution[1] = 0.5;
  for (k = 0; k < N * ND; ++k) imp[k] = NAN; /* every row written: the contacts without an impulse zero */
  status = run_fixed(q0, vel0, 0, 0, h, N, 1, 0, 0, 0, q, v, 0, 0, stats, &o, &FIXED_RUN(0, 1), &done, &splits, imp);
  for (k = 0; k < N * ND && isfinite(imp[k]); ++k) continue;
  CHECK(k == N * ND, "impulse entry %ld not written (%g)", k, imp[k < N * ND ? k : 0]);
  for (k = 0; (k + 1) * h < 0.99 * sqrt(2 * drop / G_P); ++k) /* mass 2 in flight: no impulse */
    CHECK(imp[k * ND + 2] == 0 && imp[k * ND + 3] == 0, "impulse %g in flight at row %ld", imp[k * ND + 2], k);
  CHECK(status == STEP_OK && done == N && splits == 0, "status %d, %ld steps, %ld splits", status, done, splits);
  k = (long) (t_slide / h + 0.5) - 1; /* row k: the state at (k + 1) h */
  CHECK(fabs(v[k * NQ] - (v0 - mu[0] * G_P * t_slide)) < 1e-9, "x' = %.12g at t = %g", v[k * NQ], t_slide);
  CHECK(fabs(q[k * NQ] - (v0 * t_slide - mu[0] * G_P * t_slide * t_slide / 2)) < 1e-9, "x = %.12g", q[k * NQ]);
  CHECK(fabs(v[(N - 1) * NQ]) < 1e-12, "still sliding at the end: x' = %g", v[(N - 1) * NQ]);
  CHECK(fabs(q[(N - 1) * NQ] - v0 * v0 / (2 * mu[0] * G_P)) < 1e-4, "stopped at x = %g, expected %g",
        q[(N - 1) * NQ], v0 * v0 / (2 * mu[0] * G_P));
  for (k = 0; k < N; ++k) {
    deepest = fmax(deepest, fmax(R_P - q[k * NQ + 1], R_P - q[k * NQ + 3]));
    if (k * h < t_slide) {
      pn += imp[k * ND];
      pt += imp[k * ND + 1];
    }
    bounced = bounced || v[k * NQ + 3] > 0;
    if (bounced) apex = fmax(apex, q[k * NQ + 3] - R_P);
    unconverged += (long) stats[k * NSTATS + 12];
    CHECK(stats[k * NSTATS + 14] <= 2 * PENETRATION_TOL, "penetration %g at row %ld", stats[k * NSTATS + 14], k);
  }
  CHECK(fabs(pn - M_P * G_P * t_slide) < 1e-3 * M_P * G_P * t_slide, "normal impulse %g", pn);
  CHECK(fabs(pt + mu[0] * pn) < 1e-9, "friction impulse %g, normal %g", pt, pn);
  CHECK(deepest < 2 * PENETRATION_TOL, "deepest penetration %g m", deepest);
  CHECK(unconverged == 0, "%ld contact solves did not converge", unconverged);
  CHECK(bounced && fabs(apex - 0.25 * drop) < 0.02 * 0.25 * drop, "rebound apex %g m, expected %g", apex,
        0.25 * drop);
  { /* the work by class (track_work): friction took the slider's kinetic energy exactly, the
     * balance E - E0 - W closes to round-off, and the contacts' work is all of W */
    const casadi_real *w = stats + (N - 1) * NSTATS + 5, *qe = q + (N - 1) * NQ, *ve = v + (N - 1) * NQ;
    casadi_real e0 = M_P * v0 * v0 / 2 + M_P * G_P * (q0[1] + q0[3]), e1 = M_P * G_P * (qe[1] + qe[3]);
    for (k = 0; k < NQ; ++k) e1 += M_P * ve[k] * ve[k] / 2;
    CHECK(fabs(w[WORK_FRICTION] + M_P * v0 * v0 / 2) < 1e-9, "friction work %.12g, expected %.12g",
          w[WORK_FRICTION], -M_P * v0 * v0 / 2);
    CHECK(fabs(e1 - e0 - w[WORK_TOTAL]) < 1e-9 * e0, "E - E0 = %.12g, W = %.12g", e1 - e0, w[WORK_TOTAL]);
    CHECK(fabs(w[WORK_TOTAL] - w[WORK_CONTACTS] - w[WORK_FRICTION] - w[WORK_PUSH_OUT]) < 1e-12 * e0 &&
          w[WORK_CONTACTS] < 0, "W = %g, contacts %g, friction %g, push-out %g", w[WORK_TOTAL], w[WORK_CONTACTS],
          w[WORK_FRICTION], w[WORK_PUSH_OUT]);
  }
  free(q), free(v), free(imp), free(stats);
}

/* The single step API: at rest on the floor, a step keeps the mass there with the normal
 * impulse m g h (the free step would sink it). */
static void test_step_at_rest(void) {
  const casadi_real q[NQ] = {0, R_P, 1, R_P}, v[NQ] = {0, 0, 0, 0}, h = 1e-3;
  casadi_real q1[NQ], v1[NQ], impulse[ND], y[NOUT], t = 0;
  int status, i;
  mu[0] = mu[1] = 0.5;
  status = stepper_step(q, v, 0, 0, 0, h, q1, v1, 0, 0, 0, 0, impulse);
  CHECK(status == STEP_OK, "status %d", status);
  for (i = 0; i < NQ; ++i) CHECK(fabs(q1[i] - q[i]) < 1e-12 && fabs(v1[i]) < 1e-12, "moved: q[%d]", i);
  CHECK(fabs(impulse[0] - M_P * G_P * h) < 1e-12 && fabs(impulse[2] - M_P * G_P * h) < 1e-12,
        "impulses %g, %g", impulse[0], impulse[2]);
  CHECK(impulse[1] == 0 && impulse[3] == 0, "no friction at rest");
  CHECK(stepper_outputs(1, &t, q1, v1, 0, 0, 0, 0, y) == STEP_OK && fabs(y[1] - 2 * M_P * G_P * R_P) < 1e-12,
        "potential energy %g", y[1]);
}

/* repeat_step() on a loaded contact whose linearised free gap is +delta: mass 1 held by the
 * impulse m g h at height R_P + g h^2 / 2 + delta (the free step would end delta above the
 * floor, the repeated step keeps it there at rest).  A delta of round-off (below the tolerance
 * h/2 REPEAT_TOL (1 + max |U|) = 1.5e-14 m at h = 30 ms) counts as closed: the step is kept,
 * at rest with the impulse m g h; a real gap (1e-9 m: closing it takes 6.7e-8 m/s) is not. */
static void test_repeat_round_off_gap(void) {
  const casadi_real h = 0.03, deltas[2] = {5e-15, 1e-9};
  casadi_real q[NQ], v[NQ] = {0, 0, 0, 0}, q1[NQ], v1[NQ];
  step_options o = DEFAULT_OPTIONS();
  workspace ws;
  char *block = malloc(step_work_bytes());
  int i, kept, status;
  mu[0] = mu[1] = 0.5;
  restitution[0] = restitution[1] = 0;
  layout(&ws, block);
  for (i = 0; i < 2; ++i) {
    q[0] = 0, q[1] = R_P + G_P * h * h / 2 + deltas[i], q[2] = 1, q[3] = 1; /* mass 2 far above */
    contact_clear(&ws);
    ws.F[0] = M_P * G_P;
    status = repeat_step(q, v, 0, 0, 0, h, q1, v1, 0, 0, &o, 0, &ws, &kept);
    CHECK(status == STEP_OK && kept == (i == 0), "delta %g m: status %d, kept %d", deltas[i], status, kept);
    if (i == 0)
      CHECK(fabs(q1[1] - q[1]) < 1e-15 && fabs(v1[1]) < 1e-12 && fabs(ws.Pacc[0] - M_P * G_P * h) < 1e-15,
            "y %.17g -> %.17g, y' %g, impulse %.17g", q[1], q1[1], v1[1], ws.Pacc[0]);
  }
  workspace_free(&ws);
  free(block);
}

#ifdef PAIRS
/* The broad phase: mass 1 0.3 m above the floor, mass 2 on it.  Its lower bound is the gap
 * (less the slack); skipped at a limit below it, evaluated above; the speed bound of a point
 * is its speed.  The rows of an element off are not written (NaN left there), those on are;
 * the contacts walked (ws->kon) are those of the elements on. */
static void test_broad_phase(void) {
  const casadi_real q[NQ] = {0, R_P + 0.3, 1, R_P}, v[NQ] = {1, 2, 0, -3};
  casadi_real g[NK], W[NNZ_W], U[ND];
  workspace ws;
  char *block = malloc(step_work_bytes());
  int i;
  for (i = 0; i < NK; ++i) g[i] = NAN;
  for (i = 0; i < NNZ_W; ++i) W[i] = NAN;
  for (i = 0; i < ND; ++i) U[i] = NAN;
  layout(&ws, block);
  pairs_bounds(&ws, q, v);
  pairs_select(&ws, 0.1, 0, 0);
  CHECK(fabs(ws.plb[0] - (0.3 - PAIR_SLACK * R_P)) < 1e-15 && fabs(ws.plb[1] + PAIR_SLACK * R_P) < 1e-15,
        "bounds %g %g", ws.plb[0], ws.plb[1]);
  CHECK(fabs(ws.pspd[0] - sqrt(5.0)) < 1e-15 && fabs(ws.pspd[1] - 3) < 1e-15, "speeds %g %g", ws.pspd[0], ws.pspd[1]);
  CHECK(ws.pon[0] == 0 && ws.pon[1] == 1, "on: %d %d", ws.pon[0], ws.pon[1]);
  CHECK(ws.nkon == 1 && ws.kon[0] == 1, "contacts walked: %d", ws.nkon);
  CHECK(contact_gap(&ws, q, 0, g) == STEP_OK && isnan(g[0]) && g[1] == 0, "gaps %g %g", g[0], g[1]);
  CHECK(contact_rows(&ws, q, v, 0, g, W, U, 1) == STEP_OK, "rows");
  CHECK(isnan(W[0]) && isnan(W[3]) && W[4] == 0 && W[5] == 1 && W[6] == 1 && W[7] == 0, "W of the contacts");
  CHECK(isnan(U[0]) && isnan(U[1]) && U[2] == -3 && U[3] == 0, "U = %g %g %g %g", U[0], U[1], U[2], U[3]);
  pairs_select(&ws, 0.1, 0.05, 0); /* 0.3 - slack <= 0.1 + 0.05 sqrt(5)? no; within reach at 0.1 s */
  CHECK(ws.pon[0] == 0, "on at hs = 0.05");
  pairs_select(&ws, 0.1, 0.1, 0);
  CHECK(ws.pon[0] == 1, "off at hs = 0.1");
  pairs_select(&ws, 0, 0, 0);
  CHECK(pairs_extend(&ws, 0.2) == 0 && pairs_extend(&ws, 0.4) == 1 && ws.pon[0] == 2, "extend");
  CHECK(ws.nkon == 2 && ws.kon[0] == 0 && ws.kon[1] == 1, "contacts walked after the extension: %d", ws.nkon);
  CHECK(contact_rows(&ws, q, v, 0, g, W, U, 2) == STEP_OK && ws.pon[0] == 1, "rows of the extended");
  CHECK(fabs(g[0] - 0.3) < 1e-15 && W[1] == 1 && W[2] == 1 && U[0] == 2 && U[1] == 1, "g %g U %g %g", g[0], U[0],
        U[1]);
  contact_clear(&ws);
  ws.F[1] = 1; /* a force on mass 1's tangent row: turned on whatever its bound */
  pairs_select(&ws, 0, 0, 1);
  CHECK(ws.pon[0] == 1 && ws.nkon == 2, "loaded element off");
  workspace_free(&ws);
  free(block);
}

/* pairs_sweep_boxes()'s found: each pair marked once in a table of n x n (ctx), a second report counted wrong. */
enum { SEEN_NMAX = 100 };
typedef struct {
  unsigned char seen[SEEN_NMAX * SEEN_NMAX];
  int wrong;
} seen_pairs;
static void mark_pair(void *ctx, int a, int b) {
  seen_pairs *f = ctx;
  f->wrong += a == b || f->seen[a * SEEN_NMAX + b];
  f->seen[a * SEEN_NMAX + b] = f->seen[b * SEEN_NMAX + a] = 1;
}

/* The sweep (pair_box(), pairs_sweep_boxes()) on 300 random scenes of up to SEEN_NMAX sides in
 * 2-D and 3-D, moved three times each (the kept order nearly sorted): spread and dense scenes,
 * sides whose rotation makes their box whole, a side far out, and sparse
 * 3-D grids of spheres 0.2 apart where one axis's intervals overlap by whole columns.  Against
 * every pair's box test (all axes): the same pairs, each once, and no pair whose lower bound is
 * within the level left off; on the grids fewer pairs than one axis's intervals give. */
static void test_sweep_random(void) {
  enum { NMAX = SEEN_NMAX, DMAX = 3 };
  static seen_pairs f;
  casadi_real sb[NMAX * (DMAX + 3)], iv[2 * DMAX * NMAX];
  int ord[NMAX], seed, moves, missed = 0, wrong = 0, found = 0, near = 0, grids = 0;
  long one_axis = 0, grid_pairs = 0;
  unsigned long long state = 12345;
#define RAND01() ((state = state * 6364136223846793005ULL + 1442695040888963407ULL), (double) (state >> 11) / 9007199254740992.0)
  for (seed = 0; seed < 300; ++seed) {
    const int grid = seed % 3 == 0, dim = grid || RAND01() < 0.5 ? 3 : 2, st = dim + 3, axis = (int) (RAND01() * dim);
    const int n = grid ? 27 + (int) (RAND01() * (NMAX - 26)) : 2 + (int) (RAND01() * (NMAX - 1));
    const int side = (int) ceil(cbrt((double) n));
    const casadi_real box = RAND01() < 0.3 ? 0.2 : 5.0, hs = RAND01() < 0.5 ? 0 : 0.02 * RAND01();
    const casadi_real kmin = grid || RAND01() < 0.5 ? 1 : 1 / sqrt(3.0), dmax = RAND01() < 0.5 ? 0 : 1e-3 * RAND01();
    casadi_real rmax = 0;
    int i, j, k;
    for (k = 0; k < n; ++k) {
      for (i = 0; i < dim; ++i) /* a grid: side^3 places 0.2 apart, a little off */
        sb[st * k + i] = grid ? 0.2 * (i == 0 ? k % side : i == 1 ? k / side % side : k / (side * side)) +
                                    1e-3 * RAND01()
                              : box * RAND01();
      sb[st * k + dim] = grid ? 0.03 : 0.01 + 0.1 * RAND01();
      sb[st * k + dim + 1] = grid || RAND01() < 0.5 ? 0 : 3 * RAND01();
      sb[st * k + dim + 2] = grid || RAND01() < 0.7 ? 0 : 20 * RAND01();
      ord[k] = n - 1 - k; /* reversed: the worst order to start from */
    }
    if (!grid && RAND01() < 0.2) sb[0] = 1e20; /* more than 1e15 cells out */
    for (moves = 0; moves < 3; ++moves) {
      const casadi_real L = 0.05 * RAND01() + 0.03;
      long n_found;
      memset(&f, 0, sizeof f);
      rmax = 0;
      for (k = 0; k < n; ++k) { /* a small move: the kept order is nearly sorted */
        if (moves)
          for (i = 0; i < dim; ++i) sb[st * k + i] += 0.01 * (RAND01() - 0.5);
        rmax = fmax(rmax, sb[st * k + dim]);
      }
      for (k = 0; k < n; ++k) pair_box(sb + st * k, dim, L, hs, rmax, kmin, dmax, iv + 2 * dim * k);
      n_found = pairs_sweep_boxes(iv, dim, n, axis, ord, mark_pair, &f);
      for (k = 1; k < n; ++k) wrong += iv[2 * dim * ord[k - 1] + 2 * axis] > iv[2 * dim * ord[k] + 2 * axis];
      wrong += f.wrong;
      found += (int) n_found;
      for (i = 0; i < n; ++i)
        for (j = i + 1; j < n; ++j) {
          const casadi_real *x = sb + st * i, *y = sb + st * j;
          const int overlap = pair_boxes_meet(iv + 2 * dim * i, iv + 2 * dim * j, dim, -1);
          casadi_real d2 = 0, D, S, lb;
          int c, o = 1;
          for (c = 0; c < dim; ++c) d2 += (y[c] - x[c]) * (y[c] - x[c]);
          D = sqrt(d2) - x[dim] - y[dim];
          S = x[dim + 1] + y[dim + 1] + (x[dim + 2] + y[dim + 2]) * (D + 3 * (x[dim] + y[dim]));
          lb = kmin * D - PAIR_SLACK * (x[dim] + y[dim]);
          for (c = 0; c < dim; ++c) /* the boxes by hand, every axis */
            o &= !(iv[2 * dim * i + 2 * c] > iv[2 * dim * j + 2 * c + 1] ||
                   iv[2 * dim * j + 2 * c] > iv[2 * dim * i + 2 * c + 1]);
          wrong += overlap != o || overlap != f.seen[i * NMAX + j]; /* the sweep = all pairs' box test */
          if (!f.seen[i * NMAX + j] && !(lb > L + hs * S && D >= dmax)) ++missed;
          near += lb <= L + hs * S;
          if (grid) { /* the sweep's axis alone */
            one_axis += !(iv[2 * dim * i + 2 * axis] > iv[2 * dim * j + 2 * axis + 1] ||
                          iv[2 * dim * j + 2 * axis] > iv[2 * dim * i + 2 * axis + 1]);
            grid_pairs += overlap;
          }
        }
      grids += grid;
    }
  }
#undef RAND01
  CHECK(wrong == 0 && missed == 0, "sweep: %d pairs differ from all pairs' box test, %d within the level missed", wrong,
        missed);
  CHECK(near > 100 && found > near, "the scenes have near pairs (%d) and the sweep found them (%d)", near, found);
  CHECK(grids > 100 && 4 * grid_pairs < one_axis, "sparse grids: %ld pairs overlap on every axis, %ld on one", grid_pairs,
        one_axis);
}

/* The elements' last results (pair_eval()): the rows again at the same coordinates without a
 * kernel call and equal to the first ones, gaps from kept rows, rows after kept gaps and at
 * moved coordinates from the kernel, two configurations kept (a third replaces the less
 * recently used); a new layout() starts empty. */
/* Both elements candidates and on (what a sweep and a selection would leave). */
static void both_on(workspace *ws) {
  ws->pcand[0] = 0, ws->pcand[1] = 1, ws->ncand = 2;
  ws->pcm[0] = ws->pcm[1] = ws->pon[0] = ws->pon[1] = 1;
}

static void test_pair_cache(void) {
  casadi_real q[NQ] = {0, R_P + 0.3, 1, R_P}, v[NQ] = {1, 2, 0, -3};
  casadi_real g[NK], W[NNZ_W], U[ND], g2[NK], W2[NNZ_W], U2[ND];
  workspace ws;
  char *block = malloc(step_work_bytes());
  layout(&ws, block);
  both_on(&ws);
  n_pair_gap = n_pair_rows = 0;
  CHECK(contact_gap(&ws, q, 0, g) == STEP_OK && n_pair_gap == 2, "gaps evaluated: %d", n_pair_gap);
  CHECK(contact_rows(&ws, q, v, 0, g, W, U, 1) == STEP_OK && n_pair_rows == 2, "rows after gaps: %d", n_pair_rows);
  CHECK(contact_rows(&ws, q, v, 0, g2, W2, U2, 1) == STEP_OK && n_pair_rows == 2, "rows kept: %d", n_pair_rows);
  CHECK(!memcmp(g, g2, sizeof g) && !memcmp(W, W2, sizeof W) && !memcmp(U, U2, sizeof U), "kept rows differ");
  CHECK(contact_gap(&ws, q, 0, g2) == STEP_OK && n_pair_gap == 2 && !memcmp(g, g2, sizeof g), "gaps from rows");
  const casadi_real yb = q[3];
  q[3] = yb + 1e-3; /* element 1 moved, element 0 not */
  CHECK(contact_rows(&ws, q, v, 0, g2, W2, U2, 1) == STEP_OK && n_pair_rows == 3, "moved: %d", n_pair_rows);
  CHECK(fabs(g2[1] - 1e-3) < 1e-15 && g2[0] == g[0], "gaps %g %g", g2[0], g2[1]);
  q[3] = yb; /* back: both configurations kept */
  CHECK(contact_rows(&ws, q, v, 0, g2, W2, U2, 1) == STEP_OK && n_pair_rows == 3 && !memcmp(W, W2, sizeof W),
        "the first configuration again: %d", n_pair_rows);
  q[3] = yb + 2e-3; /* a third: replaces the less recently used (the moved one), q is kept */
  CHECK(contact_rows(&ws, q, v, 0, g2, W2, U2, 1) == STEP_OK && n_pair_rows == 4, "third: %d", n_pair_rows);
  q[3] = yb;
  CHECK(contact_rows(&ws, q, v, 0, g2, W2, U2, 1) == STEP_OK && n_pair_rows == 4, "q kept: %d", n_pair_rows);
  layout(&ws, block);
  both_on(&ws);
  CHECK(contact_gap(&ws, q, 0, g2) == STEP_OK && n_pair_gap == 4, "emptied by layout: %d", n_pair_gap);
  free(block);
}
#endif

int main(void) {
  (void) project; /* used by ncgen_adaptive.h, which this test does not include */
  test_pgs_friction();
  test_pgs_frictionless_redundant();
  test_contact_steps();
  test_step_at_rest();
  test_repeat_round_off_gap();
#ifdef PAIRS
  test_broad_phase();
  test_sweep_random();
  test_pair_cache();
  return report("test_contact (element kernels, broad phase)");
#elif defined(SCHUR_FACTORED)
  return report("test_contact (Schur complement, factored KKT matrix)");
#else
  return report("test_contact (KKT solves)");
#endif
}

/* Fixed-step runs of the RATTLE stepper (ncgen_rattle.h): a step retried cold and split in
 * halves where Newton fails (step_split()), one public step (stepper_step()), runs with
 * per-row statistics and the global error estimate of a shadow run (run_fixed()), and the
 * derived outputs of samples (stepper_outputs()).  Plain C99, model-independent; included
 * after ncgen_rattle.h (and ncgen_contact.h); the including file also defines NOUT, the
 * values per sample of KERNEL_OUTPUTS.  The model's stepper glue wraps these functions as
 * <model>_step, <model>_simulate, <model>_simulate_stats and <model>_outputs. */

/* The fourth-order scheme: Suzuki's symmetric five-stage composition of RATTLE steps
 * (Suzuki 1990, Phys. Lett. A 146; Yoshida 1990), steps g h, g h, (1 - 4g) h, g h, g h with
 * g = 1 / (4 - 4^(1/3)): RATTLE is symmetric, so the symmetric composition is of order 4; it
 * stays symplectic and on both constraint levels.  Its largest step is 0.66 h (the triple
 * jump's is 1.70 h, backwards) and its error constant is far smaller, so at equal accuracy
 * it takes steps about 2.5 times the triple jump's, for 5/3 the RATTLE steps per step.
 * Each RATTLE step is warm-started from the one before (predict_scaled()); ws->x, ws->dx end
 * as after the last (of g h), so predict() warm-starts the next composed step; ws->step_work
 * is the five steps' work. */
#define COMPOSITION_STAGES 5
#define COMPOSITION_G 0.41449077179437573714
static int step_rattle4(const casadi_real *q, const casadi_real *v, casadi_real t, const casadi_real *u,
                        const casadi_real *p, casadi_real h, casadi_real *q_next, casadi_real *v_next,
                        casadi_real *lam, int *iterations, const step_options *o, int warm, workspace *ws) {
  const casadi_real g = COMPOSITION_G, gamma[COMPOSITION_STAGES] = {g, g, 1 - 4 * g, g, g};
  casadi_real *buffer[2] = {ws->sub, ws->sub + 2 * NQ}, t_i = t, h_prev = 0, work[NWORK] = {0};
  const casadi_real *q_i = q, *v_i = v;
  int s, it = 0, sum = 0, status = STEP_OK;
  for (s = 0; s < COMPOSITION_STAGES && status == STEP_OK; ++s) {
    int last = s == COMPOSITION_STAGES - 1;
    casadi_real h_s = gamma[s] * h, *q_o = last ? q_next : buffer[s % 2], *v_o = last ? v_next : buffer[s % 2] + NQ;
    if (s > 0) predict_scaled(ws->x, ws->x, ws->dx, v_i, h_s / h_prev);
    status = step(q_i, v_i, t_i, u, p, h_s, q_o, v_o, last ? lam : 0, &it, o, s > 0 ? 1 : warm, ws);
    if (status == STEP_OK && !last) work_add(work, ws->step_work);
    sum += it;
    q_i = q_o, v_i = v_o, t_i += h_s, h_prev = h_s;
  }
  if (status == STEP_OK) work_add(ws->step_work, work);
  if (iterations) *iterations = sum;
  return status;
}

/* One step of the scheme o->scheme (RATTLE, or SCHEME_RATTLE4: step_rattle4()). */
static int scheme_step(const casadi_real *q, const casadi_real *v, casadi_real t, const casadi_real *u,
                       const casadi_real *p, casadi_real h, casadi_real *q_next, casadi_real *v_next,
                       casadi_real *lam, int *iterations, const step_options *o, int warm, workspace *ws) {
  if (o->scheme == SCHEME_RATTLE4) return step_rattle4(q, v, t, u, p, h, q_next, v_next, lam, iterations, o, warm, ws);
  return step(q, v, t, u, p, h, q_next, v_next, lam, iterations, o, warm, ws);
}

/* One attempt at a step: with contacts, the contact step around the RATTLE step. */
#ifdef NCGEN_CONTACTS
#define STEP_ATTEMPT contact_step
#else
#define STEP_ATTEMPT scheme_step
#endif

/* step(), retried from the cold start if a warm start fails, then split into two steps of
 * h/2 (recursively, `depth` splits deep so far) if that fails too.  Adds the Newton
 * iterations to *iterations and the splits to *splits; ws->step_work ends as the work over h. */
static int step_split(const casadi_real *q, const casadi_real *v, casadi_real t, const casadi_real *u,
                      const casadi_real *p, casadi_real h, casadi_real *q_next, casadi_real *v_next,
                      casadi_real *lam, int *iterations, long *splits, const step_options *o,
                      int warm, workspace *ws, int depth) {
  casadi_real *q_mid = ws->mid + 2 * NQ * depth, *v_mid = q_mid + NQ;
  int it, status;
  if (!(h > 0)) return STEP_BAD_INPUT;
  status = STEP_ATTEMPT(q, v, t, u, p, h, q_next, v_next, lam, &it, o, warm, ws);
  *iterations += it;
  if (status != STEP_OK && warm && recoverable(status)) {
    status = STEP_ATTEMPT(q, v, t, u, p, h, q_next, v_next, lam, &it, o, 0, ws);
    *iterations += it;
  }
  if (status == STEP_OK || !recoverable(status) || depth >= o->max_halvings) return status;
  ++*splits;
  status = step_split(q, v, t, u, p, h / 2, q_mid, v_mid, lam, iterations, splits, o, 0, ws, depth + 1);
  if (status != STEP_OK) return status;
  predict(ws);
  {
    casadi_real work[NWORK];
    memcpy(work, ws->step_work, sizeof work);
    status = step_split(q_mid, v_mid, t + h / 2, u, p, h / 2, q_next, v_next, lam, iterations, splits, o, 1, ws,
                        depth + 1);
    work_add(ws->step_work, work);
  }
  return status;
}

static const step_options *options_or_default(const step_options *options, step_options *storage) {
  if (options) return options;
  *storage = DEFAULT_OPTIONS();
  return storage;
}

/* One step (<model>_step): options NULL for the defaults, work NULL to allocate it here,
 * impulse (contacts only, may be NULL) the step's contact impulses. */
static int stepper_step(const casadi_real *q, const casadi_real *v, casadi_real t, const casadi_real *u,
                        const casadi_real *p, casadi_real h, casadi_real *q_next, casadi_real *v_next,
                        casadi_real *lam, int *iterations, const step_options *options, void *work,
                        casadi_real *impulse) {
  step_options defaults;
  workspace ws;
  char *block = work;
  int status, iters = 0;
  long splits = 0;
  if (!block && !(block = malloc(step_work_bytes()))) return STEP_BAD_INPUT;
  layout(&ws, block);
#ifdef NCGEN_CONTACTS
  contact_clear(&ws);
#endif
  status = step_split(q, v, t, u, p, h, q_next, v_next, lam, &iters, &splits,
                      options_or_default(options, &defaults), 0, &ws, 0);
  if (iterations) *iterations = iters;
#ifdef NCGEN_CONTACTS
  if (impulse) memcpy(impulse, ws.Pacc, ND * sizeof(casadi_real));
#else
  (void) impulse;
#endif
  workspace_free(&ws);
  if (!work) free(block);
  return status;
}

/* A row of statistics holds the work of every class (a compile-time check of NSTATS). */
typedef char ncgen_nstats_holds_the_work[NSTATS >= 5 + NWORK ? 1 : -1];

/* A row of statistics: steps, Newton iterations, splits, the error estimates, and the work of
 * each class (WORK_*) since the start of the run. */
static void put_stats(casadi_real *row, long steps, long iterations, long splits, casadi_real err_q,
                      casadi_real err_v, const casadi_real *work) {
  row[0] = (casadi_real) steps;
  row[1] = (casadi_real) iterations;
  row[2] = (casadi_real) splits;
  row[3] = err_q;
  row[4] = err_v;
  memcpy(row + 5, work, NWORK * sizeof *work);
}

/* The fixed-step run's error estimates (the field `estimate` of run_fixed()'s run_options). */
#define ESTIMATE_NONE 0
#define ESTIMATE_LOCAL 1
#define ESTIMATE_SHADOW 2
/* The local estimate samples one pair of steps in LOCAL_EVERY. */
#define LOCAL_EVERY 6

/* A step of h2 from (q, v) into (q_out, v_out), Newton started from ws->x if warm and, if
 * that fails, from the cold start: 1 if it converged. */
static int step_twice(const casadi_real *q, const casadi_real *v, casadi_real t, const casadi_real *u,
                      const casadi_real *p, casadi_real h2, casadi_real *q_out, casadi_real *v_out,
                      const step_options *o, int warm, workspace *ws) {
  int it;
  if (scheme_step(q, v, t, u, p, h2, q_out, v_out, 0, &it, o, warm, ws) == STEP_OK) return 1;
  return warm && scheme_step(q, v, t, u, p, h2, q_out, v_out, 0, &it, o, 0, ws) == STEP_OK;
}

/* ws->x for a step `ratio` times as long as the one x_pred (the predicted Newton start of
 * a step from rates v) was predicted for: w = v + ratio (w_pred - v), h/2 lambda scaled. */
static void start_scaled(workspace *ws, const casadi_real *x_pred, const casadi_real *v, casadi_real ratio) {
  int i;
  for (i = 0; i < NQ; ++i) ws->x[i] = v[i] + ratio * (x_pred[i] - v[i]);
  for (i = NQ; i < NX; ++i) ws->x[i] = ratio * x_pred[i];
}

/* The largest |a_i| over n values. */
static casadi_real max_abs(const casadi_real *a, long n) {
  casadi_real m = 0;
  long i;
  for (i = 0; i < n; ++i) m = nan_max(m, fabs(a[i]));
  return m;
}

/* The largest |a_i - b_i| over n values. */
static casadi_real max_diff(const casadi_real *a, const casadi_real *b, long n) {
  casadi_real m = 0;
  long i;
  for (i = 0; i < n; ++i) m = nan_max(m, fabs(a[i] - b[i]));
  return m;
}

/* Fixed steps (see <model>_simulate_stats; impulse_out: contacts only), p the order of the
 * scheme (RATTLE 2, its composition 4), R = 2^p - 1.  Of the run's options `run` it reads
 * `estimate` and `track_work` (NULL: neither).  Error estimates (run->estimate):
 * ESTIMATE_SHADOW: a shadow run with steps of 2h from the same start (one every second
 * step) gives the global error estimate (y_h - y_2h) / R after every even step.
 * ESTIMATE_LOCAL: the pair of steps k, k+1 is sampled when k/2 is LOCAL_EVERY - 1 modulo
 * LOCAL_EVERY (and the last pair): one step of 2h from the pair's start gives the pair's local error
 * d = (y_2h - y_pair) / R (Richardson), summed along the run as S = sum of w d, w the number
 * of pairs the sample stands for (those since the previous sample): the errors made along
 * the run, without their growth.  For the composition, their growth is RATTLE's (a tenth of
 * the run's work): a RATTLE shadow run with steps of 2h has the global error E_R = y_R - y,
 * and RATTLE steps of 2h from the sampled pairs' starts the local errors d_R = y_R2h - y_pair,
 * summed likewise as S_R; the estimate is |S| G with the growth G = max(1, |E_R| / |S_R|)
 * (its last value once the RATTLE shadow's Newton fails).  |.|: the largest component, of q
 * and v apart.  A sample whose Newton fails is skipped (its pairs counted by the next).  The
 * error columns hold the latest estimate (-1 before the first, -2 once a shadow step of 2h
 * failed: no estimate from there on; models with contacts have none). */
static int run_fixed(const casadi_real *q0, const casadi_real *v0, const casadi_real *lam0, casadi_real t0,
                     casadi_real h, long n_steps, long every, const casadi_real *u, long u_stride,
                     const casadi_real *p, casadi_real *q_out, casadi_real *v_out, casadi_real *lam_out,
                     long *iter_out, casadi_real *stats_out, const step_options *o, const run_options *run,
                     long *steps_done, long *splits, casadi_real *impulse_out) {
  int estimate = run ? run->estimate : ESTIMATE_NONE, track_work = run ? run->track_work : 0;
  workspace ws;
  char *block;
  casadi_real *state, *q, *v, *q1, *v1, *lam, *swap, *q_s, *v_s, *q2, *v2, *x_save, *dx_save, *x_s, *dx_s, *u_bar;
  casadi_real *sum, *sum_r, *d_r, *q_r, *v_r, *x_r, *dx_r;
  casadi_real work[NWORK] = {0}, err_q = -1, err_v = -1, richardson = o->scheme == SCHEME_RATTLE4 ? 15 : 3;
  casadi_real growth_q = 1, growth_v = 1, first = o->scheme == SCHEME_RATTLE4 ? COMPOSITION_G : 1;
  long k = 0, i, row = 0, iter_sum = 0, n_splits = 0, row_splits = 0, last_sample = -1;
  step_options o_r = *o; /* RATTLE, for the growth */
#ifdef NCGEN_CONTACTS
  int status = STEP_OK, iters, shadow = 0, local = 0; /* contacts: no estimate (its steps would miss them) */
  (void) estimate;
#else
  int status = STEP_OK, iters, shadow = estimate == ESTIMATE_SHADOW ? 1 : 0; /* 1: cold start, 2: warm, 0: off */
  int local = estimate == ESTIMATE_LOCAL;
  (void) impulse_out;
#endif
  int shadow_r = local && o->scheme == SCHEME_RATTLE4; /* the RATTLE shadow: 1 cold, 2 warm, 0 off */
  o_r.scheme = 0;
  if (steps_done) *steps_done = 0;
  if (splits) *splits = 0;
  if (n_steps < 0 || every < 1 || n_steps % every != 0 || estimate < 0 || estimate > ESTIMATE_SHADOW)
    return STEP_BAD_INPUT;
  block = malloc(step_work_bytes() + (16 * NQ + NC + 6 * NX + NU + 1) * sizeof(casadi_real));
  if (!block) return STEP_BAD_INPUT;
#ifdef NCGEN_CONTACTS
  if (impulse_out) /* zeros once: each row then writes the contacts with an impulse (contact_row()) */
    memset(impulse_out, 0, (size_t) (n_steps / every) * ND * sizeof(casadi_real));
#endif
  state = (casadi_real *) (block + layout(&ws, block));
  q = state;
  v = q + NQ;
  q1 = v + NQ;
  v1 = q1 + NQ;
  q_s = v1 + NQ;
  v_s = q_s + NQ;
  q2 = v_s + NQ;
  v2 = q2 + NQ;
  sum = v2 + NQ;
  sum_r = sum + 2 * NQ;
  d_r = sum_r + 2 * NQ;
  q_r = d_r + 2 * NQ;
  v_r = q_r + NQ;
  lam = v_r + NQ;
  x_save = lam + NC;
  dx_save = x_save + NX;
  x_s = dx_save + NX;
  dx_s = x_s + NX;
  x_r = dx_s + NX;
  dx_r = x_r + NX;
  u_bar = dx_r + NX;
  memcpy(q, q0, NQ * sizeof *q);
  memcpy(v, v0, NQ * sizeof *v);
  memcpy(q_s, q0, NQ * sizeof *q);
  memcpy(v_s, v0, NQ * sizeof *v);
  memcpy(q_r, q0, NQ * sizeof *q);
  memcpy(v_r, v0, NQ * sizeof *v);
  for (i = 0; i < 2 * NQ; ++i) sum[i] = sum_r[i] = 0;
  for (i = 0; i < NC; ++i) lam[i] = lam0 ? lam0[i] : 0;
#ifdef NCGEN_CONTACTS
  contact_clear(&ws);
#endif
  for (k = 0; k < n_steps; ++k) {
    const casadi_real *uk = u ? u + k * u_stride : 0;
    casadi_real tk = t0 + k * h;
    int sampled = local && ((k / 2) % LOCAL_EVERY == LOCAL_EVERY - 1 || k / 2 == n_steps / 2 - 1);
    if (stop_requested(o)) {
      status = STEP_INTERRUPTED;
      break;
    }
    if (sampled && k % 2 == 0) {
      /* A sampled pair starts: its start and the Newton start predicted for its first step. */
      memcpy(q_s, q, NQ * sizeof *q);
      memcpy(v_s, v, NQ * sizeof *v);
      memcpy(x_s, ws.x, NX * sizeof *x_s);
    }
    iters = 0;
    ws.track_work = track_work;
    status = step_split(q, v, tk, uk, p, h, q1, v1, lam, &iters, &n_splits, o, k > 0, &ws, 0);
    if (status != STEP_OK) break;
    if (track_work) work_add(work, ws.step_work); /* both ends with the step's inputs */
    ws.track_work = 0;                     /* not for the shadow */
    iter_sum += iters;
    if ((shadow || local) && k % 2 == 1) {
      /* Steps of 2h over the last two steps, inputs averaged. */
      const casadi_real *u2 = 0;
      if (u) {
        for (i = 0; i < NU; ++i) u_bar[i] = (uk[i - u_stride] + uk[i]) / 2;
        u2 = u_bar;
      }
      memcpy(x_save, ws.x, NX * sizeof *x_save);
      memcpy(dx_save, ws.dx, NX * sizeof *dx_save);
      if (shadow) {
        if (shadow == 2) {
          for (i = 0; i < NQ; ++i) ws.x[i] = 2 * dx_s[i] - x_s[i];
          for (i = NQ; i < NX; ++i) ws.x[i] = dx_s[i];
        }
        if (step_twice(q_s, v_s, tk - h, u2, p, 2 * h, q2, v2, o, shadow == 2, &ws)) {
          memcpy(x_s, ws.x, NX * sizeof *x_s);
          memcpy(dx_s, ws.dx, NX * sizeof *dx_s);
          memcpy(q_s, q2, NQ * sizeof *q2);
          memcpy(v_s, v2, NQ * sizeof *v2);
          shadow = 2;
          err_q = max_diff(q1, q2, NQ) / richardson;
          err_v = max_diff(v1, v2, NQ) / richardson;
        } else {
          shadow = 0; /* Newton fails at 2h: no estimate from here on */
          err_q = err_v = -2;
        }
      } else {
        if (shadow_r) { /* the RATTLE shadow's step */
          if (shadow_r == 2) {
            for (i = 0; i < NQ; ++i) ws.x[i] = 2 * dx_r[i] - x_r[i];
            for (i = NQ; i < NX; ++i) ws.x[i] = dx_r[i];
          }
          if (step_twice(q_r, v_r, tk - h, u2, p, 2 * h, q2, v2, &o_r, shadow_r == 2, &ws)) {
            memcpy(x_r, ws.x, NX * sizeof *x_r);
            memcpy(dx_r, ws.dx, NX * sizeof *dx_r);
            memcpy(q_r, q2, NQ * sizeof *q2);
            memcpy(v_r, v2, NQ * sizeof *v2);
            shadow_r = 2;
          } else {
            shadow_r = 0;
          }
        }
        if (sampled) { /* the pair's local errors: RATTLE's (for the growth), then the scheme's */
          int ok = 1;
          if (o->scheme == SCHEME_RATTLE4) {
            start_scaled(&ws, x_s, v_s, 2 / first);
            ok = step_twice(q_s, v_s, tk - h, u2, p, 2 * h, q2, v2, &o_r, k > 1, &ws);
            for (i = 0; ok && i < NQ; ++i) {
              d_r[i] = q2[i] - q1[i];
              d_r[NQ + i] = v2[i] - v1[i];
            }
          }
          if (ok) {
            start_scaled(&ws, x_s, v_s, 2);
            ok = step_twice(q_s, v_s, tk - h, u2, p, 2 * h, q2, v2, o, k > 1, &ws);
          }
          if (ok) {
            casadi_real weight = (casadi_real) (k / 2 - last_sample);
            last_sample = k / 2;
            for (i = 0; i < NQ; ++i) {
              sum[i] += weight * (q2[i] - q1[i]) / richardson;
              sum[NQ + i] += weight * (v2[i] - v1[i]) / richardson;
            }
            if (o->scheme == SCHEME_RATTLE4)
              for (i = 0; i < 2 * NQ; ++i) sum_r[i] += weight * d_r[i];
          }
        }
        if (last_sample >= 0) {
          if (shadow_r == 2) {
            casadi_real s_q = max_abs(sum_r, NQ), s_v = max_abs(sum_r + NQ, NQ);
            if (s_q > 0) growth_q = fmax(1, max_diff(q_r, q1, NQ) / s_q);
            if (s_v > 0) growth_v = fmax(1, max_diff(v_r, v1, NQ) / s_v);
          }
          err_q = max_abs(sum, NQ) * growth_q;
          err_v = max_abs(sum + NQ, NQ) * growth_v;
        }
      }
      memcpy(ws.x, x_save, NX * sizeof *x_save);
      memcpy(ws.dx, dx_save, NX * sizeof *dx_save);
    }
    predict(&ws);
    swap = q, q = q1, q1 = swap;
    swap = v, v = v1, v1 = swap;
    if ((k + 1) % every == 0) {
      if (q_out) memcpy(q_out + row * NQ, q, NQ * sizeof *q);
      if (v_out) memcpy(v_out + row * NQ, v, NQ * sizeof *v);
      if (lam_out) memcpy(lam_out + row * NC, lam, NC * sizeof *lam);
      if (iter_out) iter_out[row] = iter_sum;
      if (stats_out)
        put_stats(stats_out + row * NSTATS, every, iter_sum, n_splits - row_splits, err_q, err_v,
                  work);
#ifdef NCGEN_CONTACTS
      contact_row(&ws, impulse_out ? impulse_out + row * ND : 0, stats_out ? stats_out + row * NSTATS : 0);
#endif
      iter_sum = 0;
      row_splits = n_splits;
      ++row;
    }
  }
  if (steps_done) *steps_done = k;
  if (splits) *splits = n_splits;
  workspace_free(&ws);
  free(block);
  return status;
}

/* Derived quantities of n samples (<model>_outputs): NOUT values per sample into y. */
static int stepper_outputs(long n, const casadi_real *t, const casadi_real *q, const casadi_real *v,
                           const casadi_real *lam, const casadi_real *u, long u_stride, const casadi_real *p,
                           casadi_real *y) {
  workspace ws;
  char *block = malloc(step_work_bytes());
  long k;
  int status = STEP_OK;
  if (!block) return STEP_BAD_INPUT;
  layout(&ws, block);
  for (k = 0; k < n; ++k) {
    ws.arg[0] = t + k;
    ws.arg[1] = q + k * NQ;
    ws.arg[2] = v + k * NQ;
    ws.arg[3] = lam ? lam + k * NC : 0;
    ws.arg[4] = u ? u + k * u_stride : 0;
    ws.arg[5] = p;
    ws.res[0] = y + k * NOUT;
    if (KERNEL_OUTPUTS(ws.arg, ws.res, ws.iw, ws.w, 0)) {
      status = STEP_KERNEL;
      break;
    }
  }
  free(block);
  return status;
}

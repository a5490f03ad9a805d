/* Fixed-step runs of the RATTLE stepper (ncgen_rattle.h): a step retried cold and split in
 * halves where Newton fails (step_split()), one public step (stepper_step()), runs with
 * per-row statistics and the global error estimate of a shadow run (run_fixed()), and the
 * derived outputs of samples (stepper_outputs()).  Plain C99, model-independent; included
 * after ncgen_rattle.h (and ncgen_contact.h); the including file also defines NOUT, the
 * values per sample of KERNEL_OUTPUTS.  The model's stepper glue wraps these functions as
 * <model>_step, <model>_simulate, <model>_simulate_stats and <model>_outputs. */

/* The fourth-order triple jump (Yoshida 1990, Suzuki 1990): RATTLE steps of h1, h2, h1 with
 * h1 = h / (2 - 2^(1/3)), h2 = -2^(1/3) h1 (a backward step).  RATTLE is symmetric, so the
 * symmetric composition is of order 4; it stays symplectic and on both constraint levels.
 * Each step is warm-started from the one before (predict_scaled()); ws->x, ws->dx end as
 * after the last step (of h1), so predict() warm-starts the next composed step; ws->step_work
 * is the three steps' work. */
static int step_rattle4(const casadi_real *q, const casadi_real *v, casadi_real t, const casadi_real *u,
                        const casadi_real *p, casadi_real h, casadi_real *q_next, casadi_real *v_next,
                        casadi_real *lam, int *iterations, const step_options *o, int warm, workspace *ws) {
  const casadi_real cbrt2 = 1.25992104989487316476721060727822835;
  casadi_real h1 = h / (2 - cbrt2), h2 = -cbrt2 * h1;
  casadi_real *qa = ws->sub, *va = qa + NQ, *qb = va + NQ, *vb = qb + NQ;
  casadi_real work = 0;
  int it = 0, sum = 0, status = step(q, v, t, u, p, h1, qa, va, 0, &it, o, warm, ws);
  sum += it;
  if (status == STEP_OK) {
    work += ws->step_work;
    predict_scaled(ws->x, ws->x, ws->dx, va, h2 / h1);
    status = step(qa, va, t + h1, u, p, h2, qb, vb, 0, &it, o, 1, ws);
    sum += it;
  }
  if (status == STEP_OK) {
    work += ws->step_work;
    predict_scaled(ws->x, ws->x, ws->dx, vb, h1 / h2);
    status = step(qb, vb, t + h1 + h2, u, p, h1, q_next, v_next, lam, &it, o, 1, ws);
    sum += it;
  }
  if (status == STEP_OK) ws->step_work += work;
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
    casadi_real work = ws->step_work;
    status = step_split(q_mid, v_mid, t + h / 2, u, p, h / 2, q_next, v_next, lam, iterations, splits, o, 1, ws,
                        depth + 1);
    ws->step_work += work;
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
  if (!work) free(block);
  return status;
}

static void put_stats(casadi_real *row, long steps, long iterations, long splits, casadi_real err_q,
                      casadi_real err_v, casadi_real work) {
  row[0] = (casadi_real) steps;
  row[1] = (casadi_real) iterations;
  row[2] = (casadi_real) splits;
  row[3] = err_q;
  row[4] = err_v;
  row[5] = work;
}

/* Fixed steps (see <model>_simulate_stats; impulse_out: contacts only).  With `estimate`, a shadow run with steps of
 * 2h from the same start (one every second step) gives the global error estimate
 * (y_h - y_2h) / (2^p - 1) after every even step, p the order of the scheme (RATTLE 2, its
 * triple jump 4). */
static int run_fixed(const casadi_real *q0, const casadi_real *v0, const casadi_real *lam0, casadi_real t0,
                     casadi_real h, long n_steps, long every, const casadi_real *u, long u_stride,
                     const casadi_real *p, casadi_real *q_out, casadi_real *v_out, casadi_real *lam_out,
                     long *iter_out, casadi_real *stats_out, const step_options *o,
                     int estimate, int track_work, long *steps_done, long *splits,
                     casadi_real *impulse_out) {
  workspace ws;
  char *block;
  casadi_real *state, *q, *v, *q1, *v1, *lam, *swap, *q_s, *v_s, *q2, *v2, *x_save, *dx_save, *x_s, *dx_s, *u_bar;
  casadi_real work = 0, err_q = -1, err_v = -1, richardson = o->scheme == SCHEME_RATTLE4 ? 15 : 3;
  long k = 0, i, row = 0, iter_sum = 0, n_splits = 0, row_splits = 0;
#ifdef NCGEN_CONTACTS
  int status = STEP_OK, iters, shadow = 0; /* contacts: no shadow run (its steps would miss them) */
  (void) estimate;
#else
  int status = STEP_OK, iters, shadow = estimate ? 1 : 0; /* 1: cold start, 2: warm, 0: off */
  (void) impulse_out;
#endif
  if (steps_done) *steps_done = 0;
  if (splits) *splits = 0;
  if (n_steps < 0 || every < 1 || n_steps % every != 0) return STEP_BAD_INPUT;
  block = malloc(step_work_bytes() + (8 * NQ + NC + 4 * NX + NU + 1) * sizeof(casadi_real));
  if (!block) return STEP_BAD_INPUT;
  state = (casadi_real *) (block + layout(&ws, block));
  q = state;
  v = q + NQ;
  q1 = v + NQ;
  v1 = q1 + NQ;
  q_s = v1 + NQ;
  v_s = q_s + NQ;
  q2 = v_s + NQ;
  v2 = q2 + NQ;
  lam = v2 + NQ;
  x_save = lam + NC;
  dx_save = x_save + NX;
  x_s = dx_save + NX;
  dx_s = x_s + NX;
  u_bar = dx_s + NX;
  memcpy(q, q0, NQ * sizeof *q);
  memcpy(v, v0, NQ * sizeof *v);
  memcpy(q_s, q0, NQ * sizeof *q);
  memcpy(v_s, v0, NQ * sizeof *v);
  for (i = 0; i < NC; ++i) lam[i] = lam0 ? lam0[i] : 0;
#ifdef NCGEN_CONTACTS
  contact_clear(&ws);
#endif
  for (k = 0; k < n_steps; ++k) {
    const casadi_real *uk = u ? u + k * u_stride : 0;
    casadi_real tk = t0 + k * h;
    if (stop_requested(o)) {
      status = STEP_INTERRUPTED;
      break;
    }
    iters = 0;
    ws.track_work = track_work;
    status = step_split(q, v, tk, uk, p, h, q1, v1, lam, &iters, &n_splits, o, k > 0, &ws, 0);
    if (status != STEP_OK) break;
    if (track_work) work += ws.step_work; /* both ends with the step's inputs */
    ws.track_work = 0;                     /* not for the shadow */
    iter_sum += iters;
    if (shadow && k % 2 == 1) {
      /* The shadow's step of 2h over the last two steps, inputs averaged. */
      const casadi_real *u2 = 0;
      int iters2, ok;
      if (u) {
        for (i = 0; i < NU; ++i) u_bar[i] = (uk[i - u_stride] + uk[i]) / 2;
        u2 = u_bar;
      }
      memcpy(x_save, ws.x, NX * sizeof *x_save);
      memcpy(dx_save, ws.dx, NX * sizeof *dx_save);
      if (shadow == 2) {
        for (i = 0; i < NQ; ++i) ws.x[i] = 2 * dx_s[i] - x_s[i];
        for (i = NQ; i < NX; ++i) ws.x[i] = dx_s[i];
      }
      ok = scheme_step(q_s, v_s, tk - h, u2, p, 2 * h, q2, v2, 0, &iters2, o, shadow == 2, &ws) == STEP_OK ||
           (shadow == 2 && scheme_step(q_s, v_s, tk - h, u2, p, 2 * h, q2, v2, 0, &iters2, o, 0, &ws) == STEP_OK);
      if (ok) {
        memcpy(x_s, ws.x, NX * sizeof *x_s);
        memcpy(dx_s, ws.dx, NX * sizeof *dx_s);
        memcpy(q_s, q2, NQ * sizeof *q2);
        memcpy(v_s, v2, NQ * sizeof *v2);
        shadow = 2;
        err_q = err_v = 0;
        for (i = 0; i < NQ; ++i) {
          casadi_real dq = fabs(q1[i] - q2[i]) / richardson, dv = fabs(v1[i] - v2[i]) / richardson;
          err_q = nan_max(err_q, dq);
          err_v = nan_max(err_v, dv);
        }
      } else {
        shadow = 0; /* Newton fails at 2h: no estimate from here on */
        err_q = err_v = -2;
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

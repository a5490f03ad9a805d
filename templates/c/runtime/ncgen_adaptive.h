/* Error-controlled steps of RATTLE (ncgen_rattle.h) or of its fourth-order composition
 * (options->scheme SCHEME_RATTLE4, ncgen_fixed.h): the local error of a step from the step
 * and its two halves (local_error(), tangent_difference()), the next step size
 * (step_factor_order()), and the run over output intervals (simulate_adaptive(), wrapped by the
 * model's glue as <model>_simulate_adaptive, documented in <model>_stepper.h).  Plain C99,
 * model-independent; included after ncgen_fixed.h. */

/* The tangent part of fine - big at the end t of a step: d = fine - big (its q part, then
 * its v part), each less its component normal to the constraints at (t, q_fine) in the mass
 * metric, K^-1 [0; A d] (the projection of project(), with A d from KERNEL_PROJECT's
 * A v + Phi_t at v = d less that at v = 0).  Both states satisfy the constraints to Newton's
 * tolerance, so the normal part of their difference is a constraint residual, not an error
 * of the motion.  Away from singular configurations it is at that tolerance; next to one
 * (the constraint Jacobian A losing rank, smallest singular value sigma relative to the
 * largest) it is not: the multipliers grow as 1 / sigma along the vanishing direction, and
 * the KKT solves put their round-off (up to eps / sigma^2) there, so the whole difference
 * stops falling with the step and error control on it collapses the step. */
static int tangent_difference(workspace *ws, casadi_real t, const casadi_real *fine, const casadi_real *big,
                              const casadi_real *p, casadi_real *d) {
  int i, k;
  for (i = 0; i < 2 * NQ; ++i) d[i] = fine[i] - big[i];
  for (k = -1; k < 2; ++k) {
    ws->arg[0] = &t;
    ws->arg[1] = fine;
    ws->arg[2] = k < 0 ? 0 : d + k * NQ;
    ws->arg[3] = p;
    ws->res[0] = ws->K;
    ws->res[1] = 0;
    ws->res[2] = k < 0 ? ws->x : ws->r + NQ; /* Phi_t (A v + Phi_t at v = 0) kept in x */
    if (KERNEL_PROJECT(ws->arg, ws->res, ws->iw, ws->w, 0)) return STEP_KERNEL;
    if (k < 0) continue;
    for (i = 0; i < NQ; ++i) ws->r[i] = 0;
    for (i = 0; i < NC; ++i) ws->r[NQ + i] -= ws->x[i];
    if (solve(ws, ws->K, ws->r, ws->dx)) return STEP_KERNEL;
    if (!all_finite(ws->dx, NX)) return STEP_NOT_FINITE;
    for (i = 0; i < NQ; ++i) d[k * NQ + i] -= ws->dx[i];
  }
  return STEP_OK;
}

/* Local error of the two half-steps `fine` against the whole step `big` from y = [q; v]:
 * diff / R, diff the tangent part of fine - big (tangent_difference), R = 2^p - 1 for a
 * scheme of order p (RATTLE: 3, its local error C h^3 gives big - fine = 3/4 C h^3; the
 * composition: 15).  Sets *err_q, *err_v to its largest component in q (m) and v (m/s);
 * returns its largest component relative to atol + rtol max(|y_i|, |fine_i|) (NaN
 * propagates). */
static casadi_real local_error(const casadi_real *y, const casadi_real *diff, const casadi_real *fine,
                               casadi_real rtol, casadi_real atol, casadi_real richardson, casadi_real *err_q,
                               casadi_real *err_v) {
  casadi_real e = 0, d;
  int i;
  *err_q = *err_v = 0;
  for (i = 0; i < 2 * NQ; ++i) {
    d = fabs(diff[i]) / richardson;
    if (i < NQ) *err_q = nan_max(*err_q, d);
    else *err_v = nan_max(*err_v, d);
    e = nan_max(e, d / (atol + rtol * fmax(fabs(y[i]), fabs(fine[i]))));
  }
  return e;
}

/* Next step size over this one for the relative local error e (<= 1: accepted) of a scheme
 * whose local error is O(h^(p + 1)): 0.9 e^(-1/(p + 1)), within 0.2 .. 4; 4 for e = 0 (and
 * for NaN: the caller rejects the step, !(e <= 1)). */
static casadi_real step_factor_order(casadi_real e, int p) {
  casadi_real factor = e > 0 ? 0.9 * pow(e, -1.0 / (p + 1)) : 4;
  return fmin(4, fmax(0.2, factor));
}

/* Error-controlled steps over n_out output intervals (see <model>_simulate_adaptive). */
static int simulate_adaptive(const casadi_real *q0, const casadi_real *v0, const casadi_real *lam0,
                             casadi_real t0, casadi_real dt, long n_out, const casadi_real *u,
                             long u_stride, const casadi_real *p, const run_options *run,
                             casadi_real *q_out, casadi_real *v_out, casadi_real *lam_out,
                             casadi_real *stats_out, const step_options *options, long *rows_done,
                             casadi_real *h_next) {
  const casadi_real rtol = run->rtol, atol = run->atol, h0 = run->h0;
  const long max_steps = run->max_steps;
  const int extrapolate = run->extrapolate, hold_linear = run->hold_linear, track_work = run->track_work;
  step_options defaults, single;
  workspace ws;
  char *block;
  casadi_real *y, *big, *mid, *fine, *y_new, *lam, *lam_fine, *x_prev, *dx_prev, *x_big, *u_buf, *phidot;
  casadi_real t = t0, H = h0 > 0 ? h0 : dt, h_prev = 0, work[NWORK] = {0}, work_mid[NWORK] = {0};
  long row = 0, i;
  int status = STEP_OK, have_prev = 0, order;
  casadi_real richardson;
  single = *options_or_default(options, &defaults);
  single.max_halvings = 0;
  order = single.scheme == SCHEME_RATTLE4 ? 4 : 2;
  richardson = (1 << order) - 1;
  if (rows_done) *rows_done = 0;
  if (!(dt > 0) || n_out < 0 || !(rtol > 0) || !(atol > 0) || max_steps < 1 || !isfinite(t0 + dt * n_out) ||
      single.scheme < 0 || single.scheme > SCHEME_RATTLE4)
    return STEP_BAD_INPUT;
  block = malloc(step_work_bytes() + (10 * NQ + 3 * NC + 3 * NX + NU + 1) * sizeof(casadi_real));
  if (!block) return STEP_BAD_INPUT;
  y = (casadi_real *) (block + layout(&ws, block));
  big = y + 2 * NQ;
  mid = big + 2 * NQ;
  fine = mid + 2 * NQ;
  y_new = fine + 2 * NQ;
  lam = y_new + 2 * NQ;
  lam_fine = lam + NC;
  phidot = lam_fine + NC;
  x_prev = phidot + NC;
  dx_prev = x_prev + NX;
  x_big = dx_prev + NX;
  u_buf = x_big + NX;
  memcpy(y, q0, NQ * sizeof *y);
  memcpy(y + NQ, v0, NQ * sizeof *y);
  for (i = 0; i < NC; ++i) lam[i] = lam0 ? lam0[i] : 0;
  for (row = 0; row < n_out; ++row) {
    casadi_real t_start = t0 + row * dt, t_end = t0 + (row + 1) * dt, sum_q = 0, sum_v = 0;
    const casadi_real *u_row = u ? u + row * u_stride : 0;
    long steps = 0, rejected = 0, attempts = 0, iter_sum = 0;
    while (t < t_end) {
      casadi_real Hs = H, e, err_q, err_v, factor;
      const casadi_real *uk = u_row;
      int land = 0, iters = 0;
      long unused = 0;
      if (stop_requested(&single)) {
        status = STEP_INTERRUPTED;
        goto done;
      }
      if (++attempts > max_steps) {
        status = STEP_TOO_MANY_STEPS;
        goto done;
      }
      if (t + 1.01 * Hs >= t_end) {
        Hs = t_end - t;
        land = 1;
      } else if (t + 2 * Hs > t_end) {
        Hs = (t_end - t) / 2;
      }
      if (!(Hs > 1e-13 * (fabs(t) + dt))) {
        status = STEP_TOO_SMALL;
        goto done;
      }
      if (hold_linear && u) {
        casadi_real frac = (t + Hs / 2 - t_start) / dt;
        for (i = 0; i < NU; ++i) u_buf[i] = u_row[i] + frac * (u_row[u_stride + i] - u_row[i]);
        uk = u_buf;
      }
      /* One step of Hs, then two of Hs/2 (each warm-started from the one before). */
      if (have_prev) predict_scaled(ws.x, x_prev, dx_prev, y + NQ, Hs / h_prev);
      ws.track_work = 0; /* the work of the two half steps only */
      status = step_split(y, y + NQ, t, uk, p, Hs, big, big + NQ, 0, &iters, &unused, &single, have_prev, &ws, 0);
      if (status == STEP_OK) {
        int warm = 1;
        ws.track_work = track_work;
        if (order == 2) { /* RATTLE: the whole step's solution halved */
          memcpy(x_big, ws.x, NX * sizeof *x_big);
          for (i = 0; i < NQ; ++i) ws.x[i] = (y[NQ + i] + x_big[i]) / 2;
          for (i = NQ; i < NX; ++i) ws.x[i] = x_big[i] / 2;
        } else if (have_prev) { /* the composition: its first stage from the last one before */
          predict_scaled(ws.x, x_prev, dx_prev, y + NQ, Hs / 2 / h_prev);
        } else {
          warm = 0;
        }
        status = step_split(y, y + NQ, t, uk, p, Hs / 2, mid, mid + NQ, 0, &iters, &unused, &single, warm, &ws, 0);
      }
      if (status == STEP_OK) {
        memcpy(work_mid, ws.step_work, sizeof work_mid);
        predict(&ws);
        status = step_split(mid, mid + NQ, t + Hs / 2, uk, p, Hs / 2, fine, fine + NQ, lam_fine, &iters, &unused,
                            &single, 1, &ws, 0);
      }
      iter_sum += iters;
      if (status != STEP_OK) {
        if (!recoverable(status)) goto done;
        status = STEP_OK;
        ++rejected;
        H = Hs / 4;
        have_prev = 0;
        continue;
      }
      memcpy(x_prev, ws.x, NX * sizeof *x_prev);
      memcpy(dx_prev, ws.dx, NX * sizeof *dx_prev);
      h_prev = Hs / 2;
      have_prev = 1;
      /* The error of the whole difference (in mid, free now), and where that fails the test,
       * of its tangent part (never larger in the mass norm; the same away from singular
       * configurations, so it costs nothing on regular motions). */
      for (i = 0; i < 2 * NQ; ++i) mid[i] = fine[i] - big[i];
      e = local_error(y, mid, fine, rtol, atol, richardson, &err_q, &err_v);
      if (!(e <= 1) && tangent_difference(&ws, t + Hs, fine, big, p, mid) == STEP_OK)
        e = local_error(y, mid, fine, rtol, atol, richardson, &err_q, &err_v);
      factor = step_factor_order(e, order);
      if (!(e <= 1)) {
        ++rejected;
        H = Hs * factor;
        continue;
      }
      /* Accepted: Richardson extrapolation fine + (fine - big)/R (order p + 1; RATTLE: 4),
       * projected. */
      memcpy(y_new, fine, 2 * NQ * sizeof *y_new);
      if (extrapolate) {
        for (i = 0; i < 2 * NQ; ++i) y_new[i] += (fine[i] - big[i]) / richardson;
        if (project(&ws, t + Hs, y_new, y_new + NQ, p, &single, phidot) != STEP_OK)
          memcpy(y_new, fine, 2 * NQ * sizeof *y_new);
      }
      memcpy(y, y_new, 2 * NQ * sizeof *y);
      memcpy(lam, lam_fine, NC * sizeof *lam);
      t = land ? t_end : t + Hs;
      ++steps;
      sum_q += err_q;
      sum_v += err_v;
      if (track_work) { /* the two steps of Hs/2 */
        work_add(work, work_mid);
        work_add(work, ws.step_work);
      }
      H = (land && Hs < H) ? fmax(H, Hs * factor) : Hs * factor;
    }
    if (q_out) memcpy(q_out + row * NQ, y, NQ * sizeof *y);
    if (v_out) memcpy(v_out + row * NQ, y + NQ, NQ * sizeof *y);
    if (lam_out) memcpy(lam_out + row * NC, lam, NC * sizeof *lam);
    if (stats_out)
      put_stats(stats_out + row * NSTATS, steps, iter_sum, rejected, sum_q, sum_v, work);
  }
done:
  if (rows_done) *rows_done = row;
  if (h_next) *h_next = H;
  workspace_free(&ws);
  free(block);
  return status;
}

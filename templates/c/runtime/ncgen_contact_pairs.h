/* The contact rows of the nonsmooth stepper (gaps g, Jacobian W, velocities U = W v) by a
 * loop over the model's contact elements, each through its kernel (one kernel per kind of
 * element and its numbers: ncgen/assembly/pair_kernels.py), with a broad phase: an element
 * whose bounding volumes are far enough apart is not evaluated, and its gaps read as a
 * lower bound of them.  Plain C99, model-independent; included after ncgen_rattle.h and
 * before ncgen_contact.h, and empty unless CONTACT_PAIRS is defined.
 *
 * What the including file defines first:
 *   NE                         contact elements
 *   pair_int[NE * 8]           per element: kernel, first point contact, point contacts,
 *                              local coordinates of side a (na) and b (nb), offset of its
 *                              coordinates in pair_qidx/pair_qconst, offset of its W map in
 *                              pair_wpos, whether its rows' velocities are bounded (1/0)
 *   pair_qidx, pair_qconst     per local coordinate: its index in q (-1: fixed) and value
 *   pair_wpos                  per entry of the element kernel's dense W (column-major,
 *                              rows: per point contact its DC rows): where it goes in the
 *                              nonzeros of W (-1: nowhere, a frictionless tangent row);
 *                              with wt_colind (ncgen_contact.h): an element's rows' nonzeros
 *                              are contiguous in W, and each is a position of its map
 *   pair_side[NE * 6]          per element and side: kind (PAIR_*), affine columns k,
 *                              offset of its data in pair_bdata
 *   pair_bdata                 a member side: centre (DC x n), axes (k of DC x n), extents
 *                              (k), radius, |G|; a fixed side: centre (DC), radius; a
 *                              half-space: point (DC), normal (DC)
 *   pair_bound[NE * 3]         per element: kappa, d_min, cap (ncgen/assembly/pair_kernels.py)
 *   PAIR_NS, pair_sid[NE * 2]  the distinct member sides (the same member's coordinates and the
 *                              same bounding data: a sphere of a heap is one side of all its
 *                              elements) and per element side its number (-1: not a member)
 *   pair_srep[PAIR_NS * 2]     per distinct member side an element and side that has it
 *   pair_gap_fn, pair_rows_fn  the kernels by number (or PAIR_KERNEL, below); PAIR_MAX_Q, PAIR_MAX_G, PAIR_MAX_W:
 *                              the largest na + nb, point contacts and dense W of an element
 *
 * Which elements are evaluated (ws->pon): pairs_bounds() computes, at a configuration q,
 * each element's lower bound b_e of its gaps (ws->plb; -INFINITY where none) and, given a
 * velocity field, a bound S_e of its rows' velocities (ws->pspd); pairs_select(limit, hs)
 * turns on the elements with b_e <= limit + hs S_e (and, if asked, those with a force), and
 * pairs_extend() more of them later.  Exactness: the step compares a gap with a threshold
 * (<= 0: closed; < GAP_REACH h/2 max |U_N|: about to close; < PENETRATION_TOL + twice the
 * deepest: pushed out with the others; g - h/2 W X j <= 0: closed in repeat_step()); an
 * element is skipped only where b_e exceeds the threshold, so its flat gaps (>= b_e) would
 * have taken the same decision, and its rows would not have entered any solve. */

#ifdef CONTACT_PAIRS
#define PAIR_UNBOUNDED 0
#define PAIR_MEMBER 1
#define PAIR_FIXED 2
#define PAIR_HALFSPACE 3
/* Relative slack of the lower bounds (BOUND_SLACK of pair_kernels.py). */
#define PAIR_SLACK 1e-6

typedef int (*pair_kernel)(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem);
/* Element e's kernel fn (pair_gap_fn or pair_rows_fn) on ws->arg, ws->res (the table stepper
 * defines its own: ncgen_table_contacts.h). */
#ifndef PAIR_KERNEL
#define PAIR_KERNEL(fn, e, ws) fn[pair_int[8 * (e)]]((ws)->arg, (ws)->res, (ws)->iw, (ws)->w, 0)
#endif

/* Per element e, its last kernel results at two configurations, at ws->pcache + e PAIR_SLOT:
 * the slot to be replaced next (0 or 1), then two slots, each whether it holds the gaps (1) or
 * also the rows (2), the local coordinates (PAIR_MAX_Q), gaps (PAIR_MAX_G) and dense W
 * (PAIR_MAX_W) at them.  A step evaluates an element several times at its start and its end
 * (the repeat at q, at q_next, at q again; the contact step at q; the push-out at the end),
 * and the results depend on the coordinates alone (p is fixed while a workspace is laid out:
 * layout() empties the slots; PAIR_SLOT in ncgen_rattle.h). */
#define PAIR_ENTRY (1 + PAIR_MAX_Q + PAIR_MAX_G + PAIR_MAX_W)

/* Element e's gaps into g and, if rows, its dense W into ws->pw, at its local coordinates in
 * ws->pq (pair_gather()): the kernel's results, or those kept where the coordinates are the
 * same bits (kept in the older of the two slots, or in the one with the gaps alone there). */
static int pair_eval(workspace *ws, int e, int rows, const casadi_real *p, casadi_real *g) {
  const int *pi = pair_int + 8 * e, n = pi[3] + pi[4];
  const size_t nw = (size_t) pi[2] * DC * n;
  casadi_real *cache = ws->pcache + (size_t) e * PAIR_SLOT, *slot, *sq, *sg, *sw;
  int k, same = -1;
  for (k = 0; k < 2; ++k) {
    slot = cache + 1 + k * PAIR_ENTRY, sq = slot + 1, sg = sq + PAIR_MAX_Q, sw = sg + PAIR_MAX_G;
    if (slot[0] > 0 && !memcmp(sq, ws->pq, n * sizeof(casadi_real))) {
      if (slot[0] < (rows ? 2 : 1)) { /* its gaps only: the rows go there */
        same = k;
        continue;
      }
      memcpy(g, sg, pi[2] * sizeof(casadi_real));
      if (rows) memcpy(ws->pw, sw, nw * sizeof(casadi_real));
      cache[0] = 1 - k;
      return STEP_OK;
    }
  }
  k = same >= 0 ? same : cache[0] != 0;
  slot = cache + 1 + k * PAIR_ENTRY, sq = slot + 1, sg = sq + PAIR_MAX_Q, sw = sg + PAIR_MAX_G;
  slot[0] = 0;
  ws->arg[0] = ws->pq;
  ws->arg[1] = ws->pq + pi[3];
  ws->arg[2] = p;
  ws->res[0] = g;
  ws->res[1] = ws->pw;
  if (rows ? PAIR_KERNEL(pair_rows_fn, e, ws) : PAIR_KERNEL(pair_gap_fn, e, ws)) return STEP_KERNEL;
  memcpy(sq, ws->pq, n * sizeof(casadi_real));
  memcpy(sg, g, pi[2] * sizeof(casadi_real));
  if (rows) memcpy(sw, ws->pw, nw * sizeof(casadi_real));
  slot[0] = rows ? 2 : 1;
  cache[0] = 1 - k;
  return STEP_OK;
}

/* Element e's local coordinates (rates: fixed ones 0) from the system's x into out. */
static void pair_gather(int e, const casadi_real *x, int rates, casadi_real *out) {
  const int *pi = pair_int + 8 * e;
  int i, n = pi[3] + pi[4];
  for (i = 0; i < n; ++i) {
    const int k = pair_qidx[pi[5] + i];
    out[i] = k >= 0 ? x[k] : (rates ? 0 : pair_qconst[pi[5] + i]);
  }
}

static casadi_real pair_norm(const casadi_real *x) {
  casadi_real s = 0;
  int d;
  for (d = 0; d < DC; ++d) s += x[d] * x[d];
  return sqrt(s);
}

/* Side s of element e, a member, from its local coordinates ql (and rates vl, or NULL):
 * out = centre x0 (DC), radius R, and the speed terms lin = |x0'| + sum_j e_j |X_j'| and
 * rot = |G| |X'|_F |X|_F (a bound of |omega|). */
static void pair_member_bound(int e, int s, const casadi_real *ql, const casadi_real *vl, casadi_real *out) {
  const int k = pair_side[6 * e + 3 * s + 1], n = pair_int[8 * e + 3 + s];
  const casadi_real *b = pair_bdata + pair_side[6 * e + 3 * s + 2], *ext = b + DC * n * (1 + k);
  casadi_real xv[DC], xf = 0, vf = 0, *x0 = out, *R = out + DC, *lin = out + DC + 1, *rot = out + DC + 2;
  int d, i, j;
  *lin = *rot = 0;
  for (d = 0; d < DC; ++d) {
    x0[d] = xv[d] = 0;
    for (i = 0; i < n; ++i) {
      x0[d] += b[d + DC * i] * ql[i];
      if (vl) xv[d] += b[d + DC * i] * vl[i];
    }
  }
  *R = ext[k];
  if (vl) *lin = pair_norm(xv);
  for (j = 0; j < k; ++j) {
    const casadi_real *a = b + DC * n * (1 + j);
    casadi_real X[DC], V[DC], nx, nv;
    for (d = 0; d < DC; ++d) {
      X[d] = V[d] = 0;
      for (i = 0; i < n; ++i) {
        X[d] += a[d + DC * i] * ql[i];
        if (vl) V[d] += a[d + DC * i] * vl[i];
      }
    }
    nx = pair_norm(X);
    *R += ext[j] * nx;
    xf += nx * nx;
    if (vl) {
      nv = pair_norm(V);
      *lin += ext[j] * nv;
      vf += nv * nv;
    }
  }
  if (vl) *rot = ext[k + 1] * sqrt(vf) * sqrt(xf);
}

/* Element e's lower bound of its gaps (-INFINITY where there is none) and the bound *speed
 * of its rows' velocities W_r v, from its member sides' numbers of the last pairs_bounds()
 * (ws->psb; their speed terms 0 without rates). */
static casadi_real pair_lower(workspace *ws, int e, casadi_real *speed) {
  const casadi_real *x[2];
  casadi_real R[2], lin[2], rot[2], D, lever, lb;
  int kind[2], s, d;
  *speed = 0;
  for (s = 0; s < 2; ++s) {
    const casadi_real *b = pair_bdata + pair_side[6 * e + 3 * s + 2];
    kind[s] = pair_side[6 * e + 3 * s];
    if (kind[s] == PAIR_UNBOUNDED) return -INFINITY;
    if (kind[s] == PAIR_MEMBER) {
      const casadi_real *sb = ws->psb + (DC + 3) * pair_sid[2 * e + s];
      x[s] = sb;
      R[s] = sb[DC];
      lin[s] = sb[DC + 1];
      rot[s] = sb[DC + 2];
    } else {
      x[s] = b;
      R[s] = kind[s] == PAIR_FIXED ? b[DC] : 0;
      lin[s] = rot[s] = 0;
    }
  }
  if (kind[0] == PAIR_HALFSPACE || kind[1] == PAIR_HALFSPACE) {
    const int h = kind[0] == PAIR_HALFSPACE ? 0 : 1, m = 1 - h;
    const casadi_real *b = pair_bdata + pair_side[6 * e + 3 * h + 2];
    D = -R[m];
    for (d = 0; d < DC; ++d) D += b[DC + d] * (x[m][d] - b[d]);
    *speed = lin[m] + rot[m] * 2 * R[m];
    lb = D - PAIR_SLACK * R[m];
  } else {
    casadi_real dx[DC];
    for (d = 0; d < DC; ++d) dx[d] = x[1][d] - x[0][d];
    D = pair_norm(dx) - R[0] - R[1];
    lever = D + 3 * (R[0] + R[1]);
    *speed = lin[0] + lin[1] + (rot[0] + rot[1]) * lever;
    lb = pair_bound[3 * e] * D - PAIR_SLACK * (R[0] + R[1]);
  }
  if (!(D >= pair_bound[3 * e + 1])) return -INFINITY;
  return fmin(lb, pair_bound[3 * e + 2]);
}

/* Every element's lower bound at q (ws->plb) and, given rates (or NULL), its speed bound
 * (ws->pspd; 0 without rates).  The bounds depend on q alone: a call without rates at the q
 * of the last call (the same bits) only clears the speeds (repeat_step() at the start of a
 * step after the push-out's call at its end; the push-out after a repeated step). */
static void pairs_bounds(workspace *ws, const casadi_real *q, const casadi_real *rates) {
  int e, k;
  if (!rates && ws->pb_rates >= 0 && !memcmp(q, ws->pbq, NQ * sizeof(casadi_real))) {
    if (ws->pb_rates) memset(ws->pspd, 0, NE * sizeof(casadi_real));
    ws->pb_rates = 0;
    return;
  }
  memcpy(ws->pbq, q, NQ * sizeof(casadi_real));
  ws->pb_rates = rates != 0;
  for (k = 0; k < PAIR_NS; ++k) { /* each member side once, however many elements it is in */
    const int se = pair_srep[2 * k], s = pair_srep[2 * k + 1], *pi = pair_int + 8 * se;
    const int o = pi[5] + (s ? pi[3] : 0), n = pi[3 + s];
    int i;
    for (i = 0; i < n; ++i) {
      const int c = pair_qidx[o + i];
      ws->pq[i] = c >= 0 ? q[c] : pair_qconst[o + i];
      ws->pq[PAIR_MAX_Q + i] = c >= 0 && rates ? rates[c] : 0;
    }
    pair_member_bound(se, s, ws->pq, rates ? ws->pq + PAIR_MAX_Q : 0, ws->psb + (DC + 3) * k);
  }
  for (e = 0; e < NE; ++e) ws->plb[e] = pair_lower(ws, e, ws->pspd + e);
}

/* Whether a contact row of element e carries a force of the last step. */
static int pair_loaded(workspace *ws, int e) {
  int r;
  for (r = pair_int[8 * e + 1] * DC; r < (pair_int[8 * e + 1] + pair_int[8 * e + 2]) * DC; ++r)
    if (ws->F[r] != 0) return 1;
  return 0;
}

/* Turns on (ws->pon = 1) the elements whose gaps may be below limit + hs S_e (every element
 * whose rows' velocities are not bounded, if hs > 0), and, if loaded, those with a force;
 * the others off. */
static void pairs_select(workspace *ws, casadi_real limit, casadi_real hs, int loaded) {
  int e;
  for (e = 0; e < NE; ++e) {
    int on = !(ws->plb[e] > limit + hs * ws->pspd[e]) || (hs > 0 && !pair_int[8 * e + 7]);
    ws->pon[e] = on || (loaded && pair_loaded(ws, e));
  }
}

/* Turns on (ws->pon = 2: to be evaluated) the elements off whose gaps may be below limit;
 * returns their number. */
static int pairs_extend(workspace *ws, casadi_real limit) {
  int e, n = 0;
  for (e = 0; e < NE; ++e)
    if (!ws->pon[e] && !(ws->plb[e] > limit)) {
      ws->pon[e] = 2;
      ++n;
    }
  return n;
}

/* The gaps at q of the elements on (the lower bounds of those off) into g. */
static int contact_gap(workspace *ws, const casadi_real *q, const casadi_real *p, casadi_real *g) {
  int e, i;
  for (e = 0; e < NE; ++e) {
    const int *pi = pair_int + 8 * e;
    if (!ws->pon[e]) {
      for (i = 0; i < pi[2]; ++i) g[pi[1] + i] = ws->plb[e];
      continue;
    }
    pair_gather(e, q, 0, ws->pq);
    if (pair_eval(ws, e, 0, p, g + pi[1])) return STEP_KERNEL;
  }
  return STEP_OK;
}

/* The contact rows at (q, v) of the elements with ws->pon >= which (which = 2: only those
 * pairs_extend() turned on, then marked 1): gaps into g, the nonzeros of W, U = W v (each
 * may be NULL).  With which = 1 the elements off get their lower bound as gaps and zero
 * rows. */
static int contact_rows(workspace *ws, const casadi_real *q, const casadi_real *v, const casadi_real *p,
                        casadi_real *g, casadi_real *W, casadi_real *U, int which) {
  int e, i, r;
  for (e = 0; e < NE; ++e) {
    const int *pi = pair_int + 8 * e, nrow = pi[2] * DC, nloc = pi[3] + pi[4];
    const int *wpos = pair_wpos + pi[6];
    /* the element's rows' nonzeros of W, contiguous (every one a position of wpos) */
    const int w0 = wt_colind[pi[1] * DC], nw = wt_colind[pi[1] * DC + nrow] - w0;
    if (ws->pon[e] < which) {
      if (which != 1) continue;
      if (g)
        for (i = 0; i < pi[2]; ++i) g[pi[1] + i] = ws->plb[e];
      if (W) memset(W + w0, 0, nw * sizeof(casadi_real));
      if (U)
        for (r = 0; r < nrow; ++r) U[pi[1] * DC + r] = 0;
      continue;
    }
    if (which == 2) ws->pon[e] = 1;
    pair_gather(e, q, 0, ws->pq);
    if (pair_eval(ws, e, 1, p, ws->pg)) return STEP_KERNEL;
    if (g) memcpy(g + pi[1], ws->pg, pi[2] * sizeof(casadi_real));
    if (W) {
      memset(W + w0, 0, nw * sizeof(casadi_real));
      for (i = 0; i < nrow * nloc; ++i) /* shared coordinates: both sides' columns add */
        if (wpos[i] >= 0) W[wpos[i]] += ws->pw[i];
    }
    if (U) {
      casadi_real *vl = ws->pq + PAIR_MAX_Q;
      pair_gather(e, v, 1, vl);
      for (r = 0; r < nrow; ++r) {
        casadi_real s = 0;
        for (i = 0; i < nloc; ++i) s += ws->pw[r + nrow * i] * vl[i];
        U[pi[1] * DC + r] = s;
      }
    }
  }
  return STEP_OK;
}
#endif

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
 * each distinct member side's bounding sphere (centre x, radius R) and, given a velocity
 * field, its speed terms; pairs_select(limit, hs) takes each element's lower bound b_e of its
 * gaps (ws->plb; -INFINITY where none) and bound S_e of its rows' velocities (ws->pspd) and
 * turns on the elements with b_e <= limit + hs S_e (and, if asked, those with a force), and
 * pairs_extend() more of them later.
 *
 * The sweep (pairs_sweep()): b_e and S_e are taken one by one only for the elements that may
 * be below the level L = max(limit, 0) + sk (sk: the largest side radius + 1e-6 m, a skin
 * that keeps pairs_extend()'s usual limits below L): the elements with a side that is not a
 * member, a finite cap or unbounded rates (ws->palw), and the member-member elements whose
 * sides' boxes overlap on every axis: side i spans x_i -/+ (R_i + a_i) on each axis d with
 *   a_i = (2 / kmin) (L / 2 + s R_i + hs lin_i + 3 rho_i (R_i + Rmax)) + dmax / 2,
 *   rho_i = hs rot_i <= kmin / 4 (else the side spans every axis whole),
 * kmin the least kappa and dmax the largest d_min of those elements, s = PAIR_SLACK, Rmax the
 * largest R.  Every other element gets b_e = L, S_e = 0, which is exact by construction: its
 * boxes are disjoint on some axis d, and |x_j - x_i| >= |x_j,d - x_i,d| > R_i + R_j + a_i + a_j
 * (the distance of the centres is at least that along any one axis), so D > a_i + a_j >= dmax >= d_min,
 * and with rho_i + rho_j <= kmin / 2 and (rho_i + rho_j)(R_i + R_j) <= sum_i rho_i (R_i + Rmax)
 *   kappa D - s (R_i + R_j) - L - hs S_e
 *     >= (kmin - hs (rot_i + rot_j)) D - [L + s (R_i + R_j) + hs (lin_i + lin_j) + 3 (rho_i + rho_j)(R_i + R_j)]
 *     >= kmin / 2 D - kmin / 2 (a_i + a_j) > 0,
 * so its true bound exceeds L + hs S_e >= L > limit: it is off as it would be with b_e taken
 * one by one, L is a lower bound of its gaps, and every later decision (a gap against 0, the
 * reach, the push-out's range, all below L or else pairs_extend() takes every b_e one by one)
 * is the same.  The boxes that overlap on every axis are found by a sweep (pairs_sweep_boxes())
 * along the axis on which the centres spread most, the sides sorted by their boxes' lower ends
 * there from the order of the last sweep (insertion: nearly sorted from step to step), and the
 * other axes tested before an element becomes a candidate, so a step costs O(NS + the pairs whose
 * boxes overlap on that axis) comparisons and O(the pairs whose boxes overlap on every axis) bound
 * computations instead of one per element.  (Tested on one axis alone, a sparse grid's intervals
 * overlap by whole columns, about N^1.5 / 2 pairs of N sides, each a bound computed; now each is
 * a comparison of the other axes.  A uniform grid over the boxes, O(NS + the pairs in
 * neighbouring cells, keyed by 3 cell numbers; commit 574e40a of branch grid38), measured 1.3-6x
 * slower than this sweep from 1000 down to 20 sides on a sparse grid and 2.5-3.6x on heaps of
 * 20-50 sides: benchmarks/issue34_targets.md.)
 * Exactness: the step compares a gap with a threshold
 * (<= 0: closed; < GAP_REACH h/2 max |U_N|: about to close; < PENETRATION_TOL + twice the
 * deepest: pushed out with the others; g - h/2 W X j <= 0: closed in repeat_step()); an
 * element is skipped only where b_e exceeds the threshold, so its flat gaps (>= b_e) would
 * have taken the same decision, and its rows would not have entered any solve.
 *
 * The candidates (ws->pcand, in the sweep's order; ws->pcm marks them): the elements whose bound the
 * sweep took one by one, and those turned on.  Every other element is off, its bound L =
 * ws->plim, its speed bound 0: what the sweep gave it, without writing it.  Only candidates are
 * walked after the sweep (pairs_select(), pairs_extend(), contact_gap(), contact_rows(): each
 * element's work its own, in any order), and only the contacts of the elements on (ws->kon,
 * sorted ascending, contacts_on()) by ncgen_contact.h:
 * an element off is neither evaluated nor written (its gaps >= its bound exceed every
 * threshold it is compared with, so no loop over the contacts would have used its rows: the
 * gaps against 0, the reach, the push-out's range, the repeat's free gaps g - h/2 W X j with
 * W = 0 on its rows, max |U| with U = 0 on its rows, its force 0).  The loops walk the same
 * contacts in the same (ascending) order as a loop over all contacts that skips those off, so
 * every sum and every solve is the same to the bit.  The elements with a force of the last step
 * (ws->pld, a superset, ws->pld_ok) are kept by the contact step, and rebuilt from ws->F after
 * contact_clear(). */

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

/* Each distinct member side's bounding sphere at q and, given rates (or NULL), its speed terms
 * (ws->psb: x0, R, lin, rot; lin = rot = 0 without rates).  They depend on q alone: a call
 * without rates at the q of the last call (the same bits) only clears the speed terms
 * (repeat_step() at the start of a step after the push-out's call at its end; the push-out
 * after a repeated step).  The elements' bounds are taken by pairs_select(). */
static void pairs_bounds(workspace *ws, const casadi_real *q, const casadi_real *rates) {
  int k;
  ws->plim = -INFINITY;
  if (!rates && ws->pb_rates >= 0 && !memcmp(q, ws->pbq, NQ * sizeof(casadi_real))) {
    if (ws->pb_rates)
      for (k = 0; k < PAIR_NS; ++k) ws->psb[(DC + 3) * k + DC + 1] = ws->psb[(DC + 3) * k + DC + 2] = 0;
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
}

/* Whether element e is swept (its bound taken only if its sides' intervals overlap): two
 * different member sides, rates bounded, no cap (the header's comment); none with
 * NCGEN_PAIRS_ALL defined. */
static int pair_swept(int e) {
#ifdef NCGEN_PAIRS_ALL /* every bound one by one (the tests' reference) */
  (void) e;
  return 0;
#else
  const int a = pair_sid[2 * e], b = pair_sid[2 * e + 1];
  return a >= 0 && b >= 0 && a != b && pair_int[8 * e + 7] && pair_bound[3 * e + 2] >= 1e300;
#endif
}

/* The sweep's tables, once after layout(): the elements not swept (ws->palw), per side the
 * swept elements it is the lower-numbered side of, by the other side (ws->padj), kmin, dmax. */
static void pairs_init(workspace *ws) {
  int e, k, *ptr = ws->padj, *ent = ws->padj + PAIR_NS + 1, *at = ws->pover;
  ws->nalw = 0;
  ws->pkmin = 1;
  ws->pdmax = 0;
  for (k = 0; k <= PAIR_NS; ++k) ptr[k] = 0;
  for (e = 0; e < NE; ++e)
    if (pair_swept(e)) {
      ++ptr[1 + (pair_sid[2 * e] < pair_sid[2 * e + 1] ? pair_sid[2 * e] : pair_sid[2 * e + 1])];
      ws->pkmin = fmin(ws->pkmin, pair_bound[3 * e]);
      ws->pdmax = fmax(ws->pdmax, pair_bound[3 * e + 1]);
    } else {
      ws->palw[ws->nalw++] = e;
    }
  for (k = 0; k < PAIR_NS; ++k) {
    ptr[k + 1] += ptr[k];
    at[k] = ptr[k];
    ws->pord[k] = k;
  }
  for (e = 0; e < NE; ++e)
    if (pair_swept(e)) {
      const int a = pair_sid[2 * e], b = pair_sid[2 * e + 1], lo = a < b ? a : b;
      int i = at[lo]++;
      for (; i > ptr[lo] && ent[2 * (i - 1)] > a + b - lo; --i) { /* insertion by the other side */
        ent[2 * i] = ent[2 * (i - 1)];
        ent[2 * i + 1] = ent[2 * (i - 1) + 1];
      }
      ent[2 * i] = a + b - lo;
      ent[2 * i + 1] = e;
    }
}

/* Every candidate off and no longer a candidate (before a sweep). */
static void pairs_uncandidate(workspace *ws) {
  int i;
  for (i = 0; i < ws->ncand; ++i) ws->pcm[ws->pcand[i]] = ws->pon[ws->pcand[i]] = 0;
  ws->ncand = 0;
}

/* Element e a candidate, with its bound taken one by one. */
static void pair_candidate(workspace *ws, int e) {
  ws->pcm[e] = 1;
  ws->pcand[ws->ncand++] = e;
  ws->plb[e] = pair_lower(ws, e, ws->pspd + e);
}

static int int_ascending(const void *a, const void *b) {
  const int x = *(const int *) a, y = *(const int *) b;
  return (x > y) - (x < y);
}

/* The box of a side (sb: x0 (dim), R, lin, rot) at level L, hs, with the largest radius rmax,
 * kmin and dmax (the header's comment): per axis d < dim its interval iv[2 d], iv[2 d + 1] =
 * x_d -/+ (R + a); every axis whole where rho = hs rot > kmin / 4 or a number is not finite. */
static void pair_box(const casadi_real *sb, int dim, casadi_real L, casadi_real hs, casadi_real rmax,
                     casadi_real kmin, casadi_real dmax, casadi_real *iv) {
  const casadi_real R = sb[dim], rho = hs * sb[dim + 2];
  const casadi_real w = R + 2 / kmin * (L / 2 + PAIR_SLACK * R + hs * sb[dim + 1] + 3 * rho * (R + rmax)) + dmax / 2;
  int d, whole = !(rho <= kmin / 4);
  for (d = 0; d < dim; ++d) {
    const casadi_real wd = w + 1e-9 * (fabs(sb[d]) + w); /* round-off of the ends */
    iv[2 * d] = sb[d] - wd;
    iv[2 * d + 1] = sb[d] + wd;
    whole |= !(fabs(iv[2 * d]) < INFINITY) || !(fabs(iv[2 * d + 1]) < INFINITY);
  }
  if (whole)
    for (d = 0; d < dim; ++d) {
      iv[2 * d] = -INFINITY;
      iv[2 * d + 1] = INFINITY;
    }
}

/* Whether the boxes a and b (2 dim numbers each) overlap on every axis but skip. */
static int pair_boxes_meet(const casadi_real *a, const casadi_real *b, int dim, int skip) {
  int d;
  for (d = 0; d < dim; ++d)
    if (d != skip && (a[2 * d] > b[2 * d + 1] || b[2 * d] > a[2 * d + 1])) return 0;
  return 1;
}

/* The pairs of n boxes (iv: lo, hi per axis, 2 dim per box) that overlap on every axis, each
 * once, given to found(ctx, a, b); returns their number.  A sweep along axis: ord (the order of
 * the last call) sorted by lo on that axis, by insertion (O(n + the pairs out of order)), then
 * each box against those after it whose lo is at most its hi there, the other axes tested
 * before a pair is given: O(n + the pairs that overlap on that axis) box tests. */
static long pairs_sweep_boxes(const casadi_real *iv, int dim, int n, int axis, int *ord,
                              void (*found)(void *, int, int), void *ctx) {
  int i, j;
  long count = 0;
  for (i = 1; i < n; ++i) {
    const int k = ord[i];
    for (j = i; j > 0 && iv[2 * dim * ord[j - 1] + 2 * axis] > iv[2 * dim * k + 2 * axis]; --j) ord[j] = ord[j - 1];
    ord[j] = k;
  }
  for (i = 0; i < n; ++i) {
    const casadi_real *a = iv + 2 * dim * ord[i], hi = a[2 * axis + 1];
    for (j = i + 1; j < n && iv[2 * dim * ord[j] + 2 * axis] <= hi; ++j)
      if (pair_boxes_meet(a, iv + 2 * dim * ord[j], dim, axis)) { /* overlap on axis: lo_a <= lo_b <= hi_a */
        found(ctx, ord[i], ord[j]);
        ++count;
      }
  }
  return count;
}

/* The swept elements of sides a and b made candidates (pairs_sweep_boxes()'s found, ctx the workspace). */
static inline void pairs_meet(void *ctx, int a, int b) {
  workspace *ws = ctx;
  const int *ptr = ws->padj, *ent = ws->padj + PAIR_NS + 1, s = a < b ? a : b, t = a + b - s;
  int lo = ptr[s], hi = ptr[s + 1];
  while (lo < hi) { /* the first entry of side s whose other side is >= t */
    const int mid = (lo + hi) / 2;
    if (ent[2 * mid] < t) lo = mid + 1;
    else hi = mid;
  }
  for (; lo < ptr[s + 1] && ent[2 * lo] == t; ++lo) pair_candidate(ws, ent[2 * lo + 1]);
}

/* Every element's lower bound and speed bound (ws->plb, ws->pspd) at the last pairs_bounds(),
 * exact for those that may be below level + sk + hs S_e, the level L = level + sk for the
 * others (the header's comment); ws->plim = L. */
static void pairs_sweep(workspace *ws, casadi_real level, casadi_real hs) {
  casadi_real rmax = 0, spread = -1, L;
  int i, k, d, axis = 0;
  if (ws->nalw < 0) pairs_init(ws);
  for (k = 0; k < PAIR_NS; ++k) rmax = fmax(rmax, ws->psb[(DC + 3) * k + DC]);
  for (d = 0; d < DC && PAIR_NS; ++d) { /* the axis along which the centres spread most */
    casadi_real lo = ws->psb[d], hi = lo;
    for (k = 1; k < PAIR_NS; ++k) {
      lo = fmin(lo, ws->psb[(DC + 3) * k + d]);
      hi = fmax(hi, ws->psb[(DC + 3) * k + d]);
    }
    if (hi - lo > spread) {
      spread = hi - lo;
      axis = d;
    }
  }
  L = level + rmax + 1e-6;
  pairs_uncandidate(ws);
  for (i = 0; i < ws->nalw; ++i) pair_candidate(ws, ws->palw[i]);
  for (k = 0; k < PAIR_NS; ++k)
    pair_box(ws->psb + (DC + 3) * k, DC, L, hs, rmax, ws->pkmin, ws->pdmax, ws->pint + 2 * DC * k);
  pairs_sweep_boxes(ws->pint, DC, PAIR_NS, axis, ws->pord, pairs_meet, ws);
  ws->plim = L;
}

/* The contacts of the elements on, ascending (ws->kon: the order of a loop over all contacts). */
static void contacts_on(workspace *ws) {
  int i, j;
  ws->nkon = 0;
  for (i = 0; i < ws->ncand; ++i) {
    const int *pi = pair_int + 8 * ws->pcand[i];
    if (ws->pon[ws->pcand[i]])
      for (j = 0; j < pi[2]; ++j) ws->kon[ws->nkon++] = pi[1] + j;
  }
  qsort(ws->kon, (size_t) ws->nkon, sizeof(int), int_ascending);
}

/* Whether a contact row of element e carries a force of the last step. */
static int pair_loaded(workspace *ws, int e) {
  int r;
  for (r = pair_int[8 * e + 1] * DC; r < (pair_int[8 * e + 1] + pair_int[8 * e + 2]) * DC; ++r)
    if (ws->F[r] != 0) return 1;
  return 0;
}

/* The elements that may carry a force (ws->pld), from ws->F if not known. */
static void pairs_forces_known(workspace *ws) {
  int e;
  if (ws->pld_ok) return;
  for (ws->npld = e = 0; e < NE; ++e)
    if (pair_loaded(ws, e)) ws->pld[ws->npld++] = e;
  ws->pld_ok = 1;
}

/* After the contact step set ws->F (a force only on the rows of elements on): the elements on
 * with a force. */
static void pairs_forces_set(workspace *ws) {
  int i;
  for (ws->npld = i = 0; i < ws->ncand; ++i)
    if (ws->pon[ws->pcand[i]] && pair_loaded(ws, ws->pcand[i])) ws->pld[ws->npld++] = ws->pcand[i];
  ws->pld_ok = 1;
}

/* Turns on (ws->pon = 1) the elements whose gaps may be below limit + hs S_e (every element
 * whose rows' velocities are not bounded, if hs > 0), and, if loaded, those with a force;
 * the others off.  Takes the bounds (pairs_sweep(); after pairs_bounds()). */
static void pairs_select(workspace *ws, casadi_real limit, casadi_real hs, int loaded) {
  int e, i;
  pairs_sweep(ws, fmax(limit, 0), hs);
  for (i = 0; i < ws->ncand; ++i) {
    e = ws->pcand[i];
    ws->pon[e] = !(ws->plb[e] > limit + hs * ws->pspd[e]) || (hs > 0 && !pair_int[8 * e + 7]);
  }
  if (loaded) {
    pairs_forces_known(ws);
    for (i = 0; i < ws->npld; ++i)
      if (!ws->pon[e = ws->pld[i]] && pair_loaded(ws, e)) {
        if (!ws->pcm[e]) { /* off by the sweep (bound L > limit): a candidate */
          ws->pcand[ws->ncand++] = e;
          ws->pcm[e] = 1;
          ws->plb[e] = ws->plim;
          ws->pspd[e] = 0;
        }
        ws->pon[e] = 1;
      }
  }
  contacts_on(ws);
}

/* Turns on (ws->pon = 2: to be evaluated) the elements off whose gaps may be below limit;
 * returns their number. */
static int pairs_extend(workspace *ws, casadi_real limit) {
  int e, i, n = 0;
  if (!(limit < ws->plim)) { /* beyond the sweep's level: every bound one by one, every element a candidate */
    for (e = 0; e < NE; ++e) {
      ws->plb[e] = pair_lower(ws, e, ws->pspd + e);
      ws->pcm[e] = 1;
      ws->pcand[e] = e;
    }
    ws->ncand = NE;
    ws->plim = INFINITY;
  }
  for (i = 0; i < ws->ncand; ++i)
    if (!ws->pon[e = ws->pcand[i]] && !(ws->plb[e] > limit)) {
      ws->pon[e] = 2;
      ++n;
    }
  if (n) contacts_on(ws);
  return n;
}

/* The gaps at q of the elements on into g (those of the elements off are not written). */
static int contact_gap(workspace *ws, const casadi_real *q, const casadi_real *p, casadi_real *g) {
  int e, i;
  for (i = 0; i < ws->ncand; ++i) {
    const int *pi = pair_int + 8 * (e = ws->pcand[i]);
    if (!ws->pon[e]) continue;
    pair_gather(e, q, 0, ws->pq);
    if (pair_eval(ws, e, 0, p, g + pi[1])) return STEP_KERNEL;
  }
  return STEP_OK;
}

/* The contact rows at (q, v) of the elements with ws->pon >= which (which = 2: only those
 * pairs_extend() turned on, then marked 1): gaps into g, the nonzeros of W, U = W v (each
 * may be NULL).  The rows of the elements off are not written. */
static int contact_rows(workspace *ws, const casadi_real *q, const casadi_real *v, const casadi_real *p,
                        casadi_real *g, casadi_real *W, casadi_real *U, int which) {
  int c, e, i, r;
  for (c = 0; c < ws->ncand; ++c) {
    const int *pi = pair_int + 8 * (e = ws->pcand[c]), nrow = pi[2] * DC, nloc = pi[3] + pi[4];
    const int *wpos = pair_wpos + pi[6];
    /* the element's rows' nonzeros of W, contiguous (every one a position of wpos) */
    const int w0 = wt_colind[pi[1] * DC], nw = wt_colind[pi[1] * DC + nrow] - w0;
    if (ws->pon[e] < which) continue;
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

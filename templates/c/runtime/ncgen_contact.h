/* Nonsmooth contacts for the RATTLE stepper of ncgen_rattle.h: the contact impulses of a
 * step by projected Gauss-Seidel (pgs(), with Newton steps on frictionless sets,
 * lcp_newton(), and the semismooth Newton method of ncgen_cone_newton.h, cone_newton(), on
 * sets with friction) on the Delassus matrix (delassus()), the repeat of the last step's
 * impulses (repeat_step()), the push-out of penetrating contacts (push_out()) and the
 * contact step around them (contact_step()).  Plain C99, model-independent; included after
 * ncgen_rattle.h and ncgen_cone_newton.h when NCGEN_CONTACTS is defined (see ncgen_rattle.h).  The scheme is
 * documented in docs/contact.md and <model>_stepper.h.
 *
 * What the including file defines first (besides ncgen_rattle.h's list):
 *   NK, DC                     contacts, impulse components per contact (normal, then
 *                              DC - 1 tangents): ND = NK DC rows
 *   NNZ_W, wt_colind, wt_row   the pattern of the contact Jacobian W by rows: row r has
 *                              nonzeros k = wt_colind[r] .. wt_colind[r + 1] - 1, in
 *                              columns wt_row[k]
 *   mu, restitution            per contact: Coulomb's friction coefficient, Newton's e
 *   ANY_RESTITUTION            defined if some restitution is > 0
 *   PGS_MAX_ITER, PGS_TOL      sweeps of pgs() and its convergence test
 *   CONTACT_REFINE_MAX, CONTACT_REFINE_TOL   refinements of a step after an impact
 *   GRAVITY_NORM               |gravity| (m/s^2), the scale of an impact
 *   PENETRATION_TOL            gaps below -PENETRATION_TOL (m) are pushed out
 *   GAP_REACH                  open contacts within GAP_REACH h/2 of the fastest closing
 *                              speed take part in a step's contact problem
 *   REPEAT_TOL                 tolerance of repeat_step()
 *   CONTACT_PAIRS              defined if the contact rows come from the element kernels
 *                              of ncgen_contact_pairs.h (included before this file, with
 *                              what it lists); else
 *   KERNEL_GAP, KERNEL_CONTACT the gap and contact kernels of all contacts at once
 *   CONTACT_FACTORED           defined if the KKT matrix is factored once per contact
 *                              solve: then NNZ_V, NNZ_R, N_BETA (sizes of its QR factors),
 *                              KERNEL_FACTOR, KERNEL_BACKSOLVE
 *   CONTACT_SCHUR              defined if the Delassus matrix comes from the constant M^-1:
 *                              then minv (NQ x NQ, column-major), its nonzeros by columns
 *                              minv_colind, minv_row, and where A sits in the KKT matrix,
 *                              NNZ_A and (if NNZ_A > 0) a_nz, a_row, a_col; or, sizes and
 *                              arrays known at run time (the table stepper), CONTACT_A_RUNTIME
 *                              (a_nz, a_row, a_col always there) and SCHUR_READY (whether
 *                              minv exists: else the KKT solves)
 */

/* Impulses that change a contact velocity by more than CONTACT_IMPACT_STEPS steps of gravity
 * make an impact (contact_step() refines it). */
#define CONTACT_IMPACT_STEPS 10
/* push_out(): passes at most. */
#define PUSH_OUT_MAX 4
/* lcp_newton(): first after NEWTON_FIRST sweeps (then after twice as many); relative pivot
 * below which a row counts as dependent on the rows before it; solves at most. */
#define NEWTON_FIRST 4
#define NEWTON_PIVOT 1e-10
#define NEWTON_SOLVES 4
/* pgs(): cone_newton() after CONE_FIRST sweeps (a power of 2 times NEWTON_FIRST) that have
 * not converged, and again after twice as many while it fails: the sweeps solve the easy
 * problems, Newton finishes those they crawl on. */
#define CONE_FIRST 4

#ifndef CONTACT_PAIRS
/* Without element kernels (ncgen_contact_pairs.h) every contact is evaluated, by the flat
 * kernels. */
#define pairs_bounds(ws, q, rates) ((void) 0)
#define pairs_select(ws, limit, hs, loaded) contacts_all(ws)
#define pairs_extend(ws, limit) 0

/* Every contact evaluated (ws->kon). */
static void contacts_all(workspace *ws) {
  int k;
  for (k = 0; k < NK; ++k) ws->kon[k] = k;
  ws->nkon = NK;
}

static int contact_gap(workspace *ws, const casadi_real *q, const casadi_real *p, casadi_real *g) {
  ws->arg[0] = q;
  ws->arg[1] = p;
  ws->res[0] = g;
  return KERNEL_GAP(ws->arg, ws->res, ws->iw, ws->w, 0) ? STEP_KERNEL : STEP_OK;
}

static int contact_rows(workspace *ws, const casadi_real *q, const casadi_real *v, const casadi_real *p,
                        casadi_real *g, casadi_real *W, casadi_real *U, int which) {
  if (which != 1) return STEP_OK; /* every row is evaluated */
  ws->arg[0] = q;
  ws->arg[1] = v;
  ws->arg[2] = p;
  ws->res[0] = g;
  ws->res[1] = W;
  ws->res[2] = U;
  return KERNEL_CONTACT(ws->arg, ws->res, ws->iw, ws->w, 0) ? STEP_KERNEL : STEP_OK;
}
#endif

/* max |x_r| over the rows of the contacts evaluated (ws->kon; NaN if some is). */
static casadi_real rows_norm_inf(const workspace *ws, const casadi_real *x) {
  casadi_real m = 0;
  int i, r;
  for (i = 0; i < ws->nkon; ++i)
    for (r = ws->kon[i] * DC; r < (ws->kon[i] + 1) * DC; ++r) m = nan_max(m, fabs(x[r]));
  return m;
}

/* Whether the last step's impulses h F are not all zero. */
static int forces_any(workspace *ws, casadi_real h) {
  int r;
#ifdef CONTACT_PAIRS
  int i;
  pairs_forces_known(ws);
  for (i = 0; i < ws->npld; ++i) {
    const int *pi = pair_int + 8 * ws->pld[i];
    for (r = pi[1] * DC; r < (pi[1] + pi[2]) * DC; ++r)
      if (h * ws->F[r] != 0) return 1;
  }
#else
  for (r = 0; r < ND; ++r)
    if (h * ws->F[r] != 0) return 1;
#endif
  return 0;
}

/* No contact force (the step's contacts all open). */
static void forces_clear(workspace *ws) {
#ifdef CONTACT_PAIRS
  int i;
  pairs_forces_known(ws);
  for (i = 0; i < ws->npld; ++i) {
    const int *pi = pair_int + 8 * ws->pld[i];
    memset(ws->F + pi[1] * DC, 0, (size_t) (pi[2] * DC) * sizeof(casadi_real));
  }
  ws->npld = 0;
#else
  memset(ws->F, 0, ND * sizeof(casadi_real));
#endif
}

/* No force on the contacts not evaluated (with CONTACT_PAIRS: the elements off are open). */
static void forces_clear_off(workspace *ws) {
#ifdef CONTACT_PAIRS
  int i;
  pairs_forces_known(ws);
  for (i = 0; i < ws->npld; ++i) {
    const int *pi = pair_int + 8 * ws->pld[i];
    if (!ws->pon[ws->pld[i]]) memset(ws->F + pi[1] * DC, 0, (size_t) (pi[2] * DC) * sizeof(casadi_real));
  }
#else
  (void) ws;
#endif
}

/* Clears what the contact steps accumulate and their warm start (before a run). */
static void contact_clear(workspace *ws) {
  memset(ws->Pacc, 0, ND * sizeof(casadi_real));
  memset(ws->psum, 0, NK * sizeof(int));
  ws->nsum = 0;
  memset(ws->F, 0, ND * sizeof(casadi_real));
#ifdef CONTACT_PAIRS
  ws->pld_ok = 0; /* rebuilt from F at the next use (a caller may set F) */
#endif
  ws->pgs_unconverged = 0;
  ws->pgs_residual = 0;
  ws->cone_residual = 0;
  ws->penetration = 0;
  ws->repeat = 1;
}

/* The first of the contact statistics' columns, after the work (ncgen_fixed.h: put_stats()). */
#define CONTACT_COL (5 + NWORK)

/* Contact k among those whose impulse sums ws->Pacc are not zero since the last row (ws->ksum). */
static void impulse_summed(workspace *ws, int k) {
  if (!ws->psum[k]) {
    ws->psum[k] = 1;
    ws->ksum[ws->nsum++] = k;
  }
}

/* Ends an output row: the impulses summed since the last row into impulse (ND values, zero
 * where written: only the contacts with a nonzero sum are) and the contact statistics into
 * columns CONTACT_COL .. CONTACT_COL + 3 of stats (each may be NULL), then clears them. */
static void contact_row(workspace *ws, casadi_real *impulse, casadi_real *stats) {
  int i;
  for (i = 0; i < ws->nsum; ++i) {
    casadi_real *sum = ws->Pacc + ws->ksum[i] * DC;
    if (impulse) memcpy(impulse + ws->ksum[i] * DC, sum, DC * sizeof(casadi_real));
    memset(sum, 0, DC * sizeof(casadi_real));
    ws->psum[ws->ksum[i]] = 0;
  }
  ws->nsum = 0;
  if (stats) {
    stats[CONTACT_COL] = (casadi_real) ws->pgs_unconverged;
    stats[CONTACT_COL + 1] = ws->pgs_residual;
    stats[CONTACT_COL + 2] = ws->penetration;
    stats[CONTACT_COL + 3] = ws->cone_residual;
  }
  ws->pgs_unconverged = 0;
  ws->pgs_residual = 0;
  ws->cone_residual = 0;
  ws->penetration = 0;
}

/* Adds impulse dP to active row r: P, the contact velocities U, and the largest change of a
 * row's own velocity |G_rr dP| to *change. */
static void pgs_update(workspace *ws, int nr, int r, casadi_real dP, casadi_real *change) {
  const casadi_real *gr = ws->G + r * nr;
  int k;
  casadi_real c;
  if (dP == 0) return;
  ws->P[r] += dP;
  for (k = (int) ws->gp[r]; k < ws->gp[r + 1]; ++k) ws->U[ws->gi[k]] += gr[ws->gi[k]] * dP;
  c = fabs(ws->G[r + r * nr] * dP);
  if (c > *change) *change = c;
}

/* The nonzeros of the n x n matrix ws->G by columns (ws->gp, ws->gi), for pgs_update(): G is
 * sparse where contacts share no member (a pile: a contact couples with those of its one or
 * two spheres). */
static void g_pattern(workspace *ws, int n) {
  int a, r, k = 0;
  for (r = 0; r < n; ++r) {
    ws->gp[r] = k;
    for (a = 0; a < n; ++a)
      if (ws->G[a + r * n] != 0) ws->gi[k++] = a;
  }
  ws->gp[n] = k;
}

/* S = the Cholesky factor of G_AA, A = the m rows idx of the n x n matrix ws->G, by rows
 * (row i at S + i n, lower triangle; m <= n); a pivot below
 * NEWTON_PIVOT of its diagonal is dropped (its column zero).  Row i of the factor depends
 * on rows 0..i of G_AA only, so the rows that idx shares, as a prefix, with the last factor's
 * rows (ws->fset) are kept.  G_AA is sparse (contacts couple only through the members they
 * share): row i of the factor is zero left of its first nonzero in G_AA (ws->fset + NK + i,
 * its envelope), and the products skip those zeros. */
static void factor_rows(workspace *ws, int n, const int *idx, int m) {
  casadi_real *S = ws->S;
  casadi_int *fset = ws->fset, *start = ws->fset + NK;
  int i, j, k, p = 0;
  if (ws->fm > 0)
    while (p < m && p < ws->fm && fset[p] == idx[p]) ++p;
  for (i = p; i < m; ++i) {
    casadi_real *li = S + i * n, d, d0;
    int f = 0;
    for (j = 0; j <= i; ++j) li[j] = ws->G[idx[i] + idx[j] * n];
    while (f < i && li[f] == 0) ++f;
    start[i] = f;
    fset[i] = idx[i];
    for (j = f; j < i; ++j) {
      const casadi_real *lj = S + j * n;
      casadi_real v = li[j];
      if (lj[j] == 0) { /* a dropped pivot: its column is zero */
        li[j] = 0;
        continue;
      }
      for (k = f > start[j] ? f : (int) start[j]; k < j; ++k) v -= li[k] * lj[k];
      li[j] = v / lj[j];
    }
    d = d0 = li[i];
    for (k = f; k < i; ++k) d -= li[k] * li[k];
    li[i] = d > NEWTON_PIVOT * d0 ? sqrt(d) : 0;
  }
  ws->fm = m;
}

/* Newton steps of the frictionless contact problem (the LCP U + b >= 0 _|_ P >= 0 with
 * U = U_0 + G P on the n rows in ws->U, ws->P, ws->G; b = 0 if null): on the rows with an
 * impulse, solves G_AA dP_A = -(U + b)_A, which zeroes their velocities, by Cholesky.  A
 * pivot below NEWTON_PIVOT of its diagonal marks a row that depends on the rows before it
 * (redundant contacts: a sphere in a corner, a pile): it keeps its impulse, and the others'
 * solve it too, as the equations are consistent at the solution.  If an impulse would turn
 * negative, the step stops where the first one reaches 0 (a descent step of the convex
 * problem min 1/2 P^T G P + (U_0 + b)^T P, P >= 0), that row leaves the set and the
 * solve is repeated, at most NEWTON_SOLVES times.  pgs() then checks the result, and
 * carries on from it if some row without an impulse ends with U + b < 0.  Projected
 * Gauss-Seidel alone crawls on redundant sets (hundreds of sweeps); this finishes them
 * once its sweeps have found the set. */
static void lcp_newton(workspace *ws, int n, const casadi_real *b) {
  casadi_real *S = ws->S, x[NK], change = 0;
  int idx[NK], in[NK], m, i, k, solve;
  for (solve = 0; solve < NEWTON_SOLVES; ++solve) {
    casadi_real step = 1;
    /* the rows with an impulse: those of the last factor first, in its order (so that its
     * rows up to the first one that left are kept), then the others */
    for (i = 0; i < n; ++i) in[i] = ws->P[i] > 0;
    m = 0;
    if (ws->fm > 0)
      for (i = 0; i < ws->fm; ++i)
        if (in[ws->fset[i]]) {
          idx[m++] = (int) ws->fset[i];
          in[ws->fset[i]] = 0;
        }
    for (i = 0; i < n; ++i)
      if (in[i]) idx[m++] = i;
    if (!m) return;
    for (i = 0; i < m; ++i) x[i] = -(ws->U[idx[i]] + (b ? b[idx[i]] : 0));
    factor_rows(ws, n, idx, m);
    for (i = 0; i < m; ++i) { /* L y = x, y_i = 0 on a dropped pivot */
      const casadi_real *li = S + i * n;
      if (li[i] == 0) { x[i] = 0; continue; }
      for (k = (int) ws->fset[NK + i]; k < i; ++k) x[i] -= li[k] * x[k];
      x[i] /= li[i];
    }
    for (i = m - 1; i >= 0; --i) { /* L^T dP = y, by columns of L^T: x_i done, then subtracted */
      const casadi_real *li = S + i * n;
      if (li[i] == 0) x[i] = 0;
      else x[i] /= li[i];
      for (k = (int) ws->fset[NK + i]; k < i; ++k) x[k] -= li[k] * x[i];
    }
    for (i = 0; i < m; ++i) {
      if (!isfinite(x[i])) return;
      if (ws->P[idx[i]] + step * x[i] < 0) step = -ws->P[idx[i]] / x[i];
    }
    for (i = 0; i < m; ++i) /* the blocking rows land on exactly 0 */
      pgs_update(ws, n, idx[i], ws->P[idx[i]] + step * x[i] > 0 ? step * x[i] : -ws->P[idx[i]], &change);
    if (step == 1) return;
  }
}

/* Projected Gauss-Seidel on the na active contacts: finds impulses P (N s) with
 *   U_N + b >= 0  _|_  P_N >= 0,  b = bias[c] = e min(U-_N, 0)  (Newton's impact law at velocity level)
 *   (for a contact still open at the end of the free step, b >= 0: see contact_step())
 *   |P_T| <= mu P_N, P_T = -mu P_N V_T / |V_T| if V_T != 0, V_T = U_T + e U-_T  (Coulomb's cone)
 * (U- the velocities at the start of the step).  Coulomb's law on U_T + e U-_T rather than on U_T
 * keeps every impact dissipative for 0 <= e <= 1 (on U_T alone, Newton's law with friction can
 * create energy: Kane's paradox); for a lasting contact U-_T ~ U_T and it is Coulomb's law.
 * where U = U_0 + G P are the contact velocities at the end of the step, linearised: ws->U
 * holds U of the active rows for the impulses ws->P on entry, and on exit.  Returns whether
 * it converged within PGS_MAX_ITER sweeps; ws->pgs_last gets the last sweep's largest change
 * of a contact velocity relative to 1 + max |U| (m/s per m/s).  When every active contact
 * is frictionless, lcp_newton() steps after NEWTON_FIRST, 2 NEWTON_FIRST, ... sweeps finish
 * what the sweeps crawl on (redundant contacts); with friction, cone_newton() does (the
 * sweeps converge linearly, slowly where contacts are coupled: a heap), and it has
 * converged when every contact law holds to PGS_TOL (1 + max |U|) m/s; if it stops short
 * (no descent), the sweeps carry on from where they were.  A converged solve ends with the
 * least-norm impulses of its family where the support is statically indeterminate
 * (cone_min_norm()). */
static int pgs(workspace *ws, int na, const int *first, const casadi_real *bias) {
  int nr = first[na], c, d, sweep, newton_at = NEWTON_FIRST;
  ws->pgs_last = 0;
  ws->pgs_sweeps = PGS_MAX_ITER;
  for (sweep = 0; sweep < PGS_MAX_ITER; ++sweep) {
    casadi_real change = 0, size = 0;
    for (c = 0; c < na; ++c) {
      int r0 = first[c], k = (int) ws->act[c];
      casadi_real gnn = ws->G[r0 + r0 * nr];
      if (gnn > 0) {
        casadi_real un = ws->U[r0] + bias[c];
        pgs_update(ws, nr, r0, fmax(0, ws->P[r0] - un / gnn) - ws->P[r0], &change);
      }
      if (first[c + 1] > r0 + 1) { /* friction: its tangent rows follow the normal row */
        casadi_real gt = 0, pt[DC], norm = 0, limit = mu[k] * ws->P[r0];
        for (d = 1; d < DC; ++d) gt = fmax(gt, ws->G[(r0 + d) + (r0 + d) * nr]);
        if (gt > 0) {
          for (d = 1; d < DC; ++d) {
            pt[d] = ws->P[r0 + d] - (ws->U[r0 + d] + restitution[k] * ws->Um[k * DC + d]) / gt;
            norm += pt[d] * pt[d];
          }
          norm = sqrt(norm);
          for (d = 1; d < DC; ++d)
            pgs_update(ws, nr, r0 + d, (norm > limit ? pt[d] * limit / norm : pt[d]) - ws->P[r0 + d], &change);
        }
      }
      for (d = r0; d < first[c + 1]; ++d) size = fmax(size, fabs(ws->U[d]));
    }
    ws->pgs_last = change / (1 + size);
    if (change <= PGS_TOL * (1 + size)) { /* a sweep changes no velocity by more than that */
      ws->pgs_sweeps = sweep;
      cone_min_norm(ws, na, first, bias, PGS_TOL);
      return 1;
    }
    if (sweep + 1 == newton_at) { /* Newton steps after 4, 8, 16, ... sweeps */
      newton_at *= 2;
      if (nr == na) lcp_newton(ws, nr, bias); /* frictionless */
      else if (sweep + 1 >= CONE_FIRST && cone_newton(ws, na, first, bias, PGS_TOL, &ws->cone_last)) {
        ws->pgs_last = 0;
        ws->pgs_sweeps = sweep + 1;
        cone_min_norm(ws, na, first, bias, PGS_TOL);
        return 1;
      } /* else no descent from there: the sweeps carry on, and Newton starts again from
           where they are after twice as many */
    }
  }
  return 0;
}

/* X_a = [M A^T; A 0]^-1 [W_r^T; 0] (first NQ rows) for the rows r = rows[a], a < n, with the
 * KKT matrix in ws->K (one factorisation, then one back-substitution per row), and
 * G = W_rows X (n x n).  Uses ws->W (rows of the contact Jacobian), ws->rhs, ws->fac. */
static int delassus_kkt(workspace *ws, const int *rows, int n) {
  int a, b, i;
#ifdef CONTACT_FACTORED
  ws->arg[0] = ws->K;
  ws->res[0] = ws->fac;
  ws->res[1] = ws->fac + NNZ_V;
  ws->res[2] = ws->fac + NNZ_V + NNZ_R;
  if (KERNEL_FACTOR(ws->arg, ws->res, ws->iw, ws->w, 0)) return STEP_KERNEL;
#endif
  for (a = 0; a < n; ++a) {
    for (i = 0; i < NX; ++i) ws->rhs[i] = 0;
    for (i = wt_colind[rows[a]]; i < wt_colind[rows[a] + 1]; ++i) ws->rhs[wt_row[i]] = ws->W[i];
#ifdef CONTACT_FACTORED
    ws->arg[0] = ws->fac;
    ws->arg[1] = ws->fac + NNZ_V;
    ws->arg[2] = ws->fac + NNZ_V + NNZ_R;
    ws->arg[3] = ws->rhs;
    ws->res[0] = ws->rhs + NX;
    if (KERNEL_BACKSOLVE(ws->arg, ws->res, ws->iw, ws->w, 0)) return STEP_KERNEL;
#else
    if (solve(ws, ws->K, ws->rhs, ws->rhs + NX)) return STEP_KERNEL;
#endif
    memcpy(ws->Xc + a * NQ, ws->rhs + NX, NQ * sizeof(casadi_real));
  }
  for (a = 0; a < n; ++a)
    for (b = 0; b < n; ++b) {
      casadi_real s = 0;
      for (i = wt_colind[rows[a]]; i < wt_colind[rows[a] + 1]; ++i) s += ws->W[i] * ws->Xc[b * NQ + wt_row[i]];
      ws->G[a + b * n] = s;
    }
  return all_finite(ws->G, n * n) ? STEP_OK : STEP_NOT_FINITE;
}
#ifdef CONTACT_SCHUR
#ifdef CONTACT_A_RUNTIME
#define CONTACT_HAS_A
#elif NNZ_A > 0
#define CONTACT_HAS_A
#endif
#ifndef SCHUR_READY
#define SCHUR_READY 1
#endif

/* The Delassus matrix of delassus_kkt() from the constant M^-1 and the Schur complement of
 * the KKT matrix: with B = M^-1 W_r^T (in ws->Xc), T = A M^-1, S = A M^-1 A^T = L L^T,
 * Z = L^-1 A B and Y = L^-T Z,
 *   X = B - T^T Y   and   G = W_r X = W_r B - Z^T Z,
 * X kept as (B, Y, T) and applied by x_add().  A is read from the KKT matrix in ws->K.  Falls
 * back to delassus_kkt() where S is not numerically positive definite (redundant or
 * singular constraints).  Everything walks nonzeros: M^-1 by columns, S's envelope (row i of
 * L is zero left of its first nonzero in S: block diagonal for free bodies, banded for a
 * chain), B's nonzeros against W's columns (G_ab = 0 where rows a and b share no member),
 * and each Z_a between its first and last nonzero. */
static int delassus(workspace *ws, const int *rows, int n) {
  casadi_real *T = ws->T, *L = ws->L, *Z = ws->Z, *Y = ws->Y, *B = ws->Xc;
  /* scratch in ws->cni after cone_newton()'s 2 ND: envelope starts of L (NC), the first and
   * last nonzero of each Z_a (2 ND), W's active nonzeros by columns (NQ + 1 starts, then
   * row and position per nonzero), the first and last nonzero of each row of T (2 NC, read
   * by x_add()), A's nonzeros by columns (NQ + 1 starts, NNZ_A positions), the first and
   * last nonzero of each B_a (2 ND, read by x_add()), the smallest envelope start of rows
   * i .. NC - 1 (NC), Z's nonzeros by rows of L (NC + 1 starts; the active rows a,
   * ascending, in ws->zr) */
  casadi_int *env = ws->cni + 2 * ND, *zlo = env + NC, *zhi = zlo + ND, *cp = zhi + ND, *cr = cp + NQ + 1,
             *ck = cr + NNZ_W, *tlo = ck + NNZ_W, *thi = tlo + NC, *acp = thi + NC, *ak = acp + NQ + 1,
             *bfirst = ak + NNZ_A, *blast = bfirst + ND, *emin = blast + ND, *zp = emin + NC, *zr = ws->zr;
  int a, b, i, j, k, finite = 1;
  if (!SCHUR_READY) {
    ws->schur = 0;
    return delassus_kkt(ws, rows, n);
  }
  if (ws->tl_zero) /* the rows of T and L the last call wrote (A's pattern does not change) */
    for (i = 0; i < NC; ++i) {
      for (j = (int) tlo[i]; j <= thi[i]; ++j) T[i * NQ + j] = 0;
      for (j = (int) env[i]; j <= i; ++j) L[i + j * NC] = 0;
    }
  else {
    memset(T, 0, NC * NQ * sizeof(casadi_real));
    memset(L, 0, NC * NC * sizeof(casadi_real));
  }
  ws->tl_zero = 0;
  for (i = 0; i < NC; ++i) tlo[i] = NQ, thi[i] = -1, env[i] = i; /* env: S's first column per row, so far */
  memset(acp, 0, (NQ + 1) * sizeof(casadi_int));
#ifdef CONTACT_HAS_A
  for (k = 0; k < NNZ_A; ++k) { /* T = A M^-1 (row a_row[k] += A_k * row a_col[k] of M^-1) */
    const casadi_real aij = ws->K[a_nz[k]], *m = minv + a_col[k] * NQ;
    casadi_real *t = T + a_row[k] * NQ;
    for (j = minv_colind[a_col[k]]; j < minv_colind[a_col[k] + 1]; ++j) {
      const int c = minv_row[j];
      t[c] += aij * m[c];
      if (c < tlo[a_row[k]]) tlo[a_row[k]] = c;
      if (c > thi[a_row[k]]) thi[a_row[k]] = c;
    }
  }
  for (k = 0; k < NNZ_A; ++k) ++acp[a_col[k] + 1]; /* A's nonzeros by columns: ak[acp[c] ..] */
  for (i = 0; i < NQ; ++i) acp[i + 1] += acp[i];
  for (k = 0; k < NNZ_A; ++k) ak[acp[a_col[k]]++] = k;
  for (i = NQ; i > 0; --i) acp[i] = acp[i - 1];
  acp[0] = 0;
  for (i = 0; i < NC; ++i) /* S = T A^T: S_ij += T_ic A_jc along row i of T */
    for (j = (int) tlo[i]; j <= thi[i]; ++j) {
      const casadi_real tij = T[i * NQ + j];
      if (tij != 0)
        for (k = (int) acp[j]; k < acp[j + 1]; ++k)
          if (a_row[ak[k]] <= i) { /* lower triangle */
            L[i + a_row[ak[k]] * NC] += tij * ws->K[a_nz[ak[k]]];
            if (a_row[ak[k]] < env[i]) env[i] = a_row[ak[k]];
          }
    }
#endif
  for (i = 0; i < NC; ++i) { /* Cholesky by rows, lower triangle of L in place, in S's envelope */
    casadi_real d, s0 = L[i + i * NC];
    int f = (int) env[i]; /* S's structural first column: its first nonzero is at or after it */
    while (f < i && L[i + f * NC] == 0) ++f;
    env[i] = f;
    for (j = f; j < i; ++j) {
      casadi_real v = L[i + j * NC];
      for (k = f > env[j] ? f : (int) env[j]; k < j; ++k) v -= L[i + k * NC] * L[j + k * NC];
      L[i + j * NC] = v / L[j + j * NC];
    }
    d = s0;
    for (k = f; k < i; ++k) d -= L[i + k * NC] * L[i + k * NC];
    if (!(d > 1e-12 * s0)) { /* T and L not cleared by ranges next time */
      ws->schur = 0;
      return delassus_kkt(ws, rows, n);
    }
    L[i + i * NC] = sqrt(d);
  }
  ws->schur = 1;
  ws->tl_zero = 1;
  for (i = NC - 1; i >= 0; --i) /* the smallest envelope start of rows i .. NC - 1 */
    emin[i] = i + 1 < NC && emin[i + 1] < env[i] ? emin[i + 1] : env[i];
  for (a = 0; a < n; ++a) {
    casadi_real *ba = B + a * NQ, *za = Z + a * NC, *ya = Y + a * NC;
    int blo = NQ, bhi = -1, zmax = -1, ylo;
    memset(ba, 0, NQ * sizeof(casadi_real));
    for (k = wt_colind[rows[a]]; k < wt_colind[rows[a] + 1]; ++k) { /* B_a = M^-1 W_r^T */
      const casadi_real w = ws->W[k], *m = minv + wt_row[k] * NQ;
      for (j = minv_colind[wt_row[k]]; j < minv_colind[wt_row[k] + 1]; ++j) {
        ba[minv_row[j]] += w * m[minv_row[j]];
        if (minv_row[j] < blo) blo = minv_row[j];
        if (minv_row[j] > bhi) bhi = minv_row[j];
      }
    }
    bfirst[a] = blo, blast[a] = bhi;
    memset(za, 0, NC * sizeof(casadi_real));
    zlo[a] = NC, zhi[a] = -1;
#ifdef CONTACT_HAS_A
    for (j = blo; j <= bhi; ++j) /* A B_a, by A's columns */
      if (ba[j] != 0)
        for (k = (int) acp[j]; k < acp[j + 1]; ++k) {
          const casadi_int r = a_row[ak[k]];
          za[r] += ws->K[a_nz[ak[k]]] * ba[j];
          if (r < zlo[a]) zlo[a] = r;
          if (r > zmax) zmax = (int) r;
        }
#else
    (void) acp, (void) ak;
#endif
    /* Z_a = L^-1 A B_a from its first nonzero; row i stays zero where A B_a's is and its
     * envelope starts after the last nonzero so far (free bodies: Z_a within their blocks),
     * and so does every row after i once A B_a's are all zero there and no envelope from i
     * on starts at or before that nonzero (emin) */
    for (i = (int) zlo[a]; i < NC; ++i) {
      if (za[i] == 0 && env[i] > zhi[a]) {
        if (i > zmax && emin[i] > zhi[a]) break;
        continue;
      }
      for (k = (int) env[i]; k < i; ++k) za[i] -= L[i + k * NC] * za[k];
      za[i] /= L[i + i * NC];
      if (za[i] != 0) zhi[a] = i;
    }
    if (zhi[a] < 0) zlo[a] = NC;
    memcpy(ya, za, NC * sizeof(casadi_real));
    /* Y_a = L^-T Z_a, by columns of L^T, from Z_a's last nonzero down to the first row a
     * nonzero reached (ylo: rows below it stay zero) */
    for (ylo = (int) zlo[a], i = (int) zhi[a]; i >= ylo; --i)
      if (ya[i] != 0) {
        ya[i] /= L[i + i * NC];
        for (k = (int) env[i]; k < i; ++k) ya[k] -= L[i + k * NC] * ya[i];
        if (env[i] < ylo) ylo = (int) env[i];
      }
  }
  /* W's nonzeros of the active rows by columns: column i has rows cr[cp[i] .. cp[i + 1] - 1],
   * at positions ck[...] of ws->W */
  memset(cp, 0, (NQ + 1) * sizeof(casadi_int));
  for (a = 0; a < n; ++a)
    for (k = wt_colind[rows[a]]; k < wt_colind[rows[a] + 1]; ++k) ++cp[wt_row[k] + 1];
  for (i = 0; i < NQ; ++i) cp[i + 1] += cp[i];
  for (a = 0; a < n; ++a)
    for (k = wt_colind[rows[a]]; k < wt_colind[rows[a] + 1]; ++k) {
      const casadi_int at = cp[wt_row[k]]++;
      cr[at] = a, ck[at] = k;
    }
  for (i = NQ; i > 0; --i) cp[i] = cp[i - 1];
  cp[0] = 0;
  /* Z's nonzeros by rows of L: row i has the active rows zr[zp[i] .. zp[i + 1] - 1] */
  memset(zp, 0, (NC + 1) * sizeof(casadi_int));
  for (a = 0; a < n; ++a)
    for (i = (int) zlo[a]; i <= zhi[a]; ++i)
      if (Z[a * NC + i] != 0) ++zp[i + 1];
  for (i = 0; i < NC; ++i) zp[i + 1] += zp[i];
  for (a = 0; a < n; ++a)
    for (i = (int) zlo[a]; i <= zhi[a]; ++i)
      if (Z[a * NC + i] != 0) zr[zp[i]++] = a;
  for (i = NC; i > 0; --i) zp[i] = zp[i - 1];
  zp[0] = 0;
  /* G_ab = W_a B_b - Z_a . Z_b for a <= b: by B_b's nonzeros, then by Z_b's (the terms of the
   * dot product in ascending order, those with a zero factor left out) */
  for (b = 0; b < n; ++b) {
    const casadi_real *bb = B + b * NQ, *zb = Z + b * NC;
    casadi_real *gb = ws->G + b * n;
    memset(gb, 0, (size_t) (b + 1) * sizeof(casadi_real)); /* the lower triangle is written below */
    for (i = (int) bfirst[b]; i <= blast[b]; ++i)
      if (bb[i] != 0)
        for (k = (int) cp[i]; k < cp[i + 1] && cr[k] <= b; ++k) gb[cr[k]] += ws->W[ck[k]] * bb[i];
    for (i = (int) zlo[b]; i <= zhi[b]; ++i)
      if (zb[i] != 0)
        for (k = (int) zp[i]; k < zp[i + 1] && zr[k] <= b; ++k) gb[zr[k]] -= Z[zr[k] * NC + i] * zb[i];
  }
  for (a = 0; a < n; ++a) /* G symmetric (every entry checked here) */
    for (b = a; b < n; ++b) {
      const casadi_real s = ws->G[a + b * n];
      ws->G[b + a * n] = s;
      if (!isfinite(s)) finite = 0;
    }
  return finite ? STEP_OK : STEP_NOT_FINITE;
}

/* out += s X c for the columns X_a (a < n) of the last delassus(): X c = B c - T^T (Y c),
 * B_a between its first and last nonzero, Y_a up to Z_a's last. */
static void x_add(workspace *ws, int n, const casadi_real *c, casadi_real s, casadi_real *out) {
  const casadi_int *zhi = ws->cni + 2 * ND + NC + ND, *tlo = zhi + ND + NQ + 1 + 2 * NNZ_W, *thi = tlo + NC,
                   *bfirst = thi + NC + NQ + 1 + NNZ_A, *blast = bfirst + ND; /* delassus()'s */
  casadi_real y[NC + 1];
  int a, i, j;
  if (!ws->schur) {
    for (a = 0; a < n; ++a)
      for (i = 0; i < NQ; ++i) out[i] += s * ws->Xc[a * NQ + i] * c[a];
    return;
  }
  for (j = 0; j < NC; ++j) y[j] = 0;
  for (a = 0; a < n; ++a) {
    const casadi_real *ya = ws->Y + a * NC, *ba = ws->Xc + a * NQ;
    casadi_real ca = s * c[a];
    if (ca == 0) continue;
    for (i = (int) bfirst[a]; i <= blast[a]; ++i) out[i] += ca * ba[i];
    for (j = 0; j <= zhi[a]; ++j) y[j] += ca * ya[j];
  }
  for (j = 0; j < NC; ++j) { /* along row j of T between its first and last nonzero */
    const casadi_real *t = ws->T + j * NQ;
    if (y[j] != 0)
      for (i = (int) tlo[j]; i <= thi[j]; ++i) out[i] -= y[j] * t[i];
  }
}
#else

/* The generic Delassus matrix (the mass matrix is singular, or too large to invert). */
static int delassus(workspace *ws, const int *rows, int n) {
  return delassus_kkt(ws, rows, n);
}

/* out += s X c for the columns X_a (a < n) of the last delassus(). */
static void x_add(workspace *ws, int n, const casadi_real *c, casadi_real s, casadi_real *out) {
  int a, i;
  for (a = 0; a < n; ++a)
    for (i = 0; i < NQ; ++i) out[i] += s * ws->Xc[a * NQ + i] * c[a];
}
#endif

/* The work of the impulses of a step that took W0^T P in its first half and W^T P in its
 * second (rows by wt_colind, wt_row; P[a] acts on row rows[a], or on row r0 + a if rows is NULL):
 * the kinetic energy they add to RATTLE's step, exactly.  The first half's momentum balance
 * M (w - v) = ... + W0^T P / 2 adds W0^T P / 2 . (w + v) / 2 to 1/2 w^T M w - 1/2 v^T M v,
 * the second's W^T P / 2 . (v+ + w) / 2 (for an impact with fixed rows, 1/2 P . (U- + U+)
 * with w the mean of v and v+).  Normal rows into WORK_CONTACTS, tangent rows into
 * WORK_FRICTION, both into WORK_TOTAL. */
static void impulse_work(workspace *ws, const casadi_real *W0, const casadi_real *W, const int *rows, int r0, int n,
                         const casadi_real *P, const casadi_real *v, const casadi_real *v_next) {
  int a, i;
  for (a = 0; a < n; ++a) {
    int r = rows ? rows[a] : r0 + a;
    casadi_real s = 0, dw;
    if (P[a] == 0) continue;
    for (i = wt_colind[r]; i < wt_colind[r + 1]; ++i) {
      int c = wt_row[i];
      s += W0[i] * (v[c] + ws->x[c]) + W[i] * (ws->x[c] + v_next[c]);
    }
    dw = s * P[a] / 4;
    ws->step_work[r % DC ? WORK_FRICTION : WORK_CONTACTS] += dw;
    ws->step_work[WORK_TOTAL] += dw;
  }
}

/* E = T + V at (t, q, v) (KERNEL_OUTPUTS) into *E. */
static int energy(workspace *ws, casadi_real t, const casadi_real *q, const casadi_real *v, const casadi_real *p,
                  casadi_real *E) {
  ws->arg[0] = &t;
  ws->arg[1] = q;
  ws->arg[2] = v;
  ws->arg[3] = 0;
  ws->arg[4] = 0;
  ws->arg[5] = p;
  ws->res[0] = ws->y;
  if (KERNEL_OUTPUTS(ws->arg, ws->res, ws->iw, ws->w, 0)) return STEP_KERNEL;
  *E = ws->y[0] + ws->y[1];
  return STEP_OK;
}

/* Contacts that end the step inside (gap < -PENETRATION_TOL) are put back on their surface: the
 * displacement dq = sum_a X_a pi_a, smallest in the KKT metric, with pi >= 0 and the
 * linearised gaps g + G pi >= 0 _|_ pi of every contact within reach (gap below
 * PENETRATION_TOL + twice the deepest penetration; projected Gauss-Seidel on the normal rows
 * with lcp_newton() steps, to 1e-12 of the deepest gap); then
 * Newton back onto Phi = 0 and the velocities projected onto A v + Phi_t = 0.  A position
 * correction: it removes the penetration of the step an impact is resolved in (at most
 * h v / 2) and adds no momentum but the bilateral constraints'.  With ws->track_work the
 * energy E = T + V it changes goes into WORK_PUSH_OUT and WORK_TOTAL. */
static int push_out(const casadi_real *p, casadi_real t1, casadi_real *q_next, casadi_real *v_next,
                    const step_options *o, workspace *ws, int *pushed) {
  int i, a, k, n = 0, it, sweep, newton_at = NEWTON_FIRST, rows[NK];
  casadi_real one = 1, zero = 0, t0 = t1 - 1, deepest = 0, E0 = 0, E1;
  pairs_bounds(ws, q_next, 0);
  pairs_select(ws, 0, 0, 0);
  if (contact_gap(ws, q_next, p, ws->g)) return STEP_KERNEL;
  for (i = 0; i < ws->nkon; ++i)
    if (ws->g[k = ws->kon[i]] < -PENETRATION_TOL) {
      ++n;
      deepest = fmax(deepest, -ws->g[k]);
    }
  *pushed = n;
  if (!n) return STEP_OK;
  if (ws->track_work && energy(ws, t1, q_next, v_next, p, &E0)) return STEP_KERNEL;
  /* every contact within reach of the push (gap below twice the deepest penetration) takes
   * part, so that pushing one out pushes no other in (a column of spheres: else one pass
   * per sphere) */
  (void) pairs_extend(ws, PENETRATION_TOL + 2 * deepest);
  if (contact_rows(ws, q_next, v_next, p, ws->g, ws->W, 0, 1)) return STEP_KERNEL;
  for (n = i = 0; i < ws->nkon; ++i)
    if (ws->g[k = ws->kon[i]] < PENETRATION_TOL + 2 * deepest) rows[n++] = k * DC;
  /* ws->K holds [M A^T; A 0] at q_next (the last second half-step). */
  ws->fm = -1;
  if (contact_reserve(ws, n)) return STEP_BAD_INPUT; /* no memory for the solve */
  if ((k = delassus(ws, rows, n)) != STEP_OK) return k;
  g_pattern(ws, n);
  for (a = 0; a < n; ++a) {
    ws->P[a] = 0;
    ws->U[a] = ws->g[rows[a] / DC];
  }
  for (sweep = 0; sweep < PGS_MAX_ITER; ++sweep) {
    casadi_real change = 0;
    for (a = 0; a < n; ++a)
      if (ws->G[a + a * n] > 0)
        pgs_update(ws, n, a, fmax(0, ws->P[a] - ws->U[a] / ws->G[a + a * n]) - ws->P[a], &change);
    if (change <= PGS_TOL * (PENETRATION_TOL + deepest)) break; /* gaps to 1e-12 of the deepest */
    if (sweep + 1 == newton_at) {
      lcp_newton(ws, n, 0);
      newton_at *= 2;
    }
  }
  x_add(ws, n, ws->P, 1, q_next);
  /* Newton back onto Phi(t1, q) = 0: step_newton at (t1 - 1, q, w = 0, h = 1) gives Phi(t1, q) and
   * K = [M - 1/2 dF/dv, A^T; A(t1, q), 0]. */
  for (it = 0;; ++it) {
    ws->arg[0] = &t0;
    ws->arg[1] = q_next;
    ws->arg[2] = 0;
    ws->arg[3] = 0;
    ws->arg[4] = p;
    ws->arg[5] = &one;
    ws->arg[6] = 0;
    ws->arg[7] = 0;
    ws->arg[8] = 0;
    ws->res[0] = ws->r;
    ws->res[1] = ws->K;
    if (KERNEL_NEWTON(ws->arg, ws->res, ws->iw, ws->w, 0)) return STEP_KERNEL;
    if (norm_inf(ws->r + NQ, NC) <= o->tol) break;
    if (it == o->max_iter) return STEP_NO_CONVERGENCE;
    for (i = 0; i < NQ; ++i) ws->rhs[i] = 0;
    memcpy(ws->rhs + NQ, ws->r + NQ, NC * sizeof(casadi_real));
    if (solve(ws, ws->K, ws->rhs, ws->rhs + NX)) return STEP_KERNEL;
    if (!all_finite(ws->rhs + NX, NX)) return STEP_NOT_FINITE;
    for (i = 0; i < NQ; ++i) q_next[i] -= ws->rhs[NX + i];
  }
  /* velocities: [M A^T; A 0] [v; mu] = [M v_next; -Phi_t] (step_velocity with h = 0, j = 0) */
  ws->arg[0] = &t1;
  ws->arg[1] = q_next;
  ws->arg[2] = v_next;
  ws->arg[3] = 0;
  ws->arg[4] = p;
  ws->arg[5] = &zero;
  ws->arg[6] = 0;
  ws->res[0] = ws->rhs;
  ws->res[1] = ws->K;
  if (KERNEL_VELOCITY(ws->arg, ws->res, ws->iw, ws->w, 0)) return STEP_KERNEL;
  if (solve(ws, ws->K, ws->rhs, ws->rhs + NX)) return STEP_KERNEL;
  if (!all_finite(ws->rhs + NX, NQ)) return STEP_NOT_FINITE;
  memcpy(v_next, ws->rhs + NX, NQ * sizeof(casadi_real));
  if (ws->track_work) {
    if (energy(ws, t1, q_next, v_next, p, &E1)) return STEP_KERNEL;
    ws->step_work[WORK_PUSH_OUT] += E1 - E0;
    ws->step_work[WORK_TOTAL] += E1 - E0;
  }
  return STEP_OK;
}

/* Whether the impulses P (rows of contact k at P + k DC) satisfy, with the end-of-step
 * contact velocities U and those at the start Um, Newton's impact law and Coulomb's law
 * (the conditions pgs() solves) to tol (m/s). */
static int contact_laws_hold(int k, const casadi_real *P, const casadi_real *U, const casadi_real *Um,
                             casadi_real tol) {
  const casadi_real pn = P[k * DC], e = restitution[k];
  casadi_real vn = U[k * DC] + e * fmin(Um[k * DC], 0), pt = 0, vt = 0, dir = 0;
  int d;
  if (pn > 0 ? fabs(vn) > tol : vn < -tol) return 0;
  for (d = 1; d < DC; ++d) {
    casadi_real v = U[k * DC + d] + e * Um[k * DC + d];
    pt += P[k * DC + d] * P[k * DC + d];
    vt += v * v;
  }
  pt = sqrt(pt);
  vt = sqrt(vt);
  if (pt < mu[k] * pn * (1 - 1e-9)) return vt <= tol; /* inside the cone: sticking */
  for (d = 1; d < DC; ++d) { /* on its boundary: slipping against the friction impulse */
    casadi_real v = U[k * DC + d] + e * Um[k * DC + d] + (pt > 0 ? vt * P[k * DC + d] / pt : 0);
    dir += v * v;
  }
  return sqrt(dir) <= tol;
}

/* repeat_step()'s impulses P = h F on the rows of the contacts evaluated (every contact with
 * a force is: pairs_select(..., loaded = 1)). */
static void repeat_impulses(workspace *ws, casadi_real h) {
  int c, r;
  for (c = 0; c < ws->nkon; ++c)
    for (r = ws->kon[c] * DC; r < (ws->kon[c] + 1) * DC; ++r) ws->P[r] = h * ws->F[r];
}

/* j = W^T P over the rows of the contacts evaluated with an impulse (W: the nonzeros of the
 * contact Jacobian by rows, ws->P by contact rows), ascending. */
static void repeat_j(workspace *ws, const casadi_real *W) {
  int c, i, r;
  for (i = 0; i < NQ; ++i) ws->j[i] = 0;
  for (c = 0; c < ws->nkon; ++c)
    for (r = ws->kon[c] * DC; r < (ws->kon[c] + 1) * DC; ++r)
      if (ws->P[r] != 0)
        for (i = wt_colind[r]; i < wt_colind[r + 1]; ++i) ws->j[wt_row[i]] += W[i] * ws->P[r];
}

/* The last step's impulses h F again, with the contact Jacobian at the start of the step:
 * where the contact forces do not change (bodies at rest, sliding or rolling at constant
 * forces) they solve this step's contact problem, and contact_step()'s Delassus matrix and
 * solve are not needed.  contact_step() would close the contacts whose gap is <= 0 at the
 * end of the free step; that gap is estimated, linearised, as g - h/2 W_N X j (the impulse
 * j = W^T P moves the midpoint rates by X j / 2, X j = [M A^T; A 0]^-1 [j; 0]: one solve).
 * The contact laws are checked to tol = REPEAT_TOL (1 + max |U|) (U the end velocities).  A
 * loaded contact counts as closed up to a free gap of h/2 tol: closing that gap within the
 * step takes an end velocity of at most tol, the laws' tolerance, so contact_step()'s laws for
 * an open contact about to close cannot be told from a closed one's there (a resting face's
 * loaded corners end the free step at gaps of +-1e-16 m, round-off of coordinates of 0.1 m;
 * h/2 tol is 5e-16 m at h = 1 ms, 1.5e-14 m at 30 ms).
 * The step is kept (*kept = 1) if every contact with an impulse is closed in that sense and
 * every closed contact satisfies the contact laws on the measured end velocities
 * (contact_laws_hold() to tol); else the caller takes contact_step()'s way from the Newton
 * start saved here.  The impulses act along the rows at q in both halves;
 * if a loaded contact's rows moved by more than REPEAT_TOL (1 + max |W|) over the step
 * (rolling spheres: by omega h), the second half is taken again along the rows at q_next, as
 * contact_step() takes it along those at the free step's end (q_next does not change: the
 * first half's impulse is the same), before the laws are checked.  Tried only while it pays
 * (ws->repeat): after a step it kept, or whose contact solve found its warm start (the last
 * forces) already converged. */
static int repeat_step(const casadi_real *q, const casadi_real *v, casadi_real t, const casadi_real *u,
                       const casadi_real *p, casadi_real h, casadi_real *q_next, casadi_real *v_next,
                       casadi_real *lam, int *iterations, const step_options *o, int warm,
                       workspace *ws, int *kept) {
  casadi_real *W0 = ws->Wr, *P = ws->P, scale = 1, gap_tol = 0;
  int c, i, k, r, status, moved = 0, closed[NK];
  *kept = 0;
  if (iterations) *iterations = 0;
  if (!ws->repeat || !forces_any(ws, h)) return STEP_OK;
  memcpy(ws->rhs + 2 * NX, ws->x, NX * sizeof(casadi_real));
  pairs_bounds(ws, q, 0);
  pairs_select(ws, -INFINITY, 0, 1); /* the elements with a force */
  repeat_impulses(ws, h);
  if (contact_rows(ws, q, v, p, 0, W0, ws->Um, 1)) return STEP_KERNEL;
  repeat_j(ws, W0);
  memcpy(ws->j0, ws->j, NQ * sizeof(casadi_real)); /* the rows hardly move: kept only if so */
  status = step(q, v, t, u, p, h, q_next, v_next, lam, iterations, o, warm, ws);
  if (status == STEP_OK) {
    memcpy(ws->rhs, ws->j, NQ * sizeof(casadi_real)); /* X j, with ws->K = [M A^T; A 0] at q_next */
    for (i = NQ; i < NX; ++i) ws->rhs[i] = 0;
    if (solve(ws, ws->K, ws->rhs, ws->rhs + NX)) return STEP_KERNEL;
    /* the elements whose gaps g - h/2 W X j may be <= 0, and those with a force; at q too
     * (the start-of-step velocities of the contacts that close) */
    pairs_bounds(ws, q_next, ws->rhs + NX);
    pairs_select(ws, 0, h / 2, 1);
    repeat_impulses(ws, h); /* on the contacts evaluated now */
    if (contact_rows(ws, q_next, v_next, p, ws->g, ws->W, ws->U, 1)) return STEP_KERNEL;
#ifdef CONTACT_PAIRS
    if (contact_rows(ws, q, v, p, 0, W0, ws->Um, 1)) return STEP_KERNEL;
#endif
    scale += rows_norm_inf(ws, ws->U); /* the elements evaluated (with CONTACT_PAIRS) */
    gap_tol = fabs(h) / 2 * REPEAT_TOL * scale;
    *kept = all_finite(ws->rhs + NX, NQ);
    for (c = 0; c < ws->nkon && *kept; ++c) {
      casadi_real g_free = ws->g[k = ws->kon[c]];
      int loaded = 0, d;
      for (i = wt_colind[k * DC]; i < wt_colind[k * DC + 1]; ++i) g_free -= h / 2 * ws->W[i] * ws->rhs[NX + wt_row[i]];
      for (d = 0; d < DC; ++d) loaded = loaded || P[k * DC + d] != 0;
      closed[k] = !(g_free > (loaded ? gap_tol : 0));
      if (!closed[k]) {
        if (loaded) *kept = 0; /* contact_step() would leave it open */
        continue;
      }
      if (loaded && !moved) {
        casadi_real wmax = 0, dw = 0;
        for (i = wt_colind[k * DC]; i < wt_colind[(k + 1) * DC]; ++i) { /* the contact's rows */
          casadi_real w = fabs(W0[i]), e = fabs(ws->W[i] - W0[i]);
          if (w > wmax) wmax = w;
          dw = nan_max(dw, e);
        }
        moved = dw > REPEAT_TOL * (1 + wmax);
      }
    }
    if (*kept && moved) { /* the second half again along the rows at q_next (q_next stays) */
      int it = 0;
      repeat_j(ws, ws->W);
      status = step(q, v, t, u, p, h, q_next, v_next, lam, &it, o, 1, ws);
      if (iterations) *iterations += it;
      if (status != STEP_OK) *kept = 0;
      else if (contact_rows(ws, q_next, v_next, p, 0, 0, ws->U, 1)) return STEP_KERNEL;
      scale = 1 + rows_norm_inf(ws, ws->U);
    }
    for (c = 0; c < ws->nkon && *kept; ++c)
      if (closed[k = ws->kon[c]] && !contact_laws_hold(k, P, ws->U, ws->Um, REPEAT_TOL * scale)) *kept = 0;
  }
  if (*kept) {
    for (c = 0; c < ws->nkon; ++c) {
      for (r = (k = ws->kon[c]) * DC; r < (k + 1) * DC; ++r) {
        ws->Pacc[r] += P[r];
        if (P[r] != 0) impulse_summed(ws, k);
      }
      if (ws->track_work) impulse_work(ws, W0, moved ? ws->W : W0, 0, k * DC, DC, P + k * DC, v, v_next);
    }
    return STEP_OK;
  }
  ws->repeat = 0;
  memcpy(ws->x, ws->rhs + 2 * NX, NX * sizeof(casadi_real));
  return status == STEP_OK || recoverable(status) ? STEP_OK : status;
}

/* Contacts that end the step inside are put back on their surface (push_out(), repeated
 * while its linearisation leaves a gap below -PENETRATION_TOL, at most PUSH_OUT_MAX times).
 * The deepest penetration left goes into ws->penetration (the largest since cleared). */
static int push_out_all(const casadi_real *p, casadi_real t1, casadi_real *q_next, casadi_real *v_next,
                        const step_options *o, workspace *ws) {
  int status = STEP_OK, n, pushed = 1, i, k;
  for (n = 0; n < PUSH_OUT_MAX && pushed; ++n)
    if ((status = push_out(p, t1, q_next, v_next, o, ws, &pushed)) != STEP_OK) return status;
  if (pushed) { /* the last pass pushed: the gaps it left */
    pairs_bounds(ws, q_next, 0);
    pairs_select(ws, 0, 0, 0);
    if (contact_gap(ws, q_next, p, ws->g)) return STEP_KERNEL;
  }
  for (i = 0; i < ws->nkon; ++i) /* ws->g: the gaps at q_next (the contacts off: above 0) */
    if (-ws->g[k = ws->kon[i]] > ws->penetration) ws->penetration = -ws->g[k];
  return status;
}

/* One step with contacts: the free step, the contacts closed at its end (gap <= 0), their
 * impulses by pgs() on the Delassus matrix G = W [M A^T; A 0]^-1 W^T there, then the step
 * again with the generalised impulse W^T P, half of it in each half-step (W at the start of
 * the step in the first half, at the free step's end in the second).  Adds the
 * impulses to ws->Pacc. */
static int contact_step(const casadi_real *q, const casadi_real *v, casadi_real t, const casadi_real *u,
                        const casadi_real *p, casadi_real h, casadi_real *q_next, casadi_real *v_next,
                        casadi_real *lam, int *iterations, const step_options *o, int warm,
                        workspace *ws) {
  int i, a, c, k, na = 0, nr, it = 0, status, refine, impact = 0, converged = 1, kept, first[NK + 1];
  int *rows = ws->rowbuf; /* the active rows, rows[0..nr) */
  int near = 0; /* whether contacts about to close take part */
  casadi_real change = 0, residual = 0, law = 0, bias[NK];
  status = repeat_step(q, v, t, u, p, h, q_next, v_next, lam, &it, o, warm, ws, &kept);
  if (status != STEP_OK) return status;
  if (kept) {
    if (iterations) *iterations = it;
    return push_out_all(p, t + h, q_next, v_next, o, ws);
  }
  for (i = 0; i < 2 * NQ; ++i) ws->j[i] = 0; /* j and j0 */
  status = step(q, v, t, u, p, h, q_next, v_next, lam, iterations, o, warm, ws);
  if (iterations) *iterations += it;
  if (status != STEP_OK) return status;
  pairs_bounds(ws, q_next, 0);
  pairs_select(ws, 0, 0, 0);
  if (contact_gap(ws, q_next, p, ws->g)) return STEP_KERNEL;
  for (c = 0; c < ws->nkon; ++c)
    if (ws->g[k = ws->kon[c]] <= 0) ws->act[na++] = k;
  if (!na) { /* no contact closed: the free step stands */
    forces_clear(ws);
    return STEP_OK;
  }
  if (contact_rows(ws, q_next, v_next, p, 0, ws->W, ws->U, 1)) return STEP_KERNEL;
  /* Contacts about to close take part too.  The impulses move the end-of-step gaps by
   * h/2 (U - U_free), U_free the free step's contact velocities: the push of a closed
   * contact can close an open neighbour within the step (a pile, a column), and push_out()
   * would have to put it back after it.  A contact open at the end of the free
   * step (gap g > 0) with e = 0 and g < GAP_REACH h/2 max(-U_free,N of the closed contacts)
   * gets
   *   U_N >= min(0, U_free,N - 2 g / h),  i.e. bias b = max(0, 2 g / h - U_free,N) >= 0:
   * it may close within the step but does not pass its surface; as b >= 0, the impulses
   * still take kinetic energy out (1/2 P^T G P + P^T b >= 0 of it, linearised).  With
   * friction too: a ball resting on a crate resting on the floor falls with the crate in
   * the free step, their gap stays 0 to round-off, and left out at +1e-17 m while the floor
   * stopped the crate, the ball sank and got twice its weight the next step (0, 2 m g, 0,
   * ... per step).  Closed contacts: b = e min(U-_N, 0).  Both keep the last step's forces
   * as their warm start: a resting face's corners end the free step at gaps of +-1e-16 m,
   * and those at + started from no force made every other solve of a 10-box stack start
   * half its weight away, one of which cycled to the sweep cap and the stack fell. */
  {
    casadi_real reach = 0;
    for (a = 0; a < na; ++a) reach = fmax(reach, -ws->U[ws->act[a] * DC]);
    reach *= GAP_REACH * h / 2;
    /* the elements skipped whose gaps may be below the reach (their gaps, W and U) */
    if (pairs_extend(ws, reach) && contact_rows(ws, q_next, v_next, p, ws->g, ws->W, ws->U, 2)) return STEP_KERNEL;
    /* the contact Jacobian at the start of the step (the impulse of the first half-step), and
     * the contact velocities there (Newton's impact law) */
#ifdef ANY_RESTITUTION
    if (contact_rows(ws, q, v, p, 0, ws->W0, ws->Um, 1)) return STEP_KERNEL;
#else
    /* every restitution coefficient is 0: the start-of-step velocities are not needed */
    if (contact_rows(ws, q, v, p, 0, ws->W0, 0, 1)) return STEP_KERNEL;
    for (c = 0; c < ws->nkon; ++c)
      memset(ws->Um + ws->kon[c] * DC, 0, DC * sizeof(casadi_real));
#endif
    for (na = c = 0; c < ws->nkon; ++c) {
      const casadi_real g = ws->g[k = ws->kon[c]];
      if (g <= 0) bias[na] = restitution[k] * fmin(ws->Um[k * DC], 0);
      else if (restitution[k] == 0 && g < reach) {
        bias[na] = fmax(0, 2 * g / h - ws->U[k * DC]);
        near = 1;
      } else {
        memset(ws->F + k * DC, 0, DC * sizeof(casadi_real)); /* open: no force, no warm start */
        continue;
      }
      ws->act[na++] = k;
    }
    forces_clear_off(ws); /* the contacts not evaluated are open */
  }
  /* the rows of the active contacts: each its normal row, then its tangent rows if it has
   * friction (contact c's rows start at first[c]) */
  for (nr = a = 0; a < na; ++a) {
    k = (int) ws->act[a];
    first[a] = nr;
    rows[nr++] = k * DC;
    if (mu[k] > 0)
      for (i = 1; i < DC; ++i) rows[nr++] = k * DC + i;
  }
  first[na] = nr;
  for (a = 0; a < nr; ++a) ws->U[a] = ws->U[rows[a]]; /* compacted: row `a` <- contact row rows[a] >= a */
  /* ws->K holds [M A^T; A 0] at q_next (the free step's second half). */
  ws->fm = -1;
  if (contact_reserve(ws, nr)) return STEP_BAD_INPUT; /* no memory for the solve */
  if ((status = delassus(ws, rows, nr)) != STEP_OK) return status;
  g_pattern(ws, nr);
  for (a = 0; a < nr; ++a) {
    ws->P[a] = ws->Pold[a] = 0;
    ws->Um[ND + a] = ws->U[a]; /* the free step's contact velocities */
  }
  for (a = 0; a < nr; ++a) /* warm start: last step's forces */
    pgs_update(ws, nr, a, h * ws->F[rows[a]], &change);
  /* The step responds to the impulses only approximately as U_0 + G P (G is taken at the free
   * step's end, and a large impulse turns the members within the step).  After an impact (the
   * impulses change a contact velocity by more than CONTACT_IMPACT_STEPS steps of gravity):
   * solve, take the step, measure the contact velocities it ends with, correct U by the
   * difference, solve again. */
  for (refine = 0;; ++refine) {
    int solved = pgs(ws, na, first, bias);
    if (!solved && near) {
      /* rare: the biases of contacts about to close can make a redundant set inconsistent
       * (lcp_newton() then fights the sweeps); solve again without them (b = inf keeps their
       * impulse at 0), and push_out() puts them back if they end inside */
      for (a = 0; a < na; ++a)
        if (ws->g[ws->act[a]] > 0) bias[a] = INFINITY;
      near = 0;
      solved = pgs(ws, na, first, bias);
    }
    if (!solved && refine > 0) {
      /* the corrected problem has no solution (redundant contacts whose measured velocities
       * leave the range of G): keep the last step, taken with the previous impulses */
      memcpy(ws->P, ws->Pold, nr * sizeof(casadi_real));
      break;
    }
    converged = solved;
    residual = ws->pgs_last;
    law = cone_residual(ws, na, first, bias);
    if (refine == 0) ws->repeat = solved && ws->pgs_sweeps == 0; /* the warm start solved it */
    if (refine == 0) {
      casadi_real jump = 0;
      for (a = 0; a < nr; ++a) jump = fmax(jump, fabs(ws->U[a] - ws->Um[ND + a]));
      impact = jump > CONTACT_IMPACT_STEPS * GRAVITY_NORM * h;
    }
    /* j = W(q_free)^T P in the second half-step, j0 = W(q)^T P in the first: each half's
     * impulse along the rows where it acts, as RATTLE does with A^T (rows taken at the free
     * step's end in both halves leave a first-order error in sliding with spin) */
    for (i = 0; i < 2 * NQ; ++i) ws->j[i] = 0;
    for (a = 0; a < nr; ++a) {
      for (i = wt_colind[rows[a]]; i < wt_colind[rows[a] + 1]; ++i) {
        ws->j[wt_row[i]] += ws->W[i] * ws->P[a];
        ws->j0[wt_row[i]] += ws->W0[i] * ws->P[a];
      }
      ws->Pold[ND + a] = ws->P[a] - ws->Pold[a];
    }
    x_add(ws, nr, ws->Pold + ND, 0.5, ws->x); /* warm start: w moves by half the impulses' change */
    /* at least one Newton iteration: the warm start is linear in the impulses along the rows
     * at the free step's end, and misses the first half's rows W(q) by O(|W(q) - W| |P|),
     * O(omega h^2 mu g) when sliding with spin: below the step's tolerance at small h, that
     * would be accepted at every step (a drift of first order, growing as h falls) */
    ws->newton_once = 1;
    status = step(q, v, t, u, p, h, q_next, v_next, lam, &it, o, 1, ws);
    ws->newton_once = 0;
    if (iterations) *iterations += it;
    if (status != STEP_OK) return status;
    if (refine == CONTACT_REFINE_MAX || !impact) break;
    /* the contact velocities the step ends with */
    if (contact_rows(ws, q_next, v_next, p, 0, 0, ws->Um + ND, 1)) return STEP_KERNEL;
    {
      casadi_real off = 0, scale = 1;
      for (a = 0; a < nr; ++a) {
        off = fmax(off, fabs(ws->Um[ND + rows[a]] - ws->U[a]));
        scale = fmax(scale, fabs(ws->U[a]));
      }
      if (off <= CONTACT_REFINE_TOL * scale) break;
    }
    for (a = 0; a < nr; ++a) {
      ws->U[a] = ws->Um[ND + rows[a]];
      ws->Pold[a] = ws->P[a];
    }
  }
  for (a = 0; a < nr; ++a) {
    ws->Pacc[rows[a]] += ws->P[a];
    if (ws->P[a] != 0) impulse_summed(ws, rows[a] / DC);
    ws->F[rows[a]] = ws->P[a] / h;
  }
#ifdef CONTACT_PAIRS
  pairs_forces_set(ws);
#endif
  if (ws->track_work) impulse_work(ws, ws->W0, ws->W, rows, 0, nr, ws->P, v, v_next);
  if (!converged) {
    ++ws->pgs_unconverged;
    ws->pgs_residual = fmax(ws->pgs_residual, residual);
  }
  ws->cone_residual = nan_max(ws->cone_residual, law);
  return push_out_all(p, t + h, q_next, v_next, o, ws);
}

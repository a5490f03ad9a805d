/* The frictional contact problem of a step by a semismooth Newton method on the
 * Alart-Curnier function (cone_newton()), for the contact solve of ncgen_contact.h, its
 * least-norm solution (cone_min_norm()), and the residual of the contact laws
 * (cone_residual()).  Plain C99, model-independent; included
 * after ncgen_rattle.h and before ncgen_contact.h when NCGEN_CONTACTS is defined (the
 * defines it reads are listed at the top of ncgen_contact.h: NK, DC, mu, restitution).
 *
 * The problem (the one pgs() solves, docs/contact.md): na active contacts, contact c with
 * rows first[c] .. first[c + 1] - 1 (its normal row, then its tangent rows if it has
 * friction), end-of-step contact velocities U = U_0 + G P (linear in the impulses P; ws->U
 * holds U for ws->P), and
 *   U_N + b >= 0  _|_  P_N >= 0,        b = bias[c]
 *   |P_T| <= mu P_N, P_T = -mu P_N V_T / |V_T| if V_T != 0,   V_T = U_T + e U-_T
 * (U-_T = ws->Um of the contact).  With rho_N = 1 / G_NN and rho_T = 1 / max G_TT of the
 * contact, its Alart-Curnier function
 *   phi_N = P_N - max(0, P~_N),                  P~_N = P_N - rho_N (U_N + b)
 *   phi_T = P_T - proj_{|x| <= mu max(0, P~_N)} (P_T - rho_T V_T)
 * vanishes exactly at a solution (Alart and Curnier 1991).  phi is piecewise smooth in P;
 * cone_newton() takes Newton steps J dP = -phi with an element J of its generalised
 * Jacobian, solved by Gaussian elimination with row pivoting on J stored dense (it has the
 * sparsity of G: contacts couple through the members they share, and the elimination skips
 * the zeros), and a backtracking line search on |phi|^2 / 2.  Redundant contacts (a sphere
 * on three others) make J singular; an elimination column whose pivot falls below
 * CONE_PIVOT is dropped (its impulse change is 0) as lcp_newton() drops dependent rows: the
 * equations are consistent at a solution, and the others solve them.  Where that step gives
 * no descent, or had to be halved CONE_LM_AFTER times (a stack of boxes: eight coincident
 * corners per face),
 * the next is Levenberg-Marquardt's (cone_lm()).  A solution is then moved to the least-norm
 * member of its family where the support is statically indeterminate (cone_min_norm()). */

/* cone_newton(): Newton steps at most; line-search halvings at most per step; the pivot
 * (rows scaled by rho, so O(1) entries) below which an elimination column is dropped;
 * the Armijo constant of the line search; the residual (relative, as cone_residual())
 * accepted when Newton stalls short of its tolerance: redundant rows of a Delassus matrix
 * formed in floating point (G = W B - Z^T Z cancels where the bilateral constraints take
 * most of an impulse: a chain lying flat) are consistent only to about that, so no
 * impulses satisfy every row to 1e-12 there (measured: stalls between 1e-12 and 2e-10 on
 * the falling chain of benchmarks/contact.py). */
#define CONE_NEWTON_MAX 30
#define CONE_BACKTRACK 12
#define CONE_PIVOT 1e-9
#define CONE_ARMIJO 1e-4
#define CONE_FLOOR 1e-9
/* cone_newton(): halvings of a step after which the next is Levenberg-Marquardt's (Newton's
 * direction then makes little progress: a stack of boxes crawled at 1/256 steps). */
#define CONE_LM_AFTER 4

/* rho_N and rho_T of active contact c into rho (row r0 = first[c]: rho_N, r0 + 1: rho_T, if
 * the contact has friction; nr rows in all).  A zero diagonal (a contact the step cannot
 * move) gives 0. */
static void cone_scale(const workspace *ws, int nr, const int *first, int c, casadi_real *rho) {
  const int r0 = first[c], nt = first[c + 1] - r0 - 1;
  const casadi_real gnn = ws->G[r0 + r0 * nr];
  casadi_real gt = 0;
  int d;
  rho[r0] = gnn > 0 ? 1 / gnn : 0;
  for (d = 1; d <= nt; ++d) gt = fmax(gt, ws->G[(r0 + d) + (r0 + d) * nr]);
  for (d = 1; d <= nt; ++d) rho[r0 + d] = gt > 0 ? 1 / gt : 0;
}

/* cone_scale() of every active contact. */
static void cone_scales(const workspace *ws, int na, const int *first, casadi_real *rho) {
  int c;
  for (c = 0; c < na; ++c) cone_scale(ws, first[na], first, c, rho);
}

/* phi of contact c at the impulses P and velocities U (compact rows) into phi; if J is not
 * null, also the contact's rows of the generalised Jacobian dphi/dP into J (row-major,
 * nr x nr, rows r0 .. r0 + nt, written whole). */
static void cone_map(const workspace *ws, int nr, int c, const int *first, const casadi_real *bias,
                     const casadi_real *rho, const casadi_real *P, const casadi_real *U, casadi_real *phi,
                     casadi_real *J) {
  const int r0 = first[c], nt = first[c + 1] - r0 - 1, k = (int) ws->act[c];
  const casadi_real rn = rho[r0], pn_aug = P[r0] - rn * (U[r0] + bias[c]);
  const casadi_real *G = ws->G;
  casadi_real z[DC], vt[DC], zn = 0, radius, rt;
  int d, e, j;
  if (J)
    for (d = 0; d <= nt; ++d) memset(J + (size_t) (r0 + d) * nr, 0, (size_t) nr * sizeof(casadi_real));
  /* normal row: rho_N (U_N + b) where the contact is closed, P_N where open */
  if (pn_aug > 0) {
    phi[r0] = rn * (U[r0] + bias[c]);
    if (J)
      for (j = (int) ws->gp[r0]; j < ws->gp[r0 + 1]; ++j) J[(size_t) r0 * nr + ws->gi[j]] = rn * G[ws->gi[j] + r0 * nr];
  } else {
    phi[r0] = P[r0];
    if (J) J[(size_t) r0 * nr + r0] = 1;
  }
  if (!nt) return;
  rt = rho[r0 + 1];
  radius = mu[k] * fmax(0, pn_aug);
  for (d = 1; d <= nt; ++d) {
    vt[d] = rt * (U[r0 + d] + restitution[k] * ws->Um[k * DC + d]);
    z[d] = P[r0 + d] - vt[d];
    zn += z[d] * z[d];
  }
  zn = sqrt(zn);
  if (radius == 0) { /* open (or on the cone's apex): P_T = 0 */
    for (d = 1; d <= nt; ++d) {
      phi[r0 + d] = P[r0 + d];
      if (J) J[(size_t) (r0 + d) * nr + r0 + d] = 1;
    }
    return;
  }
  if (zn <= radius) { /* sticking: V_T = 0 */
    for (d = 1; d <= nt; ++d) {
      phi[r0 + d] = vt[d];
      if (J)
        for (j = (int) ws->gp[r0 + d]; j < ws->gp[r0 + d + 1]; ++j)
          J[(size_t) (r0 + d) * nr + ws->gi[j]] = rt * G[ws->gi[j] + (r0 + d) * nr];
    }
    return;
  }
  /* slipping: phi_T = P_T - radius zhat; with s = radius / |z| and Q = I - zhat zhat^T,
   * dphi_T = dP_T - zhat d(radius) - s Q dz,  dz = dP_T - rho_T G_T dP,
   * d(radius) = mu (dP_N - rho_N G_N dP) */
  for (d = 1; d <= nt; ++d) phi[r0 + d] = P[r0 + d] - radius * z[d] / zn;
  if (!J) return;
  {
    const casadi_real s = radius / zn;
    for (d = 1; d <= nt; ++d) {
      casadi_real *row = J + (size_t) (r0 + d) * nr, zd = z[d] / zn;
      for (e = 1; e <= nt; ++e) {
        const casadi_real q = (d == e) - zd * z[e] / zn; /* Q_de */
        row[r0 + e] += (d == e) - s * q;
        for (j = (int) ws->gp[r0 + e]; j < ws->gp[r0 + e + 1]; ++j)
          row[ws->gi[j]] += s * q * rt * G[ws->gi[j] + (r0 + e) * nr];
      }
      row[r0] -= mu[k] * zd;
      for (j = (int) ws->gp[r0]; j < ws->gp[r0 + 1]; ++j) row[ws->gi[j]] += mu[k] * zd * rn * G[ws->gi[j] + r0 * nr];
    }
  }
}

/* phi of every active contact at (P, U) into phi (J as in cone_map()); returns |phi|^2 / 2. */
static casadi_real cone_phi(const workspace *ws, int na, const int *first, const casadi_real *bias,
                            const casadi_real *rho, const casadi_real *P, const casadi_real *U, casadi_real *phi,
                            casadi_real *J) {
  int nr = first[na], c, r;
  casadi_real theta = 0;
  for (c = 0; c < na; ++c) cone_map(ws, nr, c, first, bias, rho, P, U, phi, J);
  for (r = 0; r < nr; ++r) theta += phi[r] * phi[r];
  return theta / 2;
}

/* The contact laws' residual at ws->P, ws->U: max over the rows of |phi| / rho (m/s: by how
 * much a contact velocity misses its law), relative to 1 + max |U|. */
static casadi_real cone_residual(workspace *ws, int na, const int *first, const casadi_real *bias) {
  int nr = first[na], r;
  casadi_real *rho = ws->cn, *phi = ws->cn + ND, res = 0, size = 0;
  cone_scales(ws, na, first, rho);
  cone_phi(ws, na, first, bias, rho, ws->P, ws->U, phi, 0);
  for (r = 0; r < nr; ++r) {
    if (rho[r] > 0) res = nan_max(res, fabs(phi[r]) / rho[r]);
    size = fmax(size, fabs(ws->U[r]));
  }
  return res / (1 + size);
}

/* x = J^-1 b (J: m x m, row-major, destroyed; b: destroyed) by Gaussian elimination with
 * row pivoting, skipping zeros (J has the sparsity of G); a column whose largest pivot
 * candidate is below CONE_PIVOT is dropped (x = 0 there, its row left out).  Returns 0 if
 * a result is not finite. */
static int cone_solve(casadi_real *J, casadi_real *b, casadi_real *x, int m, casadi_int *cols, casadi_int *dropped) {
  int i, j, k, n;
  for (k = 0; k < m; ++k) {
    casadi_real *rk, best = 0, piv;
    int p = -1;
    for (i = k; i < m; ++i) { /* the diagonal unless another row is 10x larger (less fill) */
      const casadi_real a = fabs(J[(size_t) i * m + k]);
      if (a > best) best = a, p = i;
    }
    dropped[k] = !(best > CONE_PIVOT);
    if (dropped[k]) continue;
    if (fabs(J[(size_t) k * m + k]) >= 0.1 * best) p = k;
    if (p != k) {
      casadi_real t;
      for (j = k; j < m; ++j) {
        t = J[(size_t) k * m + j], J[(size_t) k * m + j] = J[(size_t) p * m + j], J[(size_t) p * m + j] = t;
      }
      t = b[k], b[k] = b[p], b[p] = t;
    }
    rk = J + (size_t) k * m;
    piv = rk[k];
    for (n = 0, j = k + 1; j < m; ++j)
      if (rk[j] != 0) cols[n++] = j;
    for (i = k + 1; i < m; ++i) {
      casadi_real *ri = J + (size_t) i * m, l;
      if (ri[k] == 0) continue;
      l = ri[k] / piv;
      ri[k] = 0;
      for (j = 0; j < n; ++j) ri[cols[j]] -= l * rk[cols[j]];
      b[i] -= l * b[k];
    }
  }
  for (k = m - 1; k >= 0; --k) {
    const casadi_real *rk = J + (size_t) k * m;
    casadi_real s = b[k];
    if (dropped[k]) {
      x[k] = 0;
      continue;
    }
    for (j = k + 1; j < m; ++j)
      if (rk[j] != 0) s -= rk[j] * x[j];
    x[k] = s / rk[k];
    if (!isfinite(x[k])) return 0;
  }
  return 1;
}

/* The Levenberg-Marquardt step (J^T J + lambda I) dP = -J^T phi, lambda = |phi| (Yamashita and
 * Fukushima: quadratic convergence also where the solutions are not isolated, as with
 * redundant contacts), with J in J (m x m, row-major) and its Gram matrix formed in H (m x m,
 * destroyed) and factored by Cholesky within its envelope (J has the sparsity of G, and so
 * has H that of G^2; the terms skipped are zeros); g gets J^T phi; cols and start: scratch (m
 * each).  A descent direction of |phi|^2 / 2 wherever Newton's step J^-1 is not one (J
 * singular or nearly so).  Returns 0 if a result is not finite. */
static int cone_lm(const casadi_real *J, const casadi_real *phi, casadi_real *H, casadi_real *g, casadi_real *dP, int m,
                   casadi_int *cols, casadi_int *start) {
  casadi_real lambda = 0;
  int i, j, k, n;
  for (i = 0; i < m; ++i) lambda += phi[i] * phi[i];
  lambda = sqrt(lambda);
  for (i = 0; i < m * m; ++i) H[i] = 0;
  for (i = 0; i < m; ++i) g[i] = 0;
  for (i = 0; i < m; ++i) start[i] = i; /* the first nonzero column of row i of H */
  for (k = 0; k < m; ++k) { /* H += J_k^T J_k row by row, lower triangle, over J_k's nonzeros */
    const casadi_real *jk = J + (size_t) k * m;
    for (n = i = 0; i < m; ++i)
      if (jk[i] != 0) cols[n++] = i;
    for (i = 0; i < n; ++i) {
      const int a = (int) cols[i];
      casadi_real *ha = H + (size_t) a * m;
      g[a] += jk[a] * phi[k];
      if (cols[0] < start[a]) start[a] = cols[0];
      for (j = 0; j <= i; ++j) ha[cols[j]] += jk[a] * jk[cols[j]];
    }
  }
  /* Cholesky, lower triangle in place; row i of the factor is zero left of row i of H's
   * first nonzero, and the products skip those zeros */
  for (i = 0; i < m; ++i) {
    casadi_real *hi = H + (size_t) i * m, d;
    const int f = (int) start[i];
    hi[i] += lambda;
    for (j = f; j < i; ++j) {
      const casadi_real *hj = H + (size_t) j * m;
      casadi_real v = hi[j];
      for (k = f > start[j] ? f : (int) start[j]; k < j; ++k) v -= hi[k] * hj[k];
      hi[j] = v / hj[j];
    }
    d = hi[i];
    for (k = f; k < i; ++k) d -= hi[k] * hi[k];
    if (!(d > 0)) return 0;
    hi[i] = sqrt(d);
  }
  for (i = 0; i < m; ++i) { /* L y = -g */
    const casadi_real *hi = H + (size_t) i * m;
    casadi_real v = -g[i];
    for (k = (int) start[i]; k < i; ++k) v -= hi[k] * dP[k];
    dP[i] = v / hi[i];
  }
  for (i = m - 1; i >= 0; --i) { /* L^T dP = y */
    const casadi_real *hi = H + (size_t) i * m;
    dP[i] /= hi[i];
    if (!isfinite(dP[i])) return 0;
    for (k = (int) start[i]; k < i; ++k) dP[k] -= hi[k] * dP[i];
  }
  return 1;
}

/* Semismooth Newton on the Alart-Curnier function from the impulses in ws->P (velocities
 * ws->U; the last step's impulses, after a few sweeps of pgs()), until every contact law
 * holds to tol (1 + max |U|) m/s (cone_residual()), or it stalls below CONE_FLOOR.  ws->P
 * and ws->U are updated by each accepted step.  Returns whether it converged; if not, ws->P
 * and ws->U are put back as they were (pgs() carries on as without it); *residual gets the
 * last residual.  Overwrites ws->S (lcp_newton()'s factor:
 * ws->fm = -1). */
static int cone_newton(workspace *ws, int na, const int *first, const casadi_real *bias, casadi_real tol,
                       casadi_real *residual) {
  const int nr = first[na];
  casadi_real *rho = ws->cn, *phi = ws->cn + ND, *dP = ws->cn + 2 * ND, *gdp = ws->cn + 3 * ND;
  casadi_real *Pt = ws->cn + 4 * ND, *Ut = ws->cn + 5 * ND, *P0 = ws->cn + 6 * ND, *U0 = ws->cn + 7 * ND, *J = ws->S;
  casadi_int *cols = ws->cni, *dropped = ws->cni + ND;
  int it, r, a, k, i = 0, lm, damped = 0;
  casadi_real theta;
  ws->fm = -1;
  memcpy(P0, ws->P, (size_t) nr * sizeof(casadi_real));
  memcpy(U0, ws->U, (size_t) nr * sizeof(casadi_real));
  cone_scales(ws, na, first, rho);
  theta = cone_phi(ws, na, first, bias, rho, ws->P, ws->U, phi, J);
  for (it = 0;; ++it) {
    casadi_real res = 0, size = 0, step = 1, theta_t = theta;
    for (r = 0; r < nr; ++r) {
      if (rho[r] > 0) res = nan_max(res, fabs(phi[r]) / rho[r]);
      size = fmax(size, fabs(ws->U[r]));
    }
    *residual = res / (1 + size);
    if (*residual <= tol) return 1;
    if (it == CONE_NEWTON_MAX || !isfinite(*residual)) break;
    for (lm = damped; lm < 2; ++lm) { /* Newton's step, then Levenberg-Marquardt's if it gives no
                                         descent; Levenberg-Marquardt's alone after a step
                                         halved CONE_LM_AFTER times or more */
      casadi_real slope = -2 * theta; /* d theta / d step at 0 */
      if (!lm) {
        for (r = 0; r < nr; ++r) phi[r] = -phi[r];
        if (!cone_solve(J, phi, dP, nr, cols, dropped)) continue;
      } else {
        theta = cone_phi(ws, na, first, bias, rho, ws->P, ws->U, phi, J);
        if (!cone_lm(J, phi, ws->S2, gdp, dP, nr, cols, dropped)) {
          lm = 2;
          break;
        }
        for (slope = 0, r = 0; r < nr; ++r) slope += gdp[r] * dP[r];
      }
      for (r = 0; r < nr; ++r) gdp[r] = 0; /* G dP, by G's column nonzeros */
      for (a = 0; a < nr; ++a)
        if (dP[a] != 0)
          for (k = (int) ws->gp[a]; k < ws->gp[a + 1]; ++k) gdp[ws->gi[k]] += ws->G[ws->gi[k] + a * nr] * dP[a];
      for (i = 0, step = 1; i < CONE_BACKTRACK; ++i, step /= 2) {
        for (r = 0; r < nr; ++r) {
          Pt[r] = ws->P[r] + step * dP[r];
          Ut[r] = ws->U[r] + step * gdp[r];
        }
        theta_t = cone_phi(ws, na, first, bias, rho, Pt, Ut, phi, 0);
        if (theta_t <= theta + CONE_ARMIJO * step * slope) break;
      }
      if (i < CONE_BACKTRACK) break;
    }
    if (lm == 2) break; /* no descent: stalled at round-off, or lost */
    damped = i >= CONE_LM_AFTER;
    memcpy(ws->P, Pt, (size_t) nr * sizeof(casadi_real));
    memcpy(ws->U, Ut, (size_t) nr * sizeof(casadi_real));
    theta = cone_phi(ws, na, first, bias, rho, ws->P, ws->U, phi, J);
  }
  if (*residual <= CONE_FLOOR) return 1;
  memcpy(ws->P, P0, (size_t) nr * sizeof(casadi_real)); /* failed: the impulses it started from */
  memcpy(ws->U, U0, (size_t) nr * sizeof(casadi_real));
  return 0;
}

/* The groups of coupled contacts: contacts c and d are in one group if G couples a row of
 * one to a row of the other (they share a member, or members that constraints link), or a
 * chain of such couplings joins them.  grp[c] gets the smallest contact of c's group. */
static void cone_groups(const workspace *ws, int na, const int *first, int *grp) {
  int owner[ND], c, r, k;
  for (c = 0; c < na; ++c) {
    grp[c] = c;
    for (r = first[c]; r < first[c + 1]; ++r) owner[r] = c;
  }
  for (r = 0; r < first[na]; ++r)
    for (k = (int) ws->gp[r]; k < ws->gp[r + 1]; ++k) { /* union of the roots, the smaller the root */
      int a = owner[r], b = owner[ws->gi[k]];
      while (grp[a] != a) a = grp[a] = grp[grp[a]];
      while (grp[b] != b) b = grp[b] = grp[grp[b]];
      if (a < b) grp[b] = a;
      else grp[a] = b;
    }
  for (c = 0; c < na; ++c) grp[c] = grp[grp[c]]; /* roots are smaller: one pass flattens */
}

/* Whether the impulses P + t dP of the contacts in the move (in[a] for contact mem[a]) are
 * all in their cones: a normal impulse > 0, or = 0 with no tangent impulse (a touching
 * contact that carried none and is given none). */
static int cone_inside(const workspace *ws, const int *first, const int *mem, int nm, const int *in,
                       const casadi_real *dP, casadi_real t) {
  int a, d;
  for (a = 0; a < nm; ++a) {
    const int c = mem[a], r0 = first[c], nt = first[c + 1] - r0 - 1;
    const casadi_real pn = ws->P[r0] + t * dP[r0];
    casadi_real pt = 0;
    if (!in[a]) continue;
    for (d = 1; d <= nt; ++d) pt += (ws->P[r0 + d] + t * dP[r0 + d]) * (ws->P[r0 + d] + t * dP[r0 + d]);
    if (pn == 0 && pt == 0) continue;
    if (!(pn > 0) || sqrt(pt) > mu[ws->act[c]] * pn) return 0;
  }
  return 1;
}

/* cone_residual() over the contacts mem[0 .. nm - 1] alone, relative to 1 + size. */
static casadi_real cone_residual_of(workspace *ws, int nr, const int *first, const casadi_real *bias, const int *mem,
                                    int nm, casadi_real size) {
  casadi_real *rho = ws->cn, *phi = ws->cn + ND, res = 0;
  int a, r;
  for (a = 0; a < nm; ++a) {
    const int c = mem[a];
    cone_scale(ws, nr, first, c, rho);
    cone_map(ws, nr, c, first, bias, rho, ws->P, ws->U, phi, 0);
    for (r = first[c]; r < first[c + 1]; ++r)
      if (rho[r] > 0) res = nan_max(res, fabs(phi[r]) / rho[r]);
  }
  return res / (1 + size);
}

/* Columns k .. k + 3 of the m x r matrix C (column-major) -= b v (v . column) for
 * v = (0, ..., 0, 1, C[j + 1 .. m - 1, j]) (its 1 at j): the four dot products side by side,
 * each summed in the order of the one-column loop of cone_qr() (the same bits), so that
 * they do not wait on one another's additions. */
static void cone_reflect4(casadi_real *C, int m, int j, int k, casadi_real b) {
  const casadi_real *cj = C + (size_t) j * m;
  casadi_real *c0 = C + (size_t) k * m, *c1 = c0 + m, *c2 = c1 + m, *c3 = c2 + m;
  casadi_real w0 = c0[j], w1 = c1[j], w2 = c2[j], w3 = c3[j];
  int i;
  for (i = j + 1; i < m; ++i) {
    const casadi_real v = cj[i];
    w0 += v * c0[i];
    w1 += v * c1[i];
    w2 += v * c2[i];
    w3 += v * c3[i];
  }
  w0 *= b, w1 *= b, w2 *= b, w3 *= b;
  c0[j] -= w0, c1[j] -= w1, c2[j] -= w2, c3[j] -= w3;
  for (i = j + 1; i < m; ++i) {
    const casadi_real v = cj[i];
    c0[i] -= w0 * v;
    c1[i] -= w1 * v;
    c2[i] -= w2 * v;
    c3[i] -= w3 * v;
  }
}

/* Householder QR of the m x r matrix C (column-major, full column rank, r <= m) in place:
 * reflection j is H_j = I - beta[j] v_j v_j^T with v_j = (0, ..., 0, 1, C[j + 1 .. m - 1, j])
 * (its 1 at j), and R on and above the diagonal; Q = H_0 H_1 ... H_{r-1}.  The columns after
 * j take reflection j four at a time (cone_reflect4()). */
static void cone_qr(casadi_real *C, int m, int r, casadi_real *beta) {
  int i, j, k;
  for (j = 0; j < r; ++j) {
    casadi_real *cj = C + (size_t) j * m, sigma = 0, alpha = cj[j], norm, v0;
    for (i = j + 1; i < m; ++i) sigma += cj[i] * cj[i];
    if (sigma == 0) { /* already upper triangular in this column: H_j = I */
      beta[j] = 0;
      continue;
    }
    norm = sqrt(alpha * alpha + sigma);
    v0 = alpha <= 0 ? alpha - norm : -sigma / (alpha + norm); /* no cancellation */
    beta[j] = 2 * v0 * v0 / (sigma + v0 * v0);
    for (i = j + 1; i < m; ++i) cj[i] /= v0;
    cj[j] = norm;
    for (k = j + 1; k + 4 <= r; k += 4) cone_reflect4(C, m, j, k, beta[j]);
    for (; k < r; ++k) { /* column k -= beta v (v . column k) */
      casadi_real *ck = C + (size_t) k * m, w = ck[j];
      for (i = j + 1; i < m; ++i) w += cj[i] * ck[i];
      w *= beta[j];
      ck[j] -= w;
      for (i = j + 1; i < m; ++i) ck[i] -= w * cj[i];
    }
  }
}

/* x = H_j x for reflection j of cone_qr() (C, m as there; H_j is its own inverse). */
static void cone_reflect(const casadi_real *C, int m, int j, casadi_real beta, casadi_real *x) {
  const casadi_real *cj = C + (size_t) j * m;
  casadi_real w = x[j];
  int i;
  if (beta == 0) return;
  for (i = j + 1; i < m; ++i) w += cj[i] * x[i];
  w *= beta;
  x[j] -= w;
  for (i = j + 1; i < m; ++i) x[i] -= w * cj[i];
}

/* Where the support is statically indeterminate (a box's four coplanar corners, a stack's
 * faces) the contact laws hold on a whole family P + null(G_AA) of impulses: this picks its
 * member of least Euclidean norm |P|, so that symmetric loads get symmetric forces.  A = the
 * rows of the contacts of one group (cone_groups()) with an impulse and, with
 * `touching`, of its closed contacts without one whose normal and tangent velocities vanish
 * (below CONE_FLOOR (1 + max |U|)): the laws let those carry a load too, and a solve that
 * happened to leave one of four symmetric corners at 0 would otherwise keep it there and
 * load the others unevenly.  Each contact of A with an impulse must stick (tangent velocity
 * below that floor) or have no friction (a slipping contact's tangent impulse is fixed by
 * its normal one: then nothing is done for the group).
 * G_AA = L L^T by Cholesky with the rows whose pivot falls below CONE_PIVOT of their
 * diagonal dropped (their columns of L zero), so range(G_AA) = range(L_K), L_K the m x r
 * kept columns of L (full column rank: its kept rows are triangular with nonzero pivots);
 * L_K = Q R by Householder reflections (cone_qr()), and the move is -P_A's part in the
 * null space, dP_A = -Q_2 Q_2^T P_A (Q_2 the last m - r columns of Q: range(L_K)'s
 * orthogonal complement, null(G_AA)).  This is what m - r null vectors orthonormalised by
 * Gram-Schmidt would give, to round-off, in about a third of the work where r << m (a
 * pyramid of boxes: 192 rows on 60 degrees of freedom).  Then P += t dP with
 * t = 1 or, if that leaves a cone (a contact on its cone's edge), the first of t = 1/2,
 * 1/4, ... that does not (the cones are convex: a step towards the least norm).  Kept only
 * if the contact laws hold as well as before (G dP is not exactly 0 where the rows are only
 * nearly dependent).  Returns 0 if a move over touching contacts without impulse left the
 * cones at every t or broke the laws (the impulses are then unchanged), else 1.  The group's
 * contacts are mem[0 .. nm - 1] (ascending), its rows rows[0 .. nr_g - 1]; size = max |U|;
 * the work is that of the group alone.  Uses ws->S (both halves; ws->fm = -1), ws->cni +
 * ND and ws->cn after its first 2 ND. */
static int cone_min_norm_over(workspace *ws, int nr, const int *first, const casadi_real *bias, casadi_real tol,
                              const int *mem, int nm, const int *rows, int nr_g, casadi_real size, int touching) {
  casadi_real *L = ws->S, *C = ws->S2, *dP = ws->cn + 2 * ND, *gdp = ws->cn + 3 * ND;
  casadi_real *beta = ws->cn + 4 * ND, *z = ws->cn + 5 * ND, *P0 = ws->cn + 6 * ND, *U0 = ws->cn + 7 * ND;
  casadi_int *dropped = ws->cni + ND, *start = ws->cni;
  casadi_real before, after, t = 1;
  int idx[ND], in[NK], m = 0, nd = 0, nz = 0, a, c, d, i, j, k, r, pass;
  for (a = 0; a < nm; ++a) {
    const int r0 = first[mem[a]], nt = first[mem[a] + 1] - r0 - 1, kc = (int) ws->act[mem[a]];
    casadi_real pt = 0, vt = 0;
    c = mem[a];
    in[a] = 0;
    for (d = 1; d <= nt; ++d) {
      const casadi_real v = ws->U[r0 + d] + restitution[kc] * ws->Um[kc * DC + d];
      pt += ws->P[r0 + d] * ws->P[r0 + d];
      vt += v * v;
    }
    if (ws->P[r0] <= 0) {
      if (pt > 0) return 1;
      if (!touching || fabs(ws->U[r0] + bias[c]) > CONE_FLOOR * (1 + size) || sqrt(vt) > CONE_FLOOR * (1 + size))
        continue;
      ++nz;
    } else if (sqrt(vt) > CONE_FLOOR * (1 + size)) return 1; /* slipping */
    in[a] = 1;
    for (d = 0; d <= nt; ++d) idx[m++] = r0 + d;
  }
  if (m < 2) return 1;
  ws->fm = -1;
  for (i = 0; i < m; ++i) { /* Cholesky by rows in L (row i at L + i m), in G_AA's envelope */
    casadi_real *li = L + (size_t) i * m, s, d0;
    int f = 0;
    for (j = 0; j <= i; ++j) li[j] = ws->G[idx[i] + idx[j] * nr];
    while (f < i && li[f] == 0) ++f;
    start[i] = f;
    for (j = f; j < i; ++j) {
      const casadi_real *lj = L + (size_t) j * m;
      if (dropped[j]) {
        li[j] = 0;
        continue;
      }
      s = li[j];
      for (k = f > start[j] ? f : (int) start[j]; k < j; ++k) s -= li[k] * lj[k];
      li[j] = s / lj[j];
    }
    d0 = li[i];
    s = d0;
    for (k = f; k < i; ++k) s -= li[k] * li[k];
    dropped[i] = !(s > CONE_PIVOT * d0);
    li[i] = dropped[i] ? 0 : sqrt(s);
    if (dropped[i]) ++nd;
  }
  if (!nd) return 1;
  for (r = 0, j = 0; j < m; ++j) /* L_K by columns, at C + r m */
    if (!dropped[j]) {
      for (i = 0; i < j; ++i) C[i + (size_t) r * m] = 0;
      for (i = j; i < m; ++i) C[i + (size_t) r * m] = L[(size_t) i * m + j];
      ++r;
    }
  cone_qr(C, m, r, beta);
  for (i = 0; i < m; ++i) z[i] = ws->P[idx[i]];
  for (j = 0; j < r; ++j) cone_reflect(C, m, j, beta[j], z); /* Q^T P_A */
  for (j = 0; j < r; ++j) z[j] = 0; /* its part in range(L_K) */
  for (j = r - 1; j >= 0; --j) cone_reflect(C, m, j, beta[j], z); /* Q_2 Q_2^T P_A */
  for (i = 0; i < nr_g; ++i) dP[rows[i]] = 0;
  for (i = 0; i < m; ++i) dP[idx[i]] = -z[i];
  for (pass = 0; pass < CONE_BACKTRACK && !cone_inside(ws, first, mem, nm, in, dP, t); ++pass) t /= 2;
  if (pass == CONE_BACKTRACK) return !nz;
  for (i = 0; i < nr_g; ++i) { /* G dP, by G's column nonzeros (all in the group's rows) */
    dP[rows[i]] *= t;
    gdp[rows[i]] = 0;
  }
  for (i = 0; i < nr_g; ++i)
    if (dP[rows[i]] != 0)
      for (k = (int) ws->gp[rows[i]]; k < ws->gp[rows[i] + 1]; ++k)
        gdp[ws->gi[k]] += ws->G[ws->gi[k] + rows[i] * nr] * dP[rows[i]];
  before = cone_residual_of(ws, nr, first, bias, mem, nm, size);
  for (i = 0; i < nr_g; ++i) {
    P0[rows[i]] = ws->P[rows[i]];
    U0[rows[i]] = ws->U[rows[i]];
    ws->P[rows[i]] += dP[rows[i]];
    ws->U[rows[i]] += gdp[rows[i]];
  }
  after = cone_residual_of(ws, nr, first, bias, mem, nm, size);
  if (after <= fmax(2 * before, tol)) return 1;
  for (i = 0; i < nr_g; ++i) {
    ws->P[rows[i]] = P0[rows[i]];
    ws->U[rows[i]] = U0[rows[i]];
  }
  return !nz;
}

/* The least-norm member of the family of solutions (cone_min_norm_over()), group by group
 * of coupled contacts (cone_groups(): a slipping contact stops the move of its own group
 * only), over the contacts with an impulse and the touching ones without; where that move
 * fails (it would pull a touching contact's impulse below 0), over those with an impulse
 * alone.  First, a contact whose impulse is of round-off size with P_N <= 0 (at most
 * CONE_FLOOR max |P|: Newton's steps leave such specks outside the cone) gets none, with U
 * updated.  1 + max |U| (the scale of the floors) is taken once, before the moves (they
 * change U by round-off). */
static void cone_min_norm(workspace *ws, int na, const int *first, const casadi_real *bias, casadi_real tol) {
  const int nr = first[na];
  casadi_real pmax = 0, size = 0;
  int grp[NK], next[NK], mem[NK], rows[ND], c, i, k;
  for (i = 0; i < nr; ++i) pmax = fmax(pmax, fabs(ws->P[i]));
  for (c = 0; c < na; ++c) {
    casadi_real most = 0;
    for (i = first[c]; i < first[c + 1]; ++i) most = fmax(most, fabs(ws->P[i]));
    if (ws->P[first[c]] > 0 || most > CONE_FLOOR * pmax) continue;
    for (i = first[c]; i < first[c + 1]; ++i) {
      for (k = (int) ws->gp[i]; k < ws->gp[i + 1]; ++k) ws->U[ws->gi[k]] -= ws->G[ws->gi[k] + i * nr] * ws->P[i];
      ws->P[i] = 0;
    }
  }
  for (i = 0; i < nr; ++i) size = fmax(size, fabs(ws->U[i]));
  cone_groups(ws, na, first, grp);
  for (c = 0; c < na; ++c) next[c] = -1; /* next[c]: the next contact of c's group (-1: none); a root heads it */
  for (c = na - 1; c >= 0; --c)
    if (grp[c] != c) next[c] = next[grp[c]], next[grp[c]] = c;
  for (c = 0; c < na; ++c) {
    int nm = 0, nr_g = 0, e;
    if (grp[c] != c) continue;
    for (e = c; e >= 0; e = next[e]) {
      mem[nm++] = e;
      for (i = first[e]; i < first[e + 1]; ++i) rows[nr_g++] = i;
    }
    if (!cone_min_norm_over(ws, nr, first, bias, tol, mem, nm, rows, nr_g, size, 1))
      (void) cone_min_norm_over(ws, nr, first, bias, tol, mem, nm, rows, nr_g, size, 0);
  }
}

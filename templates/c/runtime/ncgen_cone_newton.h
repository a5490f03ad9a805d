/* The frictional contact problem of a step by a semismooth Newton method on the
 * Alart-Curnier function (cone_newton()), for the contact solve of ncgen_contact.h, and the
 * residual of the contact laws (cone_residual()).  Plain C99, model-independent; included
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
 * equations are consistent at a solution, and the others solve them. */

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

/* rho_N and rho_T of each active contact into rho (row r0 = first[c]: rho_N, r0 + 1: rho_T,
 * if the contact has friction).  A zero diagonal (a contact the step cannot move) gives 0. */
static void cone_scales(const workspace *ws, int na, const int *first, casadi_real *rho) {
  int nr = first[na], c, d;
  for (c = 0; c < na; ++c) {
    const int r0 = first[c], nt = first[c + 1] - r0 - 1;
    const casadi_real gnn = ws->G[r0 + r0 * nr];
    casadi_real gt = 0;
    rho[r0] = gnn > 0 ? 1 / gnn : 0;
    for (d = 1; d <= nt; ++d) gt = fmax(gt, ws->G[(r0 + d) + (r0 + d) * nr]);
    for (d = 1; d <= nt; ++d) rho[r0 + d] = gt > 0 ? 1 / gt : 0;
  }
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
  int it, r, a, k, i;
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
    for (r = 0; r < nr; ++r) phi[r] = -phi[r];
    if (!cone_solve(J, phi, dP, nr, cols, dropped)) return 0;
    for (r = 0; r < nr; ++r) gdp[r] = 0; /* G dP, by G's column nonzeros */
    for (a = 0; a < nr; ++a)
      if (dP[a] != 0)
        for (k = (int) ws->gp[a]; k < ws->gp[a + 1]; ++k) gdp[ws->gi[k]] += ws->G[ws->gi[k] + a * nr] * dP[a];
    for (i = 0; i < CONE_BACKTRACK; ++i, step /= 2) {
      for (r = 0; r < nr; ++r) {
        Pt[r] = ws->P[r] + step * dP[r];
        Ut[r] = ws->U[r] + step * gdp[r];
      }
      theta_t = cone_phi(ws, na, first, bias, rho, Pt, Ut, phi, 0);
      if (theta_t <= (1 - 2 * CONE_ARMIJO * step) * theta) break;
    }
    if (i == CONE_BACKTRACK) break; /* no descent: stalled at round-off, or lost */
    memcpy(ws->P, Pt, (size_t) nr * sizeof(casadi_real));
    memcpy(ws->U, Ut, (size_t) nr * sizeof(casadi_real));
    theta = cone_phi(ws, na, first, bias, rho, ws->P, ws->U, phi, J);
  }
  if (*residual <= CONE_FLOOR) return 1;
  memcpy(ws->P, P0, (size_t) nr * sizeof(casadi_real)); /* failed: the impulses it started from */
  memcpy(ws->U, U0, (size_t) nr * sizeof(casadi_real));
  return 0;
}

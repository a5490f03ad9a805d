/* The Jacobians of one step of the table-driven stepper (ncgen_table_stepper.h) by the
 * implicit function theorem on its own converged Newton systems: no differentiation through
 * the iterations, no code per model.  Included after ncgen_table_stepper.h (and the RATTLE
 * runtime it includes).
 *
 * The step from x = [q; v] with inputs u (ncgen/control/discrete.py writes the same step as
 * one residual G(z; x, u)) is two stages in the unknowns z1 = [w; ν] and z2 = [v⁺; μ']:
 *
 *   r1(z1; q, v, u) = [M (w − v) − h/2 F(q, w, u) + A(q)ᵀ ν;  Φ(q + h w) / h]          = 0
 *   r2(z2; q⁺, w, u) = [M v⁺ + A(q⁺)ᵀ μ' − M w − h/2 F(q⁺, w, u);  A(q⁺) v⁺]          = 0
 *
 * q⁺ = q + h w, x⁺ = [q⁺; v⁺].  Their Jacobians in z are the stepper's matrices,
 * K1 = [[M − h/2 F_w(q, w), A(q)ᵀ], [A(q⁺), 0]] and K2 = [[M, A(q⁺)ᵀ], [A(q⁺), 0]], each
 * factored once (the sparse LU of ncgen_sparse_lu.h where the stepper uses it — M regular —
 * and it accepts the matrix, else the sparse QR of ncgen_sparse_qr.h).  A perturbation (δq, δv, δu) of the step's
 * inputs moves the solution by
 *
 *   δz1 = −K1⁻¹ [−M δv − h/2 (F_q(q, w) δq + F_u δu) + L(δq)ᵀ ν;  A(q⁺) δq / h]
 *   δq⁺ = δq + h δw
 *   δz2 = −K2⁻¹ [L(δq⁺)ᵀ μ' − M δw − h/2 (F_q(q⁺, w) δq⁺ + F_w(q⁺, w) δw + F_u δu);  L(δq⁺) v⁺]
 *
 * and δx⁺ = [δq⁺; δv⁺].  L(d) = A(q + d) − A(q) is exact for every q: every covered
 * constraint is quadratic in q, so A is affine in q and L linear and constant (L(d)ᵀ ν =
 * Σ_k ν_k H_k d, L(d) v⁺ = [v⁺ᵀ H_k d]_k).  F_q, F_w of the springs come from their kernel's J (∂f/∂[r_a; r_b; ṙ_a;
 * ṙ_b], evaluated once per stage); gravity is constant; the input forces B_u u and the
 * actuators' Σ τ_j ∇θ_j (their Hessians exact: ncgen_table_stepper.h).  The
 * columns of ∂x⁺/∂x (2nq x 2nq) and ∂x⁺/∂u (2nq x nu) are these δx⁺ for unit perturbations;
 * since every δx⁺ lies in the 2 dof-dimensional tangent space of the state manifold at x⁺,
 * tab_jac_rows computes them as Q (Qᵀ [Jx Ju]) from 2 dof reverse passes instead (6 dof solves
 * and one more factorisation against 2 (2nq + nu) solves), and the columns (tab_jac_columns:
 * in blocks, each stage's solves over a whole block in one sweep of the factors) are taken
 * where that does not apply, where it takes more solves, or where its result disagrees with
 * one forward column (TAB_JAC_COLUMNS and TAB_JAC_ROWS force either path for their unit
 * tests).
 * L is given as the constant matrix D (tab_jac_hessian), computed once per model by the
 * caller from A(e_i) − A(0).
 *
 * Before the solve the converged z1 is polished by one more Newton step (the stepper's
 * test stops a few digits above the rounding floor; the quadratic step reaches it) and z2 is
 * solved at it, as ncgen/control/discrete.py does; *res is then max(‖r1‖∞, ‖r2‖∞).
 * tab_step_jacobians returns the stepper's status (STEP_OK, ...), or STEP_BAD_INPUT when out
 * of memory. */
#ifndef NCGEN_TABLE_JACOBIANS_H
#define NCGEN_TABLE_JACOBIANS_H

/* The factors of one stage matrix K (its nonzeros): the sparse LU's (lu = 1: L, D U and the
 * pivots' reciprocals) where the tables use it and it accepts the matrix, else the sparse QR's
 * (V, R, beta). */
typedef struct {
  int lu, refine;                  /* refine: the LU's solutions refined once (tab_jac_solve) */
  const double *K;
  double *V, *R, *beta, *lo, *up, *dinv;
} tab_jac_factors;

/* The scratch of tab_step_jacobians: the factors of K1 and K2 and the vectors of the solves. */
typedef struct {
  tab_jac_factors f1, f2;
  double *K, *K1, *r, *z1, *z2, *dr, *dz1, *dz2, *dq1, *dy, *zero;
  double *A1, *La, *phis, *ew, *fd, *fdw, *sj1, *sj2, *dF, *x, *y;
} tab_jac_work;

/* Doubles of tab_jac_work for the tables of the run in progress. */
static long tab_jac_size(void) {
  const ncgen_stepper_tables *S = tab_cur;
  const ncgen_tables *T = S->T;
  long n = T->nq + T->nc, nf = (long)T->nf * T->dim, nsj = (long)S->n_spring * T->dim * 4 * T->dim;
  return 2 * ((long)S->nnz_v + S->nnz_r + n + 2L * S->lu.nnz_l + n) + 2L * S->nnz_k + 12 * n +
         (2L * T->nq + S->nu) + T->nq + 2L * T->a_nnz + T->nq + T->nc + tab_ew_size + 2 * nf + 2 * nsj;
}

static tab_jac_work tab_jac_layout(double *p) {
  const ncgen_stepper_tables *S = tab_cur;
  const ncgen_tables *T = S->T;
  long n = T->nq + T->nc, nf = (long)T->nf * T->dim, nsj = (long)S->n_spring * T->dim * 4 * T->dim;
  tab_jac_work b;
  tab_jac_factors *f[2];
  int i;
  f[0] = &b.f1;
  f[1] = &b.f2;
  for (i = 0; i < 2; ++i) {
    f[i]->lu = 0;
    f[i]->refine = i;              /* K2's solves (tab_jac_solve) */
    f[i]->V = p; f[i]->R = f[i]->V + S->nnz_v; f[i]->beta = f[i]->R + S->nnz_r;
    f[i]->lo = f[i]->beta + n; f[i]->up = f[i]->lo + S->lu.nnz_l; f[i]->dinv = f[i]->up + S->lu.nnz_l;
    p = f[i]->dinv + n;
  }
  b.K = p; b.K1 = b.K + S->nnz_k; b.r = b.K1 + S->nnz_k; b.z1 = b.r + n; b.z2 = b.z1 + n; b.dr = b.z2 + n;
  b.dz1 = b.dr + n; b.dz2 = b.dz1 + n; b.dq1 = b.dz2 + n; b.x = b.dq1 + n; b.y = b.x + n;
  b.dy = b.y + 3 * n; b.zero = b.dy + 2 * T->nq + S->nu;
  b.A1 = b.zero + T->nq; b.La = b.A1 + T->a_nnz;
  b.phis = b.La + T->a_nnz; b.dF = b.phis + T->nc; b.ew = b.dF + T->nq;
  b.fd = b.ew + tab_ew_size; b.fdw = b.fd + nf; b.sj1 = b.fdw + nf; b.sj2 = b.sj1 + nsj;
  return b;
}

/* The constant second derivatives of the constraints: L(d) = D d (the nonzeros of A, a_nnz
 * x nq, CSC d_colind, d_row, d_val), D's column i the nonzeros of A(e_i) − A(0). */
typedef struct {
  const int *colind, *row;
  const double *val;
} tab_jac_hessian;

/* The factors of K (nonzeros in the stepper's pattern) into f: 0, or 1 when K is singular;
 * x: n doubles of scratch. */
static int tab_jac_factor(tab_jac_factors *f, const double *K, double *x) {
  const ncgen_stepper_tables *S = tab_cur;
  memset(x, 0, sizeof(double) * (size_t)S->qr.n);
  f->K = K;
  f->lu = S->lu.n && !ncgen_lu_factor(&S->lu, K, f->lo, f->up, f->dinv, x);
  return f->lu ? 0 : ncgen_qr_factor(&S->qr, K, f->V, f->R, f->beta, x);
}

/* x = K⁻¹ r (transposed: K⁻ᵀ r, the LU's factors only) from the factors f of K; y: 3n doubles of
 * scratch.  With f->refine the LU's solution is refined once (the residual r − K x solved
 * again and added): without pivoting its forward error on the second stage's K2 can be far
 * above the QR's (the Panda's reverse passes disagreed with a forward column by 3.7e-8
 * relative, 5.7e-10 with the QR, 5e-12 with K2's solves refined; refining K1's solves too,
 * plain or transposed, changed nothing). */
static void tab_jac_solve(const tab_jac_factors *f, int transposed, const double *r, double *x, double *y) {
  const ncgen_qr_pattern *P = &tab_cur->qr;
  const ncgen_lu_pattern *U = &tab_cur->lu;
  double *res = y + P->n, *dx = y + 2 * P->n;
  int i, j, k;
  if (!f->lu) {
    ncgen_qr_solve(P, f->V, f->R, f->beta, r, x, y);
    return;
  }
  for (i = 0; i < 1 + f->refine; ++i) {
    const double *rhs = i ? res : r;
    double *sol = i ? dx : x;
    if (transposed) ncgen_lu_solve_transposed(U, f->lo, f->up, f->dinv, rhs, sol, y);
    else ncgen_lu_solve(U, f->lo, f->up, f->dinv, rhs, sol, y);
    if (i || !f->refine) break;
    memcpy(res, r, sizeof(double) * (size_t)P->n);
    for (j = 0; j < P->n; ++j)
      for (k = P->k_colind[j]; k < P->k_colind[j + 1]; ++k) {
        if (transposed) res[j] -= f->K[k] * x[P->k_row[k]];
        else res[P->k_row[k]] -= f->K[k] * x[j];
      }
  }
  if (f->refine)
    for (j = 0; j < P->n; ++j) x[j] += dx[j];
}

/* La = L(d) = D d (nonzeros of A). */
static void tab_jac_dA(const tab_jac_hessian *D, const double *d, tab_jac_work *b) {
  const ncgen_tables *T = tab_cur->T;
  int i, k;
  memset(b->La, 0, sizeof(double) * (size_t)T->a_nnz);
  for (i = 0; i < T->nq; ++i)
    if (d[i] != 0)
      for (k = D->colind[i]; k < D->colind[i + 1]; ++k) b->La[D->row[k]] += D->val[k] * d[i];
}

/* Every spring's J = ∂f/∂[r_a; r_b; ṙ_a; ṙ_b] at (q, w) into sj (dim x 4 dim each). */
static int tab_jac_springs(const double *q, const double *w, double *sj, tab_work *b) {
  const ncgen_stepper_tables *S = tab_cur;
  const ncgen_tables *T = S->T;
  int dim = T->dim, s, X, nj = dim * 4 * dim;
  ncgen_kernel spring = dim == 3 ? TAB_SPRING_3D : TAB_SPRING_2D;
  if (!S->n_spring) return 0;
  ncgen_tables_features(T, q, b->fq, T->feat_const);
  ncgen_tables_features(T, w, b->fv, 0);
  for (s = 0; s < S->n_spring; ++s) {
    const int *f = S->spr_feat + 2 * s;
    const double *arg[1];
    double *res[2];
    for (X = 0; X < 2; ++X) {
      memcpy(b->sx + X * dim, b->fq + f[X] * dim, sizeof(double) * (size_t)dim);
      memcpy(b->sx + (2 + X) * dim, b->fv + f[X] * dim, sizeof(double) * (size_t)dim);
    }
    memcpy(b->sx + 4 * dim, S->spr_par + 3 * s, 3 * sizeof(double));
    arg[0] = b->sx;
    res[0] = b->sy;
    res[1] = sj + (size_t)s * nj;
    if (spring(arg, res, 0, b->ew, 0)) return 1;
  }
  return 0;
}

/* dF = F_q dq + F_w dw + F_u du at (q, w, u) (du may be NULL): the springs' (sj: their J at
 * the stage's point, tab_jac_springs), B_u du, and the actuators' Σ (δτ_j ∇θ_j + τ_j ∇²θ_j dq). */
static void tab_jac_forces(const double *q, const double *u, const double *sj, const double *dq, const double *dw,
                           const double *du, tab_jac_work *b) {
  const ncgen_stepper_tables *S = tab_cur;
  const ncgen_tables *T = S->T;
  int dim = T->dim, s, X, i, j, e, nj = dim * 4 * dim;
  double grad[TAB_ACT_MAX_K], hd[TAB_ACT_MAX_K];
  memset(b->dF, 0, sizeof(double) * (size_t)T->nq);
  if (du)
    for (j = 0; j < S->nu; ++j)
      for (e = S->bu_colind[j]; e < S->bu_colind[j + 1]; ++e) b->dF[S->bu_row[e]] += S->bu_val[e] * du[j];
  for (j = 0; j < S->n_act; ++j) {
    double tau = tab_act_tau(j, u), dtau = tab_act_tau(j, du);
    int n = tab_act_gradient(j, q, dq, grad, hd);
    for (i = 0; i < n; ++i) b->dF[S->act_col[S->act_ptr[j] + i]] += dtau * grad[i] + tau * hd[i];
  }
  if (!S->n_spring) return;
  ncgen_tables_features(T, dq, b->fd, 0);
  ncgen_tables_features(T, dw, b->fdw, 0);
  for (s = 0; s < S->n_spring; ++s) {
    const int *f = S->spr_feat + 2 * s;
    const double *J = sj + (size_t)s * nj;
    double df[3] = {0, 0, 0};
    for (X = 0; X < 2; ++X)       /* df = J [δr_a; δr_b; δṙ_a; δṙ_b] */
      for (j = 0; j < dim; ++j) {
        double dr = b->fd[f[X] * dim + j], drd = b->fdw[f[X] * dim + j];
        for (i = 0; i < dim; ++i) df[i] += J[i + dim * (X * dim + j)] * dr + J[i + dim * ((2 + X) * dim + j)] * drd;
      }
    for (X = 0; X < 2; ++X) {
      double sign = X ? 1.0 : -1.0;
      for (e = T->feat_ptr[f[X]]; e < T->feat_ptr[f[X] + 1]; ++e)
        b->dF[T->feat_col[e]] += sign * T->feat_coef[e] * df[T->feat_row[e]];
    }
  }
}

/* y = K x for K's nonzeros (n = nq + nc). */
static void tab_jac_kkt_times(const double *K, const double *x, double *y) {
  const ncgen_qr_pattern *P = &tab_cur->qr;
  int j, k;
  memset(y, 0, sizeof(double) * (size_t)P->n);
  for (j = 0; j < P->n; ++j)
    for (k = P->k_colind[j]; k < P->k_colind[j + 1]; ++k) y[P->k_row[k]] += K[k] * x[j];
}

/* The force derivatives at (q, w, u) as dense column-major matrices: Fq = ∂F/∂q and Fw =
 * ∂F/∂w (nq x nq, NULL when the model has no springs nor actuators) and Fu = ∂F/∂u (nq x nu),
 * assembled element by element (sj: the springs' J at the stage's point, tab_jac_springs;
 * unit: nq doubles of zeros, left so). */
static void tab_jac_force_matrices(const double *q, const double *u, const double *sj, double *unit, double *Fq,
                                   double *Fw, double *Fu) {
  const ncgen_stepper_tables *S = tab_cur;
  const ncgen_tables *T = S->T;
  const int nq = T->nq, nu = S->nu, dim = T->dim, nj = dim * 4 * dim;
  double grad[TAB_ACT_MAX_K], hd[TAB_ACT_MAX_K];
  int j, i, c, e, e2, s, X, Y;
  memset(Fu, 0, sizeof(double) * (size_t)nq * nu);
  for (j = 0; j < nu; ++j)
    for (e = S->bu_colind[j]; e < S->bu_colind[j + 1]; ++e) Fu[S->bu_row[e] + (size_t)nq * j] += S->bu_val[e];
  if (!Fq) return;
  memset(Fq, 0, sizeof(double) * (size_t)nq * nq);
  memset(Fw, 0, sizeof(double) * (size_t)nq * nq);
  for (j = 0; j < S->n_act; ++j) {       /* Σ_j (τ_j ∇²θ_j, ∇θ_j act_tau_jᵀ) */
    const int lo = S->act_ptr[j], k = S->act_ptr[j + 1] - lo, *col = S->act_col + lo;
    double tau = tab_act_tau(j, u);
    for (c = 0; c < k; ++c) {
      unit[col[c]] = 1;
      tab_act_gradient(j, q, unit, grad, hd);
      unit[col[c]] = 0;
      for (i = 0; i < k; ++i) Fq[col[i] + (size_t)nq * col[c]] += tau * hd[i];
    }
    tab_act_gradient(j, q, 0, grad, 0);
    for (c = 0; c < nu; ++c)
      for (i = 0; i < k; ++i) Fu[col[i] + (size_t)nq * c] += S->act_tau[(size_t)j * nu + c] * grad[i];
  }
  for (s = 0; s < S->n_spring; ++s) {    /* G_Xᵀ (±J) G_Y over the ends X, Y of each spring */
    const int *f = S->spr_feat + 2 * s;
    const double *J = sj + (size_t)s * nj;
    for (X = 0; X < 2; ++X)
      for (Y = 0; Y < 2; ++Y)
        for (e = T->feat_ptr[f[X]]; e < T->feat_ptr[f[X] + 1]; ++e)
          for (e2 = T->feat_ptr[f[Y]]; e2 < T->feat_ptr[f[Y] + 1]; ++e2) {
            double g = (X ? 1.0 : -1.0) * T->feat_coef[e] * T->feat_coef[e2];
            size_t at = T->feat_col[e] + (size_t)nq * T->feat_col[e2];
            int r = T->feat_row[e], cc = T->feat_row[e2];
            Fq[at] += g * J[r + dim * (Y * dim + cc)];
            Fw[at] += g * J[r + dim * ((2 + Y) * dim + cc)];
          }
  }
}

/* A dense column-major matrix (rows x cols) compressed in place to its nonzeros (CSC: colind
 * cols + 1, row as many as the entries, val over the dense array's start). */
typedef struct {
  int *colind, *row;
  double *val;
} tab_jac_csc;

static void tab_jac_compress(double *F, int rows, int cols, tab_jac_csc *C) {
  size_t at = 0, k = 0;
  int i, j;
  C->val = F;
  C->colind[0] = 0;
  for (j = 0; j < cols; ++j) {
    for (i = 0; i < rows; ++i, ++at)
      if (F[at] != 0) {
        C->row[k] = i;
        F[k++] = F[at];
      }
    C->colind[j + 1] = (int)k;
  }
}

/* (Cᵀ x)_j. */
static double tab_jac_tdot(const tab_jac_csc *C, int j, const double *x) {
  double d = 0;
  int k;
  for (k = C->colind[j]; k < C->colind[j + 1]; ++k) d += C->val[k] * x[C->row[k]];
  return d;
}

/* The rows of the Jacobians along the tangent space of the state manifold at x⁺.
 *
 * Every δx⁺ = [δq⁺; δv⁺] lies in T(x⁺) = {A(q⁺) δq = 0, A(q⁺) δv + L(δq) v⁺ = 0} (the
 * linearised constraints that the converged step meets exactly), of dimension 2 dof =
 * 2 (nq − nc).  With Q an orthonormal basis of T(x⁺) (2nq x 2dof), [Jx Ju] = Q (Qᵀ [Jx Ju]),
 * and each row wᵀ [Jx Ju] (w a column of Q) is one reverse pass through the two stages:
 * 2 dof solves with K2 (symmetric) and 2 dof with K1ᵀ, instead of 2 (2nq + nu) forward
 * solves.  With δr1 = [P1 δq − M δv − h/2 F_u1 δu; A(q⁺) δq / h], P1 = Σ ν_k H_k − h/2 F_q1,
 * δr2 = [P2 δq⁺ − W2 δw − h/2 F_u2 δu; L_v δq⁺], P2 = Σ μ'_k H_k − h/2 F_q2,
 * W2 = M + h/2 F_w2, L_v d = L(d) v⁺, and w = [a; b]:
 *
 *   [α; β] = K2⁻¹ [b; 0],  g_q = a − P2ᵀ α − L_vᵀ β,  g_u = h/2 F_u2ᵀ α,
 *   [α1; β1] = K1⁻ᵀ [W2ᵀ α + h g_q; 0],
 *   wᵀ Jx = [g_q − P1ᵀ α1 − A(q⁺)ᵀ β1 / h;  M α1],  wᵀ Ju = g_u + h/2 F_u1ᵀ α1.
 *
 * Q comes from K2 too: n_k = [I 0] K2⁻¹ [M r_k; 0] (r_k fixed pseudo-random vectors) spans
 * null A(q⁺), p_k = [I 0] K2⁻¹ [0; −L_v n_k] completes [n_k; p_k] and [0; n_k] to a basis of
 * T(x⁺), orthonormalised by Gram–Schmidt twice.  K1ᵀ is solved by the LU's transposed solve
 * with K1's own factors; where K1 has QR factors, K1ᵀ is QR-factored in K's own pattern (its
 * values moved by the pattern's transpose).  Returns 0, 1 when this path does not apply (K's
 * pattern not structurally symmetric on the QR's path, a basis vector lost in the orthonormalisation: the
 * caller then takes the columns, tab_jac_columns) or 2 when out of memory. */
static int tab_jac_rows(const double *q, const double *u, double h, const tab_jac_hessian *D, const double *q_next,
                        tab_jac_work *b, double *Jx, double *Ju) {
  const ncgen_stepper_tables *S = tab_cur;
  const ncgen_tables *T = S->T;
  const ncgen_qr_pattern *P = &S->qr;
  const int nq = T->nq, nc = T->nc, n = nq + nc, nu = S->nu, nx = 2 * nq, m = 2 * nq + nu;
  const int dof = nq - nc, nt = 2 * dof, nnz = S->nnz_k, forces = S->n_act > 0 || S->n_spring > 0;
  const double *nu1 = b->z1 + nq, *mu2 = b->z2 + nq, *v1 = b->z2;
  int i, j, k, e, status = 2;
  size_t nqq = (size_t)nq * nq;
  double *mem, *Fq1, *Fq2, *Fw2, *Fu1, *Fu2, *Q, *R, *Kt, *V3, *R3, *beta3, *rhs, *sol, *gq, *c, *unit;
  int *imem, *tpos, *colof, *cnt, *ci;
  tab_jac_csc Cq1 = {0, 0, 0}, Cq2 = Cq1, Cw2 = Cq1, Cu1 = Cq1, Cu2 = Cq1;
#ifdef TAB_JAC_COLUMNS                   /* the fallback forced (its unit test) */
  return 1;
#endif
  if (dof < 0) return 1;
  mem = malloc(sizeof(double) * ((forces ? 3 * nqq : 0) + 2 * (size_t)nq * nu + (size_t)nx * nt + (size_t)nt * m +
                                 nnz + S->nnz_v + S->nnz_r + 5 * (size_t)n + nq + 1));
  imem = malloc(sizeof(int) * ((size_t)nnz + T->a_nnz + n + 1 + (forces ? 3 * (nqq + nq + 1) : 0) +
                               2 * ((size_t)nq * nu + nu + 1)));
  if (!mem || !imem) goto done;
  Fq1 = mem; Fq2 = Fq1 + (forces ? nqq : 0); Fw2 = Fq2 + (forces ? nqq : 0); Fu1 = Fw2 + (forces ? nqq : 0);
  Fu2 = Fu1 + (size_t)nq * nu; Q = Fu2 + (size_t)nq * nu; R = Q + (size_t)nx * nt; Kt = R + (size_t)nt * m;
  V3 = Kt + nnz; R3 = V3 + S->nnz_v; beta3 = R3 + S->nnz_r; rhs = beta3 + n; sol = rhs + n; gq = sol + n;
  c = gq + n; unit = c + n;
  tpos = imem; colof = tpos + nnz; cnt = colof + T->a_nnz; ci = cnt + n + 1;
  status = 1;
  if (!b->f1.lu) {                         /* K1ᵀ solved by the LU's transposed solve, else */
    /* K1ᵀ in K's pattern, QR-factored: entry k at (i, j) goes to the entry at (j, i) */
    for (i = 0; i <= n; ++i) cnt[i] = 0;
    for (k = 0; k < nnz; ++k) ++cnt[P->k_row[k]];
    for (i = 0; i < n; ++i)
      if (cnt[i] != P->k_colind[i + 1] - P->k_colind[i]) goto done;
    for (i = 0; i < n; ++i) cnt[i] = P->k_colind[i];
    for (j = 0; j < n; ++j)
      for (k = P->k_colind[j]; k < P->k_colind[j + 1]; ++k) {
        int t = cnt[P->k_row[k]]++;
        if (P->k_row[t] != j) goto done;   /* rows of a column not ascending, or not symmetric */
        tpos[k] = t;
      }
    for (k = 0; k < nnz; ++k) Kt[tpos[k]] = b->K1[k];
    if (ncgen_qr_factor(P, Kt, V3, R3, beta3, b->x)) goto done;
  }
  for (j = 0; j < nq; ++j)
    for (k = S->a_colind[j]; k < S->a_colind[j + 1]; ++k) colof[k] = j;
  /* the force derivatives: F_q1 at (q, w), F_q2 and F_w2 at (q⁺, w) (F_w1 is in K1) */
  memset(unit, 0, sizeof(double) * (size_t)nq);
  tab_jac_force_matrices(q, u, b->sj1, unit, forces ? Fq1 : 0, forces ? Fw2 : 0, Fu1);
  tab_jac_force_matrices(q_next, u, b->sj2, unit, forces ? Fq2 : 0, forces ? Fw2 : 0, Fu2);
  {
    tab_jac_csc *C[5] = {&Cu1, &Cu2, &Cq1, &Cq2, &Cw2};
    double *F[5] = {Fu1, Fu2, Fq1, Fq2, Fw2};
    for (i = 0; i < (forces ? 5 : 2); ++i) {
      int cols = i < 2 ? nu : nq;
      C[i]->colind = ci;
      C[i]->row = ci + cols + 1;
      ci = C[i]->row + (size_t)nq * cols;
      tab_jac_compress(F[i], nq, cols, C[i]);
    }
  }
  /* the basis of T(x⁺): [n_k; p_k] in column k, [0; n_k] in column dof + k */
  {
    unsigned long long seed = 0x9E3779B97F4A7C15ULL;
    for (k = 0; k < dof; ++k) {
      double *cq = Q + (size_t)k * nx, *cv = Q + (size_t)(dof + k) * nx;
      for (i = 0; i < nq; ++i) {
        seed = seed * 6364136223846793005ULL + 1442695040888963407ULL;
        unit[i] = (double)(seed >> 11) / 9007199254740992.0 - 0.5;
      }
      memset(rhs, 0, sizeof(double) * (size_t)n);
      tab_mass_times(unit, rhs);
      tab_jac_solve(&b->f2, 0, rhs, sol, b->y);
      memcpy(cq, sol, sizeof(double) * (size_t)nq);
      memset(cv, 0, sizeof(double) * (size_t)nq);
      memcpy(cv + nq, sol, sizeof(double) * (size_t)nq);
      tab_jac_dA(D, sol, b);                 /* L(n_k) v⁺ */
      memset(rhs, 0, sizeof(double) * (size_t)n);
      tab_a_times(b->La, v1, rhs + nq, 0);
      for (i = 0; i < nc; ++i) rhs[nq + i] = -rhs[nq + i];
      for (i = 0; i < nq; ++i) rhs[i] = 0;
      tab_jac_solve(&b->f2, 0, rhs, sol, b->y);
      memcpy(cq + nq, sol, sizeof(double) * (size_t)nq);
    }
    for (k = 0; k < nt; ++k) {              /* Gram–Schmidt, twice */
      double *x = Q + (size_t)k * nx, norm0 = 0, norm = 0;
      int pass;
      for (i = 0; i < nx; ++i) norm0 += x[i] * x[i];
      for (pass = 0; pass < 2; ++pass)
        for (j = 0; j < k; ++j) {
          const double *y = Q + (size_t)j * nx;
          double d = 0;
          for (i = 0; i < nx; ++i) d += x[i] * y[i];
          for (i = 0; i < nx; ++i) x[i] -= d * y[i];
        }
      for (i = 0; i < nx; ++i) norm += x[i] * x[i];
      if (!(norm > 1e-16 * norm0) || !(norm0 > 0)) goto done;
      norm = sqrt(norm);
      for (i = 0; i < nx; ++i) x[i] /= norm;
    }
  }
  /* the rows wᵀ [Jx Ju], w = [a; b] each column of Q */
  for (k = 0; k < nt; ++k) {
    const double *a = Q + (size_t)k * nx, *bb = a + nq, *al, *be;
    double *row = R + (size_t)k * m;
    memcpy(rhs, bb, sizeof(double) * (size_t)nq);
    memset(rhs + nq, 0, sizeof(double) * (size_t)nc);
    tab_jac_solve(&b->f2, 0, rhs, sol, b->y);
    al = sol;
    be = sol + nq;
    for (i = 0; i < nq; ++i) {              /* g_q = a − P2ᵀ α − L_vᵀ β */
      double s = a[i];
      for (e = D->colind[i]; e < D->colind[i + 1]; ++e) {
        int ae = D->row[e];
        s -= D->val[e] * (mu2[S->a_row[ae]] * al[colof[ae]] + v1[colof[ae]] * be[S->a_row[ae]]);
      }
      if (forces) s += h / 2 * tab_jac_tdot(&Cq2, i, al);
      gq[i] = s;
    }
    for (j = 0; j < nu; ++j) row[2 * nq + j] = h / 2 * tab_jac_tdot(&Cu2, j, al);
    memset(c, 0, sizeof(double) * (size_t)n);   /* c = W2ᵀ α + h g_q */
    tab_mass_times(al, c);
    for (i = 0; i < nq; ++i) c[i] += (forces ? h / 2 * tab_jac_tdot(&Cw2, i, al) : 0) + h * gq[i];
    if (b->f1.lu) tab_jac_solve(&b->f1, 1, c, sol, b->y);
    else ncgen_qr_solve(P, V3, R3, beta3, c, sol, b->y);
    al = sol;
    be = sol + nq;
    for (i = 0; i < nq; ++i) {              /* g_q − P1ᵀ α1 − A(q⁺)ᵀ β1 / h */
      double s = gq[i];
      for (e = D->colind[i]; e < D->colind[i + 1]; ++e) {
        int ae = D->row[e];
        s -= D->val[e] * nu1[S->a_row[ae]] * al[colof[ae]];
      }
      if (forces) s += h / 2 * tab_jac_tdot(&Cq1, i, al);
      for (e = S->a_colind[i]; e < S->a_colind[i + 1]; ++e) s -= b->A1[e] * be[S->a_row[e]] / h;
      row[i] = s;
    }
    memset(row + nq, 0, sizeof(double) * (size_t)nq);
    tab_mass_times(al, row + nq);
    for (j = 0; j < nu; ++j) row[2 * nq + j] += h / 2 * tab_jac_tdot(&Cu1, j, al);
  }
  /* [Jx Ju] = Q R */
  for (j = 0; j < m; ++j) {
    double *col = j < nx ? Jx + (size_t)j * nx : Ju + (size_t)(j - nx) * nx;
    memset(col, 0, sizeof(double) * (size_t)nx);
    for (k = 0; k < nt; ++k) {
      const double *y = Q + (size_t)k * nx, r = R[(size_t)k * m + j];
      if (r != 0)
        for (i = 0; i < nx; ++i) col[i] += r * y[i];
    }
  }
  status = 0;
done:
  free(mem);
  free(imem);
  return status;
}

/* The relative agreement below which the rows' [Jx Ju] d (tab_jac_rows) must meet the
 * forward column of a pseudo-random d, else the columns are taken (tab_jac_columns): the reverse
 * passes lose digits where K2's solves are not accurate enough (their forward error, amplified
 * in the basis of T(x⁺) and in α: with K2's solves unrefined, Talos with its floating base
 * 9e-8 by the LU and 1e-5 by the QR, the Panda 4e-8 by the LU; refined, Talos 6e-10, the
 * Panda 5e-12). */
#define TAB_JAC_ROWS_TOL 1e-9

/* y −= a x over m entries (unrolled by four: gcc's -O2 pairs them into vector operations). */
static void tab_jac_sub_scaled(int m, double a, const double *restrict x, double *restrict y) {
  int r = 0;
  for (; r + 4 <= m; r += 4) {
    y[r] -= a * x[r];
    y[r + 1] -= a * x[r + 1];
    y[r + 2] -= a * x[r + 2];
    y[r + 3] -= a * x[r + 3];
  }
  for (; r < m; ++r) y[r] -= a * x[r];
}

/* X = K⁻¹ B for m right-hand sides at once from the factors f of K (with f->refine, refined
 * once as tab_jac_solve does).  B and X are n x m row by row (row i of every right-hand side
 * contiguous, B + i m), so that the sweeps over the factors' nonzeros run over the m values
 * (one index read per m multiply-adds instead of one each); Y: 3 n m doubles of scratch,
 * y: 3n (the QR's solves, column by column). */
static void tab_jac_solve_many(const tab_jac_factors *f, const double *B, double *X, int m, double *Y, double *y) {
  const ncgen_qr_pattern *P = &tab_cur->qr;
  const ncgen_lu_pattern *U = &tab_cur->lu;
  const int n = P->n;
  double *res = Y + (size_t)n * m, *dx = res + (size_t)n * m;
  int i, j, k, r, pass;
  if (!f->lu) {
    for (j = 0; j < m; ++j) {
      for (i = 0; i < n; ++i) res[i] = B[(size_t)i * m + j];
      ncgen_qr_solve(P, f->V, f->R, f->beta, res, dx, y);
      for (i = 0; i < n; ++i) X[(size_t)i * m + j] = dx[i];
    }
    return;
  }
  for (pass = 0; pass < 1 + f->refine; ++pass) {
    const double *rhs = pass ? res : B;
    double *sol = pass ? dx : X;
    if (pass) {                          /* res = B − K X */
      memcpy(res, B, sizeof(double) * (size_t)n * m);
      for (j = 0; j < n; ++j)
        for (k = P->k_colind[j]; k < P->k_colind[j + 1]; ++k)
          tab_jac_sub_scaled(m, f->K[k], X + (size_t)j * m, res + (size_t)P->k_row[k] * m);
    }
    for (i = 0; i < n; ++i) memcpy(Y + (size_t)U->pinv[i] * m, rhs + (size_t)i * m, sizeof(double) * (size_t)m);
    for (j = 0; j < n; ++j)              /* L z = y, column by column */
      for (k = U->l_colind[j]; k < U->l_colind[j + 1]; ++k)
        tab_jac_sub_scaled(m, f->lo[k], Y + (size_t)j * m, Y + (size_t)U->l_row[k] * m);
    for (j = n - 1; j >= 0; --j) {       /* (D U) x = z, column by column */
      double *yc = Y + (size_t)j * m;
      const double d = f->dinv[j];
      for (r = 0; r < m; ++r) yc[r] *= d;
      for (k = U->u_colind[j]; k < U->u_colind[j + 1]; ++k)
        tab_jac_sub_scaled(m, f->up[k], yc, Y + (size_t)U->u_row[k] * m);
    }
    for (j = 0; j < n; ++j) memcpy(sol + (size_t)U->p[j] * m, Y + (size_t)j * m, sizeof(double) * (size_t)m);
  }
  if (f->refine)
    for (i = 0; i < n * m; ++i) X[i] += dx[i];
}

/* The right-hand sides taken at once by tab_jac_columns (its scratch: 6 n of them; smaller
 * in a unit test, so that a tiny model's columns span several blocks). */
#ifndef TAB_JAC_BLOCK
#define TAB_JAC_BLOCK 64
#endif

/* Column j of row-by-row storage (n rows, m columns) from or into the vector x. */
static void tab_jac_put(double *M, int n, int m, int j, const double *x) {
  int i;
  for (i = 0; i < n; ++i) M[(size_t)i * m + j] = x[i];
}

static void tab_jac_get(const double *M, int n, int m, int j, double *x) {
  int i;
  for (i = 0; i < n; ++i) x[i] = M[(size_t)i * m + j];
}

/* dy = column k of dY ((ny x ·), column-major), or the unit vector e_i when dY is NULL. */
static void tab_jac_perturbation(double *dy, const double *dY, int ny, int i, int k) {
  if (dY) {
    memcpy(dy, dY + (size_t)k * ny, sizeof(double) * (size_t)ny);
    return;
  }
  memset(dy, 0, sizeof(double) * (size_t)ny);
  dy[i] = 1;
}

/* out = [δx⁺ for each perturbation] (2nq x m, column-major): the perturbations [δq; δv; δu]
 * the columns of dY ((2nq + nu) x m, column-major), or the unit vectors e_first, ...,
 * e_(first + m − 1) when dY is NULL (the top of the file gives the equations).  Taken in
 * blocks of TAB_JAC_BLOCK, each stage's solves for a whole block in one sweep
 * (tab_jac_solve_many).  Returns 0, or 1 when out of memory. */
static int tab_jac_columns(const double *q, const double *u, double h, const tab_jac_hessian *D,
                           const double *q_next, tab_jac_work *b, const double *dY, int first, int m, double *out) {
  const ncgen_stepper_tables *S = tab_cur;
  const int nq = S->T->nq, nc = S->T->nc, n = nq + nc, ny = 2 * nq + S->nu;
  const double *dq = b->dy, *dv = b->dy + nq, *du = S->nu ? b->dy + 2 * nq : 0;
  const int most = m < TAB_JAC_BLOCK ? m : TAB_JAC_BLOCK;
  double *mem = malloc(sizeof(double) * (size_t)6 * n * most + 1), *R = mem, *Z = R + (size_t)n * most,
         *Y = Z + (size_t)n * most;
  int lo, mb, j, i;
  if (!mem) return 1;
  for (lo = 0; lo < m; lo += mb) {
    mb = m - lo < TAB_JAC_BLOCK ? m - lo : TAB_JAC_BLOCK;
    for (j = 0; j < mb; ++j) {           /* first stage: δr1, solved for δz1 = −K1⁻¹ δr1 */
      tab_jac_perturbation(b->dy, dY, ny, first + lo + j, lo + j);
      tab_jac_forces(q, u, b->sj1, dq, b->zero, du, b);
      memset(b->dr, 0, sizeof(double) * (size_t)n);
      if (dY || (first + lo + j >= nq && first + lo + j < 2 * nq)) tab_mass_times(dv, b->dr);   /* δv ≠ 0 */
      for (i = 0; i < nq; ++i) b->dr[i] = -b->dr[i] - h / 2 * b->dF[i];
      if (dY || first + lo + j < nq) {    /* δq ≠ 0 */
        tab_jac_dA(D, dq, b);
        tab_a_times(b->La, b->z1 + nq, b->dr, 1);
        tab_a_times(b->A1, dq, b->dr + nq, 0);
        for (i = 0; i < nc; ++i) b->dr[nq + i] /= h;
      }
      tab_jac_put(R, n, mb, j, b->dr);
    }
    tab_jac_solve_many(&b->f1, R, Z, mb, Y, b->y);
    for (j = 0; j < mb; ++j) {           /* second stage: δq⁺ = δq + h δw, δr2 */
      double *col = out + (size_t)(lo + j) * 2 * nq;
      tab_jac_perturbation(b->dy, dY, ny, first + lo + j, lo + j);
      tab_jac_get(Z, n, mb, j, b->dz1);
      for (i = 0; i < n; ++i) b->dz1[i] = -b->dz1[i];
      for (i = 0; i < nq; ++i) col[i] = b->dq1[i] = dq[i] + h * b->dz1[i];
      tab_jac_dA(D, b->dq1, b);
      tab_jac_forces(q_next, u, b->sj2, b->dq1, b->dz1, du, b);
      memset(b->dr, 0, sizeof(double) * (size_t)n);
      tab_mass_times(b->dz1, b->dr);
      for (i = 0; i < nq; ++i) b->dr[i] = -b->dr[i] - h / 2 * b->dF[i];
      tab_a_times(b->La, b->z2 + nq, b->dr, 1);
      tab_a_times(b->La, b->z2, b->dr + nq, 0);
      tab_jac_put(R, n, mb, j, b->dr);
    }
    tab_jac_solve_many(&b->f2, R, Z, mb, Y, b->y);   /* δz2 = −K2⁻¹ δr2 */
    for (j = 0; j < mb; ++j)
      for (i = 0; i < nq; ++i) out[(size_t)(lo + j) * 2 * nq + nq + i] = -Z[(size_t)i * mb + j];
  }
  free(mem);
  return 0;
}

/* The step and, when Jx is not NULL, its Jacobians Jx = ∂x⁺/∂x (2nq x 2nq) and Ju = ∂x⁺/∂u
 * (2nq x nu), column-major (see the top of the file); *res: the residual of the solution. */
static int tab_step_jacobians(const double *q, const double *v, double t, const double *u, const double *p,
                              double h, const step_options *o, const tab_jac_hessian *D, double *q_next,
                              double *v_next, double *Jx, double *Ju, double *res, int *iterations) {
  const ncgen_stepper_tables *S = tab_cur;
  const ncgen_tables *T = S->T;
  int nq = T->nq, nc = T->nc, n = nq + nc, nu = S->nu, i, j, status = STEP_BAD_INPUT;
  char *block = malloc(step_work_bytes());
  double *mem = malloc(sizeof(double) * (size_t)tab_jac_size() + 1), *kw = 0, t1 = t + h, r1, r2;
  const double *arg[8];
  double *out[2];
  workspace ws;
  tab_jac_work b;
  tab_work kb;
  if (!block || !mem || !(kw = malloc(sizeof(double) * (size_t)tab_work_size(S) + 1))) goto done;
  layout(&ws, block);
  ws.track_work = 0;
  b = tab_jac_layout(mem);
  kb = tab_layout(kw);
  status = step(q, v, t, u, p, h, q_next, v_next, 0, iterations, o, 0, &ws);
  if (status != STEP_OK) goto done;
  memcpy(b.z1, ws.x, sizeof(double) * (size_t)n);
  /* first stage: one more Newton step, then K1 at the polished z1, factored */
  arg[0] = &t; arg[1] = q; arg[2] = v; arg[3] = u; arg[4] = p; arg[5] = &h; arg[6] = b.z1; arg[7] = b.z1 + nq;
  out[0] = b.r; out[1] = b.K;
  status = STEP_KERNEL;
  if (tab_newton(arg, out, 0, kw, 0) || tab_jac_factor(&b.f1, b.K, b.x)) goto done;
  tab_jac_solve(&b.f1, 0, b.r, b.dz1, b.y);
  for (i = 0; i < n; ++i) b.z1[i] -= b.dz1[i];
  if (tab_newton(arg, out, 0, kw, 0) || tab_jac_factor(&b.f1, b.K, b.x)) goto done;
  memcpy(b.K1, b.K, sizeof(double) * (size_t)S->nnz_k);
  b.f1.K = b.K1;                         /* b.K is K2's below */
  r1 = tab_norm_inf(b.r, n);
  for (i = 0; i < nq; ++i) q_next[i] = q[i] + h * b.z1[i];
  /* second stage at (q⁺, w): K2 z2 = b, factored */
  arg[0] = &t1; arg[1] = q_next; arg[2] = b.z1;
  out[0] = b.r; out[1] = b.K;
  if (tab_velocity(arg, out, 0, kw, 0) || tab_jac_factor(&b.f2, b.K, b.x)) goto done;
  tab_jac_solve(&b.f2, 0, b.r, b.z2, b.y);
  tab_jac_kkt_times(b.K, b.z2, b.dr);
  for (i = 0; i < n; ++i) b.dr[i] -= b.r[i];
  r2 = tab_norm_inf(b.dr, n);
  memcpy(v_next, b.z2, sizeof(double) * (size_t)nq);
  *res = isnan(r1) || isnan(r2) ? NAN : (r1 > r2 ? r1 : r2);
  status = STEP_OK;
  if (!Jx) goto done;
  /* A(q⁺) and the springs' J at both stages */
  status = STEP_KERNEL;
  if (ncgen_tables_phi_jacobian(TAB_KINDS, T, q_next, b.phis, b.A1, b.ew)) goto done;
  if (tab_jac_springs(q, b.z1, b.sj1, &kb) || tab_jac_springs(q_next, b.z1, b.sj2, &kb)) goto done;
  memset(b.zero, 0, sizeof(double) * (size_t)nq);
  /* the reverse passes (6 dof solves, a factorisation, 2 for the check) where they take fewer
   * solves than the columns (2 (2nq + nu)) */
#ifdef TAB_JAC_ROWS                      /* the reverse passes forced (their unit test) */
  i = tab_jac_rows(q, u, h, D, q_next, &b, Jx, Ju);
#else
  i = 3 * (nq - nc) + 3 < 2 * nq + nu ? tab_jac_rows(q, u, h, D, q_next, &b, Jx, Ju) : 1;
#endif
  status = STEP_BAD_INPUT;
  if (i == 2) goto done;
  if (i == 0) {                          /* the rows checked on one forward column */
    double *want = malloc(sizeof(double) * (size_t)(4 * nq + nu) + 1), *dir = want + 2 * nq, scale = 1, err = 0;
    unsigned long long seed = 0x2545F4914F6CDD1DULL;
    if (!want) goto done;
    for (j = 0; j < 2 * nq + nu; ++j) {
      seed = seed * 6364136223846793005ULL + 1442695040888963407ULL;
      dir[j] = (double)(seed >> 11) / 9007199254740992.0 - 0.5;
    }
    if (tab_jac_columns(q, u, h, D, q_next, &b, dir, 0, 1, want)) {
      free(want);
      goto done;
    }
    for (i = 0; i < 2 * nq; ++i) {
      double got = 0;
      for (j = 0; j < 2 * nq + nu; ++j)
        got += (j < 2 * nq ? Jx[i + (size_t)j * 2 * nq] : Ju[i + (size_t)(j - 2 * nq) * 2 * nq]) * dir[j];
      scale = fabs(want[i]) > scale ? fabs(want[i]) : scale;
      err = fabs(got - want[i]) > err || isnan(got) ? fabs(got - want[i]) : err;
    }
    free(want);
    i = err <= TAB_JAC_ROWS_TOL * scale ? 0 : 1;
  }
#ifdef TAB_JAC_ROWS                      /* no fallback: a failed check fails the step */
  status = STEP_KERNEL;
  if (i) goto done;
#endif
  status = STEP_OK;
  if (i != 1) goto done;
  status = STEP_BAD_INPUT;                /* the columns, unit perturbations of x then of u */
  if (tab_jac_columns(q, u, h, D, q_next, &b, 0, 0, 2 * nq, Jx) ||
      (nu && tab_jac_columns(q, u, h, D, q_next, &b, 0, 2 * nq, nu, Ju)))
    goto done;
  status = STEP_OK;
done:
  free(block);
  free(mem);
  free(kw);
  return status;
}

#endif

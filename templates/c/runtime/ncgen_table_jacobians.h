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
 * factored once (sparse QR, ncgen_sparse_qr.h).  A perturbation (δq, δv, δu) of the step's
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
 * columns of ∂x⁺/∂x (2nq x 2nq) and ∂x⁺/∂u (2nq x nu) are these δx⁺ for unit perturbations.
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

/* The scratch of tab_step_jacobians: the factors of K1 and K2 and the vectors of the solves. */
typedef struct {
  double *V1, *R1, *beta1, *V2, *R2, *beta2, *K, *r, *z1, *z2, *dr, *dz1, *dz2, *dq1, *dy, *zero;
  double *A1, *La, *phis, *ew, *fd, *fdw, *sj1, *sj2, *dF, *x, *y;
} tab_jac_work;

/* Doubles of tab_jac_work for the tables of the run in progress. */
static long tab_jac_size(void) {
  const ncgen_stepper_tables *S = tab_cur;
  const ncgen_tables *T = S->T;
  long n = T->nq + T->nc, nf = (long)T->nf * T->dim, nsj = (long)S->n_spring * T->dim * 4 * T->dim;
  return 2 * ((long)S->nnz_v + S->nnz_r + n) + S->nnz_k + 10 * n + (2L * T->nq + S->nu) + T->nq +
         2L * T->a_nnz + T->nq + T->nc + tab_ew_size + 2 * nf + 2 * nsj;
}

static tab_jac_work tab_jac_layout(double *p) {
  const ncgen_stepper_tables *S = tab_cur;
  const ncgen_tables *T = S->T;
  long n = T->nq + T->nc, nf = (long)T->nf * T->dim, nsj = (long)S->n_spring * T->dim * 4 * T->dim;
  tab_jac_work b;
  b.V1 = p; b.R1 = b.V1 + S->nnz_v; b.beta1 = b.R1 + S->nnz_r;
  b.V2 = b.beta1 + n; b.R2 = b.V2 + S->nnz_v; b.beta2 = b.R2 + S->nnz_r;
  b.K = b.beta2 + n; b.r = b.K + S->nnz_k; b.z1 = b.r + n; b.z2 = b.z1 + n; b.dr = b.z2 + n;
  b.dz1 = b.dr + n; b.dz2 = b.dz1 + n; b.dq1 = b.dz2 + n; b.x = b.dq1 + n; b.y = b.x + n;
  b.dy = b.y + 2 * n; b.zero = b.dy + 2 * T->nq + S->nu;
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
  if (tab_newton(arg, out, 0, kw, 0) || ncgen_qr_factor(&S->qr, b.K, b.V1, b.R1, b.beta1, b.x)) goto done;
  ncgen_qr_solve(&S->qr, b.V1, b.R1, b.beta1, b.r, b.dz1, b.y);
  for (i = 0; i < n; ++i) b.z1[i] -= b.dz1[i];
  if (tab_newton(arg, out, 0, kw, 0) || ncgen_qr_factor(&S->qr, b.K, b.V1, b.R1, b.beta1, b.x)) goto done;
  r1 = tab_norm_inf(b.r, n);
  for (i = 0; i < nq; ++i) q_next[i] = q[i] + h * b.z1[i];
  /* second stage at (q⁺, w): K2 z2 = b, factored */
  arg[0] = &t1; arg[1] = q_next; arg[2] = b.z1;
  out[0] = b.r; out[1] = b.K;
  if (tab_velocity(arg, out, 0, kw, 0) || ncgen_qr_factor(&S->qr, b.K, b.V2, b.R2, b.beta2, b.x)) goto done;
  ncgen_qr_solve(&S->qr, b.V2, b.R2, b.beta2, b.r, b.z2, b.y);
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
  for (j = 0; j < 2 * nq + nu; ++j) {
    const double *dq = b.dy, *dv = b.dy + nq, *du = j >= 2 * nq ? b.dy + 2 * nq : 0;
    double *col = j < 2 * nq ? Jx + (size_t)j * 2 * nq : Ju + (size_t)(j - 2 * nq) * 2 * nq;
    memset(b.dy, 0, sizeof(double) * (size_t)(2 * nq + nu));
    b.dy[j] = 1;
    /* first stage: δz1 = −K1⁻¹ δr1 */
    tab_jac_forces(q, u, b.sj1, dq, b.zero, du, &b);
    memset(b.dr, 0, sizeof(double) * (size_t)n);
    tab_mass_times(dv, b.dr);
    for (i = 0; i < nq; ++i) b.dr[i] = -b.dr[i] - h / 2 * b.dF[i];
    if (j < nq) {
      tab_jac_dA(D, dq, &b);
      tab_a_times(b.La, b.z1 + nq, b.dr, 1);
      tab_a_times(b.A1, dq, b.dr + nq, 0);
      for (i = 0; i < nc; ++i) b.dr[nq + i] /= h;
    }
    ncgen_qr_solve(&S->qr, b.V1, b.R1, b.beta1, b.dr, b.dz1, b.y);
    for (i = 0; i < n; ++i) b.dz1[i] = -b.dz1[i];
    /* second stage: δq⁺ = δq + h δw, δz2 = −K2⁻¹ δr2 */
    for (i = 0; i < nq; ++i) b.dq1[i] = dq[i] + h * b.dz1[i];
    tab_jac_dA(D, b.dq1, &b);
    tab_jac_forces(q_next, u, b.sj2, b.dq1, b.dz1, du, &b);
    memset(b.dr, 0, sizeof(double) * (size_t)n);
    tab_mass_times(b.dz1, b.dr);
    for (i = 0; i < nq; ++i) b.dr[i] = -b.dr[i] - h / 2 * b.dF[i];
    tab_a_times(b.La, b.z2 + nq, b.dr, 1);
    tab_a_times(b.La, b.z2, b.dr + nq, 0);
    ncgen_qr_solve(&S->qr, b.V2, b.R2, b.beta2, b.dr, b.dz2, b.y);
    for (i = 0; i < nq; ++i) {
      col[i] = b.dq1[i];
      col[nq + i] = -b.dz2[i];
    }
  }
  status = STEP_OK;
done:
  free(block);
  free(mem);
  free(kw);
  return status;
}

#endif

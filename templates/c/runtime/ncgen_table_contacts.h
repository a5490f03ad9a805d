/* Nonsmooth contacts on the stepper tables (ncgen_table_stepper.h): the sizes and tables that
 * ncgen_contact.h, ncgen_cone_newton.h and ncgen_contact_pairs.h read as macros are the fields
 * of the run's contact tables (tab_cur->ct, an ncgen_contact_tables packed by
 * ncgen/codegen/contact_tables.py), and an element's rows come from the pair kinds of the
 * library (tab_pair_eval) instead of a per-model kernel.  Included by ncgen_table_stepper.h
 * before ncgen_rattle.h when NCGEN_CONTACTS is defined.
 *
 * What the including file defines first (besides ncgen_table_stepper.h's list): TAB_PAIR_KINDS
 * (a const ncgen_pair_kind *), N_PAIR_KINDS, TAB_PAIR_W (the largest work of their kernels),
 * TAB_PAIR_QC (the largest canonical side: dim (k + 1) coordinates), and the model-independent
 * constants of ncgen_contact.h (PGS_MAX_ITER, PGS_TOL, CONTACT_REFINE_MAX, CONTACT_REFINE_TOL,
 * PENETRATION_TOL, GAP_REACH, REPEAT_TOL). */
#ifndef NCGEN_TABLE_CONTACTS_H
#define NCGEN_TABLE_CONTACTS_H

/* Element e's gaps (res[0]: its point contacts') and, if rows, its dense W (res[1]: per point
 * contact its normal row, then its tangent rows, zero without friction; columns: the local
 * coordinates arg[0] of its first side, then arg[1] of its second), as its per-model kernel
 * step_pair<k>_rows gives them: each point contact's kind on the canonical coordinates of the
 * two sides (q_c = B q_local, B's nonzeros cm_*), its W mapped back, W_local = W_c B (an
 * element's last results are kept by ncgen_contact_pairs.h's pair_eval()).  w: TAB_PAIR_WORK
 * doubles (ncgen_table_stepper.h).  Returns 0, or 1 when a kernel failed. */
static int tab_pair_eval(const casadi_real **arg, casadi_real **res, casadi_real *w, int e, int rows) {
  const struct ncgen_contact_tables *C = tab_cur->ct;
  const int *pi = C->pair_int + 8 * e, dim = tab_cur->T->dim;
  const int count = pi[2], nrow = pi[2] * dim, n[2] = {pi[3], pi[4]};
  const size_t nw = (size_t)nrow * (size_t)(n[0] + n[1]);
  casadi_real *qc = w + TAB_PAIR_W, *x = qc + 2 * TAB_PAIR_QC, *g = x + 2 * TAB_PAIR_QC, *Wc = g + 1;
  int ncs[2], lo[2], hi[2], s, j, d, k, t;
  for (s = 0; s < 2; ++s) {
    ncs[s] = C->cm_n[2 * e + s];
    lo[s] = C->cm_ptr[2 * e + s];
    hi[s] = C->cm_ptr[2 * e + s + 1];
    memset(qc + s * TAB_PAIR_QC, 0, sizeof(casadi_real) * (size_t)ncs[s]);
    for (t = lo[s]; t < hi[s]; ++t) qc[s * TAB_PAIR_QC + C->cm_row[t]] += C->cm[t] * arg[s][C->cm_col[t]];
  }
  if (rows) memset(res[1], 0, sizeof(casadi_real) * nw);
  for (j = 0; j < count; ++j) {
    const int pc = pi[1] + j, sa = C->pk_swap[pc];
    const ncgen_pair_kind *K = &TAB_PAIR_KINDS[C->pk_kind[pc]];
    const double *karg[2];
    double *kres[2];
    memcpy(x, qc + sa * TAB_PAIR_QC, sizeof(casadi_real) * (size_t)ncs[sa]);
    memcpy(x + ncs[sa], qc + (1 - sa) * TAB_PAIR_QC, sizeof(casadi_real) * (size_t)ncs[1 - sa]);
    karg[0] = x;
    karg[1] = C->pk_c + C->pk_c_ptr[pc];
    kres[0] = g;
    kres[1] = Wc;
    if (K->eval(karg, kres, 0, w, 0)) return 1;
    res[0][j] = *g;
    if (!rows) continue;
    for (k = 0; k < 2; ++k) {                         /* the kind's sides: its columns off .. */
      const int side = k ? 1 - sa : sa, off = k ? ncs[sa] : 0, base = side ? n[0] : 0;
      for (t = lo[side]; t < hi[side]; ++t) {         /* W_local[:, i] += W_c[:, off + c] B[c, i] */
        const casadi_real b = C->cm[t], *wc = Wc + dim * (off + C->cm_row[t]);
        casadi_real *out = res[1] + j * dim + (size_t)nrow * (size_t)(base + C->cm_col[t]);
        for (d = 0; d < (C->mu[pc] > 0 ? dim : 1); ++d) out[d] += wc[d] * b;  /* frictionless: tangents 0 */
      }
    }
  }
  return 0;
}

static int tab_in_range(const int *x, int n, int lo, int hi) {
  int i;
  for (i = 0; i < n; ++i)
    if (x[i] < lo || x[i] >= hi) return 0;
  return 1;
}

/* 0 when the contact tables of S are consistent with S and the library's kinds, else 1. */
static int tab_contacts_check(const ncgen_stepper_tables *S) {
  const struct ncgen_contact_tables *C = S->ct;
  const ncgen_tables *T = S->T;
  int e, s, j, dim = T->dim, nd;
  if (!C || C->nk < 1 || C->ne < 1 || C->ns < 0 || C->max_q < 1 || C->max_g < 1 || C->max_w < 1) return 1;
  nd = C->nk * dim;
  if (C->wt_colind[0] != 0 || C->wt_colind[nd] != C->nnz_w || !tab_in_range(C->wt_row, C->nnz_w, 0, T->nq) ||
      !tab_in_range(C->pk_kind, C->nk, 0, N_PAIR_KINDS) || !tab_in_range(C->pk_swap, C->nk, 0, 2) ||
      C->pk_c_ptr[0] != 0 || C->cm_ptr[0] != 0 || !tab_in_range(C->pair_sid, 2 * C->ne, -1, C->ns) ||
      !tab_in_range(C->pair_srep, 2 * C->ns, 0, C->ne))
    return 1;
  for (j = 0; j < nd; ++j)
    if (C->wt_colind[j + 1] < C->wt_colind[j]) return 1;
  if (C->schur) {                       /* M⁻¹'s nonzeros by columns, A's columns */
    if (C->minv_colind[0] != 0 || !tab_in_range(C->a_col, T->a_nnz, 0, T->nq)) return 1;
    for (j = 0; j < T->nq; ++j)
      if (C->minv_colind[j + 1] < C->minv_colind[j] ||
          !tab_in_range(C->minv_row + C->minv_colind[j], C->minv_colind[j + 1] - C->minv_colind[j], 0, T->nq))
        return 1;
    for (j = 0; j < T->a_nnz; ++j)
      if (j && C->a_col[j] < C->a_col[j - 1]) return 1;
  }
  for (e = 0, j = 0; e < C->ne; ++e) {
    const int *pi = C->pair_int + 8 * e, nloc = pi[3] + pi[4];
    if (pi[1] != j || pi[2] < 1 || pi[2] > C->max_g || nloc > C->max_q || pi[2] * dim * nloc > C->max_w ||
        !tab_in_range(C->pair_qidx + pi[5], nloc, -1, T->nq) ||
        !tab_in_range(C->pair_wpos + pi[6], pi[2] * dim * nloc, -1, C->nnz_w))
      return 1;
    for (s = 0; s < 2; ++s) {
      const int nc = C->cm_n[2 * e + s], lo = C->cm_ptr[2 * e + s], hi = C->cm_ptr[2 * e + s + 1];
      if (nc < 0 || nc > TAB_PAIR_QC || hi < lo || !tab_in_range(C->cm_row + lo, hi - lo, 0, nc) ||
          !tab_in_range(C->cm_col + lo, hi - lo, 0, pi[3 + s]) || !tab_in_range(C->pair_side + 6 * e + 3 * s, 1, 0, 4))
        return 1;
    }
    for (; j < pi[1] + pi[2]; ++j) {
      const ncgen_pair_kind *K = &TAB_PAIR_KINDS[C->pk_kind[j]];
      const int sa = C->pk_swap[j];
      if (K->dim != dim || K->n_a != C->cm_n[2 * e + sa] || K->n_b != C->cm_n[2 * e + 1 - sa] ||
          C->pk_c_ptr[j + 1] - C->pk_c_ptr[j] != K->n_c)
        return 1;
    }
  }
  return j != C->nk;
}

/* The names ncgen_contact*.h read (after the functions above, which read the fields). */
#define tab_ct (tab_cur->ct)
#define NK (tab_ct->nk)
#define DC (tab_cur->T->dim)
#define mu (tab_ct->mu)
#define restitution (tab_ct->restitution)
/* the start-of-step contact velocities are computed whatever the coefficients (e = 0 makes
 * their terms zero) */
#define ANY_RESTITUTION
#define GRAVITY_NORM (tab_ct->gravity_norm)
#define NNZ_W (tab_ct->nnz_w)
#define wt_colind (tab_ct->wt_colind)
#define wt_row (tab_ct->wt_row)
#define CONTACT_PAIRS
#define NE (tab_ct->ne)
#define PAIR_MAX_Q (tab_ct->max_q)
#define PAIR_MAX_G (tab_ct->max_g)
#define PAIR_MAX_W (tab_ct->max_w)
#define PAIR_NS (tab_ct->ns)
#define pair_int (tab_ct->pair_int)
#define pair_qidx (tab_ct->pair_qidx)
#define pair_qconst (tab_ct->pair_qconst)
#define pair_wpos (tab_ct->pair_wpos)
#define pair_side (tab_ct->pair_side)
#define pair_bdata (tab_ct->pair_bdata)
#define pair_bound (tab_ct->pair_bound)
#define pair_sid (tab_ct->pair_sid)
#define pair_srep (tab_ct->pair_srep)
/* PAIR_KERNEL(pair_gap_fn | pair_rows_fn, e, ws) of ncgen_contact_pairs.h: the pair kinds */
#define pair_gap_fn 0
#define pair_rows_fn 1
#define PAIR_KERNEL(rows, e, ws) tab_pair_eval((ws)->arg, (ws)->res, (ws)->w, (e), (rows))
/* The Delassus matrix by the Schur complement of ncgen_contact.h where M is regular (schur):
 * M⁻¹ from the contact tables, A's nonzeros from the stepper tables (their positions k_apos in
 * the KKT matrix's lower block, rows a_row) and A's columns a_col; ncgen_table_stepper.h
 * undefines a_nz, a_row, a_col after the runtime. */
#define CONTACT_SCHUR
#define CONTACT_A_RUNTIME
#define SCHUR_READY (tab_ct->schur)
#define minv (tab_ct->minv)
#define minv_colind (tab_ct->minv_colind)
#define minv_row (tab_ct->minv_row)
#define NNZ_A (tab_cur->T->a_nnz)
#define a_nz (tab_cur->k_apos)
#define a_row (tab_cur->a_row)
#define a_col (tab_ct->a_col)
#endif

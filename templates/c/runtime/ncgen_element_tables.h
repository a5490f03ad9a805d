/* Table-driven system functions: Φ(q), A = ∂Φ/∂q, Φ_t, γ and the constant mass matrix M of a
 * whole model, as loops over index tables that call one small kernel per kind of element
 * (ncgen/codegen/element_kernels.py generates the kernels, ncgen/codegen/model_tables.py
 * packs the tables).  The same C for every model: a model is data.
 *
 * Notation (docs/architecture.md, "Element tables"):
 *   feature f   a point or direction of a member, affine in q:  f = G q + g  (dim components);
 *               entries e of feature i: feat_ptr[i] <= e < feat_ptr[i+1], component feat_row[e],
 *               coordinate feat_col[e], coefficient feat_coef[e]; g = feat_const[i*dim ...].
 *   joint element   kind el_kind[k] (index into the joint kinds), vector arguments the features
 *               el_arg[el_arg_ptr[k] ...], scalars el_sc[el_sc_ptr[k] ...]; output r goes to
 *               row el_row[el_row_ptr[k] + r] of Φ (-1: not a row of the model).
 *   member element  kind mem_kind[k] (index into the member kinds), local coordinates
 *               q_I[i] = q[mem_q_col[...]] or mem_q_const[...] where the column is -1 (a
 *               ground point), constants mem_c[mem_c_ptr[k] ...], output rows mem_row[...].
 *   A, M        compressed sparse column, nonzeros only; el_apos / mem_apos give, in the
 *               order the loops below visit them, the nonzero each product is added to;
 *               mem_mpos the nonzero of M of each entry (i, j) of M_I with both columns free.
 *
 * Kernels have CasADi's signature and need no integer work (sz_iw = 0); their real work, at
 * most max_w doubles, is part of the caller's work array (ncgen_tables_work_size).
 * Call ncgen_tables_check once on new tables: the loops trust them (they index without
 * checks).  The loops return 0, or NCGEN_TABLES_KERNEL when a kernel failed. */
#ifndef NCGEN_ELEMENT_TABLES_H
#define NCGEN_ELEMENT_TABLES_H

#include <string.h>

#define NCGEN_TABLES_KERNEL 1
#define NCGEN_TABLES_BAD 2

typedef int (*ncgen_kernel)(const double **arg, double **res, long long *iw, double *w, int mem);

/* A joint kind: x = [f_1; ...; f_n_vec; s_1; ...] -> phi (n_out), J = dphi/df (n_out x n_vec*dim)
 * by eval; (x, fdot) -> [fdotᵀ ∇²_f phi_r fdot]_r (n_out) by hvv. */
typedef struct {
  ncgen_kernel eval, hvv;
  int dim, n_vec, n_scalar, n_out;
} ncgen_joint_kind;

/* A member kind: (q_I, c) -> phi (n_out), J (n_out x n_q) by phi; (q̇_I, c) -> [q̇_Iᵀ H_k q̇_I]_k
 * (n_out) by hvv (both NULL when n_out = 0); c -> M_I (n_q x n_q) by mass. */
typedef struct {
  ncgen_kernel phi, hvv, mass;
  int n_q, n_c, n_out;
} ncgen_member_kind;

/* A force kind over features (the stepper's, ncgen_table_stepper.h): its kernel (y = [g; V; P]
 * and J = ∂g/∂ḟ from x = [f; ḟ; numbers]), the features' size, their number and the numbers'. */
typedef struct {
  ncgen_kernel eval;
  int dim, n_feat, n_par;
} ncgen_feature_force_kind;

/* A member kind's torque kernel (the stepper's: Q_I = W(q_I)ᵀ τ from x = [q_I; c_W; τ]; NULL
 * without W) and the number of constants c_W. */
typedef struct {
  ncgen_kernel eval;
  int n_c;
} ncgen_torque_kind;

/* A contact pair kind (the contact library's stepper, ncgen_table_contacts.h;
 * ncgen/assembly/pair_kinds.py): its kernel q = [q_a; q_b], c -> g, W (dim x (n_a + n_b)) and the
 * sizes of its sides' canonical coordinates and of its numbers c. */
typedef struct {
  ncgen_kernel eval;
  int dim, n_a, n_b, n_c;
} ncgen_pair_kind;

typedef struct {
  const ncgen_joint_kind *joint;
  int n_joint;
  const ncgen_member_kind *member;
  int n_member;
  int max_w;                       /* largest real work of a kernel */
} ncgen_kinds;

typedef struct {
  int nq, nc, dim, a_nnz, m_nnz;
  int nf;
  const int *feat_ptr, *feat_row, *feat_col;
  const double *feat_coef, *feat_const;
  int ne;
  const int *el_kind, *el_arg_ptr, *el_arg, *el_sc_ptr;
  const double *el_sc;
  const int *el_row_ptr, *el_row, *el_apos_ptr, *el_apos;
  int nm;
  const int *mem_kind, *mem_q_ptr, *mem_q_col;
  const double *mem_q_const;
  const int *mem_c_ptr;
  const double *mem_c;
  const int *mem_row_ptr, *mem_row, *mem_apos_ptr, *mem_apos, *mem_mpos_ptr, *mem_mpos;
} ncgen_tables;

static int ncgen_tables_max_in(const ncgen_kinds *K) {
  int i, n = 1;
  for (i = 0; i < K->n_joint; ++i) {
    const ncgen_joint_kind *k = &K->joint[i];
    int m = 2 * k->n_vec * k->dim + k->n_scalar;     /* x and fdot */
    if (m > n) n = m;
  }
  for (i = 0; i < K->n_member; ++i)
    if (K->member[i].n_q + K->member[i].n_c > n) n = K->member[i].n_q + K->member[i].n_c;
  return n;
}

static int ncgen_tables_max_out(const ncgen_kinds *K) {
  int i, n = 1;
  for (i = 0; i < K->n_joint; ++i) {
    const ncgen_joint_kind *k = &K->joint[i];
    int m = k->n_out * (1 + k->n_vec * k->dim);
    if (m > n) n = m;
  }
  for (i = 0; i < K->n_member; ++i) {
    const ncgen_member_kind *k = &K->member[i];
    int m = k->n_out * (1 + k->n_q);
    if (m > n) n = m;
    if (k->n_q * k->n_q > n) n = k->n_q * k->n_q;
  }
  return n;
}

/* Doubles of work the functions below need for the tables T. */
static long ncgen_tables_work_size(const ncgen_kinds *K, const ncgen_tables *T) {
  return 2L * T->nf * T->dim + ncgen_tables_max_in(K) + ncgen_tables_max_out(K) + K->max_w;
}

static int ncgen_in_range(int x, int lo, int hi) { return x >= lo && x < hi; }

/* 0 when every index of T is in range and every element's sizes match its kind; otherwise
 * NCGEN_TABLES_BAD (so that no loop reads or writes out of bounds). */
static int ncgen_tables_check(const ncgen_kinds *K, const ncgen_tables *T) {
  int i, e;
  if (T->nq < 0 || T->nc < 0 || T->nf < 0 || T->ne < 0 || T->nm < 0 || T->a_nnz < 0 || T->m_nnz < 0 ||
      T->dim < 2 || T->dim > 3)
    return NCGEN_TABLES_BAD;
  if (T->feat_ptr[0] != 0) return NCGEN_TABLES_BAD;
  for (i = 0; i < T->nf; ++i) {
    if (T->feat_ptr[i + 1] < T->feat_ptr[i]) return NCGEN_TABLES_BAD;
    for (e = T->feat_ptr[i]; e < T->feat_ptr[i + 1]; ++e)
      if (!ncgen_in_range(T->feat_row[e], 0, T->dim) || !ncgen_in_range(T->feat_col[e], 0, T->nq))
        return NCGEN_TABLES_BAD;
  }
  if (T->el_arg_ptr[0] != 0 || T->el_sc_ptr[0] != 0 || T->el_row_ptr[0] != 0 || T->el_apos_ptr[0] != 0)
    return NCGEN_TABLES_BAD;
  for (i = 0; i < T->ne; ++i) {
    const ncgen_joint_kind *k;
    int a, r, n_pos = 0;
    if (!ncgen_in_range(T->el_kind[i], 0, K->n_joint)) return NCGEN_TABLES_BAD;
    k = &K->joint[T->el_kind[i]];
    if (k->dim != T->dim || T->el_arg_ptr[i + 1] - T->el_arg_ptr[i] != k->n_vec ||
        T->el_sc_ptr[i + 1] - T->el_sc_ptr[i] != k->n_scalar || T->el_row_ptr[i + 1] - T->el_row_ptr[i] != k->n_out)
      return NCGEN_TABLES_BAD;
    for (a = T->el_arg_ptr[i]; a < T->el_arg_ptr[i + 1]; ++a)
      if (!ncgen_in_range(T->el_arg[a], 0, T->nf)) return NCGEN_TABLES_BAD;
    for (r = T->el_row_ptr[i]; r < T->el_row_ptr[i + 1]; ++r) {
      if (T->el_row[r] < -1 || T->el_row[r] >= T->nc) return NCGEN_TABLES_BAD;
      if (T->el_row[r] < 0) continue;
      for (a = T->el_arg_ptr[i]; a < T->el_arg_ptr[i + 1]; ++a)
        n_pos += T->feat_ptr[T->el_arg[a] + 1] - T->feat_ptr[T->el_arg[a]];
    }
    if (T->el_apos_ptr[i + 1] - T->el_apos_ptr[i] != n_pos) return NCGEN_TABLES_BAD;
    for (e = T->el_apos_ptr[i]; e < T->el_apos_ptr[i + 1]; ++e)
      if (!ncgen_in_range(T->el_apos[e], 0, T->a_nnz)) return NCGEN_TABLES_BAD;
  }
  if (T->mem_q_ptr[0] != 0 || T->mem_c_ptr[0] != 0 || T->mem_row_ptr[0] != 0 || T->mem_apos_ptr[0] != 0 ||
      T->mem_mpos_ptr[0] != 0)
    return NCGEN_TABLES_BAD;
  for (i = 0; i < T->nm; ++i) {
    const ncgen_member_kind *k;
    int r, n_free = 0, n_rows = 0;
    if (!ncgen_in_range(T->mem_kind[i], 0, K->n_member)) return NCGEN_TABLES_BAD;
    k = &K->member[T->mem_kind[i]];
    if (T->mem_q_ptr[i + 1] - T->mem_q_ptr[i] != k->n_q || T->mem_c_ptr[i + 1] - T->mem_c_ptr[i] != k->n_c ||
        T->mem_row_ptr[i + 1] - T->mem_row_ptr[i] != k->n_out)
      return NCGEN_TABLES_BAD;
    for (e = T->mem_q_ptr[i]; e < T->mem_q_ptr[i + 1]; ++e) {
      if (T->mem_q_col[e] < -1 || T->mem_q_col[e] >= T->nq) return NCGEN_TABLES_BAD;
      n_free += T->mem_q_col[e] >= 0;
    }
    for (r = T->mem_row_ptr[i]; r < T->mem_row_ptr[i + 1]; ++r) {
      if (T->mem_row[r] < -1 || T->mem_row[r] >= T->nc) return NCGEN_TABLES_BAD;
      n_rows += T->mem_row[r] >= 0;
    }
    if (T->mem_apos_ptr[i + 1] - T->mem_apos_ptr[i] != n_rows * n_free ||
        T->mem_mpos_ptr[i + 1] - T->mem_mpos_ptr[i] != n_free * n_free)
      return NCGEN_TABLES_BAD;
    for (e = T->mem_apos_ptr[i]; e < T->mem_apos_ptr[i + 1]; ++e)
      if (!ncgen_in_range(T->mem_apos[e], 0, T->a_nnz)) return NCGEN_TABLES_BAD;
    for (e = T->mem_mpos_ptr[i]; e < T->mem_mpos_ptr[i + 1]; ++e)
      if (!ncgen_in_range(T->mem_mpos[e], 0, T->m_nnz)) return NCGEN_TABLES_BAD;
  }
  return 0;
}

/* Every feature's value f = G q + g into F (nf x dim, row-major); with g = NULL, G q (the
 * features' rates for q = q̇). */
static void ncgen_tables_features(const ncgen_tables *T, const double *q, double *F, const double *g) {
  int i, e;
  if (g) memcpy(F, g, sizeof(double) * (size_t)T->nf * (size_t)T->dim);
  else memset(F, 0, sizeof(double) * (size_t)T->nf * (size_t)T->dim);
  for (i = 0; i < T->nf; ++i)
    for (e = T->feat_ptr[i]; e < T->feat_ptr[i + 1]; ++e)
      F[i * T->dim + T->feat_row[e]] += T->feat_coef[e] * q[T->feat_col[e]];
}

/* The kernel of joint element i at the features F: phi in out[0 .. n_out), J after it. */
static int ncgen_tables_joint(const ncgen_kinds *K, const ncgen_tables *T, int i, const double *F, double *x,
                              double *out, double *w) {
  const ncgen_joint_kind *k = &K->joint[T->el_kind[i]];
  const double *arg[1];
  double *res[2];
  int a, n = 0, s;
  for (a = T->el_arg_ptr[i]; a < T->el_arg_ptr[i + 1]; ++a, n += T->dim)
    memcpy(x + n, F + T->el_arg[a] * T->dim, sizeof(double) * (size_t)T->dim);
  for (s = T->el_sc_ptr[i]; s < T->el_sc_ptr[i + 1]; ++s) x[n++] = T->el_sc[s];
  arg[0] = x;
  res[0] = out;
  res[1] = out + k->n_out;
  return k->eval(arg, res, 0, w, 0) ? NCGEN_TABLES_KERNEL : 0;
}

/* The kernel of member element i at q: phi in out[0 .. n_out), J after it. */
static int ncgen_tables_member(const ncgen_kinds *K, const ncgen_tables *T, int i, const double *q, double *x,
                               double *out, double *w) {
  const ncgen_member_kind *k = &K->member[T->mem_kind[i]];
  const double *arg[2];
  double *res[2];
  int j, b = T->mem_q_ptr[i];
  for (j = 0; j < k->n_q; ++j)
    x[j] = T->mem_q_col[b + j] >= 0 ? q[T->mem_q_col[b + j]] : T->mem_q_const[b + j];
  memcpy(x + k->n_q, T->mem_c + T->mem_c_ptr[i], sizeof(double) * (size_t)k->n_c);
  arg[0] = x;
  arg[1] = x + k->n_q;
  res[0] = out;
  res[1] = out + k->n_out;
  return k->phi(arg, res, 0, w, 0) ? NCGEN_TABLES_KERNEL : 0;
}

/* Φ(q) into phi (nc); work: ncgen_tables_work_size doubles. */
static int ncgen_tables_phi(const ncgen_kinds *K, const ncgen_tables *T, const double *q, double *phi,
                            double *work) {
  double *F = work, *x = F + 2 * (size_t)T->nf * T->dim, *out = x + ncgen_tables_max_in(K);
  double *w = out + ncgen_tables_max_out(K);
  int i, r;
  memset(phi, 0, sizeof(double) * (size_t)T->nc);
  for (i = 0; i < T->nm; ++i) {
    if (K->member[T->mem_kind[i]].n_out == 0) continue;
    if (ncgen_tables_member(K, T, i, q, x, out, w)) return NCGEN_TABLES_KERNEL;
    for (r = 0; r < K->member[T->mem_kind[i]].n_out; ++r)
      if (T->mem_row[T->mem_row_ptr[i] + r] >= 0) phi[T->mem_row[T->mem_row_ptr[i] + r]] = out[r];
  }
  ncgen_tables_features(T, q, F, T->feat_const);
  for (i = 0; i < T->ne; ++i) {
    if (ncgen_tables_joint(K, T, i, F, x, out, w)) return NCGEN_TABLES_KERNEL;
    for (r = 0; r < K->joint[T->el_kind[i]].n_out; ++r)
      if (T->el_row[T->el_row_ptr[i] + r] >= 0) phi[T->el_row[T->el_row_ptr[i] + r]] = out[r];
  }
  return 0;
}

/* Φ(q) into phi (nc, if not NULL) and the nonzeros of A(q) = ∂Φ/∂q (a_nnz, the pattern of
 * the tables) into A, from one evaluation of each kernel. */
static int ncgen_tables_phi_jacobian(const ncgen_kinds *K, const ncgen_tables *T, const double *q, double *phi,
                                     double *A, double *work) {
  double *F = work, *x = F + 2 * (size_t)T->nf * T->dim, *out = x + ncgen_tables_max_in(K);
  double *w = out + ncgen_tables_max_out(K);
  int i, r, j, a, e;
  memset(A, 0, sizeof(double) * (size_t)T->a_nnz);
  if (phi) memset(phi, 0, sizeof(double) * (size_t)T->nc);
  for (i = 0; i < T->nm; ++i) {
    const ncgen_member_kind *k = &K->member[T->mem_kind[i]];
    const int *pos = T->mem_apos + T->mem_apos_ptr[i];
    if (k->n_out == 0) continue;
    if (ncgen_tables_member(K, T, i, q, x, out, w)) return NCGEN_TABLES_KERNEL;
    for (r = 0; r < k->n_out; ++r) {
      int row = T->mem_row[T->mem_row_ptr[i] + r];
      if (row < 0) continue;
      if (phi) phi[row] = out[r];
      for (j = 0; j < k->n_q; ++j)       /* J is column-major, n_out x n_q */
        if (T->mem_q_col[T->mem_q_ptr[i] + j] >= 0) A[*pos++] += out[k->n_out + j * k->n_out + r];
    }
  }
  ncgen_tables_features(T, q, F, T->feat_const);
  for (i = 0; i < T->ne; ++i) {
    const ncgen_joint_kind *k = &K->joint[T->el_kind[i]];
    const int *pos = T->el_apos + T->el_apos_ptr[i];
    if (ncgen_tables_joint(K, T, i, F, x, out, w)) return NCGEN_TABLES_KERNEL;
    for (r = 0; r < k->n_out; ++r) {
      int row = T->el_row[T->el_row_ptr[i] + r];
      if (row < 0) continue;
      if (phi) phi[row] = out[r];
      for (a = 0; a < k->n_vec; ++a) {
        int f = T->el_arg[T->el_arg_ptr[i] + a];
        for (e = T->feat_ptr[f]; e < T->feat_ptr[f + 1]; ++e)   /* dΦ_r/df · ∂f/∂q_col */
          A[*pos++] += out[k->n_out + (a * T->dim + T->feat_row[e]) * k->n_out + r] * T->feat_coef[e];
      }
    }
  }
  return 0;
}

/* The nonzeros of A(q) = ∂Φ/∂q (a_nnz, the pattern of the tables) into A. */
static int ncgen_tables_jacobian(const ncgen_kinds *K, const ncgen_tables *T, const double *q, double *A,
                                 double *work) {
  return ncgen_tables_phi_jacobian(K, T, q, 0, A, work);
}

/* γ(q, v) = −[vᵀ H_r v]_r (nc): the acceleration right-hand side of A q̈ = γ for scleronomic
 * constraints (Φ quadratic in q: constant Hessians H_r); work as ncgen_tables_phi. */
static int ncgen_tables_gamma(const ncgen_kinds *K, const ncgen_tables *T, const double *q, const double *v,
                              double *gamma, double *work) {
  double *F = work, *Fd = F + (size_t)T->nf * T->dim, *x = Fd + (size_t)T->nf * T->dim;
  double *out = x + ncgen_tables_max_in(K), *w = out + ncgen_tables_max_out(K);
  const double *arg[2];
  double *res[1];
  int i, j, r, a, s, n;
  memset(gamma, 0, sizeof(double) * (size_t)T->nc);
  for (i = 0; i < T->nm; ++i) {
    const ncgen_member_kind *k = &K->member[T->mem_kind[i]];
    int b = T->mem_q_ptr[i];
    if (k->n_out == 0) continue;
    for (j = 0; j < k->n_q; ++j) x[j] = T->mem_q_col[b + j] >= 0 ? v[T->mem_q_col[b + j]] : 0.0;
    arg[0] = x;
    arg[1] = T->mem_c + T->mem_c_ptr[i];
    res[0] = out;
    if (k->hvv(arg, res, 0, w, 0)) return NCGEN_TABLES_KERNEL;
    for (r = 0; r < k->n_out; ++r)
      if (T->mem_row[T->mem_row_ptr[i] + r] >= 0) gamma[T->mem_row[T->mem_row_ptr[i] + r]] = -out[r];
  }
  ncgen_tables_features(T, q, F, T->feat_const);
  ncgen_tables_features(T, v, Fd, 0);
  for (i = 0; i < T->ne; ++i) {
    const ncgen_joint_kind *k = &K->joint[T->el_kind[i]];
    double *xd = x + k->n_vec * T->dim + k->n_scalar;
    for (a = T->el_arg_ptr[i], n = 0; a < T->el_arg_ptr[i + 1]; ++a, n += T->dim) {
      memcpy(x + n, F + T->el_arg[a] * T->dim, sizeof(double) * (size_t)T->dim);
      memcpy(xd + n, Fd + T->el_arg[a] * T->dim, sizeof(double) * (size_t)T->dim);
    }
    for (s = T->el_sc_ptr[i]; s < T->el_sc_ptr[i + 1]; ++s) x[n++] = T->el_sc[s];
    arg[0] = x;
    arg[1] = xd;
    res[0] = out;
    if (k->hvv(arg, res, 0, w, 0)) return NCGEN_TABLES_KERNEL;
    for (r = 0; r < k->n_out; ++r)
      if (T->el_row[T->el_row_ptr[i] + r] >= 0) gamma[T->el_row[T->el_row_ptr[i] + r]] = -out[r];
  }
  return 0;
}

/* ∂Φ/∂t (nc): every element of the tables is scleronomic (ncgen/codegen/model_tables.py
 * refuses geometry or scalars that depend on t), so it is zero. */
static int ncgen_tables_phi_t(const ncgen_tables *T, double *phi_t) {
  memset(phi_t, 0, sizeof(double) * (size_t)T->nc);
  return 0;
}

/* The nonzeros of the constant mass matrix M (m_nnz) into M. */
static int ncgen_tables_mass(const ncgen_kinds *K, const ncgen_tables *T, double *M, double *work) {
  double *x = work + 2 * (size_t)T->nf * T->dim, *out = x + ncgen_tables_max_in(K);
  double *w = out + ncgen_tables_max_out(K);
  int i, j, l;
  memset(M, 0, sizeof(double) * (size_t)T->m_nnz);
  for (i = 0; i < T->nm; ++i) {
    const ncgen_member_kind *k = &K->member[T->mem_kind[i]];
    const int *col = T->mem_q_col + T->mem_q_ptr[i], *pos = T->mem_mpos + T->mem_mpos_ptr[i];
    const double *arg[1];
    double *res[1];
    memcpy(x, T->mem_c + T->mem_c_ptr[i], sizeof(double) * (size_t)k->n_c);
    arg[0] = x;
    res[0] = out;
    if (k->mass(arg, res, 0, w, 0)) return NCGEN_TABLES_KERNEL;
    for (l = 0; l < k->n_q; ++l)          /* M_I column-major; entries with both columns free */
      for (j = 0; j < k->n_q; ++j)
        if (col[l] >= 0 && col[j] >= 0) M[*pos++] += out[l * k->n_q + j];
  }
  return 0;
}

#endif

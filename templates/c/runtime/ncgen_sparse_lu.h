/* Sparse LU of a square matrix with a symmetric pattern, without pivoting, in an order and
 * over factor patterns analysed beforehand, and the solve with its factors: plain C99, the
 * same for every matrix.
 *
 * The symbolic analysis (done once per pattern, in Python: ncgen/codegen/stepper_tables.py)
 * gives an order p (row and column c of the ordered matrix are row and column p[c] of K;
 * pinv its inverse) and the pattern of L (unit lower triangular, diagonal not stored) of
 * K(p, p) = L D U: column c of L holds rows > c, column c of U rows < c (U unit upper
 * triangular, the pattern of Lᵀ; D diagonal, the pivots d), both compressed sparse column, rows ascending;
 * u_lpos[e] is the position in L of the entry L(c, k) of each entry U(k, c).  Then column c
 * of K(p, p) is factored left-looking: scattered into x, the columns k of L with U(k, c) in
 * the pattern subtracted in increasing k (a topological order of a symmetric pattern),
 * U(:, c) and d_c = x[c] read off, L(:, c) = x(rows) / d_c.  K x = b is solved as
 * x(p) = U⁻¹ D⁻¹ L⁻¹ b(p).
 *
 * Without pivoting the order must make every pivot safe; for the stepper's KKT matrix
 * [[M̃, Aᵀ], [A, 0]] (M̃ near the mass matrix, positive definite) the analysis orders each
 * multiplier after all the coordinates its constraint touches, so a pivot is a Schur
 * complement of a regular KKT block.  ncgen_lu_factor does not trust it blindly: it returns 1
 * (factors unusable; the caller solves another way) when a pivot d_c is not finite or
 * cancels to |d_c| <= NCGEN_LU_PIVOT_TOL (|K_cc| + Σ_k |L(c, k) (D U)(k, c)|), the size of
 * the terms it is the sum of: K singular or too ill-conditioned for this order.
 *
 * The arrays of the analysis are int, the numbers double; x is n doubles of scratch, all
 * zero on entry and left so. */
#ifndef NCGEN_SPARSE_LU_H
#define NCGEN_SPARSE_LU_H

#include <math.h>

/* Largest cancellation a pivot may show relative to its terms (about 10 digits lost). */
#define NCGEN_LU_PIVOT_TOL 1e-10

typedef struct {
  int n, nnz_l;                              /* K is n x n; nonzeros of L (and of U) */
  const int *k_colind, *k_prow;              /* the pattern of K (CSC), its rows in the order (pinv[row]) */
  const int *p, *pinv;                       /* the order and its inverse */
  const int *l_colind, *l_row;               /* the pattern of L (strictly lower) */
  const int *u_colind, *u_row, *u_lpos;      /* the pattern of U (strictly upper), L(c, k) of U(k, c) */
} ncgen_lu_pattern;

/* The factors lo = L, up = D U (nnz_l each: K(p, p) = L (D U)) and the reciprocals dinv of
 * the pivots (n) of K (nonzeros in its pattern): 0, or 1 when a pivot is unsafe (above). */
static int ncgen_lu_factor(const ncgen_lu_pattern *P, const double *K, double *lo, double *up, double *dinv,
                           double *x) {
  int c, e, k, i, n = P->n;
  for (c = 0; c < n; ++c) {
    int col = P->p[c];
    double ref = 0, piv;
    for (e = P->k_colind[col]; e < P->k_colind[col + 1]; ++e) x[P->k_prow[e]] = K[e];
    ref = fabs(x[c]);
    for (e = P->u_colind[c]; e < P->u_colind[c + 1]; ++e) {    /* (D U)(k, c), k ascending */
      double u;
      k = P->u_row[e];
      u = x[k];
      x[k] = 0;
      up[e] = u;
      if (u == 0) continue;                                   /* a zero in the pattern: nothing to subtract */
      for (i = P->l_colind[k]; i < P->l_colind[k + 1]; ++i) x[P->l_row[i]] -= lo[i] * u;
      ref += fabs(lo[P->u_lpos[e]] * u);
    }
    piv = x[c];
    x[c] = 0;
    if (!(fabs(piv) > NCGEN_LU_PIVOT_TOL * ref) || !isfinite(piv)) {
      for (i = P->l_colind[c]; i < P->l_colind[c + 1]; ++i) x[P->l_row[i]] = 0;
      return 1;
    }
    dinv[c] = 1 / piv;
    for (i = P->l_colind[c]; i < P->l_colind[c + 1]; ++i) {
      lo[i] = x[P->l_row[i]] * dinv[c];
      x[P->l_row[i]] = 0;
    }
  }
  return 0;
}

/* x = K⁻¹ b from the factors (as ncgen_lu_factor gives them); y: n doubles of scratch. */
static void ncgen_lu_solve(const ncgen_lu_pattern *P, const double *lo, const double *up, const double *dinv,
                           const double *b, double *x, double *y) {
  int c, i, n = P->n;
  for (i = 0; i < n; ++i) y[P->pinv[i]] = b[i];
  for (c = 0; c < n; ++c)                    /* L z = y, column by column */
    for (i = P->l_colind[c]; i < P->l_colind[c + 1]; ++i) y[P->l_row[i]] -= lo[i] * y[c];
  for (c = n - 1; c >= 0; --c) {             /* (D U) x = z, column by column */
    y[c] *= dinv[c];
    for (i = P->u_colind[c]; i < P->u_colind[c + 1]; ++i) y[P->u_row[i]] -= up[i] * y[c];
  }
  for (c = 0; c < n; ++c) x[P->p[c]] = y[c];
}

/* x = K⁻ᵀ b from the same factors: K(p, p)ᵀ = (D U)ᵀ Lᵀ, so (D U)ᵀ z = b(p) forwards (row c
 * of (D U)ᵀ is column c of D U), then Lᵀ x(p) = z backwards (row c of Lᵀ is column c of L);
 * y: n doubles of scratch.  Inline: only the step Jacobians use it. */
static inline void ncgen_lu_solve_transposed(const ncgen_lu_pattern *P, const double *lo, const double *up,
                                             const double *dinv, const double *b, double *x, double *y) {
  int c, i, n = P->n;
  for (i = 0; i < n; ++i) y[P->pinv[i]] = b[i];
  for (c = 0; c < n; ++c) {
    double s = y[c];
    for (i = P->u_colind[c]; i < P->u_colind[c + 1]; ++i) s -= up[i] * y[P->u_row[i]];
    y[c] = s * dinv[c];
  }
  for (c = n - 1; c >= 0; --c) {
    double s = y[c];
    for (i = P->l_colind[c]; i < P->l_colind[c + 1]; ++i) s -= lo[i] * y[P->l_row[i]];
    y[c] = s;
  }
  for (c = 0; c < n; ++c) x[P->p[c]] = y[c];
}

#endif

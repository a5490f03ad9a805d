/* Sparse Householder QR of a square matrix over a pattern analysed beforehand, and the solve
 * with its factors: plain C99, the same for every matrix.
 *
 * The symbolic analysis (done once per pattern, in Python: CasADi's qr_sparse on the pattern,
 * ncgen/codegen/stepper_tables.py) gives a row permutation prinv (row i of K is row prinv[i]
 * of the factored matrix), a fill-reducing column order pc (column c of the factored matrix
 * is column pc[c] of K), and the patterns (compressed sparse column, rows ascending) of the
 * Householder vectors V (column c starts at its diagonal row c) and of R (column c ends at
 * its diagonal).  Then
 *
 *     K(prinv⁻¹, pc) = H_0 H_1 … H_{n−1} R,   H_c = I − beta_c v_c v_cᵀ,
 *
 * factored column by column (left-looking: column c of the permuted K, the reflectors
 * 0 .. c−1 that reach it in increasing order, then the reflector of column c), and
 * K x = b is solved as x(pc) = R⁻¹ H_{n−1} … H_0 b(prinv).  No pivoting: Householder QR is
 * stable in any column order, so the order depends on the pattern only.
 *
 * The arrays of the analysis are int, the numbers double; `x` is n doubles of scratch.
 * ncgen_qr_factor returns 0, or 1 when a diagonal of R is zero (K singular: the solve would
 * divide by zero). */
#ifndef NCGEN_SPARSE_QR_H
#define NCGEN_SPARSE_QR_H

#include <math.h>

typedef struct {
  int n;                                     /* K is n x n */
  const int *k_colind, *k_row;               /* the pattern of K (CSC) */
  const int *v_colind, *v_row;               /* the pattern of V (n x n) */
  const int *r_colind, *r_row;               /* the pattern of R (n x n) */
  const int *prinv, *pc;                     /* row and column permutations (above) */
} ncgen_qr_pattern;

/* The reflector that maps v (m entries) to (alpha, 0, …, 0): v is overwritten by the
 * Householder vector scaled to v[0] = 1, *beta set; returns alpha. */
static double ncgen_qr_house(double *v, int m, double *beta) {
  double sigma = 0, x0 = v[0], mu, v0;
  int i;
  for (i = 1; i < m; ++i) sigma += v[i] * v[i];
  if (sigma == 0) {
    *beta = 0;
    v[0] = 1;
    return x0;
  }
  mu = sqrt(x0 * x0 + sigma);
  v0 = x0 <= 0 ? x0 - mu : -sigma / (x0 + mu);
  *beta = 2 * v0 * v0 / (sigma + v0 * v0);
  v[0] = 1;
  for (i = 1; i < m; ++i) v[i] /= v0;
  return mu;
}

/* y -= beta_c v_c (v_cᵀ y): reflector c applied to y (n); nothing when beta_c = 0 (a column
 * with nothing below its diagonal). */
static void ncgen_qr_reflect(const ncgen_qr_pattern *P, const double *V, const double *beta, int c, double *y) {
  const int lo = P->v_colind[c], hi = P->v_colind[c + 1], *row = P->v_row;
  double s = 0;
  int k;
  if (beta[c] == 0) return;
  for (k = lo; k < hi; ++k) s += V[k] * y[row[k]];
  s *= beta[c];
  for (k = lo; k < hi; ++k) y[row[k]] -= s * V[k];
}

/* The factors V, R (their patterns' nonzeros) and beta (n) of K (nonzeros in its pattern). */
static int ncgen_qr_factor(const ncgen_qr_pattern *P, const double *K, double *V, double *R, double *beta,
                           double *x) {
  int c, k, i, n = P->n;
  for (i = 0; i < n; ++i) x[i] = 0;
  for (c = 0; c < n; ++c) {
    int col = P->pc[c], kr = P->r_colind[c], end = P->r_colind[c + 1] - 1;   /* end: R's diagonal */
    for (k = P->k_colind[col]; k < P->k_colind[col + 1]; ++k) x[P->prinv[P->k_row[k]]] = K[k];
    for (; kr < end; ++kr) {                 /* reflectors of the rows above the diagonal */
      i = P->r_row[kr];
      ncgen_qr_reflect(P, V, beta, i, x);
      R[kr] = x[i];
      x[i] = 0;
    }
    for (k = P->v_colind[c]; k < P->v_colind[c + 1]; ++k) {
      V[k] = x[P->v_row[k]];
      x[P->v_row[k]] = 0;
    }
    R[end] = ncgen_qr_house(V + P->v_colind[c], P->v_colind[c + 1] - P->v_colind[c], beta + c);
    if (R[end] == 0) return 1;
  }
  return 0;
}

/* x = K⁻¹ b from the factors; y: n doubles of scratch. */
static void ncgen_qr_solve(const ncgen_qr_pattern *P, const double *V, const double *R, const double *beta,
                           const double *b, double *x, double *y) {
  int c, k, n = P->n;
  for (k = 0; k < n; ++k) y[P->prinv[k]] = b[k];
  for (c = 0; c < n; ++c) ncgen_qr_reflect(P, V, beta, c, y);
  for (c = n - 1; c >= 0; --c) {             /* R z = y, column by column */
    int end = P->r_colind[c + 1] - 1;
    y[c] /= R[end];
    for (k = P->r_colind[c]; k < end; ++k) y[P->r_row[k]] -= R[k] * y[c];
  }
  for (c = 0; c < n; ++c) x[P->pc[c]] = y[c];
}

#endif

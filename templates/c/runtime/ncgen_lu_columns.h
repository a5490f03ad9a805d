/* Many sparse right-hand sides solved with the sparse LU factors of a square matrix A
 * computed elsewhere (SuperLU's, as SciPy returns them): Pr A Pc = L U, L unit lower
 * triangular and U upper triangular, both compressed sparse column (rows in any order within
 * a column; L may store its unit diagonal, which is not read).  The permutations are
 * SuperLU's perm_r and perm_c: row i of A is row perm_r[i] of Pr A, and x = Pc y is
 * x[i] = y[perm_c[i]].
 *
 * The right-hand sides B (n x m) are compressed sparse column (b_colind, b_row, b_x; the
 * implicit-function theorem's R_y of a contact step: a few nonzeros a column).  Of each
 * solution x_k = A⁻¹ b_k only the nr entries rows[0..nr) are returned, in X (nr x m,
 * column-major: column k at X + k nr), and the whole solutions' combination
 * xs = Σ_k signs[k] x_k (n numbers), for the caller's residual test A xs = B signs.
 *
 * Each column is solved on its own in the dense scratch y (n numbers), column-oriented, and a
 * column j of a factor is applied only where y[j] is nonzero: a sparse right-hand side then
 * costs the nonzeros of the factors it reaches, not all of them (the 20-sphere heap: 52 000 of
 * 451 000 multiply-adds).  Skipping exact zeros changes no result.  y is 2n numbers of
 * scratch (the pivots' reciprocals in its second half).  plain C99, no allocation.
 *
 * Returns 0, or 1 when a diagonal entry of U is missing, zero or not finite (X and xs are then
 * not written). */
#ifndef NCGEN_LU_COLUMNS_H
#define NCGEN_LU_COLUMNS_H

#include <math.h>
#include <stddef.h>

static int ncgen_lu_columns(int n, int m, const int *l_colind, const int *l_row, const double *l_x,
                            const int *u_colind, const int *u_row, const double *u_x, const int *perm_r,
                            const int *perm_c, const int *b_colind, const int *b_row, const double *b_x,
                            int nr, const int *rows, const double *signs, double *y, double *X, double *xs) {
  double *dinv = y + n;
  int i, j, e, k;
  for (j = 0; j < n; ++j) {                     /* every pivot present, nonzero and finite */
    dinv[j] = 0;
    for (e = u_colind[j]; e < u_colind[j + 1]; ++e)
      if (u_row[e] == j) dinv[j] = u_x[e];
    if (dinv[j] == 0 || !isfinite(dinv[j])) return 1;
    dinv[j] = 1 / dinv[j];
  }
  for (i = 0; i < n; ++i) xs[i] = 0;            /* Σ signs[k] y_k first, Pc applied at the end */
  for (k = 0; k < m; ++k) {
    double *x = X + (size_t)k * nr;
    int first = n;                              /* y's first nonzero: L leaves y above it alone */
    for (i = 0; i < n; ++i) y[i] = 0;
    for (e = b_colind[k]; e < b_colind[k + 1]; ++e) {
      i = perm_r[b_row[e]];
      y[i] += b_x[e];
      if (i < first) first = i;
    }
    for (j = first; j < n; ++j) {               /* L y = Pr b */
      double yj = y[j];
      if (yj == 0) continue;
      for (e = l_colind[j]; e < l_colind[j + 1]; ++e)
        if (l_row[e] > j) y[l_row[e]] -= l_x[e] * yj;
    }
    for (j = n - 1; j >= 0; --j) {              /* U z = y, the last column first */
      double yj = y[j];
      if (yj == 0) continue;
      y[j] = yj = yj * dinv[j];
      for (e = u_colind[j]; e < u_colind[j + 1]; ++e)
        if (u_row[e] < j) y[u_row[e]] -= u_x[e] * yj;
    }
    for (i = 0; i < nr; ++i) x[i] = y[perm_c[rows[i]]];
    for (i = 0; i < n; ++i) xs[i] += signs[k] * y[i];
  }
  for (i = 0; i < n; ++i) y[i] = xs[i];
  for (i = 0; i < n; ++i) xs[i] = y[perm_c[i]];
  return 0;
}

#endif

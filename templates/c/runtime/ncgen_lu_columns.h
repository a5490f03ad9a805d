/* Many right-hand sides solved with the sparse LU factors of a square matrix A computed
 * elsewhere (SuperLU's, as SciPy returns them): Pr A Pc = L U, L unit lower triangular and U
 * upper triangular, both compressed sparse column (rows in any order within a column; L may
 * store its unit diagonal, which is not read).  The permutations are SuperLU's perm_r and
 * perm_c: row i of A is row perm_r[i] of Pr A, and x = Pc y is x[i] = y[perm_c[i]].
 *
 * The right-hand sides B and the solutions X are n x m, row-major (row i of B holds the m
 * columns' entries i): each nonzero of the factors then updates one contiguous row of m
 * numbers, the same operation for every column, which the compiler vectorises (a
 * column-at-a-time solve walks the factors' index arrays once per column).  Y is n x m of
 * scratch.  plain C99, no allocation.
 *
 * Returns 0, or 1 when a diagonal entry of U is missing, zero or not finite (X is then not
 * written). */
#ifndef NCGEN_LU_COLUMNS_H
#define NCGEN_LU_COLUMNS_H

#include <math.h>
#include <string.h>

static int ncgen_lu_columns(int n, int m, const int *l_colind, const int *l_row, const double *l_x,
                            const int *u_colind, const int *u_row, const double *u_x, const int *perm_r,
                            const int *perm_c, const double *B, double *Y, double *X) {
  int i, j, e, k;
  for (i = 0; i < n; ++i) memcpy(Y + (size_t)perm_r[i] * m, B + (size_t)i * m, sizeof(double) * m);
  for (j = 0; j < n; ++j) {                     /* L y = Pr b, column by column */
    const double *yj = Y + (size_t)j * m;
    for (e = l_colind[j]; e < l_colind[j + 1]; ++e) {
      double *yi, l = l_x[e];
      i = l_row[e];
      if (i <= j || l == 0) continue;
      yi = Y + (size_t)i * m;
      for (k = 0; k < m; ++k) yi[k] -= l * yj[k];
    }
  }
  for (j = n - 1; j >= 0; --j) {                /* U z = y, the last column first */
    double d = 0, *yj = Y + (size_t)j * m;
    for (e = u_colind[j]; e < u_colind[j + 1]; ++e)
      if (u_row[e] == j) d = u_x[e];
    if (d == 0 || !isfinite(d)) return 1;
    d = 1 / d;
    for (k = 0; k < m; ++k) yj[k] *= d;
    for (e = u_colind[j]; e < u_colind[j + 1]; ++e) {
      double *yi, u = u_x[e];
      i = u_row[e];
      if (i >= j || u == 0) continue;
      yi = Y + (size_t)i * m;
      for (k = 0; k < m; ++k) yi[k] -= u * yj[k];
    }
  }
  for (i = 0; i < n; ++i) memcpy(X + (size_t)i * m, Y + (size_t)perm_c[i] * m, sizeof(double) * m);
  return 0;
}

#endif

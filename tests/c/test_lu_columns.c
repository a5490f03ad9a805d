/* Unit tests of the many-column solve with sparse LU factors (ncgen_lu_columns.h) on factors
 * written by hand: L unit lower triangular with its diagonal stored (as SuperLU's), U upper
 * triangular with the rows of a column out of order, row and column permutations; the matrix
 * A with Pr A Pc = L U is formed here from them (A[i][j] = (L U)[perm_r[i]][perm_c[j]]) and
 * every column's solution is checked against the residual A x − b (B compressed sparse
 * column from a dense B with zeros, a duplicated entry summed; X column-major); a selection of
 * the rows, out of order, equal to those entries of the whole solutions; the signed combination
 * xs = Σ signs[k] x_k.  The
 * refusals (return 1, X and xs not written): a zero diagonal entry of U, a missing one, a NaN.  Built
 * and run by tests/test_stepper_runtime_c.py under AddressSanitizer and
 * UndefinedBehaviorSanitizer. */
#include "check.h"
#include "ncgen_lu_columns.h"

#define N 4
#define M 3

/* L (CSC, the unit diagonal stored first in each column) of
 * [[1, 0, 0, 0], [0.5, 1, 0, 0], [0, -0.25, 1, 0], [2, 0, 0.75, 1]]. */
static const int l_colind[N + 1] = {0, 3, 5, 7, 8};
static const int l_row[8] = {0, 1, 3, 1, 2, 2, 3, 3};
static const double l_x[8] = {1, 0.5, 2, 1, -0.25, 1, 0.75, 1};
/* U (CSC, rows out of order) of [[4, 1, 0, 2], [0, -3, 0.5, 0], [0, 0, 2, 1], [0, 0, 0, 5]]. */
static const int u_colind[N + 1] = {0, 1, 3, 5, 8};
static const int u_row[8] = {0, 1, 0, 2, 1, 3, 0, 2};
static const double u_x[8] = {4, -3, 1, 2, 0.5, 5, 2, 1};
static const int perm_r[N] = {2, 0, 3, 1}, perm_c[N] = {1, 3, 0, 2};

/* Dense (row-major) of a CSC matrix. */
static void dense(const int *colind, const int *row, const double *x, double *D) {
  int j, e;
  memset(D, 0, sizeof(double) * N * N);
  for (j = 0; j < N; ++j)
    for (e = colind[j]; e < colind[j + 1]; ++e) D[row[e] * N + j] = x[e];
}

/* A (row-major) with Pr A Pc = L U for the factors above (u_x may be altered). */
static void matrix(const double *ux, double *A) {
  double L[N * N], U[N * N], LU[N * N];
  int i, j, k;
  dense(l_colind, l_row, l_x, L);
  dense(u_colind, u_row, ux, U);
  for (i = 0; i < N; ++i)
    for (j = 0; j < N; ++j) {
      LU[i * N + j] = 0;
      for (k = 0; k < N; ++k) LU[i * N + j] += L[i * N + k] * U[k * N + j];
    }
  for (i = 0; i < N; ++i)
    for (j = 0; j < N; ++j) A[i * N + j] = LU[perm_r[i] * N + perm_c[j]];
}

/* B (dense, column-major N x M, a zero in each column) as compressed sparse columns, its entry
 * in row 2 of column 1 split in two summed entries. */
static void sparse_columns(const double *B, int *colind, int *row, double *x) {
  int i, k, e = 0;
  for (k = 0; k < M; ++k) {
    colind[k] = e;
    for (i = 0; i < N; ++i)
      if (B[k * N + i] != 0) {
        row[e] = i;
        x[e++] = (k == 1 && i == 2) ? 0.25 * B[k * N + i] : B[k * N + i];
        if (k == 1 && i == 2) row[e] = i, x[e++] = 0.75 * B[k * N + i];
      }
  }
  colind[M] = e;
}

static void test_solve(void) {
  double A[N * N], B[N * M], X[N * M], Xs[2 * M], xs[N], y[2 * N], b_x[N * M + 1];
  const double signs[M] = {1, -1, 0.5};
  const int all[N] = {0, 1, 2, 3}, some[2] = {3, 1};
  int b_colind[M + 1], b_row[N * M + 1];
  int i, j, k;
  matrix(u_x, A);
  for (i = 0; i < N; ++i)
    for (k = 0; k < M; ++k)
      B[k * N + i] = (k == 0) ? (i == 2) : (i == k) ? 0 : (double)(i + 1) * (k == 1 ? 1.5 : -0.3) + k;
  sparse_columns(B, b_colind, b_row, b_x);
  CHECK(ncgen_lu_columns(N, M, l_colind, l_row, l_x, u_colind, u_row, u_x, perm_r, perm_c, b_colind, b_row, b_x,
                         N, all, signs, y, X, xs) == 0, "a regular matrix is solved");
  for (k = 0; k < M; ++k)
    for (i = 0; i < N; ++i) {
      double r = -B[k * N + i];
      for (j = 0; j < N; ++j) r += A[i * N + j] * X[k * N + j];
      CHECK(fabs(r) <= 1e-14 * (1 + fabs(B[k * N + i])), "column %d, row %d: residual %g", k, i, r);
    }
  for (i = 0; i < N; ++i) {
    double s = 0;
    for (k = 0; k < M; ++k) s += signs[k] * X[k * N + i];
    CHECK(fabs(xs[i] - s) <= 1e-15 * (1 + fabs(s)), "xs[%d] = %g, the combination %g", i, xs[i], s);
  }
  CHECK(ncgen_lu_columns(N, M, l_colind, l_row, l_x, u_colind, u_row, u_x, perm_r, perm_c, b_colind, b_row, b_x,
                         2, some, signs, y, Xs, xs) == 0, "rows selected");
  for (k = 0; k < M; ++k)
    for (i = 0; i < 2; ++i)
      CHECK(Xs[k * 2 + i] == X[k * N + some[i]], "column %d, selected row %d", k, some[i]);
}

static void test_refused(void) {
  double B[N * M], X[N * M], xs[N], y[2 * N], ux[8], b_x[N * M + 1];
  const double signs[M] = {1, 1, 1};
  const int all[N] = {0, 1, 2, 3};
  const int no_diagonal_row[8] = {0, 1, 0, 2, 1, 0, 0, 2};   /* column 3: no row 3 */
  int b_colind[M + 1], b_row[N * M + 1];
  int i;
  for (i = 0; i < N * M; ++i) B[i] = 1, X[i] = 7;
  for (i = 0; i < N; ++i) xs[i] = 7;
  sparse_columns(B, b_colind, b_row, b_x);
  memcpy(ux, u_x, sizeof ux);
  ux[3] = 0;                                                  /* U(2, 2) = 0 */
  CHECK(ncgen_lu_columns(N, M, l_colind, l_row, l_x, u_colind, u_row, ux, perm_r, perm_c, b_colind, b_row, b_x,
                         N, all, signs, y, X, xs) == 1, "a zero pivot is refused");
  memcpy(ux, u_x, sizeof ux);
  ux[1] = NAN;                                                /* U(1, 1) */
  CHECK(ncgen_lu_columns(N, M, l_colind, l_row, l_x, u_colind, u_row, ux, perm_r, perm_c, b_colind, b_row, b_x,
                         N, all, signs, y, X, xs) == 1, "a NaN pivot is refused");
  CHECK(ncgen_lu_columns(N, M, l_colind, l_row, l_x, u_colind, no_diagonal_row, u_x, perm_r, perm_c, b_colind, b_row,
                         b_x, N, all, signs, y, X, xs) == 1, "a missing pivot is refused");
  for (i = 0; i < N * M; ++i) CHECK(X[i] == 7, "X[%d] written by a refused solve", i);
  for (i = 0; i < N; ++i) CHECK(xs[i] == 7, "xs[%d] written by a refused solve", i);
}

int main(void) {
  test_solve();
  test_refused();
  return report("test_lu_columns");
}

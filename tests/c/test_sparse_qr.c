/* Unit tests of the sparse Householder QR (ncgen_sparse_qr.h) on matrices whose analysis is
 * written by hand: a dense pattern (V the lower triangle, R the upper, so every fill is
 * allowed) with row and column permutations, and a tridiagonal matrix with zeros on every
 * other diagonal entry in identity order (V: the diagonal and the row below; R: the diagonal
 * and the two rows above).  Checked: K x = b to round-off for several matrices, including
 * [[M, Aᵀ], [A, 0]] with its zero diagonal block, and the singular-matrix report.  Built
 * and run by tests/test_stepper_runtime_c.py under AddressSanitizer and
 * UndefinedBehaviorSanitizer. */
#include "check.h"
#include "ncgen_sparse_qr.h"

#define N 5

/* ‖K x − b‖∞ for K dense column-major (N x N). */
static double residual(const double *K, const double *x, const double *b, int n) {
  double m = 0;
  int i, j;
  for (i = 0; i < n; ++i) {
    double s = -b[i];
    for (j = 0; j < n; ++j) s += K[j * n + i] * x[j];
    if (fabs(s) > m) m = fabs(s);
  }
  return m;
}

/* Dense pattern: every entry; V lower triangle, R upper (CSC, rows ascending). */
static void dense_pattern(int n, int *k_colind, int *k_row, int *v_colind, int *v_row, int *r_colind, int *r_row) {
  int i, j, kk = 0, kv = 0, kr = 0;
  for (j = 0; j < n; ++j) {
    k_colind[j] = kk;
    v_colind[j] = kv;
    r_colind[j] = kr;
    for (i = 0; i < n; ++i) k_row[kk++] = i;
    for (i = j; i < n; ++i) v_row[kv++] = i;
    for (i = 0; i <= j; ++i) r_row[kr++] = i;
  }
  k_colind[n] = kk;
  v_colind[n] = kv;
  r_colind[n] = kr;
}

static void test_dense(void) {
  int k_colind[N + 1], k_row[N * N], v_colind[N + 1], v_row[N * (N + 1) / 2], r_colind[N + 1],
      r_row[N * (N + 1) / 2];
  int prinv[N] = {3, 0, 4, 1, 2}, pc[N] = {2, 4, 0, 1, 3};
  double K[N * N], V[N * (N + 1) / 2], R[N * (N + 1) / 2], beta[N], x[N], y[N], b[N];
  ncgen_qr_pattern P;
  int trial, i, j;
  dense_pattern(N, k_colind, k_row, v_colind, v_row, r_colind, r_row);
  P.n = N;
  P.k_colind = k_colind; P.k_row = k_row;
  P.v_colind = v_colind; P.v_row = v_row;
  P.r_colind = r_colind; P.r_row = r_row;
  P.prinv = prinv; P.pc = pc;
  for (trial = 0; trial < 4; ++trial) {
    for (j = 0; j < N; ++j)
      for (i = 0; i < N; ++i) K[j * N + i] = sin(1.3 + 1.7 * i * j + 0.4 * i + 2.3 * j + 0.9 * trial) + (i == j ? 2.0 * (trial % 2) : 0);
    if (trial == 3)   /* [[M, Aᵀ], [A, 0]]: M = 3 x 3 SPD, A = 2 x 3, zero 2 x 2 block */
      for (j = 0; j < N; ++j)
        for (i = 0; i < N; ++i) {
          if (i >= 3 && j >= 3) K[j * N + i] = 0;
          else if (i < 3 && j < 3) K[j * N + i] = i == j ? 2.0 + i : 0.3;
          else if (i >= 3) K[j * N + i] = K[i * N + j] = sin(1.0 + i * j);
        }
    for (i = 0; i < N; ++i) b[i] = cos(0.7 * i + trial);
    CHECK(ncgen_qr_factor(&P, K, V, R, beta, x) == 0, "trial %d: factored", trial);
    ncgen_qr_solve(&P, V, R, beta, b, x, y);
    CHECK(residual(K, x, b, N) < 1e-12, "trial %d: |K x - b| = %g", trial, residual(K, x, b, N));
  }
  for (i = 0; i < N * N; ++i) K[i] = 0;       /* rank 1: a zero diagonal of R */
  for (j = 0; j < N; ++j)
    for (i = 0; i < N; ++i) K[j * N + i] = (i + 1.0) * (j + 1.0);
  CHECK(ncgen_qr_factor(&P, K, V, R, beta, x) != 0 || fabs(R[r_colind[N] - 1]) < 1e-12,
        "a singular matrix is reported (or its last pivot is round-off)");
}

/* Tridiagonal pattern in identity order: V column j rows {j, j+1}, R column j rows
 * {j-2, j-1, j} (the fill of Householder QR of a tridiagonal matrix). */
static void test_tridiagonal(void) {
  int k_colind[N + 1], k_row[3 * N], v_colind[N + 1], v_row[2 * N], r_colind[N + 1], r_row[3 * N];
  int prinv[N] = {0, 1, 2, 3, 4}, pc[N] = {0, 1, 2, 3, 4};
  double K[3 * N], Kd[N * N], V[2 * N], R[3 * N], beta[N], x[N], y[N], b[N];
  ncgen_qr_pattern P;
  int i, j, kk = 0, kv = 0, kr = 0;
  for (i = 0; i < N * N; ++i) Kd[i] = 0;
  for (j = 0; j < N; ++j) {
    k_colind[j] = kk;
    v_colind[j] = kv;
    r_colind[j] = kr;
    for (i = j - 1; i <= j + 1; ++i)
      if (i >= 0 && i < N) {
        k_row[kk] = i;
        K[kk] = i == j ? (j % 2 ? 0.0 : 1.5 + j) : 1.0 + 0.1 * (i + j);   /* zeros on odd diagonals */
        Kd[j * N + i] = K[kk++];
      }
    for (i = j; i <= j + 1 && i < N; ++i) v_row[kv++] = i;
    for (i = j - 2; i <= j; ++i)
      if (i >= 0) r_row[kr++] = i;
  }
  k_colind[N] = kk;
  v_colind[N] = kv;
  r_colind[N] = kr;
  P.n = N;
  P.k_colind = k_colind; P.k_row = k_row;
  P.v_colind = v_colind; P.v_row = v_row;
  P.r_colind = r_colind; P.r_row = r_row;
  P.prinv = prinv; P.pc = pc;
  for (i = 0; i < N; ++i) b[i] = 1.0 - 0.3 * i;
  CHECK(ncgen_qr_factor(&P, K, V, R, beta, x) == 0, "tridiagonal: factored");
  ncgen_qr_solve(&P, V, R, beta, b, x, y);
  CHECK(residual(Kd, x, b, N) < 1e-12, "tridiagonal: |K x - b| = %g", residual(Kd, x, b, N));
}

int main(void) {
  test_dense();
  test_tridiagonal();
  return report("test_sparse_qr");
}

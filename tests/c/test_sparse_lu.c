/* Unit tests of the sparse LU without pivoting (ncgen_sparse_lu.h) on matrices whose analysis
 * is written by hand: a dense pattern (L the whole strictly lower triangle, U the upper) in a
 * given order, and a tridiagonal pattern in identity order (L: the row below, U: the row
 * above, no fill).  Checked: K x = b to round-off against the residual, for general matrices
 * and for KKT matrices [[M, Aᵀ], [A, 0]] (A nonsymmetric too: [[M, A_1ᵀ], [A_2, 0]]) in an
 * order with each multiplier after the coordinates of its constraint; the refusals (return
 * 1, the scratch left zero): a zero pivot of an order that puts a multiplier first, a
 * redundant constraint (K singular), a constraint redundant to 1e-14 (ill-conditioned beyond
 * the pivot test; also 1e-6: a pivot cancelling to 1e-12 of its terms), NaN in K; an
 * ill-conditioned but acceptable KKT matrix (constraints 1e-4 apart) still solved to a small
 * backward error.  The transposed solve Kᵀ x = b from the same factors, against the
 * residual of Kᵀ, in each of these.  Built and run by
 * tests/test_stepper_runtime_c.py under AddressSanitizer and UndefinedBehaviorSanitizer. */
#include "check.h"
#include "ncgen_sparse_lu.h"

#define N 5
#define NL (N * (N - 1) / 2)

/* ‖K x − b‖∞ / (‖K‖∞ ‖x‖∞ + ‖b‖∞) for K dense column-major (n x n): the backward error. */
static double backward_error(const double *K, const double *x, const double *b, int n) {
  double r = 0, kn = 0, xn = 0, bn = 0;
  int i, j;
  for (i = 0; i < n; ++i) {
    double s = -b[i], row = 0;
    for (j = 0; j < n; ++j) {
      s += K[j * n + i] * x[j];
      row += fabs(K[j * n + i]);
    }
    if (fabs(s) > r) r = fabs(s);
    if (row > kn) kn = row;
    if (fabs(x[i]) > xn) xn = fabs(x[i]);
    if (fabs(b[i]) > bn) bn = fabs(b[i]);
  }
  return r / (kn * xn + bn);
}

/* Kᵀ (n x n, column-major) of K into Kt. */
static void transpose(const double *K, double *Kt, int n) {
  int i, j;
  for (j = 0; j < n; ++j)
    for (i = 0; i < n; ++i) Kt[i * n + j] = K[j * n + i];
}

/* The analysis of the dense pattern (K stored whole, column-major) in the order p. */
typedef struct {
  int k_colind[N + 1], k_prow[N * N], pinv[N], l_colind[N + 1], l_row[NL], u_colind[N + 1], u_row[NL], u_lpos[NL];
  ncgen_lu_pattern P;
} dense_analysis;

static void dense(dense_analysis *a, const int *p) {
  int i, c, k, kl = 0, ku = 0;
  for (c = 0; c < N; ++c) a->pinv[p[c]] = c;
  for (c = 0; c < N; ++c) {
    a->k_colind[c] = c * N;
    for (i = 0; i < N; ++i) a->k_prow[c * N + i] = a->pinv[i];
    a->l_colind[c] = kl;
    a->u_colind[c] = ku;
    for (i = c + 1; i < N; ++i) a->l_row[kl++] = i;
    for (k = 0; k < c; ++k) {   /* U(k, c) is L(c, k): column k of L holds rows k+1 .. N-1 */
      a->u_row[ku] = k;
      a->u_lpos[ku++] = k * (2 * N - k - 1) / 2 + (c - k - 1);
    }
  }
  a->k_colind[N] = N * N;
  a->l_colind[N] = kl;
  a->u_colind[N] = ku;
  a->P.n = N;
  a->P.nnz_l = NL;
  a->P.k_colind = a->k_colind;
  a->P.k_prow = a->k_prow;
  a->P.p = p;
  a->P.pinv = a->pinv;
  a->P.l_colind = a->l_colind;
  a->P.l_row = a->l_row;
  a->P.u_colind = a->u_colind;
  a->P.u_row = a->u_row;
  a->P.u_lpos = a->u_lpos;
}

static int all_zero(const double *x, int n) {
  int i;
  for (i = 0; i < n; ++i)
    if (x[i] != 0) return 0;
  return 1;
}

/* K = [[M, A1ᵀ], [A2, 0]] (N = 3 + 2): M symmetric positive definite, A1, A2 (2 x 3). */
static void kkt(double *K, const double *A1, const double *A2) {
  static const double M[9] = {2.0, 0.3, 0.1, 0.3, 1.5, -0.2, 0.1, -0.2, 1.1};
  int i, j;
  for (j = 0; j < N * N; ++j) K[j] = 0;
  for (j = 0; j < 3; ++j)
    for (i = 0; i < 3; ++i) K[j * N + i] = M[j * 3 + i];
  for (j = 0; j < 3; ++j)
    for (i = 0; i < 2; ++i) {
      K[j * N + 3 + i] = A2[j * 2 + i];       /* lower block: A2 (column-major 2 x 3) */
      K[(3 + i) * N + j] = A1[j * 2 + i];     /* upper block: A1ᵀ */
    }
}

static void test_dense(void) {
  static const int order[3][N] = {{0, 1, 2, 3, 4}, {2, 4, 0, 1, 3}, {1, 0, 2, 3, 4}};
  double K[N * N], Kt[N * N], L[NL], U[NL], d[N], x[N], y[N], b[N], s[N] = {0};
  dense_analysis a;
  int trial, i, j, o;
  for (o = 0; o < 3; ++o) {
    dense(&a, order[o]);
    for (trial = 0; trial < 3; ++trial) {   /* diagonally dominant: any order is safe */
      for (j = 0; j < N; ++j)
        for (i = 0; i < N; ++i) K[j * N + i] = sin(1.3 + 1.7 * i * j + 0.4 * i + 2.3 * j + 0.9 * trial) + (i == j ? 6.0 : 0);
      for (i = 0; i < N; ++i) b[i] = cos(0.7 * i + trial);
      CHECK(ncgen_lu_factor(&a.P, K, L, U, d, s) == 0, "order %d, trial %d: factored", o, trial);
      CHECK(all_zero(s, N), "the scratch is left zero");
      ncgen_lu_solve(&a.P, L, U, d, b, x, y);
      CHECK(backward_error(K, x, b, N) < 1e-15, "order %d, trial %d: backward error %g", o, trial,
            backward_error(K, x, b, N));
      transpose(K, Kt, N);
      ncgen_lu_solve_transposed(&a.P, L, U, d, b, x, y);
      CHECK(backward_error(Kt, x, b, N) < 1e-15, "order %d, trial %d: Kᵀ x = b, backward error %g", o, trial,
            backward_error(Kt, x, b, N));
    }
  }
}

static void test_kkt(void) {
  /* each multiplier (3, 4) after the coordinates 0, 1, 2 its constraint touches */
  static const int safe[N] = {1, 0, 2, 3, 4}, lambda_first[N] = {3, 0, 1, 2, 4};
  double A1[6] = {1.0, 0.2, -0.5, 1.1, 0.3, 0.7}, A2[6], K[N * N], Kt[N * N], L[NL], U[NL], d[N], x[N], y[N],
         s[N] = {0};
  double b[N] = {0.3, -1.2, 0.8, 0.05, -0.4};
  dense_analysis a;
  int i;
  for (i = 0; i < 6; ++i) A2[i] = A1[i] + 0.01 * sin(3.0 * i);   /* A at q and at q + h w */
  kkt(K, A1, A2);
  dense(&a, safe);
  CHECK(ncgen_lu_factor(&a.P, K, L, U, d, s) == 0, "KKT: factored");
  ncgen_lu_solve(&a.P, L, U, d, b, x, y);
  CHECK(backward_error(K, x, b, N) < 1e-15, "KKT: backward error %g", backward_error(K, x, b, N));
  transpose(K, Kt, N);                   /* A1 ≠ A2: Kᵀ is another matrix */
  ncgen_lu_solve_transposed(&a.P, L, U, d, b, x, y);
  CHECK(backward_error(Kt, x, b, N) < 1e-15, "KKT: Kᵀ x = b, backward error %g", backward_error(Kt, x, b, N));

  dense(&a, lambda_first);               /* a multiplier first: its pivot is K's zero diagonal */
  CHECK(ncgen_lu_factor(&a.P, K, L, U, d, s) == 1, "a zero pivot is refused");
  CHECK(all_zero(s, N), "the scratch is left zero after a refusal");

  dense(&a, safe);
  for (i = 0; i < 3; ++i) A1[2 * i + 1] = A1[2 * i];  /* the second constraint repeats the first */
  kkt(K, A1, A1);
  CHECK(ncgen_lu_factor(&a.P, K, L, U, d, s) == 1, "a redundant constraint (K singular) is refused");
  CHECK(all_zero(s, N), "the scratch is left zero after a refusal");

  for (i = 0; i < 3; ++i) A2[2 * i] = A1[2 * i], A2[2 * i + 1] = A1[2 * i] * (1 + 1e-14 * (i + 1));
  kkt(K, A2, A2);                        /* redundant to 1e-14: cond(K) ~ 1e28 */
  CHECK(ncgen_lu_factor(&a.P, K, L, U, d, s) == 1, "a constraint redundant to 1e-14 is refused");

  for (i = 0; i < 3; ++i) A2[2 * i + 1] = A1[2 * i] + 1e-4 * (i + 1) * (i - 1.5);
  kkt(K, A2, A2);                        /* 1e-4 apart: the last pivot cancels to 1e-8, accepted */
  CHECK(ncgen_lu_factor(&a.P, K, L, U, d, s) == 0, "constraints 1e-4 apart: factored");
  ncgen_lu_solve(&a.P, L, U, d, b, x, y);
  CHECK(backward_error(K, x, b, N) < 1e-13, "constraints 1e-4 apart: backward error %g",
        backward_error(K, x, b, N));

  for (i = 0; i < 3; ++i) A2[2 * i + 1] = A1[2 * i] + 1e-6 * (i + 1) * (i - 1.5);
  kkt(K, A2, A2);                        /* 1e-6 apart: cancels to 1e-12, beyond the pivot test */
  CHECK(ncgen_lu_factor(&a.P, K, L, U, d, s) == 1, "constraints 1e-6 apart are refused");

  kkt(K, A1, A2);
  K[7] = NAN;
  CHECK(ncgen_lu_factor(&a.P, K, L, U, d, s) == 1, "NaN in K is refused");
  CHECK(all_zero(s, N), "the scratch is left zero after a refusal");
}

/* Tridiagonal, identity order: no fill; K stored as its 3n − 2 nonzeros column by column. */
static void test_tridiagonal(void) {
  enum { M = 7, NNZ = 3 * M - 2 };
  int k_colind[M + 1], k_prow[NNZ], p[M], l_colind[M + 1], l_row[M - 1], u_colind[M + 1], u_row[M - 1],
      u_lpos[M - 1], c, i, e = 0;
  double K[NNZ], L[M - 1], U[M - 1], d[M], x[M], y[M], b[M], s[M] = {0}, dense_K[M * M] = {0}, dense_Kt[M * M];
  ncgen_lu_pattern P;
  for (c = 0; c < M; ++c) {
    k_colind[c] = e;
    p[c] = c;
    for (i = c - 1; i <= c + 1; ++i) {
      if (i < 0 || i >= M) continue;
      k_prow[e] = i;
      K[e] = i == c ? 2.5 + 0.1 * c : (i < c ? -1.0 : 0.7 + 0.05 * c);   /* nonsymmetric */
      dense_K[c * M + i] = K[e];
      ++e;
    }
    l_colind[c] = c < M - 1 ? c : M - 1;
    u_colind[c] = c > 0 ? c - 1 : 0;
    b[c] = sin(1.0 + c);
  }
  k_colind[M] = e;
  l_colind[M] = u_colind[M] = M - 1;
  for (c = 0; c < M - 1; ++c) {
    l_row[c] = c + 1;      /* L(c + 1, c) at position c */
    u_row[c] = c;          /* U(c, c + 1), column c + 1 */
    u_lpos[c] = c;
  }
  P.n = M; P.nnz_l = M - 1;
  P.k_colind = k_colind; P.k_prow = k_prow; P.p = p; P.pinv = p;
  P.l_colind = l_colind; P.l_row = l_row; P.u_colind = u_colind; P.u_row = u_row; P.u_lpos = u_lpos;
  CHECK(ncgen_lu_factor(&P, K, L, U, d, s) == 0, "tridiagonal: factored");
  CHECK(all_zero(s, M), "the scratch is left zero");
  ncgen_lu_solve(&P, L, U, d, b, x, y);
  CHECK(backward_error(dense_K, x, b, M) < 1e-15, "tridiagonal: backward error %g", backward_error(dense_K, x, b, M));
  transpose(dense_K, dense_Kt, M);
  ncgen_lu_solve_transposed(&P, L, U, d, b, x, y);
  CHECK(backward_error(dense_Kt, x, b, M) < 1e-15, "tridiagonal: Kᵀ x = b, backward error %g",
        backward_error(dense_Kt, x, b, M));
}

int main(void) {
  test_dense();
  test_kkt();
  test_tridiagonal();
  return report("test_sparse_lu");
}

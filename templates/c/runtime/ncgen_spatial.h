/* Spatial algebra of the local tree recursion (ncgen_tree_tables.h: RNEA, CRBA, ABA), plain C99,
 * arboris conventions as ncgen/symbolic/rigid_motion.py: twists T = [ω; v], wrenches
 * W = [τ; f]; a pose (R, p) of frame b in frame a (H_ab = [[R, p], [0, 1]], R column-major);
 * twists go from a to b by Ad(H_ab)⁻¹, wrenches from b to a by Ad(H_ab)⁻ᵀ; ad(T) = [[ω̂, 0],
 * [v̂, ω̂]].  A rigid-body inertia about a frame's origin, in its axes, is 13 numbers
 * [m; h = m c; I_o] (kg, kg·m, kg·m², I_o the inertia about the origin, column-major), its
 * mass matrix [[I_o, ĥ], [ĥᵀ, m 1]]; an articulated-body inertia is a 6 × 6 column-major
 * matrix.  tests/test_spatial_c.py checks every function here against ncgen.rigid_motion's
 * forms of the SymPy formulas to 1e-12. */
#ifndef NCGEN_SPATIAL_H
#define NCGEN_SPATIAL_H

/* c = a × b (c not a or b) */
static void sp_cross(const double *a, const double *b, double *c) {
  c[0] = a[1] * b[2] - a[2] * b[1];
  c[1] = a[2] * b[0] - a[0] * b[2];
  c[2] = a[0] * b[1] - a[1] * b[0];
}

/* y = R x */
static void sp_rot(const double *R, const double *x, double *y) {
  int i;
  for (i = 0; i < 3; ++i) y[i] = R[i] * x[0] + R[i + 3] * x[1] + R[i + 6] * x[2];
}

/* y = Rᵀ x */
static void sp_rot_t(const double *R, const double *x, double *y) {
  int i;
  for (i = 0; i < 3; ++i) y[i] = R[3 * i] * x[0] + R[3 * i + 1] * x[1] + R[3 * i + 2] * x[2];
}

/* T_b = Ad(H_ab)⁻¹ T_a: ω_b = Rᵀ ω_a, v_b = Rᵀ (v_a + ω_a × p) (T_b not T_a) */
static void sp_twist_in(const double *R, const double *p, const double *Ta, double *Tb) {
  double t[3];
  sp_cross(Ta, p, t);
  t[0] += Ta[3];
  t[1] += Ta[4];
  t[2] += Ta[5];
  sp_rot_t(R, Ta, Tb);
  sp_rot_t(R, t, Tb + 3);
}

/* W_a += Ad(H_ab)⁻ᵀ W_b: f_a = R f_b, τ_a = R τ_b + p × f_a */
static void sp_wrench_out_add(const double *R, const double *p, const double *Wb, double *Wa) {
  double n[3], f[3], t[3];
  int i;
  sp_rot(R, Wb, n);
  sp_rot(R, Wb + 3, f);
  sp_cross(p, f, t);
  for (i = 0; i < 3; ++i) {
    Wa[i] += n[i] + t[i];
    Wa[3 + i] += f[i];
  }
}

/* Y = ad(T) X = [ω × X_ω; v × X_ω + ω × X_v] (Y not T or X) */
static void sp_ad(const double *T, const double *X, double *Y) {
  double t[3];
  sp_cross(T, X, Y);
  sp_cross(T + 3, X, Y + 3);
  sp_cross(T, X + 3, t);
  Y[3] += t[0];
  Y[4] += t[1];
  Y[5] += t[2];
}

/* Y = −ad(T)ᵀ W = [ω × τ + v × f; ω × f] (Y not T or W) */
static void sp_ad_star(const double *T, const double *W, double *Y) {
  double t[3];
  sp_cross(T, W, Y);
  sp_cross(T + 3, W + 3, t);
  Y[0] += t[0];
  Y[1] += t[1];
  Y[2] += t[2];
  sp_cross(T, W + 3, Y + 3);
}

/* W = M T of the rigid inertia I: τ = I_o ω + h × v, f = m v − h × ω */
static void sp_inertia_apply(const double *I, const double *T, double *W) {
  double t[3];
  sp_rot(I + 4, T, W);
  sp_cross(I + 1, T + 3, t);
  W[0] += t[0];
  W[1] += t[1];
  W[2] += t[2];
  sp_cross(I + 1, T, t);
  W[3] = I[0] * T[3] - t[0];
  W[4] = I[0] * T[4] - t[1];
  W[5] = I[0] * T[5] - t[2];
}

/* Ia (in a) += the rigid inertia Ib (in b), b at (R, p) in a: M_a = Ad(H_ab)⁻ᵀ M_b Ad(H_ab)⁻¹,
 * h_a = R h + m p, I_o,a = R I_o Rᵀ − p h_aᵀ' − h' pᵀ + 2 (h'·p) 1 − m (p pᵀ − |p|² 1) with
 * h' = R h (Ia not Ib). */
static void sp_inertia_out_add(const double *R, const double *p, const double *Ib, double *Ia) {
  double m = Ib[0], h[3], RI[9], hp, pp;
  int i, j, k;
  sp_rot(R, Ib + 1, h);
  hp = h[0] * p[0] + h[1] * p[1] + h[2] * p[2];
  pp = p[0] * p[0] + p[1] * p[1] + p[2] * p[2];
  for (j = 0; j < 3; ++j) sp_rot(R, Ib + 4 + 3 * j, RI + 3 * j);      /* R I_o */
  for (i = 0; i < 3; ++i)
    for (j = 0; j < 3; ++j) {
      double t = 0.0;
      for (k = 0; k < 3; ++k) t += RI[i + 3 * k] * R[j + 3 * k];       /* (R I_o Rᵀ)_ij */
      t -= p[i] * h[j] + h[i] * p[j] + m * p[i] * p[j];
      if (i == j) t += 2.0 * hp + m * pp;
      Ia[4 + i + 3 * j] += t;
    }
  Ia[0] += m;
  for (i = 0; i < 3; ++i) Ia[1 + i] += h[i] + m * p[i];
}

/* M (6 × 6, column-major) of the rigid inertia I: [[I_o, ĥ], [ĥᵀ, m 1]] */
static void sp_inertia_matrix(const double *I, double *M) {
  const double *h = I + 1;
  int i, j;
  for (j = 0; j < 3; ++j)
    for (i = 0; i < 3; ++i) {
      M[i + 6 * j] = I[4 + i + 3 * j];
      M[3 + i + 6 * (3 + j)] = i == j ? I[0] : 0.0;
    }
  M[0 + 6 * 3] = 0.0;  M[0 + 6 * 4] = -h[2]; M[0 + 6 * 5] = h[1];
  M[1 + 6 * 3] = h[2]; M[1 + 6 * 4] = 0.0;   M[1 + 6 * 5] = -h[0];
  M[2 + 6 * 3] = -h[1]; M[2 + 6 * 4] = h[0]; M[2 + 6 * 5] = 0.0;
  for (i = 0; i < 3; ++i)
    for (j = 0; j < 3; ++j) M[3 + i + 6 * j] = M[j + 6 * (3 + i)];
}

/* C = R A Rᵀ (3 × 3 blocks at stride ld of A and C, column-major) */
static void sp_rotate_block(const double *R, const double *A, int lda, double *C, int ldc) {
  double RA[9];
  int i, j, k;
  for (j = 0; j < 3; ++j)
    for (i = 0; i < 3; ++i) RA[i + 3 * j] = R[i] * A[lda * j] + R[i + 3] * A[1 + lda * j] + R[i + 6] * A[2 + lda * j];
  for (j = 0; j < 3; ++j)
    for (i = 0; i < 3; ++i) {
      double t = 0.0;
      for (k = 0; k < 3; ++k) t += RA[i + 3 * k] * R[j + 3 * k];
      C[i + ldc * j] = t;
    }
}

/* Ma (6 × 6, in a) += Ad(H_ab)⁻ᵀ Mb Ad(H_ab)⁻¹ of a symmetric Mb (in b), b at (R, p) in a: with
 * Mb = [[A, B], [Bᵀ, C]] turned into a's axes (A1 = R A Rᵀ, ...), the blocks
 * [[A1 − B1 p̂ + p̂ B1ᵀ − p̂ C1 p̂, B1 + p̂ C1], [·ᵀ, C1]]. */
static void sp_matrix_out_add(const double *R, const double *p, const double *Mb, double *Ma) {
  double A[9], B[9], C[9], PC[9], PB[9], X[9];
  int i, j, k;
  const double P[9] = {0.0, p[2], -p[1], -p[2], 0.0, p[0], p[1], -p[0], 0.0};   /* p̂, column-major */
  sp_rotate_block(R, Mb, 6, A, 3);
  sp_rotate_block(R, Mb + 18, 6, B, 3);
  sp_rotate_block(R, Mb + 21, 6, C, 3);
  for (j = 0; j < 3; ++j)
    for (i = 0; i < 3; ++i) {
      double pc = 0.0, pb = 0.0;
      for (k = 0; k < 3; ++k) {
        pc += P[i + 3 * k] * C[k + 3 * j];          /* p̂ C1 */
        pb += P[i + 3 * k] * B[j + 3 * k];          /* p̂ B1ᵀ */
      }
      PC[i + 3 * j] = pc;
      PB[i + 3 * j] = pb;
    }
  for (j = 0; j < 3; ++j)
    for (i = 0; i < 3; ++i) {
      double t = 0.0;
      for (k = 0; k < 3; ++k) t += (B[i + 3 * k] + PC[i + 3 * k]) * P[k + 3 * j];   /* (B1 + p̂ C1) p̂ */
      X[i + 3 * j] = t;
    }
  for (j = 0; j < 3; ++j)
    for (i = 0; i < 3; ++i) {
      double b = B[i + 3 * j] + PC[i + 3 * j];
      Ma[i + 6 * j] += A[i + 3 * j] - X[i + 3 * j] + PB[i + 3 * j];
      Ma[i + 6 * (3 + j)] += b;
      Ma[3 + j + 6 * i] += b;
      Ma[3 + i + 6 * (3 + j)] += C[i + 3 * j];
    }
}

#endif

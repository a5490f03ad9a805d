/* Spatial algebra of the tree recursions (ncgen_tree_tables.h: RNEA in local frames, CRBA and
 * ABA in the ground frame), plain C99, arboris conventions as ncgen/symbolic/rigid_motion.py:
 * twists T = [ω; v], wrenches W = [τ; f]; a pose (R, p) of frame b in frame a
 * (H_ab = [[R, p], [0, 1]], R column-major); twists go from a to b by Ad(H_ab)⁻¹ and from b to
 * a by Ad(H_ab), wrenches from b to a by Ad(H_ab)⁻ᵀ; ad(T) = [[ω̂, 0], [v̂, ω̂]].  A rigid-body
 * inertia about a frame's origin, in its axes, is 13 numbers [m; h = m c; I_o] (kg, kg·m,
 * kg·m², I_o the inertia about the origin, column-major, symmetric), its mass matrix
 * [[I_o, ĥ], [ĥᵀ, m 1]]; an articulated-body inertia is a 6 × 6 column-major matrix.
 * tests/test_spatial_c.py checks every function here against ncgen.rigid_motion's forms of the
 * SymPy formulas to 1e-12. */
#ifndef NCGEN_SPATIAL_H
#define NCGEN_SPATIAL_H

/* an output no other argument overlaps (lets the compiler keep the inputs in registers) */
#if defined(__STDC_VERSION__) && __STDC_VERSION__ >= 199901L
#define SP_RESTRICT restrict
#else
#define SP_RESTRICT
#endif

/* c = a × b (c not a or b) */
static inline void sp_cross(const double *a, const double *b, double *SP_RESTRICT c) {
  c[0] = a[1] * b[2] - a[2] * b[1];
  c[1] = a[2] * b[0] - a[0] * b[2];
  c[2] = a[0] * b[1] - a[1] * b[0];
}

/* y = R x (y not x; written out: gcc -O2 keeps 3-step loops) */
static inline void sp_rot(const double *R, const double *x, double *SP_RESTRICT y) {
  y[0] = R[0] * x[0] + R[3] * x[1] + R[6] * x[2];
  y[1] = R[1] * x[0] + R[4] * x[1] + R[7] * x[2];
  y[2] = R[2] * x[0] + R[5] * x[1] + R[8] * x[2];
}

/* y = Rᵀ x (y not x) */
static inline void sp_rot_t(const double *R, const double *x, double *SP_RESTRICT y) {
  y[0] = R[0] * x[0] + R[1] * x[1] + R[2] * x[2];
  y[1] = R[3] * x[0] + R[4] * x[1] + R[5] * x[2];
  y[2] = R[6] * x[0] + R[7] * x[1] + R[8] * x[2];
}

/* T_b = Ad(H_ab)⁻¹ T_a: ω_b = Rᵀ ω_a, v_b = Rᵀ (v_a + ω_a × p) (T_b not T_a) */
static inline void sp_twist_in(const double *R, const double *p, const double *Ta, double *SP_RESTRICT Tb) {
  double t[3];
  sp_cross(Ta, p, t);
  t[0] += Ta[3];
  t[1] += Ta[4];
  t[2] += Ta[5];
  sp_rot_t(R, Ta, Tb);
  sp_rot_t(R, t, Tb + 3);
}

/* W_a += Ad(H_ab)⁻ᵀ W_b: f_a = R f_b, τ_a = R τ_b + p × f_a */
static inline void sp_wrench_out_add(const double *R, const double *p, const double *Wb, double *SP_RESTRICT Wa) {
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
static inline void sp_ad(const double *T, const double *X, double *SP_RESTRICT Y) {
  double t[3];
  sp_cross(T, X, Y);
  sp_cross(T + 3, X, Y + 3);
  sp_cross(T, X + 3, t);
  Y[3] += t[0];
  Y[4] += t[1];
  Y[5] += t[2];
}

/* Y = −ad(T)ᵀ W = [ω × τ + v × f; ω × f] (Y not T or W) */
static inline void sp_ad_star(const double *T, const double *W, double *SP_RESTRICT Y) {
  double t[3];
  sp_cross(T, W, Y);
  sp_cross(T + 3, W + 3, t);
  Y[0] += t[0];
  Y[1] += t[1];
  Y[2] += t[2];
  sp_cross(T, W + 3, Y + 3);
}

/* W = M T of the rigid inertia I: τ = I_o ω + h × v, f = m v − h × ω */
static inline void sp_inertia_apply(const double *I, const double *T, double *SP_RESTRICT W) {
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
 * h_a = R h + m p, I_o,a = R I_o Rᵀ + 2 (g·p) 1 − p gᵀ − g pᵀ with g = R h + (m / 2) p
 * (Ia not Ib; I_o symmetric: its upper triangle read, both written). */
static inline void sp_inertia_out_add(const double *R, const double *p, const double *Ib, double *SP_RESTRICT Ia) {
  const double m = Ib[0], *I = Ib + 4;
  double h[3], g[3], A[9], gp, d;
  sp_rot(R, Ib + 1, h);
#define SP_GA(i)                                            /* A = R I_o: row i of R times the symmetric I_o */ \
  g[i] = h[i] + 0.5 * m * p[i];                                                                                  \
  A[i] = R[i] * I[0] + R[(i) + 3] * I[3] + R[(i) + 6] * I[6];                                                    \
  A[(i) + 3] = R[i] * I[3] + R[(i) + 3] * I[4] + R[(i) + 6] * I[7];                                              \
  A[(i) + 6] = R[i] * I[6] + R[(i) + 3] * I[7] + R[(i) + 6] * I[8]
  SP_GA(0);
  SP_GA(1);
  SP_GA(2);
#undef SP_GA
  gp = 2.0 * (g[0] * p[0] + g[1] * p[1] + g[2] * p[2]);
  /* (A Rᵀ)_ij = Σ_k A_ik R_jk */
#define SP_IO(i, j) (A[i] * R[j] + A[i + 3] * R[j + 3] + A[i + 6] * R[j + 6] - p[i] * g[j] - g[i] * p[j])
  Ia[4] += SP_IO(0, 0) + gp;
  Ia[8] += SP_IO(1, 1) + gp;
  Ia[12] += SP_IO(2, 2) + gp;
  d = SP_IO(0, 1);
  Ia[5] += d;
  Ia[7] += d;
  d = SP_IO(0, 2);
  Ia[6] += d;
  Ia[10] += d;
  d = SP_IO(1, 2);
  Ia[9] += d;
  Ia[11] += d;
#undef SP_IO
  Ia[0] += m;
  Ia[1] += h[0] + m * p[0];
  Ia[2] += h[1] + m * p[1];
  Ia[3] += h[2] + m * p[2];
}

/* Ia = the rigid inertia Ib (in b) in the axes of a, about the same origin (b turned by R in
 * a): h_a = R h, I_o,a = R I_o Rᵀ (Ia not Ib; I_o symmetric: its lower triangle read, both
 * written). */
static inline void sp_inertia_rotate(const double *R, const double *Ib, double *SP_RESTRICT Ia) {
  const double *I = Ib + 4;
  double A[9];
  sp_rot(R, Ib + 1, Ia + 1);
#define SP_RI(i)                                            /* A = R I_o: row i of R times the symmetric I_o */ \
  A[i] = R[i] * I[0] + R[(i) + 3] * I[1] + R[(i) + 6] * I[2];                                                    \
  A[(i) + 3] = R[i] * I[1] + R[(i) + 3] * I[4] + R[(i) + 6] * I[5];                                              \
  A[(i) + 6] = R[i] * I[2] + R[(i) + 3] * I[5] + R[(i) + 6] * I[8]
  SP_RI(0);
  SP_RI(1);
  SP_RI(2);
#undef SP_RI
#define SP_AR(i, j) (A[i] * R[j] + A[i + 3] * R[j + 3] + A[i + 6] * R[j + 6])
  Ia[0] = Ib[0];
  Ia[4] = SP_AR(0, 0);
  Ia[8] = SP_AR(1, 1);
  Ia[12] = SP_AR(2, 2);
  Ia[5] = Ia[7] = SP_AR(1, 0);
  Ia[6] = Ia[10] = SP_AR(2, 0);
  Ia[9] = Ia[11] = SP_AR(2, 1);
#undef SP_AR
}

/* Ia += the rigid inertia Ib, both in the same axes, Ib about a point b and Ia about a point a
 * with b − a = d (the move of sp_inertia_out_add with R = 1): h_a = h + m d, I_o,a = I_o + 2 (g·d) 1 − d gᵀ − g dᵀ with
 * g = h + (m / 2) d (Ia not Ib). */
static inline void sp_inertia_shift_add(const double *d, const double *Ib, double *SP_RESTRICT Ia) {
  const double m = Ib[0];
  double g[3], gd, x;
  g[0] = Ib[1] + 0.5 * m * d[0];
  g[1] = Ib[2] + 0.5 * m * d[1];
  g[2] = Ib[3] + 0.5 * m * d[2];
  gd = 2.0 * (g[0] * d[0] + g[1] * d[1] + g[2] * d[2]);
  Ia[4] += Ib[4] + gd - 2.0 * d[0] * g[0];
  Ia[8] += Ib[8] + gd - 2.0 * d[1] * g[1];
  Ia[12] += Ib[12] + gd - 2.0 * d[2] * g[2];
  x = -d[0] * g[1] - g[0] * d[1];
  Ia[5] += Ib[5] + x;
  Ia[7] += Ib[7] + x;
  x = -d[0] * g[2] - g[0] * d[2];
  Ia[6] += Ib[6] + x;
  Ia[10] += Ib[10] + x;
  x = -d[1] * g[2] - g[1] * d[2];
  Ia[9] += Ib[9] + x;
  Ia[11] += Ib[11] + x;
  Ia[0] += m;
  Ia[1] += Ib[1] + m * d[0];
  Ia[2] += Ib[2] + m * d[1];
  Ia[3] += Ib[3] + m * d[2];
}

/* The wrench W about a point b, made about a point a with b − a = d (same axes): τ += d × f */
static inline void sp_wrench_shift(const double *d, double *W) {
  double t[3];
  sp_cross(d, W + 3, t);
  W[0] += t[0];
  W[1] += t[1];
  W[2] += t[2];
}

/* T_a = Ad(H_ab) T_b: ω_a = R ω_b, v_a = R v_b + p × ω_a (T_a not T_b) */
static inline void sp_twist_out(const double *R, const double *p, const double *Tb, double *SP_RESTRICT Ta) {
  double t[3];
  sp_rot(R, Tb, Ta);
  sp_rot(R, Tb + 3, Ta + 3);
  sp_cross(p, Ta, t);
  Ta[3] += t[0];
  Ta[4] += t[1];
  Ta[5] += t[2];
}

/* M (6 × 6, column-major) of the rigid inertia I: [[I_o, ĥ], [ĥᵀ, m 1]] */
static inline void sp_inertia_matrix(const double *I, double *SP_RESTRICT M) {
  const double m = I[0], h0 = I[1], h1 = I[2], h2 = I[3];
  M[0] = I[4];   M[1] = I[5];   M[2] = I[6];   M[3] = 0.0;   M[4] = -h2;  M[5] = h1;
  M[6] = I[7];   M[7] = I[8];   M[8] = I[9];   M[9] = h2;    M[10] = 0.0; M[11] = -h0;
  M[12] = I[10]; M[13] = I[11]; M[14] = I[12]; M[15] = -h1;  M[16] = h0;  M[17] = 0.0;
  M[18] = 0.0;   M[19] = h2;    M[20] = -h1;   M[21] = m;    M[22] = 0.0; M[23] = 0.0;
  M[24] = -h2;   M[25] = 0.0;   M[26] = h0;    M[27] = 0.0;  M[28] = m;   M[29] = 0.0;
  M[30] = h1;    M[31] = -h0;   M[32] = 0.0;   M[33] = 0.0;  M[34] = 0.0; M[35] = m;
}

#endif

/* A run's start on a tree: whether natural coordinates (q, v) hold every constraint, and the joint state
 * (q_j, v_j) they stand for, in one pass over the tables of ncgen_tree_tables.h and the members' coordinate
 * maps (packed by ncgen/codegen/tree_start.py) — the check ncgen/assembly/joint_space.py's
 * JointSpace._checked_state makes, for trees of every joint kind of the tables (mimic joints included).
 *
 * A tree's constraints hold at (q, v) iff q is the natural coordinates of the tree at some joint positions and
 * v their rate.  So: extract (q_j, v_j) from (q, v) joint by joint, map them forward through the tree, and
 * compare: check = [max |q − q(q_j)|, max |v − v(q_j, v_j)|, max |q|, max |v|, Σ (q, v, both differences)]
 * (a mimic joint's position and rate, read off like the others, also compared with its source's through the
 * tables' mimic map: those differences count in the first two)
 * (the sum finite only if every value is).
 *
 * Poses are 12 doubles [R (3×3, column-major); p], rates the same 12 of their time derivative.  Per body b
 * (tables' order) the members' numbers num + NCGEN_TREE_START_NUM b are
 *   cst (12)  the member's fixed local coordinates (where idx[12 b + k] < 0; idx: the slot's index in q),
 *   P (12×13, column-major) [pose] = P [q_m; 1]: the pose of the body's joint frame after the motion f_b
 *     from its member's local coordinates q_m,
 *   L (12×13, column-major) [q_m] = L [pose; 1]: the member's local coordinates at a pose of f_b;
 * the nonzeros of P's and L's linear parts at nz[nz_ptr[2 b] ..], nz[nz_ptr[2 b + 1] ..] (r | k << 4); how[b]
 * how its joint is read off (NCGEN_START_*, below: the kind's, ncgen/codegen/tree_start.py's READ).
 * The joint frames chain as f_b = f_parent · xin_b · T_J(q_j) (ncgen_tree_local_poses); each joint is read
 * off its member's pose relative to its parent's frame forward (on the tree, the same frame): the relative
 * pose T = (R, p) = A⁻¹ H of the measured pose H of f_b and A = f_parent · xin_b, and its body twist
 * ξ = [ω; v] = vee(T⁻¹ Ṫ) (ω from the skew part of Rᵀ Ṙ).
 * A revolute joint's angle is atan2 of R's (1,0), (0,0) entries, its rate ω_z; a prismatic joint's displacement
 * p_z, its rate that's.  The kinds the tables move by their kernel `local` (T_J and the motion subspace S in
 * f_b, vee(T_J⁻¹ Ṫ_J) = S w), with their axes from the tables' numbers (num[num_ptr[b] + 24 ..]):
 *   cylindrical (axis a)  s = a·p / a·a, θ = atan2(â·(u × R u), u·R u) (u ⟂ a, unit)
 *   universal (a, b)      R = Rot(a, θ_a) Rot(b, θ_b): θ_a = atan2(c·R b, b⊥·R b), θ_b = atan2(c·Rᵀa, a⊥·Rᵀa)
 *                         (unit axes, c = a × b, b⊥ = b − (a·b) a, a⊥ = a − (a·b) b)
 *   planar (n, e1, e2)    x = e1·p, y = e2·p, θ = atan2(n·(e1 × R e1), e1·R e1)
 *   spherical             the quaternion of R (Shepperd's, qw ≥ 0, as ncgen/symbolic/rigid_motion.py's
 *                         quaternion: not normalised, so the one CasADi's check returns)
 *   free                  [p; the quaternion of R]
 * and their rates the least-squares solution of S w = ξ (S at the positions read off); the joint frame forward
 * is then F = A T_J(q_j) from the kernel (which normalises a quaternion) with rate dA T_J + F (S w)^, so that
 * a rate ξ outside S's range, or a rotation that is not one, shows in the distances.
 * Work w: NCGEN_TREE_START_WORK_SIZE(K, T) doubles.  Returns 0, or 1 when a body's joint is of a kind this
 * check does not take (how[b] not matching its kind's sizes and mode, or its kernel not set). */
#ifndef NCGEN_TREE_START_H
#define NCGEN_TREE_START_H

#include <math.h>
#include <string.h>

#define NCGEN_TREE_START_NUM 324  /* cst 12, P 156, L 156 */
/* How a joint is read off its relative pose (how[b]): the tables' modes 1 .. 3 (a rotation about z, a
 * translation along z, none), then the kinds moved by their kernel. */
#define NCGEN_START_REVOLUTE 1
#define NCGEN_START_PRISMATIC 2
#define NCGEN_START_FIXED 3
#define NCGEN_START_CYLINDRICAL 4
#define NCGEN_START_UNIVERSAL 5
#define NCGEN_START_PLANAR 6
#define NCGEN_START_SPHERICAL 7
#define NCGEN_START_FREE 8

/* The arguments of ncgen_tree_start_state: the tree, its members' maps, the n natural coordinates q, v, and where
 * the joint state, the check and the work go (one pointer for a caller that sets them once). */
typedef struct {
  const ncgen_tree *T;
  const int *idx, *how, *nz_ptr, *nz;
  const double *num;
  int n;
  const double *q, *v;
  double *qj, *vj, *check, *w;
} ncgen_tree_start;

/* out = A B (poses). */
static void ncgen_start_compose(const double *A, const double *B, double *out) {
  int i, j;
  for (j = 0; j < 3; ++j)
    for (i = 0; i < 3; ++i) out[i + 3 * j] = A[i] * B[3 * j] + A[i + 3] * B[3 * j + 1] + A[i + 6] * B[3 * j + 2];
  for (i = 0; i < 3; ++i) out[9 + i] = A[i] * B[9] + A[i + 3] * B[10] + A[i + 6] * B[11] + A[9 + i];
}

/* dout = d(A B) = dA B + A dB (rates of poses: dA, dB with no constant part). */
static void ncgen_start_dcompose(const double *A, const double *dA, const double *B, const double *dB,
                                 double *dout) {
  int i, j;
  for (j = 0; j < 3; ++j)
    for (i = 0; i < 3; ++i)
      dout[i + 3 * j] = dA[i] * B[3 * j] + dA[i + 3] * B[3 * j + 1] + dA[i + 6] * B[3 * j + 2]
                        + A[i] * dB[3 * j] + A[i + 3] * dB[3 * j + 1] + A[i + 6] * dB[3 * j + 2];
  for (i = 0; i < 3; ++i)
    dout[9 + i] = dA[i] * B[9] + dA[i + 3] * B[10] + dA[i + 6] * B[11]
                  + A[i] * dB[9] + A[i + 3] * dB[10] + A[i + 6] * dB[11] + dA[9 + i];
}

/* y = M [x; 1] and dy = M [dx; 0] for a 12×13 column-major M whose linear part has its nonzeros at nz[0 .. m − 1]
 * (row r, column k as r | k << 4): a pose or coordinates and their rates. */
static void ncgen_start_apply(const double *M, const int *nz, int m, const double *x, const double *dx, double *y,
                              double *dy) {
  int i;
  for (i = 0; i < 12; ++i) y[i] = M[i + 144], dy[i] = 0.0;
  for (i = 0; i < m; ++i) {
    int r = nz[i] & 15, k = nz[i] >> 4;
    double a = M[r + 12 * k];
    y[r] += a * x[k];
    dy[r] += a * dx[k];
  }
}

static double ncgen_start_dot(const double *a, const double *b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

/* Body b's joint frame forward, F = A T_J(x) with A = f_parent · xin (rate dF from dA and the rate r of x), after
 * the joint's position x and rate r are read off the measured pose H (rate dH) of f_b relative to A: a revolute
 * joint's angle atan2 of (Aᵀ H)'s (1,0), (0,0) entries, its rate the z component of the skew part of Rᵀ Ṙ for
 * R = Aᵀ H (columns 0, 1 of both needed); a prismatic joint's displacement e_zᵀ Aᵀ (p_H − p_A) and its rate. */
static void ncgen_start_joint(int mode, const double *A, const double *dA, const double *H, const double *dH,
                              double *x, double *r, double *F, double *dF) {
  int i;
  memcpy(F, A, 12 * sizeof(double));
  memcpy(dF, dA, 12 * sizeof(double));
  if (mode == 1) {
    double r0[3], r1[3], d0[3], d1[3], h, c, s;
    for (i = 0; i < 3; ++i) {
      r0[i] = ncgen_start_dot(A + 3 * i, H), r1[i] = ncgen_start_dot(A + 3 * i, H + 3);
      d0[i] = ncgen_start_dot(dA + 3 * i, H) + ncgen_start_dot(A + 3 * i, dH);
      d1[i] = ncgen_start_dot(dA + 3 * i, H + 3) + ncgen_start_dot(A + 3 * i, dH + 3);
    }
    *x = atan2(r0[1], r0[0]);
    *r = 0.5 * (ncgen_start_dot(r1, d0) - ncgen_start_dot(r0, d1));
    h = sqrt(r0[0] * r0[0] + r0[1] * r0[1]);      /* cos x, sin x (a NaN where h is 0: the sum shows it) */
    c = r0[0] / h, s = r0[1] / h;
    for (i = 0; i < 3; ++i) {                     /* R = R_A Rz(x), Ṙ = Ṙ_A Rz(x) + r R_A Rz'(x) */
      F[i] = c * A[i] + s * A[3 + i], F[3 + i] = c * A[3 + i] - s * A[i];
      dF[i] = c * dA[i] + s * dA[3 + i] + *r * F[3 + i], dF[3 + i] = c * dA[3 + i] - s * dA[i] - *r * F[i];
    }
  } else if (mode == 2) {
    double d[3], dd[3];
    for (i = 0; i < 3; ++i) d[i] = H[9 + i] - A[9 + i], dd[i] = dH[9 + i] - dA[9 + i];
    *x = ncgen_start_dot(A + 6, d);
    *r = ncgen_start_dot(dA + 6, d) + ncgen_start_dot(A + 6, dd);
    for (i = 0; i < 3; ++i) F[9 + i] += *x * A[6 + i], dF[9 + i] += *r * A[6 + i] + *x * dA[6 + i];
  }
}

static void ncgen_start_cross(const double *a, const double *b, double *c) {
  c[0] = a[1] * b[2] - a[2] * b[1], c[1] = a[2] * b[0] - a[0] * b[2], c[2] = a[0] * b[1] - a[1] * b[0];
}

/* y = R x (R column-major) and y = Rᵀ x. */
static void ncgen_start_rot(const double *R, const double *x, double *y) {
  int i;
  for (i = 0; i < 3; ++i) y[i] = R[i] * x[0] + R[i + 3] * x[1] + R[i + 6] * x[2];
}

static void ncgen_start_rot_t(const double *R, const double *x, double *y) {
  int i;
  for (i = 0; i < 3; ++i) y[i] = ncgen_start_dot(R + 3 * i, x);
}

/* The relative pose T = A⁻¹ H (12) of the pose H (rate dH) in A (rate dA), and its body twist
 * xi = [ω; v] = vee(T⁻¹ Ṫ) (ω from the skew part of Rᵀ Ṙ). */
static void ncgen_start_relative(const double *A, const double *dA, const double *H, const double *dH, double *T,
                                 double *xi) {
  double dR[9], d[3], dd[3], dp[3], O[9];
  int i, j;
  for (j = 0; j < 3; ++j)
    for (i = 0; i < 3; ++i) {
      T[i + 3 * j] = ncgen_start_dot(A + 3 * i, H + 3 * j);
      dR[i + 3 * j] = ncgen_start_dot(dA + 3 * i, H + 3 * j) + ncgen_start_dot(A + 3 * i, dH + 3 * j);
    }
  for (i = 0; i < 3; ++i) d[i] = H[9 + i] - A[9 + i], dd[i] = dH[9 + i] - dA[9 + i];
  for (i = 0; i < 3; ++i) T[9 + i] = ncgen_start_dot(A + 3 * i, d), dp[i] = ncgen_start_dot(dA + 3 * i, d) + ncgen_start_dot(A + 3 * i, dd);
  for (j = 0; j < 3; ++j)
    for (i = 0; i < 3; ++i) O[i + 3 * j] = ncgen_start_dot(T + 3 * i, dR + 3 * j);      /* Rᵀ Ṙ */
  xi[0] = 0.5 * (O[5] - O[7]), xi[1] = 0.5 * (O[6] - O[2]), xi[2] = 0.5 * (O[1] - O[3]);
  ncgen_start_rot_t(T, dp, xi + 3);
}

/* The unit quaternion [qx, qy, qz, qw] (qw ≥ 0) of R by Shepperd's method, as
 * ncgen/symbolic/rigid_motion.py's quaternion: the branch of the largest of tr R, R₀₀, R₁₁, R₂₂, roots of
 * max(·, 1), the branch's sign that of its qw (1 at 0); not normalised. */
static void ncgen_start_quaternion(const double *R, double *q) {
  double tr = R[0] + R[4] + R[8], d21 = R[5] - R[7], d02 = R[6] - R[2], d10 = R[1] - R[3];
  double s01 = R[3] + R[1], s02 = R[6] + R[2], s12 = R[7] + R[5], r, g;
  if (tr >= R[0] && tr >= R[4] && tr >= R[8]) {
    r = 0.5 * sqrt(fmax(1.0 + tr, 1.0));
    q[0] = d21 / (4 * r), q[1] = d02 / (4 * r), q[2] = d10 / (4 * r), q[3] = r;
    return;
  }
  if (R[0] >= R[4] && R[0] >= R[8]) {
    r = 0.5 * sqrt(fmax(1.0 + R[0] - R[4] - R[8], 1.0)), g = d21 < 0 ? -1.0 : 1.0;
    q[0] = g * r, q[1] = g * (s01 / (4 * r)), q[2] = g * (s02 / (4 * r)), q[3] = g * (d21 / (4 * r));
  } else if (R[4] >= R[8]) {
    r = 0.5 * sqrt(fmax(1.0 - R[0] + R[4] - R[8], 1.0)), g = d02 < 0 ? -1.0 : 1.0;
    q[0] = g * (s01 / (4 * r)), q[1] = g * r, q[2] = g * (s12 / (4 * r)), q[3] = g * (d02 / (4 * r));
  } else {
    r = 0.5 * sqrt(fmax(1.0 - R[0] - R[4] + R[8], 1.0)), g = d10 < 0 ? -1.0 : 1.0;
    q[0] = g * (s02 / (4 * r)), q[1] = g * (s12 / (4 * r)), q[2] = g * r, q[3] = g * (d10 / (4 * r));
  }
}

/* atan2(n·(u × R u), u·R u): the angle R turns the unit u about the unit n (u ⟂ n). */
static double ncgen_start_angle(const double *R, const double *n, const double *u) {
  double Ru[3], c[3];
  ncgen_start_rot(R, u, Ru);
  ncgen_start_cross(u, Ru, c);
  return atan2(ncgen_start_dot(n, c), ncgen_start_dot(u, Ru));
}

static void ncgen_start_unit(const double *a, double *u) {
  double h = sqrt(ncgen_start_dot(a, a));
  u[0] = a[0] / h, u[1] = a[1] / h, u[2] = a[2] / h;
}

/* The positions x of a joint read off (how, module comment) its relative pose T, its axes ax. */
static void ncgen_start_positions(int how, const double *T, const double *ax, double *x) {
  const double *R = T, *p = T + 9;
  double a[3], b[3], c[3], u[3], y[3];
  int i;
  if (how == NCGEN_START_CYLINDRICAL) {
    int m = 0;
    ncgen_start_unit(ax, a);
    for (i = 1; i < 3; ++i) m = fabs(a[i]) < fabs(a[m]) ? i : m;
    for (i = 0; i < 3; ++i) y[i] = (i == m) - a[i] * a[m];
    ncgen_start_unit(y, u);
    x[0] = ncgen_start_dot(ax, p) / ncgen_start_dot(ax, ax), x[1] = ncgen_start_angle(R, a, u);
  } else if (how == NCGEN_START_UNIVERSAL) {
    double ab, Rb[3], Rta[3], ap[3], bp[3];
    ncgen_start_unit(ax, a), ncgen_start_unit(ax + 3, b), ncgen_start_cross(a, b, c);
    ab = ncgen_start_dot(a, b);
    for (i = 0; i < 3; ++i) ap[i] = a[i] - ab * b[i], bp[i] = b[i] - ab * a[i];
    ncgen_start_rot(R, b, Rb), ncgen_start_rot_t(R, a, Rta);
    x[0] = atan2(ncgen_start_dot(c, Rb), ncgen_start_dot(bp, Rb));
    x[1] = atan2(ncgen_start_dot(c, Rta), ncgen_start_dot(ap, Rta));
  } else if (how == NCGEN_START_PLANAR) {
    x[0] = ncgen_start_dot(ax + 3, p), x[1] = ncgen_start_dot(ax + 6, p), x[2] = ncgen_start_angle(R, ax, ax + 3);
  } else if (how == NCGEN_START_SPHERICAL) {
    ncgen_start_quaternion(R, x);
  } else {                                         /* free */
    for (i = 0; i < 3; ++i) x[i] = p[i];
    ncgen_start_quaternion(R, x + 3);
  }
}

/* w = argmin |S w − xi| (S 6 × nv column-major, full column rank: by Cholesky of Sᵀ S; a NaN where it is not
 * positive definite, which the check's sum shows). */
static void ncgen_start_rates(const double *S, int nv, const double *xi, double *w) {
  double G[36], r[6];
  int i, j, k;
  for (i = 0; i < nv; ++i) {
    r[i] = 0.0;
    for (k = 0; k < 6; ++k) r[i] += S[k + 6 * i] * xi[k];
    for (j = 0; j <= i; ++j) {
      double g = 0.0;
      for (k = 0; k < 6; ++k) g += S[k + 6 * i] * S[k + 6 * j];
      G[i + 6 * j] = g;
    }
  }
  for (j = 0; j < nv; ++j) {                       /* G = L Lᵀ (lower triangle, in place) */
    double d = G[j + 6 * j];
    for (k = 0; k < j; ++k) d -= G[j + 6 * k] * G[j + 6 * k];
    d = d > 0.0 ? sqrt(d) : NAN;
    G[j + 6 * j] = d;
    for (i = j + 1; i < nv; ++i) {
      double e = G[i + 6 * j];
      for (k = 0; k < j; ++k) e -= G[i + 6 * k] * G[j + 6 * k];
      G[i + 6 * j] = e / d;
    }
  }
  for (i = 0; i < nv; ++i) {
    for (k = 0; k < i; ++k) r[i] -= G[i + 6 * k] * r[k];
    r[i] /= G[i + 6 * i];
  }
  for (i = nv - 1; i >= 0; --i) {
    for (k = i + 1; k < nv; ++k) r[i] -= G[k + 6 * i] * w[k];
    w[i] = r[i] / G[i + 6 * i];
  }
}

/* Body b's joint of a kind moved by its kernel: its positions x and rates r read off the measured pose H (rate
 * dH) relative to A (rate dA), its frame forward F = A T_J(x) and rate dF = dA T_J + F (S r)^.  in, out, kw:
 * the kernel's input, output and work.  Returns the kernel's status. */
static int ncgen_start_local(const ncgen_tree_joint_kind *k, int how, const double *numbers, const double *A,
                             const double *dA, const double *H, const double *dH, double *x, double *r, double *F,
                             double *dF, double *in, double *out, double *kw) {
  static const double Z[12] = {0};
  double T[12], xi[6], fit[6];
  int i, j;
  ncgen_start_relative(A, dA, H, dH, T, xi);
  ncgen_start_positions(how, T, numbers + 24, x);
  for (i = 0; i < k->nq; ++i) in[i] = x[i];
  for (i = 0; i < k->nv; ++i) in[k->nq + i] = 0.0;
  for (i = 0; i < k->n_num; ++i) in[k->nq + k->nv + i] = numbers[i];
  if (ncgen_tree_call(k->local, in, out, kw)) return NCGEN_TREE_KERNEL;
  ncgen_start_rates(out + 12, k->nv, xi, r);
  for (i = 0; i < 6; ++i) {
    fit[i] = 0.0;
    for (j = 0; j < k->nv; ++j) fit[i] += out[12 + i + 6 * j] * r[j];
  }
  ncgen_start_compose(A, out, F);
  ncgen_start_dcompose(A, dA, out, Z, dF);
  for (i = 0; i < 3; ++i) {                         /* + R_F ω̂ (columns R_F (ω × e_j)) and R_F v */
    dF[i] += F[3 + i] * fit[2] - F[6 + i] * fit[1];
    dF[3 + i] += F[6 + i] * fit[0] - F[i] * fit[2];
    dF[6 + i] += F[i] * fit[1] - F[3 + i] * fit[0];
    dF[9 + i] += F[i] * fit[3] + F[3 + i] * fit[4] + F[6 + i] * fit[5];
  }
  return 0;
}

/* The positions and rates each way of reading a joint off takes (how, module comment; 0 unused). */
static const int NCGEN_START_NQ[9] = {0, 1, 1, 0, 2, 2, 3, 4, 7}, NCGEN_START_NV[9] = {0, 1, 1, 0, 2, 2, 3, 3, 6};

/* Doubles of work ncgen_tree_start_state needs for the tables T (a macro: units that do not call it warn of no
 * unused function): the frames forward (24 nb), a kernel's input, output and work. */
#define NCGEN_TREE_START_WORK_SIZE(K, T) \
  (24L * (T)->nb + ncgen_tree_max_in(K) + ncgen_tree_max_out(K) + ((K)->max_w > 0 ? (K)->max_w : 1))

static int ncgen_tree_start_state(const ncgen_tree_kinds *K, const ncgen_tree_start *S) {
  const ncgen_tree *T = S->T;
  const int *idx = S->idx, *how = S->how, *nz_ptr = S->nz_ptr, *nz = S->nz, n = S->n;
  const double *num = S->num, *q = S->q, *v = S->v;
  double *qj = S->qj, *vj = S->vj, *check = S->check, *w = S->w;
  double *in = w + 24 * T->nb, *out = in + ncgen_tree_max_in(K), *kw = out + ncgen_tree_max_out(K);
  static const double I[12] = {1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0}, Z[12] = {0};
  double qm[12], vm[12], H[12], dH[12], A[12], dA[12], y[12], dy[12];
  double e_q = 0.0, e_v = 0.0, q_max = 0.0, v_max = 0.0, sum = 0.0;
  int b, i, failed = 0;
  for (b = 0; b < T->nb; ++b) {
    const ncgen_tree_joint_kind *k = &K->joint[T->kind[b]];
    int h = how[b];
    if (h < 1 || h > NCGEN_START_FREE || k->nq != NCGEN_START_NQ[h] || k->nv != NCGEN_START_NV[h] ||
        (k->mode ? k->mode != h : h <= NCGEN_START_FIXED || !k->local))
      return 1;
  }
  for (b = 0; b < T->nb; ++b) {
    const ncgen_tree_joint_kind *k = &K->joint[T->kind[b]];
    const int *ix = idx + 12 * b, m = k->mode, par = T->parent[b];
    const double *cst = num + NCGEN_TREE_START_NUM * b, *P = cst + 12, *L = P + 156;
    const int *nzP = nz + nz_ptr[2 * b], *nzL = nz + nz_ptr[2 * b + 1];
    int mP = nz_ptr[2 * b + 1] - nz_ptr[2 * b], mL = nz_ptr[2 * b + 2] - nz_ptr[2 * b + 1];
    double *F = w + 24 * b, *dF = F + 12, x = 0.0, r = 0.0;                  /* f_b forward and its rate */
    const double *Fp = par < 0 ? I : w + 24 * par, *dFp = par < 0 ? Z : Fp + 12;
    for (i = 0; i < 12; ++i) qm[i] = ix[i] >= 0 ? q[ix[i]] : cst[i], vm[i] = ix[i] >= 0 ? v[ix[i]] : 0.0;
    ncgen_start_apply(P, nzP, mP, qm, vm, H, dH);                         /* f_b measured and its rate */
    ncgen_start_compose(Fp, T->xin + 12 * b, A);                          /* A = f_p xin (forward) */
    ncgen_start_dcompose(Fp, dFp, T->xin + 12 * b, Z, dA);
    if (m) {
      ncgen_start_joint(m, A, dA, H, dH, &x, &r, F, dF);
      if (m == 1 || m == 2) qj[T->q_at[b]] = x, vj[T->v_at[b]] = r;
    } else {
      failed |= ncgen_start_local(k, how[b], T->num + T->num_ptr[b], A, dA, H, dH, qj + T->q_at[b], vj + T->v_at[b],
                                  F, dF, in, out, kw);
    }
    ncgen_start_apply(L, nzL, mL, F, dF, y, dy);                          /* the member's coordinates forward */
    for (i = 0; i < 12; ++i) {
      double d = fabs(y[i] - qm[i]), dv = fabs(dy[i] - vm[i]);
      e_q = d > e_q ? d : e_q;
      e_v = dv > e_v ? dv : e_v;
      sum += d + dv;
    }
  }
  for (i = 0; T->q_src && i < T->nq; ++i)        /* mimic joints: q_j[i] = q_coef q_j[q_src] + q_off (the map's) */
    if (T->q_src[i] >= 0) {
      double d = fabs(qj[i] - (T->q_coef[i] * qj[T->q_src[i]] + T->q_off[i]));
      e_q = d > e_q ? d : e_q;
      sum += d;
    }
  for (i = 0; T->rate_src && i < T->nv; ++i)     /* and v_j[i] = rate_coef v_j[rate_src] */
    if (T->rate_src[i] != i) {
      double d = fabs(vj[i] - T->rate_coef[i] * vj[T->rate_src[i]]);
      e_v = d > e_v ? d : e_v;
      sum += d;
    }
  for (i = 0; i < n; ++i) {
    double a = fabs(q[i]), c = fabs(v[i]);
    q_max = a > q_max ? a : q_max;
    v_max = c > v_max ? c : v_max;
    sum += q[i] + v[i];
  }
  check[0] = e_q, check[1] = e_v, check[2] = q_max, check[3] = v_max, check[4] = failed ? NAN : sum;
  return 0;
}

#endif

/* A run's start on a tree: whether natural coordinates (q, v) hold every constraint, and the joint state
 * (q_j, v_j) they stand for, in one pass over the tables of ncgen_tree_tables.h and the members' coordinate
 * maps (packed by ncgen/codegen/tree_start.py) — the check ncgen/assembly/joint_space.py's
 * JointSpace._checked_state makes, for trees of revolute, prismatic and fixed joints (mimic joints included).
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
 * the nonzeros of P's and L's linear parts at nz[nz_ptr[2 b] ..], nz[nz_ptr[2 b + 1] ..] (r | k << 4).
 * The joint frames chain as f_b = f_parent · xin_b · T_J(q_j) (ncgen_tree_local_poses); each joint is read
 * off its member's pose relative to its parent's frame forward (on the tree, the same frame).
 * A revolute joint's angle is atan2 of the relative rotation's (1,0), (0,0) entries, its rate the z
 * component of Rᵀ Ṙ (its skew part); a prismatic joint's displacement is the relative position's z, its rate that's.
 * Work w: 24 nb doubles.  Returns 0, or 1 when a body's joint is of a kind this check does not take. */
#ifndef NCGEN_TREE_START_H
#define NCGEN_TREE_START_H

#include <math.h>
#include <string.h>

#define NCGEN_TREE_START_NUM 324  /* cst 12, P 156, L 156 */

/* The arguments of ncgen_tree_start_state: the tree, its members' maps, the n natural coordinates q, v, and where
 * the joint state, the check and the work go (one pointer for a caller that sets them once). */
typedef struct {
  const ncgen_tree *T;
  const int *idx, *nz_ptr, *nz;
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

static int ncgen_tree_start_state(const ncgen_tree_kinds *K, const ncgen_tree_start *S) {
  const ncgen_tree *T = S->T;
  const int *idx = S->idx, *nz_ptr = S->nz_ptr, *nz = S->nz, n = S->n;
  const double *num = S->num, *q = S->q, *v = S->v;
  double *qj = S->qj, *vj = S->vj, *check = S->check, *w = S->w;
  static const double I[12] = {1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0}, Z[12] = {0};
  double qm[12], vm[12], H[12], dH[12], A[12], dA[12], y[12], dy[12];
  double e_q = 0.0, e_v = 0.0, q_max = 0.0, v_max = 0.0, sum = 0.0;
  int b, i;
  for (b = 0; b < T->nb; ++b)
    if (!K->joint[T->kind[b]].mode) return 1;
  for (b = 0; b < T->nb; ++b) {
    const int *ix = idx + 12 * b, m = K->joint[T->kind[b]].mode, par = T->parent[b];
    const double *cst = num + NCGEN_TREE_START_NUM * b, *P = cst + 12, *L = P + 156;
    const int *nzP = nz + nz_ptr[2 * b], *nzL = nz + nz_ptr[2 * b + 1];
    int mP = nz_ptr[2 * b + 1] - nz_ptr[2 * b], mL = nz_ptr[2 * b + 2] - nz_ptr[2 * b + 1];
    double *F = w + 24 * b, *dF = F + 12, x = 0.0, r = 0.0;                  /* f_b forward and its rate */
    const double *Fp = par < 0 ? I : w + 24 * par, *dFp = par < 0 ? Z : Fp + 12;
    for (i = 0; i < 12; ++i) qm[i] = ix[i] >= 0 ? q[ix[i]] : cst[i], vm[i] = ix[i] >= 0 ? v[ix[i]] : 0.0;
    ncgen_start_apply(P, nzP, mP, qm, vm, H, dH);                         /* f_b measured and its rate */
    ncgen_start_compose(Fp, T->xin + 12 * b, A);                          /* A = f_p xin (forward) */
    ncgen_start_dcompose(Fp, dFp, T->xin + 12 * b, Z, dA);
    ncgen_start_joint(m, A, dA, H, dH, &x, &r, F, dF);
    if (m == 1 || m == 2) qj[T->q_at[b]] = x, vj[T->v_at[b]] = r;
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
  check[0] = e_q, check[1] = e_v, check[2] = q_max, check[3] = v_max, check[4] = sum;
  return 0;
}

#endif

/* A run's start on a tree: whether natural coordinates (q, v) hold every constraint, and the joint state
 * (q_j, v_j) they stand for, in one pass over the tables of ncgen_tree_tables.h and the members' coordinate
 * maps (packed by ncgen/codegen/tree_start.py) — the check ncgen/assembly/joint_space.py's
 * JointSpace._checked_state makes, for trees of revolute, prismatic and fixed joints without mimic joints.
 *
 * A tree's constraints hold at (q, v) iff q is the natural coordinates of the tree at some joint positions and
 * v their rate.  So: extract (q_j, v_j) from (q, v) joint by joint, map them forward through the tree, and
 * compare: check = [max |q − q(q_j)|, max |v − v(q_j, v_j)|, max |q|, max |v|, Σ (q, v, both differences)]
 * (the sum finite only if every value is).
 *
 * Poses are 12 doubles [R (3×3, column-major); p], rates the same 12 of their time derivative.  Per body b
 * (tables' order) the members' numbers num + NCGEN_TREE_START_NUM b are
 *   cst (12)  the member's fixed local coordinates (where idx[12 b + k] < 0; idx: the slot's index in q),
 *   P (12×13, column-major) [pose] = P [q_m; 1]: the pose of the body's joint frame after the motion f_b
 *     from its member's local coordinates q_m,
 *   L (12×13, column-major) [q_m] = L [pose; 1]: the member's local coordinates at a pose of f_b;
 * the nonzeros of P's and L's linear parts at nz[nz_ptr[2 b] ..], nz[nz_ptr[2 b + 1] ..] (r | k << 4).
 * The joint frames chain as f_b = f_parent · xin_b · T_J(q_j) (ncgen_tree_local_poses).
 * A revolute joint's angle is atan2 of the relative rotation's (1,0), (0,0) entries, its rate the z
 * component of Rᵀ Ṙ (its skew part); a prismatic joint's displacement is the relative position's z, its rate that's.
 * Work w: 48 nb doubles.  Returns 0, or 1 when a body's joint is of a kind this check does not take. */
#ifndef NCGEN_TREE_START_H
#define NCGEN_TREE_START_H

#include <math.h>
#include <string.h>

#define NCGEN_TREE_START_NUM 324  /* cst 12, P 156, L 156 */

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

/* y = M [x; c] for a 12×13 column-major M whose linear part has its nonzeros at nz[0 .. m − 1] (row r, column k
 * as r | k << 4), c = 1: with its constant column, 0: the linear part alone. */
static void ncgen_start_apply(const double *M, const int *nz, int m, const double *x, double c, double *y) {
  int i;
  for (i = 0; i < 12; ++i) y[i] = c * M[i + 144];
  for (i = 0; i < m; ++i) {
    int r = nz[i] & 15, k = nz[i] >> 4;
    y[r] += M[r + 12 * k] * x[k];
  }
}

/* (θ or s, its rate) of the relative motion of f_b from A = f_parent · xin (pose H, rate dH of f_b). */
static void ncgen_start_extract(int mode, const double *A, const double *dA, const double *H, const double *dH,
                                double *x, double *w) {
  double R[9], dR[9], d[3], dd[3];
  int i, j, k;
  for (j = 0; j < 3; ++j)
    for (i = 0; i < 3; ++i) {         /* R = Aᵀ H, dR = dAᵀ H + Aᵀ dH (rotations) */
      R[i + 3 * j] = dR[i + 3 * j] = 0.0;
      for (k = 0; k < 3; ++k) {
        R[i + 3 * j] += A[k + 3 * i] * H[k + 3 * j];
        dR[i + 3 * j] += dA[k + 3 * i] * H[k + 3 * j] + A[k + 3 * i] * dH[k + 3 * j];
      }
    }
  if (mode == 1) {
    *x = atan2(R[1], R[0]);
    *w = 0.5 * (R[3] * dR[0] + R[4] * dR[1] + R[5] * dR[2] - R[0] * dR[3] - R[1] * dR[4] - R[2] * dR[5]);
    return;
  }
  for (i = 0; i < 3; ++i) d[i] = H[9 + i] - A[9 + i], dd[i] = dH[9 + i] - dA[9 + i];
  *x = A[6] * d[0] + A[7] * d[1] + A[8] * d[2];     /* e_zᵀ Aᵀ (p_H − p_A) */
  *w = dA[6] * d[0] + dA[7] * d[1] + dA[8] * d[2] + A[6] * dd[0] + A[7] * dd[1] + A[8] * dd[2];
}

static int ncgen_tree_start_state(const ncgen_tree_kinds *K, const ncgen_tree *T, const int *idx, const int *nz_ptr,
                                  const int *nz, const double *num, int n, const double *q, const double *v, double *qj,
                                  double *vj, double *check, double *w) {
  static const double I[12] = {1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0}, Z[12] = {0};
  double qm[12], vm[12], A[12], dA[12], J[12], dJ[12], y[12], dy[12];
  double e_q = 0.0, e_v = 0.0, q_max = 0.0, v_max = 0.0, sum = 0.0;
  int b, i;
  for (b = 0; b < T->nb; ++b)
    if (!K->joint[T->kind[b]].mode) return 1;
  for (b = 0; b < T->nb; ++b) {
    const int *ix = idx + 12 * b, m = K->joint[T->kind[b]].mode;
    const double *cst = num + NCGEN_TREE_START_NUM * b, *P = cst + 12, *L = P + 156;
    const int *nzP = nz + nz_ptr[2 * b], *nzL = nz + nz_ptr[2 * b + 1];
    int mP = nz_ptr[2 * b + 1] - nz_ptr[2 * b], mL = nz_ptr[2 * b + 2] - nz_ptr[2 * b + 1];
    const double *xin = T->xin + 12 * b;
    int par = T->parent[b];
    double *Hf = w + 48 * b, *dHf = Hf + 12, *F = Hf + 24, *dF = Hf + 36;       /* measured f_b, forward f_b */
    const double *Hp = par < 0 ? I : w + 48 * par, *dHp = par < 0 ? Z : Hp + 12;
    const double *Fp = par < 0 ? I : Hp + 24, *dFp = par < 0 ? Z : Hp + 36;
    for (i = 0; i < 12; ++i) qm[i] = ix[i] >= 0 ? q[ix[i]] : cst[i], vm[i] = ix[i] >= 0 ? v[ix[i]] : 0.0;
    ncgen_start_apply(P, nzP, mP, qm, 1.0, Hf);                                   /* f_b's pose and rate */
    ncgen_start_apply(P, nzP, mP, vm, 0.0, dHf);
    ncgen_start_compose(Hp, xin, A);
    ncgen_start_dcompose(Hp, dHp, xin, Z, dA);
    memcpy(J, I, sizeof J);
    memset(dJ, 0, sizeof dJ);
    if (m == 1 || m == 2) {
      double x, r;
      ncgen_start_extract(m, A, dA, Hf, dHf, &x, &r);
      qj[T->q_at[b]] = x, vj[T->v_at[b]] = r;
      if (m == 1) {
        double c = cos(x), s = sin(x);
        J[0] = c, J[1] = s, J[3] = -s, J[4] = c;
        dJ[0] = -s * r, dJ[1] = c * r, dJ[3] = -c * r, dJ[4] = -s * r;
      } else {
        J[11] = x, dJ[11] = r;
      }
    }
    ncgen_start_compose(Fp, xin, A);                                     /* forward: f_b = f_p xin T_J */
    ncgen_start_dcompose(Fp, dFp, xin, Z, dA);
    ncgen_start_compose(A, J, F);
    ncgen_start_dcompose(A, dA, J, dJ, dF);
    ncgen_start_apply(L, nzL, mL, F, 1.0, y);                                     /* the member's coordinates */
    ncgen_start_apply(L, nzL, mL, dF, 0.0, dy);
    for (i = 0; i < 12; ++i) {
      double d = fabs(y[i] - qm[i]), dv = fabs(dy[i] - vm[i]);
      e_q = d > e_q ? d : e_q;
      e_v = dv > e_v ? dv : e_v;
      sum += d + dv;
    }
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

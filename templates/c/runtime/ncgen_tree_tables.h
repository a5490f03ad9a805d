/* Joint-space algorithms of a tree over data tables: inverse dynamics (RNEA), the joint-space
 * mass matrix (CRBA), forward dynamics (up to NCGEN_TREE_DENSE_NV rates M_i a_i = τ_i − b_i by
 * Cholesky, M_i and b_i of one pass out and in; above, the articulated-body algorithm, with mimic
 * joints the followers held by their constraints and the Cholesky the fallback, which an includer
 * may supply instead: NCGEN_TREE_EXTERNAL_FALLBACK) and the derivatives of RNEA and forward dynamics, as plain
 * loops over the bodies that call one small kernel per kind of joint and one per rigid body
 * (ncgen/codegen/tree_kernels.py generates them, ncgen/codegen/tree_tables.py packs the
 * tables).  The same C for every tree: a model is data.
 *
 * Body b's frame f_b is its joint frame after the joint's motion, at xin[12 b ...] · T(q) in its
 * parent's (xin: R column-major, p), its rigid inertia inertia[13 b ...] = [m; h; I_o] about
 * f_b's origin (ncgen_spatial.h); a kind's mode says how T(q) and the motion subspace S (in f_b)
 * are had: 1 a rotation about z (S = [e_z; 0]), 2 a translation along z (S = [0; e_z]), 3 none
 * (fixed), 0 its kernel local.  RNEA runs in the local frames f_b (Featherstone's recursion);
 * CRBA in the ground's axes about each body's origin (composite inertias and forces carried up
 * by translations alone); forward dynamics in the ground frame about its origin (ABA's
 * articulated inertias, and the Cholesky path's composite inertias, summed into the parent with
 * no change of frame, as Pinocchio's).  The derivatives run the tangent recursion in the ground
 * frame.
 *
 * Notation (docs/architecture.md, "Element tables"): poses H = [[R, p], [0, 1]] of member
 * frames in the ground frame g, twists [ω; v] and wrenches [τ; f] expressed in g; R column-major.
 *   body b      parent[b] (-1: the ground; parents come before their children), the kind of
 *               the joint to its parent kind[b], its first position q_at[b] in qj and rate
 *               v_at[b] in vj, its joint's numbers num[num_ptr[b] ...], its [m; c; I_c]
 *               body[13 b ...]; gravity: the ground's acceleration is [0; −g].
 *   mimic map   v_j[i] = rate_coef[i] v_j[rate_src[i]], independent column rate_col[i] (ni
 *               columns; τ_i = Gᵀ τ, M_i = Gᵀ M G); q_j[i] = q_coef[i] q_j[q_src[i]] + q_off[i]
 *               where q_src[i] >= 0.
 * Kernels (CasADi's signature, no integer work, real work at most max_w doubles):
 *   edge      [R_p; p_p; T_p; q; w; numbers] -> [R_c; p_c; S_g (6 × nv); c_g = Ṡ_g w]
 *   edge_fwd  [edge input; dR_p; dp_p; dT_p; δ; dw] -> d(edge output), q moved in the tangent space
 *   body      [R; p; T; dT; m; c; I_c] -> [M_g (6 × 6); W = M_g dT − ad(T)ᵀ M_g T]
 *   body_fwd  [body input; dR; dp; dT; ddT] -> d(body output)
 *   qdot      [q; w] -> q̇ (the joint's position rates, quaternions normalised first; NULL where q̇ = w)
 *   local     [q; w; numbers] -> [R_J; p_J; S (6 × nv, in f_b); c_J = Ṡ w] (mode 0 only; else NULL)
 * Call ncgen_tree_check once on new tables: the loops trust them.  Position derivatives are
 * per independent rate in the tangent space (Pinocchio's convention). */
#ifndef NCGEN_TREE_TABLES_H
#define NCGEN_TREE_TABLES_H

#include <math.h>
#include <string.h>

#include "ncgen_spatial.h"

#define NCGEN_TREE_KERNEL 1
#define NCGEN_TREE_BAD 2
#define NCGEN_TREE_BODY 13
#ifndef NCGEN_TREE_DENSE_NV
#define NCGEN_TREE_DENSE_NV 12       /* forward dynamics by Cholesky of M_i up to this many rates (O(n³)), else ABA (O(n)) */
#endif
#ifndef NCGEN_TREE_PIVOT_TOL
#define NCGEN_TREE_PIVOT_TOL 1e-12   /* ncgen/codegen/tree_check.py: PIVOT_TOL */
#endif

typedef int (*ncgen_tree_kernel)(const double **arg, double **res, long long *iw, double *w, int mem);

typedef struct {
  ncgen_tree_kernel edge, edge_fwd, qdot, local;
  int nq, nv, n_num, mode;
} ncgen_tree_joint_kind;

typedef struct {
  const ncgen_tree_joint_kind *joint;
  int n_joint;
  ncgen_tree_kernel body, body_fwd;
  int max_w;
} ncgen_tree_kinds;

typedef struct {
  int nb, nq, nv, ni;
  const int *parent, *kind, *q_at, *v_at, *num_ptr;
  const double *num, *body, *gravity;
  const int *rate_src, *rate_col;
  const double *rate_coef;
  const int *q_src;
  const double *q_coef, *q_off;
  const double *xin, *inertia;
} ncgen_tree;

/* The work array, cut into the pieces the loops use. */
typedef struct {
  double *q, *v, *a, *R, *p, *T, *dT, *W, *Mg, *S, *tau;
  double *dR, *dp, *dTt, *ddT, *dW, *dS, *dtau;
  double *M, *Mi, *L, *rhs, *taui, *in, *out, *kw;
  double *X, *Sl, *cl, *vl, *al, *fl, *IC, *IA, *U, *Dl, *ul;
  double *Y, *Kc, *pr, *ar, *ur, *tf, *d;
} ncgen_tree_work;


static long ncgen_tree_max_in(const ncgen_tree_kinds *K) {
  long n = 37 + 24;
  int i;
  for (i = 0; i < K->n_joint; ++i) {
    const ncgen_tree_joint_kind *k = &K->joint[i];
    long m = 18 + k->nq + k->nv + k->n_num + 18 + 2L * k->nv;
    if (m > n) n = m;
  }
  return n;
}

static long ncgen_tree_max_out(const ncgen_tree_kinds *K) {
  long n = 42;
  int i;
  for (i = 0; i < K->n_joint; ++i)
    if (18 + 6L * K->joint[i].nv > n) n = 18 + 6L * K->joint[i].nv;
  return n;
}

/* The pieces of the work array w (w NULL: none); returns the doubles it needs. */
static long ncgen_tree_layout(const ncgen_tree_kinds *K, const ncgen_tree *T, double *w, ncgen_tree_work *s) {
  long o = 0, nb = T->nb, nv = T->nv, ni = T->ni;
#define NCGEN_TREE_TAKE(f, n) (s->f = w ? w + o : 0, o += (n))
  NCGEN_TREE_TAKE(q, T->nq);
  NCGEN_TREE_TAKE(v, nv);
  NCGEN_TREE_TAKE(a, nv);
  NCGEN_TREE_TAKE(tau, nv);
  NCGEN_TREE_TAKE(R, 9 * nb);
  NCGEN_TREE_TAKE(p, 3 * nb);
  NCGEN_TREE_TAKE(T, 6 * nb);
  NCGEN_TREE_TAKE(dT, 6 * nb);
  NCGEN_TREE_TAKE(W, 6 * nb);
  NCGEN_TREE_TAKE(Mg, 36 * nb);
  NCGEN_TREE_TAKE(S, 6 * nv);
  NCGEN_TREE_TAKE(dtau, nv);
  NCGEN_TREE_TAKE(dR, 9 * nb);
  NCGEN_TREE_TAKE(dp, 3 * nb);
  NCGEN_TREE_TAKE(dTt, 6 * nb);
  NCGEN_TREE_TAKE(ddT, 6 * nb);
  NCGEN_TREE_TAKE(dW, 6 * nb);
  NCGEN_TREE_TAKE(dS, 6 * nv);
  NCGEN_TREE_TAKE(M, nv * nv);
  NCGEN_TREE_TAKE(Mi, ni * ni);
  NCGEN_TREE_TAKE(L, ni * ni);
  NCGEN_TREE_TAKE(rhs, 3 * ni * ni + ni);
  NCGEN_TREE_TAKE(taui, ni);
  NCGEN_TREE_TAKE(in, ncgen_tree_max_in(K));
  NCGEN_TREE_TAKE(out, ncgen_tree_max_out(K));
  NCGEN_TREE_TAKE(kw, K->max_w > 0 ? K->max_w : 1);
  NCGEN_TREE_TAKE(X, 12 * nb);
  NCGEN_TREE_TAKE(Sl, 6 * nv);
  NCGEN_TREE_TAKE(cl, 6 * nb);
  NCGEN_TREE_TAKE(vl, 6 * nb);
  NCGEN_TREE_TAKE(al, 6 * nb);
  NCGEN_TREE_TAKE(fl, 6 * nb);
  NCGEN_TREE_TAKE(IC, NCGEN_TREE_BODY * nb);
  NCGEN_TREE_TAKE(IA, 36 * nb);
  NCGEN_TREE_TAKE(U, 6 * nv);
  NCGEN_TREE_TAKE(Dl, 36 * nb);
  NCGEN_TREE_TAKE(ul, nv);
  NCGEN_TREE_TAKE(Y, nv * nv);
  NCGEN_TREE_TAKE(Kc, 2 * nv * nv);
  NCGEN_TREE_TAKE(pr, 6 * nb);
  NCGEN_TREE_TAKE(ar, 6 * nb);
  NCGEN_TREE_TAKE(ur, nv);
  NCGEN_TREE_TAKE(tf, nv);
  NCGEN_TREE_TAKE(d, 3 * nb);
#undef NCGEN_TREE_TAKE
  return o;
}

/* Doubles of work the functions below need for the tables T. */
static long ncgen_tree_work_size(const ncgen_tree_kinds *K, const ncgen_tree *T) {
  ncgen_tree_work s;
  return ncgen_tree_layout(K, T, 0, &s);
}

static int ncgen_tree_in(int x, int lo, int hi) { return x >= lo && x < hi; }

/* 0 when every index of T is in range and every body's sizes match its kind, else NCGEN_TREE_BAD. */
static int ncgen_tree_check(const ncgen_tree_kinds *K, const ncgen_tree *T) {
  int b, i;
  if (T->nb < 0 || T->nq < 0 || T->nv < 0 || T->ni < 0 || T->ni > T->nv) return NCGEN_TREE_BAD;
  if (T->num_ptr[0] != 0) return NCGEN_TREE_BAD;
  for (b = 0; b < T->nb; ++b) {
    const ncgen_tree_joint_kind *k;
    if (!ncgen_tree_in(T->parent[b], -1, b) || !ncgen_tree_in(T->kind[b], 0, K->n_joint)) return NCGEN_TREE_BAD;
    k = &K->joint[T->kind[b]];
    if (T->num_ptr[b + 1] - T->num_ptr[b] != k->n_num) return NCGEN_TREE_BAD;
    if (T->q_at[b] < 0 || T->q_at[b] + k->nq > T->nq || T->v_at[b] < 0 || T->v_at[b] + k->nv > T->nv ||
        (k->nq && !k->qdot && k->nq != k->nv))  /* no rate kernel: q̇ = w */
      return NCGEN_TREE_BAD;
  }
  for (i = 0; i < T->nv; ++i)
    if (!ncgen_tree_in(T->rate_src[i], 0, T->nv) || !ncgen_tree_in(T->rate_col[i], 0, T->ni)) return NCGEN_TREE_BAD;
  for (i = 0; i < T->nq; ++i)
    if (!ncgen_tree_in(T->q_src[i], -1, T->nq)) return NCGEN_TREE_BAD;
  return 0;
}

static int ncgen_tree_call(ncgen_tree_kernel f, const double *in, double *out, double *kw) {
  const double *arg[1];
  double *res[1];
  arg[0] = in;
  res[0] = out;
  return f(arg, res, 0, kw, 0) ? NCGEN_TREE_KERNEL : 0;
}

/* q, v, a of the work with the mimic followers set from their leaders (a: NULL for zero). */
static void ncgen_tree_expand(const ncgen_tree *T, ncgen_tree_work *s, const double *q, const double *v,
                              const double *a) {
  int i;
  for (i = 0; i < T->nq; ++i) s->q[i] = T->q_src[i] >= 0 ? T->q_coef[i] * q[T->q_src[i]] + T->q_off[i] : q[i];
  for (i = 0; i < T->nv; ++i) {
    s->v[i] = T->rate_coef[i] * v[T->rate_src[i]];
    s->a[i] = a ? T->rate_coef[i] * a[T->rate_src[i]] : 0.0;
  }
}

/* The edge kernel's input for body b (the parent's pose, twist; the joint's q, w, numbers). */
static int ncgen_tree_edge_input(const ncgen_tree_kinds *K, const ncgen_tree *T, ncgen_tree_work *s, int b) {
  static const double eye[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  const ncgen_tree_joint_kind *k = &K->joint[T->kind[b]];
  int par = T->parent[b], i, n = 0;
  double *in = s->in;
  for (i = 0; i < 9; ++i) in[n++] = par < 0 ? eye[i] : s->R[9 * par + i];
  for (i = 0; i < 3; ++i) in[n++] = par < 0 ? 0.0 : s->p[3 * par + i];
  for (i = 0; i < 6; ++i) in[n++] = par < 0 ? 0.0 : s->T[6 * par + i];
  for (i = 0; i < k->nq; ++i) in[n++] = s->q[T->q_at[b] + i];
  for (i = 0; i < k->nv; ++i) in[n++] = s->v[T->v_at[b] + i];
  for (i = 0; i < k->n_num; ++i) in[n++] = T->num[T->num_ptr[b] + i];
  return n;
}

/* The body kernel's input of body b: [R; p; T; dT; m; c; I_c]. */
static void ncgen_tree_body_input(const ncgen_tree *T, const ncgen_tree_work *s, int b, double *in) {
  memcpy(in, s->R + 9 * b, 9 * sizeof(double));
  memcpy(in + 9, s->p + 3 * b, 3 * sizeof(double));
  memcpy(in + 12, s->T + 6 * b, 6 * sizeof(double));
  memcpy(in + 18, s->dT + 6 * b, 6 * sizeof(double));
  memcpy(in + 24, T->body + NCGEN_TREE_BODY * b, NCGEN_TREE_BODY * sizeof(double));
}

/* Outwards: poses, motion subspaces S, twists, accelerations (with s->a), then each body's
 * M_g and wrench W.  The ground's acceleration is [0; −g] (gravity as a fictitious acceleration). */
static int ncgen_tree_forward(const ncgen_tree_kinds *K, const ncgen_tree *T, ncgen_tree_work *s) {
  int b, i, j;
  for (b = 0; b < T->nb; ++b) {
    const ncgen_tree_joint_kind *k = &K->joint[T->kind[b]];
    int par = T->parent[b], va = T->v_at[b];
    double *out = s->out, *S = s->S + 6 * va;
    ncgen_tree_edge_input(K, T, s, b);
    if (ncgen_tree_call(k->edge, s->in, out, s->kw)) return NCGEN_TREE_KERNEL;
    memcpy(s->R + 9 * b, out, 9 * sizeof(double));
    memcpy(s->p + 3 * b, out + 9, 3 * sizeof(double));
    memcpy(S, out + 12, 6 * (size_t)k->nv * sizeof(double));
    for (i = 0; i < 6; ++i) {
      double t = par < 0 ? 0.0 : s->T[6 * par + i];
      double dt = par < 0 ? (i < 3 ? 0.0 : -T->gravity[i - 3]) : s->dT[6 * par + i];
      dt += out[12 + 6 * k->nv + i];
      for (j = 0; j < k->nv; ++j) {
        t += S[6 * j + i] * s->v[va + j];
        dt += S[6 * j + i] * s->a[va + j];
      }
      s->T[6 * b + i] = t;
      s->dT[6 * b + i] = dt;
    }
    ncgen_tree_body_input(T, s, b, s->in);
    if (ncgen_tree_call(K->body, s->in, out, s->kw)) return NCGEN_TREE_KERNEL;
    memcpy(s->Mg + 36 * b, out, 36 * sizeof(double));
    memcpy(s->W + 6 * b, out + 36, 6 * sizeof(double));
  }
  return 0;
}

/* Inwards: W summed over each subtree (in place), τ_j = S_jᵀ W per joint rate (s->tau, nv). */
static void ncgen_tree_backward(const ncgen_tree_kinds *K, const ncgen_tree *T, double *W, const double *S,
                                double *tau) {
  int b, i, j;
  for (b = T->nb - 1; b >= 0; --b) {
    const ncgen_tree_joint_kind *k = &K->joint[T->kind[b]];
    int va = T->v_at[b];
    for (j = 0; j < k->nv; ++j) {
      double t = 0.0;
      for (i = 0; i < 6; ++i) t += S[6 * (va + j) + i] * W[6 * b + i];
      tau[va + j] = t;
    }
    if (T->parent[b] >= 0)
      for (i = 0; i < 6; ++i) W[6 * T->parent[b] + i] += W[6 * b + i];
  }
}

/* τ_i = Gᵀ τ (ni) from τ per joint rate (nv). */
static void ncgen_tree_project(const ncgen_tree *T, const double *tau, double *tau_i) {
  int i;
  for (i = 0; i < T->ni; ++i) tau_i[i] = 0.0;
  for (i = 0; i < T->nv; ++i) tau_i[T->rate_col[i]] += T->rate_coef[i] * tau[i];
}

/* M_i = Gᵀ M G (ni × ni, column-major, both triangles) by composite inertias from the M_g of
 * the last forward pass (s->Mg is summed over subtrees in place). */
static void ncgen_tree_composite(const ncgen_tree_kinds *K, const ncgen_tree *T, ncgen_tree_work *s, double *Mi) {
  int b, i, j, r, c, nv = T->nv, ni = T->ni;
  double F[6];
  for (b = T->nb - 1; b >= 0; --b)
    if (T->parent[b] >= 0)
      for (i = 0; i < 36; ++i) s->Mg[36 * T->parent[b] + i] += s->Mg[36 * b + i];
  for (i = 0; i < nv * nv; ++i) s->M[i] = 0.0;
  for (b = 0; b < T->nb; ++b) {
    const ncgen_tree_joint_kind *k = &K->joint[T->kind[b]];
    for (j = 0; j < k->nv; ++j) {
      int col = T->v_at[b] + j, up;
      const double *Sj = s->S + 6 * col, *Mc = s->Mg + 36 * b;
      for (r = 0; r < 6; ++r) {
        double t = 0.0;
        for (c = 0; c < 6; ++c) t += Mc[r + 6 * c] * Sj[c];
        F[r] = t;
      }
      for (up = b; up >= 0; up = T->parent[up]) {
        const ncgen_tree_joint_kind *ku = &K->joint[T->kind[up]];
        for (i = 0; i < ku->nv; ++i) {
          int row = T->v_at[up] + i;
          double t = 0.0;
          for (r = 0; r < 6; ++r) t += s->S[6 * row + r] * F[r];
          s->M[row + nv * col] = t;
          s->M[col + nv * row] = t;
        }
      }
    }
  }
  for (i = 0; i < ni * ni; ++i) Mi[i] = 0.0;
  for (c = 0; c < nv; ++c)
    for (r = 0; r < nv; ++r)
      Mi[T->rate_col[r] + ni * T->rate_col[c]] += T->rate_coef[r] * T->rate_coef[c] * s->M[r + nv * c];
}

/* L Lᵀ = A (n × n, column-major, lower triangle read) into L's lower triangle (its upper one
 * not written); returns min_k d_k / A_kk (the
 * smallest relative pivot, NaN when a pivot is 0/0). */
static double ncgen_tree_cholesky(int n, const double *A, double *L) {
  int i, j, k;
  double ratio = 1.0;
  for (k = 0; k < n; ++k) {
    double d = A[k + n * k];
    for (j = 0; j < k; ++j) d -= L[k + n * j] * L[k + n * j];
    double r = d / A[k + n * k], g;
    if (k == 0 || r < ratio || !(r == r)) ratio = r;          /* NaN (0/0) stays */
    L[k + n * k] = sqrt(d > 0.0 ? d : 0.0);
    g = 1.0 / L[k + n * k];
    for (i = k + 1; i < n; ++i) {
      double t = A[i + n * k];
      for (j = 0; j < k; ++j) t -= L[i + n * j] * L[k + n * j];
      L[i + n * k] = t * g;
    }
  }
  return ratio;
}

/* x = (L Lᵀ)⁻¹ x in place, m columns of n. */
static void ncgen_tree_solve(int n, const double *L, double *x, int m) {
  int i, j, c;
  for (c = 0; c < m; ++c) {
    double *y = x + (long)n * c;
    for (i = 0; i < n; ++i) {
      double t = y[i];
      for (j = 0; j < i; ++j) t -= L[i + n * j] * y[j];
      y[i] = t / L[i + n * i];
    }
    for (i = n - 1; i >= 0; --i) {
      double t = y[i];
      for (j = i + 1; j < n; ++j) t -= L[j + n * i] * y[j];
      y[i] = t / L[i + n * i];
    }
  }
}

/* Local frames, outwards: each body's pose in its parent's frame (s->X: R, p), its motion
 * subspace S (s->Sl) and c = c_J + v × (S w) (s->cl), from q and v of the work. */
static int ncgen_tree_local_poses(const ncgen_tree_kinds *K, const ncgen_tree *T, ncgen_tree_work *s) {
  int b, i, j;
  for (b = 0; b < T->nb; ++b) {
    const ncgen_tree_joint_kind *k = &K->joint[T->kind[b]];
    const double *xin = T->xin + 12 * b, *q = s->q + T->q_at[b];
    double *R = s->X + 12 * b, *p = R + 9, *S = s->Sl + 6 * T->v_at[b], *c = s->cl + 6 * b;
    memset(c, 0, 6 * sizeof(double));
    if (k->mode == 1) {                                   /* R = R_in Rz(q) (written out: gcc -O2 keeps short loops) */
      double cq = cos(q[0]), sq = sin(q[0]);
      R[0] = cq * xin[0] + sq * xin[3];
      R[1] = cq * xin[1] + sq * xin[4];
      R[2] = cq * xin[2] + sq * xin[5];
      R[3] = cq * xin[3] - sq * xin[0];
      R[4] = cq * xin[4] - sq * xin[1];
      R[5] = cq * xin[5] - sq * xin[2];
      memcpy(R + 6, xin + 6, 6 * sizeof(double));        /* R's third column and p */
      S[0] = S[1] = S[3] = S[4] = S[5] = 0.0;
      S[2] = 1.0;
    } else if (k->mode == 2 || k->mode == 3) {            /* p = p_in + q R_in e_z; fixed: H_in */
      for (i = 0; i < 9; ++i) R[i] = xin[i];
      for (i = 0; i < 3; ++i) p[i] = xin[9 + i] + (k->mode == 2 ? q[0] * xin[6 + i] : 0.0);
      if (k->mode == 2)
        for (i = 0; i < 6; ++i) S[i] = i == 5 ? 1.0 : 0.0;
    } else {                                              /* H_in T(q) from the kind's kernel */
      double *in = s->in, *out = s->out;
      int n = 0;
      for (i = 0; i < k->nq; ++i) in[n++] = q[i];
      for (i = 0; i < k->nv; ++i) in[n++] = s->v[T->v_at[b] + i];
      for (i = 0; i < k->n_num; ++i) in[n++] = T->num[T->num_ptr[b] + i];
      if (ncgen_tree_call(k->local, in, out, s->kw)) return NCGEN_TREE_KERNEL;
      for (j = 0; j < 3; ++j) sp_rot(xin, out + 3 * j, R + 3 * j);
      sp_rot(xin, out + 9, p);
      for (i = 0; i < 3; ++i) p[i] += xin[9 + i];
      memcpy(S, out + 12, 6 * (size_t)k->nv * sizeof(double));
      memcpy(c, out + 12 + 6 * k->nv, 6 * sizeof(double));
    }
  }
  return 0;
}

/* Local frames, outwards after ncgen_tree_local_poses: twists (s->vl), c of the poses
 * completed to c_J + v × (S w) (s->cl) and each body's wrench (s->fl): with accelerations, the
 * accelerations with s->a (s->al; the ground's [0; −g]) and f = I a − ad(v)ᵀ I v, else the
 * bias f = −ad(v)ᵀ I v. */
static void ncgen_tree_local_motion(const ncgen_tree_kinds *K, const ncgen_tree *T, ncgen_tree_work *s,
                                    int accelerations) {
  int b, i, j;
  const double zero[6] = {0, 0, 0, 0, 0, 0};
  const double a0[6] = {0, 0, 0, -T->gravity[0], -T->gravity[1], -T->gravity[2]};
  for (b = 0; b < T->nb; ++b) {
    const ncgen_tree_joint_kind *k = &K->joint[T->kind[b]];
    int par = T->parent[b], va = T->v_at[b], mode = k->mode;
    const double *R = s->X + 12 * b, *p = R + 9, *S = s->Sl + 6 * va, *I = T->inertia + NCGEN_TREE_BODY * b;
    double *v = s->vl + 6 * b, *a = s->al + 6 * b, *c = s->cl + 6 * b, *f = s->fl + 6 * b;
    double t[6], h[6];
    sp_twist_in(R, p, par < 0 ? zero : s->vl + 6 * par, v);
    if (mode == 1) {                            /* S = [e_z; 0]: ad(v) S w = w [ω_y, −ω_x, 0, v_y, −v_x, 0] */
      double w = s->v[va];
      v[2] += w;
      c[0] = w * v[1];
      c[1] = -w * v[0];
      c[3] = w * v[4];
      c[4] = -w * v[3];
    } else if (mode == 2) {                     /* S = [0; e_z]: ad(v) S w = w [0, 0, 0, ω_y, −ω_x, 0] */
      double w = s->v[va];
      v[5] += w;
      c[3] = w * v[1];
      c[4] = -w * v[0];
    } else if (mode == 0) {
      double vJ[6];
      for (i = 0; i < 6; ++i) {
        double x = 0.0;
        for (j = 0; j < k->nv; ++j) x += S[6 * j + i] * s->v[va + j];
        vJ[i] = x;
        v[i] += x;
      }
      sp_ad(v, vJ, t);
      for (i = 0; i < 6; ++i) c[i] += t[i];
    }
    sp_inertia_apply(I, v, h);
    sp_ad_star(v, h, f);
    if (!accelerations) continue;
    sp_twist_in(R, p, par < 0 ? a0 : s->al + 6 * par, a);
    for (i = 0; i < 6; ++i) a[i] += c[i];
    if (mode == 1)
      a[2] += s->a[va];
    else if (mode == 2)
      a[5] += s->a[va];
    else
      for (j = 0; j < k->nv; ++j)
        for (i = 0; i < 6; ++i) a[i] += S[6 * j + i] * s->a[va + j];
    sp_inertia_apply(I, a, t);
    for (i = 0; i < 6; ++i) f[i] += t[i];
  }
}

/* Local frames, inwards: τ_j = S_jᵀ f per joint rate (s->tau), f summed into the parents. */
static void ncgen_tree_local_backward(const ncgen_tree_kinds *K, const ncgen_tree *T, ncgen_tree_work *s) {
  int b, i, j;
  for (b = T->nb - 1; b >= 0; --b) {
    const ncgen_tree_joint_kind *k = &K->joint[T->kind[b]];
    const double *f = s->fl + 6 * b, *S = s->Sl + 6 * T->v_at[b];
    if (k->mode == 1 || k->mode == 2)           /* S = [e_z; 0] or [0; e_z] */
      s->tau[T->v_at[b]] = f[k->mode == 1 ? 2 : 5];
    else
      for (j = 0; j < k->nv; ++j) {
        double t = 0.0;
        for (i = 0; i < 6; ++i) t += S[6 * j + i] * f[i];
        s->tau[T->v_at[b] + j] = t;
      }
    if (T->parent[b] >= 0) sp_wrench_out_add(s->X + 12 * b, s->X + 12 * b + 9, f, s->fl + 6 * T->parent[b]);
  }
}

/* a · b of 6-vectors */
static inline double ncgen_tree_dot6(const double *a, const double *b) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3] + a[4] * b[4] + a[5] * b[5];
}

/* Sᵀ M S of the rigid inertia I = [m; h; I_o] (M = [[I_o, ĥ], [ĥᵀ, m 1]]) and S = [ω; v]:
 * ωᵀ I_o ω + 2 ω · (h × v) + m v · v */
static inline double ncgen_tree_inertia_quad(const double *I, const double *S) {
  const double *w = S, *v = S + 3, *h = I + 1, *Io = I + 4;
  double hv0 = h[1] * v[2] - h[2] * v[1], hv1 = h[2] * v[0] - h[0] * v[2], hv2 = h[0] * v[1] - h[1] * v[0];
  return Io[0] * w[0] * w[0] + Io[4] * w[1] * w[1] + Io[8] * w[2] * w[2] +
         2.0 * (Io[1] * w[0] * w[1] + Io[2] * w[0] * w[2] + Io[5] * w[1] * w[2] + w[0] * hv0 + w[1] * hv1 + w[2] * hv2) +
         I[0] * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
}

/* y = A x (A 6 × 6, column-major; y not x) */
static inline void ncgen_tree_mat6_apply(const double *A, const double *x, double *y) {
  int r;
  for (r = 0; r < 6; ++r)
    y[r] = A[r] * x[0] + A[r + 6] * x[1] + A[r + 12] * x[2] + A[r + 18] * x[3] + A[r + 24] * x[4] + A[r + 30] * x[5];
}

/* y = A x (A 6 × 6 symmetric, column-major, its lower triangle read; y not x) */
static inline void ncgen_tree_sym6_apply(const double *A, const double *x, double *y) {
#define NCGEN_TREE_SYM(r, c) ((r) >= (c) ? A[(r) + 6 * (c)] : A[(c) + 6 * (r)])
#define NCGEN_TREE_ROW(r) (NCGEN_TREE_SYM(r, 0) * x[0] + NCGEN_TREE_SYM(r, 1) * x[1] + NCGEN_TREE_SYM(r, 2) * x[2] + \
                           NCGEN_TREE_SYM(r, 3) * x[3] + NCGEN_TREE_SYM(r, 4) * x[4] + NCGEN_TREE_SYM(r, 5) * x[5])
  y[0] = NCGEN_TREE_ROW(0);
  y[1] = NCGEN_TREE_ROW(1);
  y[2] = NCGEN_TREE_ROW(2);
  y[3] = NCGEN_TREE_ROW(3);
  y[4] = NCGEN_TREE_ROW(4);
  y[5] = NCGEN_TREE_ROW(5);
#undef NCGEN_TREE_ROW
#undef NCGEN_TREE_SYM
}

/* The ground frame, outwards after ncgen_tree_local_poses: each body's pose (s->R, s->p), its
 * motion subspace S_g = Ad(H_gb) S (s->S) and, for kinds by kernel, Ad(H_gb) c_J (s->cl; the
 * other kinds' c_J is 0).  A revolute joint's S_g is [z_b; p_b × z_b], a prismatic one's
 * [0; z_b] (z_b: the third column of R_gb). */
static void ncgen_tree_ground_poses(const ncgen_tree_kinds *K, const ncgen_tree *T, ncgen_tree_work *s) {
  int b, i, j;
  for (b = 0; b < T->nb; ++b) {
    const ncgen_tree_joint_kind *k = &K->joint[T->kind[b]];
    int par = T->parent[b], va = T->v_at[b];
    const double *Rl = s->X + 12 * b, *pl = Rl + 9;
    double *R = s->R + 9 * b, *p = s->p + 3 * b, *S = s->S + 6 * va;
    if (par < 0) {
      memcpy(R, Rl, 9 * sizeof(double));
      memcpy(p, pl, 3 * sizeof(double));
    } else {
      const double *Rp = s->R + 9 * par, *pp = s->p + 3 * par;
      for (j = 0; j < 3; ++j) sp_rot(Rp, Rl + 3 * j, R + 3 * j);
      sp_rot(Rp, pl, p);
      p[0] += pp[0];
      p[1] += pp[1];
      p[2] += pp[2];
    }
    if (k->mode == 1) {
      memcpy(S, R + 6, 3 * sizeof(double));
      sp_cross(p, S, S + 3);
    } else if (k->mode == 2) {
      for (i = 0; i < 3; ++i) {
        S[i] = 0.0;
        S[3 + i] = R[6 + i];
      }
    } else if (k->mode == 0) {
      double c[6];
      for (j = 0; j < k->nv; ++j) sp_twist_out(R, p, s->Sl + 6 * (va + j), S + 6 * j);
      memcpy(c, s->cl + 6 * b, sizeof c);
      sp_twist_out(R, p, c, s->cl + 6 * b);
    }
  }
}

/* Each body's rigid inertia in the ground frame, about its origin (s->IC), from the poses of
 * ncgen_tree_ground_poses. */
static void ncgen_tree_ground_inertias(const ncgen_tree *T, ncgen_tree_work *s) {
  int b;
  memset(s->IC, 0, NCGEN_TREE_BODY * (size_t)T->nb * sizeof(double));
  for (b = 0; b < T->nb; ++b)
    sp_inertia_out_add(s->R + 9 * b, s->p + 3 * b, T->inertia + NCGEN_TREE_BODY * b, s->IC + NCGEN_TREE_BODY * b);
}

/* 1 when the rates are all independent (no mimic joint: G = 1). */
static int ncgen_tree_unmapped(const ncgen_tree *T) {
  int i;
  if (T->ni != T->nv) return 0;
  for (i = 0; i < T->nv; ++i)
    if (T->rate_src[i] != i || T->rate_coef[i] != 1.0) return 0;
  return 1;
}

/* M_i = Gᵀ M G (ni × ni) from M (nv × nv, s->M). */
static void ncgen_tree_map_mass(const ncgen_tree *T, const double *M, double *Mi) {
  int r, c, nv = T->nv, ni = T->ni;
  for (r = 0; r < ni * ni; ++r) Mi[r] = 0.0;
  for (c = 0; c < nv; ++c)
    for (r = 0; r < nv; ++r)
      Mi[T->rate_col[r] + ni * T->rate_col[c]] += T->rate_coef[r] * T->rate_coef[c] * M[r + nv * c];
}

/* M (nv × nv, s->M) by the composite-rigid-body algorithm in the ground's axes about each body's
 * origin (poses of ncgen_tree_ground_poses): body b's motion subspace S'_b = R_gb S (s->Sl, in
 * place) and composite inertia I^C_b (s->IC) about p_b, a child's moved to its parent by a
 * translation (no rotation; short lever arms, so no digits lost to the distance from the
 * ground's origin); M_rc = S'_rᵀ F for a rate c of body b and a rate r of b or an ancestor u,
 * F = I^C_b S'_c moved from p_b to p_u.  Then M_i = Gᵀ M G. */
static void ncgen_tree_ground_mass(const ncgen_tree_kinds *K, const ncgen_tree *T, ncgen_tree_work *s, double *Mi) {
  int b, i, j, nv = T->nv, direct = ncgen_tree_unmapped(T);
  double *M = direct ? Mi : s->M;               /* G = 1: M_i = M */
  for (b = 0; b < T->nb; ++b) {
    const ncgen_tree_joint_kind *k = &K->joint[T->kind[b]];
    const double *R = s->R + 9 * b;
    double *S = s->Sl + 6 * T->v_at[b], *d = s->d + 3 * b, x[6];
    sp_inertia_rotate(R, T->inertia + NCGEN_TREE_BODY * b, s->IC + NCGEN_TREE_BODY * b);
    if (T->parent[b] >= 0) {                    /* d_b = p_b − p_parent */
      const double *pb = s->p + 3 * b, *pp = s->p + 3 * T->parent[b];
      d[0] = pb[0] - pp[0];
      d[1] = pb[1] - pp[1];
      d[2] = pb[2] - pp[2];
    }
    if (k->mode == 1 || k->mode == 2)           /* S' = [z_b; 0] or [0; z_b] */
      for (i = 0; i < 3; ++i) {
        S[i] = k->mode == 1 ? R[6 + i] : 0.0;
        S[3 + i] = k->mode == 1 ? 0.0 : R[6 + i];
      }
    else
      for (j = 0; j < k->nv; ++j, S += 6) {
        memcpy(x, S, sizeof x);
        sp_rot(R, x, S);
        sp_rot(R, x + 3, S + 3);
      }
  }
  for (b = T->nb - 1; b >= 0; --b)
    if (T->parent[b] >= 0)
      sp_inertia_shift_add(s->d + 3 * b, s->IC + NCGEN_TREE_BODY * b, s->IC + NCGEN_TREE_BODY * T->parent[b]);
  for (i = 0; i < nv * nv; ++i) M[i] = 0.0;
  for (b = 0; b < T->nb; ++b) {
    const ncgen_tree_joint_kind *k = &K->joint[T->kind[b]];
    for (j = 0; j < k->nv; ++j) {
      int col = T->v_at[b] + j, up = b;
      const double *IC = s->IC + NCGEN_TREE_BODY * b, *z = s->Sl + 6 * col;
      double F[6];
      if (k->mode == 1) {                       /* F = I^C [z; 0] = [I_o z; z × h] */
        sp_rot(IC + 4, z, F);
        sp_cross(z, IC + 1, F + 3);
      } else
        sp_inertia_apply(IC, z, F);
      for (;;) {
        const ncgen_tree_joint_kind *ku = &K->joint[T->kind[up]];
        int nu = ku->nv, row = T->v_at[up], par = T->parent[up];
        for (i = 0; i < nu; ++i, ++row) {
          const double *Sr = s->Sl + 6 * row;
          double t = ku->mode == 1 ? Sr[0] * F[0] + Sr[1] * F[1] + Sr[2] * F[2] : ncgen_tree_dot6(Sr, F);
          M[row + nv * col] = t;
          M[col + nv * row] = t;
        }
        if (par < 0) break;
        sp_wrench_shift(s->d + 3 * up, F);
        up = par;
      }
    }
  }
  if (!direct) ncgen_tree_map_mass(T, M, Mi);
}

/* τ_i (ni): the efforts of the independent rates giving accelerations a at (q, v), in the
 * work s (ncgen_tree_layout). */
static int ncgen_tree_rnea_at(const ncgen_tree_kinds *K, const ncgen_tree *T, ncgen_tree_work *s, const double *q,
                              const double *v, const double *a, double *tau_i) {
  ncgen_tree_expand(T, s, q, v, a);
  if (ncgen_tree_local_poses(K, T, s)) return NCGEN_TREE_KERNEL;
  ncgen_tree_local_motion(K, T, s, 1);
  ncgen_tree_local_backward(K, T, s);
  ncgen_tree_project(T, s->tau, tau_i);
  return 0;
}

/* The same with the work array work. */
static int ncgen_tree_rnea(const ncgen_tree_kinds *K, const ncgen_tree *T, const double *q, const double *v,
                           const double *a, double *tau_i, double *work) {
  ncgen_tree_work s;
  ncgen_tree_layout(K, T, work, &s);
  return ncgen_tree_rnea_at(K, T, &s, q, v, a, tau_i);
}

/* M_i (ni × ni, column-major, both triangles) at q, in the work s. */
static int ncgen_tree_crba_at(const ncgen_tree_kinds *K, const ncgen_tree *T, ncgen_tree_work *s, const double *q,
                              double *Mi) {
  int i;
  for (i = 0; i < T->nv; ++i) s->tau[i] = 0.0;
  ncgen_tree_expand(T, s, q, s->tau, 0);
  if (ncgen_tree_local_poses(K, T, s)) return NCGEN_TREE_KERNEL;
  ncgen_tree_ground_poses(K, T, s);
  ncgen_tree_ground_mass(K, T, s, Mi);
  return 0;
}

/* The same with the work array work. */
static int ncgen_tree_crba(const ncgen_tree_kinds *K, const ncgen_tree *T, const double *q, double *Mi,
                           double *work) {
  ncgen_tree_work s;
  ncgen_tree_layout(K, T, work, &s);
  return ncgen_tree_crba_at(K, T, &s, q, Mi);
}

/* M_i = Gᵀ M G: M_i += the entries (r, c) and (c, r) of M (rates r, c; r = c: one entry) worth x,
 * in M_i's lower triangle */
static inline void ncgen_tree_mass_add(const ncgen_tree *T, int r, int c, double x, double *Mi) {
  int i = T->rate_col[r], j = T->rate_col[c];
  x *= T->rate_coef[r] * T->rate_coef[c];
  if (i == j && r != c) x *= 2.0;
  Mi[i > j ? i + T->ni * j : j + T->ni * i] += x;
}

/* The bias b = τ(q, v, a = 0) per joint rate (nv) and M_i = Gᵀ M G (ni × ni, column-major, its
 * lower triangle; G = 1 where direct) of one pass out and one in, every quantity in the ground
 * frame about the ground's origin (after ncgen_tree_ground_poses), as the articulated-body
 * algorithm's: outwards each body's twist, bias acceleration (the ground's [0; −g]) and wrench
 * f = I a − ad(v)ᵀ I v with its rigid inertia I in the ground frame (s->IC); inwards b_j = S_jᵀ f
 * and f summed into the parent, the composite inertia I^C summed into the parent (about the same
 * origin: a sum), and M_rc = S_rᵀ I^C_b S_c for a rate c of body b and a rate r of b or an
 * ancestor (no force moved: one origin). */
static void ncgen_tree_mass_bias(const ncgen_tree_kinds *K, const ncgen_tree *T, ncgen_tree_work *s, int direct,
                                 double *SP_RESTRICT bias, double *SP_RESTRICT Mi) {
  int b, i, j;
  const double zero[6] = {0, 0, 0, 0, 0, 0};
  const double a0[6] = {0, 0, 0, -T->gravity[0], -T->gravity[1], -T->gravity[2]};
  ncgen_tree_ground_inertias(T, s);
  for (b = 0; b < T->nb; ++b) {
    const ncgen_tree_joint_kind *k = &K->joint[T->kind[b]];
    int par = T->parent[b], va = T->v_at[b];
    const double *S = s->S + 6 * va, *vp = par < 0 ? zero : s->vl + 6 * par, *ap = par < 0 ? a0 : s->al + 6 * par;
    const double *I = s->IC + NCGEN_TREE_BODY * b;
    double *v = s->vl + 6 * b, *a = s->al + 6 * b, *f = s->fl + 6 * b, vJ[6], t[6], h[6];
    if (k->nv == 1) {                           /* written out (gcc -O2 keeps short loops) */
      double w = s->v[va];
#define NCGEN_TREE_VJ(i) vJ[i] = S[i] * w, v[i] = vp[i] + vJ[i]
      NCGEN_TREE_VJ(0); NCGEN_TREE_VJ(1); NCGEN_TREE_VJ(2); NCGEN_TREE_VJ(3); NCGEN_TREE_VJ(4); NCGEN_TREE_VJ(5);
#undef NCGEN_TREE_VJ
    } else
      for (i = 0; i < 6; ++i) {
        double x = 0.0;
        for (j = 0; j < k->nv; ++j) x += S[6 * j + i] * s->v[va + j];
        vJ[i] = x;
        v[i] = vp[i] + x;
      }
    sp_ad(v, vJ, t);                            /* a = a_p + c_J + v × S w */
    if (k->mode == 0)
      for (i = 0; i < 6; ++i) t[i] += s->cl[6 * b + i];
    a[0] = ap[0] + t[0];
    a[1] = ap[1] + t[1];
    a[2] = ap[2] + t[2];
    a[3] = ap[3] + t[3];
    a[4] = ap[4] + t[4];
    a[5] = ap[5] + t[5];
    sp_inertia_apply(I, v, h);
    sp_ad_star(v, h, f);
    sp_inertia_apply(I, a, t);
    f[0] += t[0];
    f[1] += t[1];
    f[2] += t[2];
    f[3] += t[3];
    f[4] += t[4];
    f[5] += t[5];
  }
  memset(Mi, 0, (size_t)T->ni * T->ni * sizeof(double));
  for (b = T->nb - 1; b >= 0; --b) {
    const ncgen_tree_joint_kind *k = &K->joint[T->kind[b]];
    int par = T->parent[b], va = T->v_at[b];
    const double *IC = s->IC + NCGEN_TREE_BODY * b, *f = s->fl + 6 * b;
    for (j = 0; j < k->nv; ++j) {
      int col = va + j, up = b;
      double F[6];
      bias[col] = ncgen_tree_dot6(s->S + 6 * col, f);
      sp_inertia_apply(IC, s->S + 6 * col, F);
      /* each pair of rates once: b's own up to col, then every rate of each ancestor */
      if (direct)                               /* M_rc in M_i's lower triangle */
        do {
          int row = T->v_at[up], end = up == b ? col + 1 : row + K->joint[T->kind[up]].nv;
          for (; row < end; ++row)
            Mi[row > col ? row + T->ni * col : col + T->ni * row] = ncgen_tree_dot6(s->S + 6 * row, F);
          up = T->parent[up];
        } while (up >= 0);
      else
        do {
          int row = T->v_at[up], end = up == b ? col + 1 : row + K->joint[T->kind[up]].nv;
          for (; row < end; ++row) ncgen_tree_mass_add(T, row, col, ncgen_tree_dot6(s->S + 6 * row, F), Mi);
          up = T->parent[up];
        } while (up >= 0);
    }
    if (par >= 0) {                             /* f_p += f, I^C_p += I^C (written out) */
      double *fp = s->fl + 6 * par, *ICp = s->IC + NCGEN_TREE_BODY * par;
      fp[0] += f[0];
      fp[1] += f[1];
      fp[2] += f[2];
      fp[3] += f[3];
      fp[4] += f[4];
      fp[5] += f[5];
#define NCGEN_TREE_IC(i) ICp[i] += IC[i]
      NCGEN_TREE_IC(0); NCGEN_TREE_IC(1); NCGEN_TREE_IC(2); NCGEN_TREE_IC(3); NCGEN_TREE_IC(4); NCGEN_TREE_IC(5);
      NCGEN_TREE_IC(6); NCGEN_TREE_IC(7); NCGEN_TREE_IC(8); NCGEN_TREE_IC(9); NCGEN_TREE_IC(10); NCGEN_TREE_IC(11);
      NCGEN_TREE_IC(12);
#undef NCGEN_TREE_IC
    }
  }
}

/* aj (nv) = G M_i⁻¹ (τ_i − b_i) in the work s by the mass matrix and the bias of one pass out and
 * in (ncgen_tree_mass_bias) and a dense Cholesky of M_i = Gᵀ M G: forward dynamics of the trees of
 * at most NCGEN_TREE_DENSE_NV rates (about the ground's origin: a tree far from it loses digits,
 * as the articulated-body algorithm's quantities do, somewhat more); check = [smallest relative
 * pivot of the Cholesky (NaN stays), Σ aj]. */
static int ncgen_tree_dense_aba(const ncgen_tree_kinds *K, const ncgen_tree *T, ncgen_tree_work *s, const double *q,
                                const double *v, const double *tau_i, double *aj, double *check) {
  int i, ni = T->ni, direct = ncgen_tree_unmapped(T);
  double sum = 0.0;
  ncgen_tree_expand(T, s, q, v, 0);
  if (ncgen_tree_local_poses(K, T, s)) return NCGEN_TREE_KERNEL;
  ncgen_tree_ground_poses(K, T, s);
  ncgen_tree_mass_bias(K, T, s, direct, s->tau, s->Mi);
  if (direct)
    for (i = 0; i < ni; ++i) s->rhs[i] = tau_i[i] - s->tau[i];
  else {
    ncgen_tree_project(T, s->tau, s->rhs);
    for (i = 0; i < ni; ++i) s->rhs[i] = tau_i[i] - s->rhs[i];
  }
  check[0] = ncgen_tree_cholesky(ni, s->Mi, s->L);
  ncgen_tree_solve(ni, s->L, s->rhs, 1);
  for (i = 0; i < T->nv; ++i) {
    aj[i] = T->rate_coef[i] * s->rhs[T->rate_col[i]];
    sum += aj[i];
  }
  check[1] = sum;
  return 0;
}

/* x = D⁻¹ y of one joint (nv rates) from the Cholesky factor L (lower, column stride 6) of D;
 * one rate: L[0] = 1 / d. */
static void ncgen_tree_joint_solve(int nv, const double *L, const double *y, double *x) {
  int j, c;
  if (nv == 1) {
    x[0] = y[0] * L[0];
    return;
  }
  for (j = 0; j < nv; ++j) {
    double t = y[j];
    for (c = 0; c < j; ++c) t -= L[j + 6 * c] * x[c];
    x[j] = t / L[j + 6 * j];
  }
  for (j = nv - 1; j >= 0; --j) {
    double t = x[j];
    for (c = j + 1; c < nv; ++c) t -= L[c + 6 * j] * x[c];
    x[j] = t / L[j + 6 * j];
  }
}

/* The articulated-body algorithm (no mimic joint): aj = M⁻¹ (τ − bias) in three passes over
 * the bodies, every quantity in the ground frame (twists and accelerations of the bodies as
 * [ω; v] at the ground's origin, articulated inertias I^A and bias wrenches p^A about it), so
 * that an articulated inertia passes to its parent by a sum, I^A_p += I^A − U D⁻¹ Uᵀ
 * (U = I^A S, D = Sᵀ U), with no change of frame (I^A symmetric: its lower triangle kept); *pivot = min d_k / (S_kᵀ I^C S_k) over
 * the Cholesky pivots d_k of each joint's D (the pivots of M's factorisation from the leaves,
 * relative to M's diagonal; NaN stays). */
static int ncgen_tree_articulated(const ncgen_tree_kinds *K, const ncgen_tree *T, ncgen_tree_work *s,
                                  const double *tau, double *aj, double *pivot) {
  int b, i, j, r, c, first = 1;
  const double zero[6] = {0, 0, 0, 0, 0, 0};
  const double a0[6] = {0, 0, 0, -T->gravity[0], -T->gravity[1], -T->gravity[2]};
  double ratio = 1.0;
  if (ncgen_tree_local_poses(K, T, s)) return NCGEN_TREE_KERNEL;
  ncgen_tree_ground_poses(K, T, s);
  ncgen_tree_ground_inertias(T, s);
  for (b = 0; b < T->nb; ++b) {                 /* twists, c = Ṡ w, I^A = I, p^A = −ad(v)ᵀ I v */
    const ncgen_tree_joint_kind *k = &K->joint[T->kind[b]];
    int par = T->parent[b], va = T->v_at[b];
    const double *S = s->S + 6 * va, *vp = par < 0 ? zero : s->vl + 6 * par, *I = s->IC + NCGEN_TREE_BODY * b;
    double *v = s->vl + 6 * b, *cb = s->cl + 6 * b, vJ[6], t[6];
    if (k->nv == 1) {                           /* written out (gcc -O2 keeps short loops) */
      double w = s->v[va];
#define NCGEN_TREE_VJ(i) vJ[i] = S[i] * w, v[i] = vp[i] + vJ[i]
      NCGEN_TREE_VJ(0); NCGEN_TREE_VJ(1); NCGEN_TREE_VJ(2); NCGEN_TREE_VJ(3); NCGEN_TREE_VJ(4); NCGEN_TREE_VJ(5);
#undef NCGEN_TREE_VJ
    } else
      for (i = 0; i < 6; ++i) {
        double x = 0.0;
        for (j = 0; j < k->nv; ++j) x += S[6 * j + i] * s->v[va + j];
        vJ[i] = x;
        v[i] = vp[i] + x;
      }
    sp_ad(v, vJ, t);
    cb[0] += t[0];
    cb[1] += t[1];
    cb[2] += t[2];
    cb[3] += t[3];
    cb[4] += t[4];
    cb[5] += t[5];
    sp_inertia_matrix(I, s->IA + 36 * b);
    sp_inertia_apply(I, v, t);
    sp_ad_star(v, t, s->fl + 6 * b);
  }
  for (b = T->nb - 1; b >= 0; --b) {
    const ncgen_tree_joint_kind *k = &K->joint[T->kind[b]];
    int nv = k->nv, va = T->v_at[b], par = T->parent[b];
    const double *S = s->S + 6 * va, *cb = s->cl + 6 * b, *IC = s->IC + NCGEN_TREE_BODY * b;
    double *IA = s->IA + 36 * b, *pA = s->fl + 6 * b, *U = s->U + 6 * va, *L = s->Dl + 36 * b, *u = s->ul + va;
    double mkk[6], w[6], F[6];
    if (par >= 0) {                             /* I^C_p += I^C (written out) */
      double *ICp = s->IC + NCGEN_TREE_BODY * par;
#define NCGEN_TREE_IC(i) ICp[i] += IC[i]
      NCGEN_TREE_IC(0); NCGEN_TREE_IC(1); NCGEN_TREE_IC(2); NCGEN_TREE_IC(3); NCGEN_TREE_IC(4); NCGEN_TREE_IC(5);
      NCGEN_TREE_IC(6); NCGEN_TREE_IC(7); NCGEN_TREE_IC(8); NCGEN_TREE_IC(9); NCGEN_TREE_IC(10); NCGEN_TREE_IC(11);
      NCGEN_TREE_IC(12);
#undef NCGEN_TREE_IC
    }
    if (nv == 1) {                              /* one rate: D = d, L[0] = 1 / d, I^a = I^A − Z Uᵀ, Z = U / d */
      double d, x, m, q, g, e, *IAp, *pAp, Z[6], y[6];
      ncgen_tree_sym6_apply(IA, S, U);
      d = ncgen_tree_dot6(S, U);
      u[0] = x = tau[va] - ncgen_tree_dot6(S, pA);
      m = ncgen_tree_inertia_quad(IC, S);       /* M_kk = Sᵀ I^C S */
      q = d / m;
      if (first || q < ratio || !(q == q)) ratio = q;
      first = 0;
      L[0] = g = 1.0 / (d > 0.0 ? d : 0.0);     /* inf where d <= 0 (the pivot says so) */
      if (par < 0) continue;
      IAp = s->IA + 36 * par;
      pAp = s->fl + 6 * par;
      e = (x - ncgen_tree_dot6(U, cb)) * g;     /* p^A_p += p^A + I^A c + U (u − Uᵀ c) / d */
      ncgen_tree_sym6_apply(IA, cb, y);
      for (r = 0; r < 6; ++r) {
        Z[r] = U[r] * g;
        pAp[r] += pA[r] + y[r] + U[r] * e;
      }
      /* I^A_p += I^A − Z Uᵀ (lower triangle) */
#define NCGEN_TREE_UPD(r, c) IAp[(r) + 6 * (c)] += IA[(r) + 6 * (c)] - Z[r] * U[c]
      NCGEN_TREE_UPD(0, 0); NCGEN_TREE_UPD(1, 0); NCGEN_TREE_UPD(2, 0); NCGEN_TREE_UPD(3, 0); NCGEN_TREE_UPD(4, 0);
      NCGEN_TREE_UPD(5, 0); NCGEN_TREE_UPD(1, 1); NCGEN_TREE_UPD(2, 1); NCGEN_TREE_UPD(3, 1); NCGEN_TREE_UPD(4, 1);
      NCGEN_TREE_UPD(5, 1); NCGEN_TREE_UPD(2, 2); NCGEN_TREE_UPD(3, 2); NCGEN_TREE_UPD(4, 2); NCGEN_TREE_UPD(5, 2);
      NCGEN_TREE_UPD(3, 3); NCGEN_TREE_UPD(4, 3); NCGEN_TREE_UPD(5, 3); NCGEN_TREE_UPD(4, 4); NCGEN_TREE_UPD(5, 4);
      NCGEN_TREE_UPD(5, 5);
#undef NCGEN_TREE_UPD
      continue;
    }
    for (j = 0; j < nv; ++j) {                  /* U = I^A S, D = Sᵀ U (lower), u = τ − Sᵀ p^A */
      const double *Sj = S + 6 * j;
      double *Uj = U + 6 * j, x = tau[va + j], m = 0.0;
      ncgen_tree_sym6_apply(IA, Sj, Uj);
      for (i = j; i < nv; ++i) {
        double y = 0.0;
        for (r = 0; r < 6; ++r) y += S[6 * i + r] * Uj[r];
        L[i + 6 * j] = y;
      }
      for (r = 0; r < 6; ++r) x -= Sj[r] * pA[r];
      u[j] = x;
      sp_inertia_apply(IC, Sj, F);              /* M_kk = S_kᵀ I^C S_k */
      for (r = 0; r < 6; ++r) m += Sj[r] * F[r];
      mkk[j] = m;
    }
    for (j = 0; j < nv; ++j) {                  /* D = L Lᵀ */
      double d = L[j + 6 * j], q;
      for (c = 0; c < j; ++c) d -= L[j + 6 * c] * L[j + 6 * c];
      q = d / mkk[j];
      if (first || q < ratio || !(q == q)) ratio = q;
      first = 0;
      L[j + 6 * j] = sqrt(d > 0.0 ? d : 0.0);
      for (i = j + 1; i < nv; ++i) {
        double x = L[i + 6 * j];
        for (c = 0; c < j; ++c) x -= L[i + 6 * c] * L[j + 6 * c];
        L[i + 6 * j] = x / L[j + 6 * j];
      }
    }
    if (par < 0) continue;
    {
      double *IAp = s->IA + 36 * par, *pAp = s->fl + 6 * par;
      double y[6], Z[36];
      for (r = 0; r < 6; ++r) {                 /* Z = U L⁻ᵀ (6 × nv) */
        for (j = 0; j < nv; ++j) {
          double x = U[6 * j + r];
          for (c = 0; c < j; ++c) x -= Z[6 * c + r] * L[j + 6 * c];
          Z[6 * j + r] = x / L[j + 6 * j];
        }
      }
      for (j = 0; j < nv; ++j) {                /* w = L⁻¹ (u − Uᵀ c) */
        double x = u[j];
        for (r = 0; r < 6; ++r) x -= U[6 * j + r] * cb[r];
        for (c = 0; c < j; ++c) x -= L[j + 6 * c] * w[c];
        w[j] = x / L[j + 6 * j];
      }
      /* p^A_p += p^A + I^A c + Z w (= p^A + I^a c + U D⁻¹ u, I^a = I^A − Z Zᵀ); I^A_p += I^a */
      ncgen_tree_sym6_apply(IA, cb, y);
      for (r = 0; r < 6; ++r) y[r] += pA[r];
      for (j = 0; j < nv; ++j)
        for (r = 0; r < 6; ++r) y[r] += Z[6 * j + r] * w[j];
      for (r = 0; r < 6; ++r) pAp[r] += y[r];
      for (c = 0; c < 6; ++c)
        for (r = c; r < 6; ++r) {
          double x = IA[r + 6 * c];
          for (j = 0; j < nv; ++j) x -= Z[6 * j + r] * Z[6 * j + c];
          IAp[r + 6 * c] += x;
        }
    }
  }
  for (b = 0; b < T->nb; ++b) {                 /* a = a_p + c + S ẇ, ẇ = D⁻¹ (u − Uᵀ (a_p + c)) */
    const ncgen_tree_joint_kind *k = &K->joint[T->kind[b]];
    int nv = k->nv, va = T->v_at[b], par = T->parent[b];
    const double *S = s->S + 6 * va, *U = s->U + 6 * va, *ap = par < 0 ? a0 : s->al + 6 * par;
    const double *cb = s->cl + 6 * b;
    double *a = s->al + 6 * b, y[6], x[6];
    a[0] = ap[0] + cb[0];
    a[1] = ap[1] + cb[1];
    a[2] = ap[2] + cb[2];
    a[3] = ap[3] + cb[3];
    a[4] = ap[4] + cb[4];
    a[5] = ap[5] + cb[5];
    if (nv == 1) {                              /* written out (gcc -O2 keeps short loops) */
      x[0] = aj[va] = (s->ul[va] - ncgen_tree_dot6(U, a)) * s->Dl[36 * b];
#define NCGEN_TREE_ACC(r) a[r] += S[r] * x[0]
      NCGEN_TREE_ACC(0); NCGEN_TREE_ACC(1); NCGEN_TREE_ACC(2); NCGEN_TREE_ACC(3); NCGEN_TREE_ACC(4); NCGEN_TREE_ACC(5);
#undef NCGEN_TREE_ACC
      continue;
    }
    for (j = 0; j < nv; ++j) y[j] = s->ul[va + j] - ncgen_tree_dot6(U + 6 * j, a);
    ncgen_tree_joint_solve(nv, s->Dl + 36 * b, y, x);
    for (j = 0; j < nv; ++j) {
      aj[va + j] = x[j];
      for (r = 0; r < 6; ++r) a[r] += S[6 * j + r] * x[j];
    }
  }
  *pivot = ratio;
  return 0;
}

/* y = M⁻¹ e (nv) for the joint efforts e (nv) by the last two passes of the articulated-body
 * algorithm on the factors of the last ncgen_tree_articulated (no velocity, no gravity). */
static void ncgen_tree_articulated_solve(const ncgen_tree_kinds *K, const ncgen_tree *T, ncgen_tree_work *s,
                                         const double *e, double *y) {
  int b, i, j, r;
  const double zero[6] = {0, 0, 0, 0, 0, 0};
  for (i = 0; i < 6 * T->nb; ++i) s->pr[i] = 0.0;
  for (b = T->nb - 1; b >= 0; --b) {
    const ncgen_tree_joint_kind *k = &K->joint[T->kind[b]];
    int nv = k->nv, va = T->v_at[b], par = T->parent[b];
    const double *S = s->S + 6 * va, *U = s->U + 6 * va, *pA = s->pr + 6 * b;
    double *u = s->ur + va, x[6];
    for (j = 0; j < nv; ++j) u[j] = e[va + j] - ncgen_tree_dot6(S + 6 * j, pA);  /* u = e − Sᵀ p^A */
    if (par < 0) continue;
    if (nv == 1) {                              /* written out (gcc -O2 keeps short loops) */
      double *pp = s->pr + 6 * par, g = u[0] * s->Dl[36 * b];
#define NCGEN_TREE_PR(r) pp[r] += pA[r] + U[r] * g
      NCGEN_TREE_PR(0); NCGEN_TREE_PR(1); NCGEN_TREE_PR(2); NCGEN_TREE_PR(3); NCGEN_TREE_PR(4); NCGEN_TREE_PR(5);
#undef NCGEN_TREE_PR
      continue;
    }
    ncgen_tree_joint_solve(nv, s->Dl + 36 * b, u, x);  /* p^A_p += p^A + U D⁻¹ u */
    for (r = 0; r < 6; ++r) {
      double t = pA[r];
      for (j = 0; j < nv; ++j) t += U[6 * j + r] * x[j];
      s->pr[6 * par + r] += t;
    }
  }
  for (b = 0; b < T->nb; ++b) {
    const ncgen_tree_joint_kind *k = &K->joint[T->kind[b]];
    int nv = k->nv, va = T->v_at[b], par = T->parent[b];
    const double *S = s->S + 6 * va, *U = s->U + 6 * va, *ap = par < 0 ? zero : s->ar + 6 * par;
    double *a = s->ar + 6 * b, z[6], x[6];
    memcpy(a, ap, 6 * sizeof(double));
    if (nv == 1) {                              /* written out */
      double g = y[va] = (s->ur[va] - ncgen_tree_dot6(U, a)) * s->Dl[36 * b];
#define NCGEN_TREE_AR(r) a[r] += S[r] * g
      NCGEN_TREE_AR(0); NCGEN_TREE_AR(1); NCGEN_TREE_AR(2); NCGEN_TREE_AR(3); NCGEN_TREE_AR(4); NCGEN_TREE_AR(5);
#undef NCGEN_TREE_AR
      continue;
    }
    for (j = 0; j < nv; ++j) z[j] = s->ur[va + j] - ncgen_tree_dot6(U + 6 * j, a);
    ncgen_tree_joint_solve(nv, s->Dl + 36 * b, z, x);
    for (j = 0; j < nv; ++j) {
      y[va + j] = x[j];
      for (r = 0; r < 6; ++r) a[r] += S[6 * j + r] * x[j];
    }
  }
}

/* Forward dynamics of a tree with mimic joints by the articulated-body algorithm on the tree
 * with every rate free and the followers held by the constraints C a = 0 (rows
 * e_f − k_f e_leader): a = a₀ + Y λ with a₀ = M⁻¹ (τ − bias) (the efforts τ_i on the leaders),
 * Y = M⁻¹ Cᵀ, (C Y) λ = −C a₀; the constraint forces Cᵀλ have no part along G, so G ᵀ τ = τ_i.
 * Returns 1 (nothing written) when M or C Y is not positive definite beyond the pivot
 * tolerance: the caller then solves M_i a_i = τ_i − b_i by Cholesky, which names the cause. */
static int ncgen_tree_constrained(const ncgen_tree_kinds *K, const ncgen_tree *T, ncgen_tree_work *s,
                                  const double *tau_i, double *aj, double *pivot, int *failed) {
  int i, j, k, m = 0, nv = T->nv;
  double ratio;
  *failed = 0;
  for (i = 0; i < nv; ++i) s->tf[i] = T->rate_src[i] == i ? tau_i[T->rate_col[i]] : 0.0;
  if (ncgen_tree_articulated(K, T, s, s->tf, aj, &ratio)) return NCGEN_TREE_KERNEL;
  if (!(ratio > NCGEN_TREE_PIVOT_TOL)) {
    *failed = 1;
    return 0;
  }
  for (i = 0; i < nv; ++i) {                    /* Y's columns, one per follower */
    if (T->rate_src[i] == i) continue;
    for (j = 0; j < nv; ++j) s->tf[j] = 0.0;
    s->tf[i] = 1.0;
    s->tf[T->rate_src[i]] = -T->rate_coef[i];
    ncgen_tree_articulated_solve(K, T, s, s->tf, s->Y + (long)nv * m);
    ++m;
  }
  for (k = 0, j = 0; j < nv; ++j) {              /* C Y (m × m) and −C a₀ */
    int f, c = 0;
    if (T->rate_src[j] == j) continue;
    for (f = 0; f < nv; ++f) {
      if (T->rate_src[f] == f) continue;
      s->Kc[k + m * c] = s->Y[(long)nv * c + j] - T->rate_coef[j] * s->Y[(long)nv * c + T->rate_src[j]];
      ++c;
    }
    s->ur[k] = -(aj[j] - T->rate_coef[j] * aj[T->rate_src[j]]);
    ++k;
  }
  ratio = fmin(ratio, ncgen_tree_cholesky(m, s->Kc, s->Kc + (long)m * m));
  if (!(ratio > NCGEN_TREE_PIVOT_TOL)) {
    *failed = 1;
    return 0;
  }
  ncgen_tree_solve(m, s->Kc + (long)m * m, s->ur, 1);
  for (k = 0; k < m; ++k)
    for (i = 0; i < nv; ++i) aj[i] += s->Y[(long)nv * k + i] * s->ur[k];
  for (i = 0; i < nv; ++i)
    if (T->rate_src[i] != i) aj[i] = T->rate_coef[i] * aj[T->rate_src[i]];
  *pivot = ratio;
  return 0;
}

/* M_i and the bias b_i = τ_i(q, v, a = 0) (in s->rhs) of one local pass; the Cholesky
 * factor of M_i in s->L; returns the smallest relative pivot in *pivot. */
static int ncgen_tree_factored(const ncgen_tree_kinds *K, const ncgen_tree *T, ncgen_tree_work *s, const double *q,
                               const double *v, double *pivot) {
  ncgen_tree_expand(T, s, q, v, 0);
  if (ncgen_tree_local_poses(K, T, s)) return NCGEN_TREE_KERNEL;
  ncgen_tree_local_motion(K, T, s, 1);
  ncgen_tree_local_backward(K, T, s);
  ncgen_tree_project(T, s->tau, s->rhs);
  ncgen_tree_ground_poses(K, T, s);
  ncgen_tree_ground_mass(K, T, s, s->Mi);
  *pivot = ncgen_tree_cholesky(T->ni, s->Mi, s->L);
  return 0;
}

/* aj (nv) = G M_i⁻¹ (τ_i − b_i) by Cholesky of M_i (the fallback of forward dynamics with mimic
 * joints when M or C Y is not positive definite); check = [smallest relative pivot, Σ aj]. */
static int ncgen_tree_factored_aba(const ncgen_tree_kinds *K, const ncgen_tree *T, ncgen_tree_work *s,
                                   const double *q, const double *v, const double *tau_i, double *aj,
                                   double *check) {
  int i;
  double sum = 0.0;
  if (ncgen_tree_factored(K, T, s, q, v, &check[0])) return NCGEN_TREE_KERNEL;
  for (i = 0; i < T->ni; ++i) s->rhs[i] = tau_i[i] - s->rhs[i];
  ncgen_tree_solve(T->ni, s->L, s->rhs, 1);
  for (i = 0; i < T->nv; ++i) {
    aj[i] = T->rate_coef[i] * s->rhs[T->rate_col[i]];
    sum += aj[i];
  }
  check[1] = sum;
  return 0;
}

#ifdef NCGEN_TREE_EXTERNAL_FALLBACK
/* Defined by the includer (a unit of the tree library without the Cholesky path): the
 * fallback of ncgen_tree_aba_at, the same contract as ncgen_tree_factored_aba. */
static int ncgen_tree_fallback(const ncgen_tree *T, ncgen_tree_work *s, const double *q, const double *v,
                               const double *tau_i, double *aj, double *check);
#endif

/* aj (nv) = G M_i⁻¹ (τ_i − b_i) in the work s: forward dynamics, by Cholesky of M_i
 * (ncgen_tree_dense_aba) for trees of at most NCGEN_TREE_DENSE_NV rates, else by the
 * articulated-body algorithm (with mimic joints: their followers held by constraints, and where
 * M or C Y is not positive definite by Cholesky of M_i: ncgen_tree_factored_aba, or the
 * includer's ncgen_tree_fallback where NCGEN_TREE_EXTERNAL_FALLBACK is defined); check =
 * [smallest relative pivot, Σ aj]. */
static int ncgen_tree_aba_at(const ncgen_tree_kinds *K, const ncgen_tree *T, ncgen_tree_work *s, const double *q,
                             const double *v, const double *tau_i, double *aj, double *check) {
  int i;
  double sum = 0.0;
  if (T->nv <= NCGEN_TREE_DENSE_NV) return ncgen_tree_dense_aba(K, T, s, q, v, tau_i, aj, check);
  ncgen_tree_expand(T, s, q, v, 0);
  if (ncgen_tree_unmapped(T)) {
    if (ncgen_tree_articulated(K, T, s, tau_i, aj, &check[0])) return NCGEN_TREE_KERNEL;
    for (i = 0; i < T->nv; ++i) sum += aj[i];
    check[1] = sum;
    return 0;
  } else {
    int failed;
    if (ncgen_tree_constrained(K, T, s, tau_i, aj, &check[0], &failed)) return NCGEN_TREE_KERNEL;
    if (!failed) {
      for (i = 0; i < T->nv; ++i) sum += aj[i];
      check[1] = sum;
      return 0;
    }
  }
#ifdef NCGEN_TREE_EXTERNAL_FALLBACK
  return ncgen_tree_fallback(T, s, q, v, tau_i, aj, check);
#else
  return ncgen_tree_factored_aba(K, T, s, q, v, tau_i, aj, check);
#endif
}

/* The same with the work array work. */
static int ncgen_tree_aba(const ncgen_tree_kinds *K, const ncgen_tree *T, const double *q, const double *v,
                          const double *tau_i, double *aj, double *check, double *work) {
  ncgen_tree_work s;
  ncgen_tree_layout(K, T, work, &s);
  return ncgen_tree_aba_at(K, T, &s, q, v, tau_i, aj, check);
}

/* The tangent pass along direction d of the independent rates (d < ni: positions, q moved
 * in the tangent space; else rates, column d − ni): dτ_i (ni) at the state of the last
 * forward pass (its a held). */
static int ncgen_tree_tangent(const ncgen_tree_kinds *K, const ncgen_tree *T, ncgen_tree_work *s, int d,
                              double *dtau_i) {
  int b, i, j, col = d < T->ni ? d : d - T->ni, rates = d >= T->ni;
  for (b = 0; b < T->nb; ++b) {
    const ncgen_tree_joint_kind *k = &K->joint[T->kind[b]];
    int par = T->parent[b], va = T->v_at[b], n = ncgen_tree_edge_input(K, T, s, b);
    double *in = s->in, *out = s->out, *S = s->S + 6 * va, *dS = s->dS + 6 * va, *dc;
    for (i = 0; i < 9; ++i) in[n++] = par < 0 ? 0.0 : s->dR[9 * par + i];
    for (i = 0; i < 3; ++i) in[n++] = par < 0 ? 0.0 : s->dp[3 * par + i];
    for (i = 0; i < 6; ++i) in[n++] = par < 0 ? 0.0 : s->dTt[6 * par + i];
    for (i = 0; i < k->nv; ++i)
      in[n++] = !rates && T->rate_col[va + i] == col ? T->rate_coef[va + i] : 0.0;
    for (i = 0; i < k->nv; ++i)
      in[n++] = rates && T->rate_col[va + i] == col ? T->rate_coef[va + i] : 0.0;
    if (ncgen_tree_call(k->edge_fwd, in, out, s->kw)) return NCGEN_TREE_KERNEL;
    memcpy(s->dR + 9 * b, out, 9 * sizeof(double));
    memcpy(s->dp + 3 * b, out + 9, 3 * sizeof(double));
    memcpy(dS, out + 12, 6 * (size_t)k->nv * sizeof(double));
    dc = out + 12 + 6 * k->nv;
    for (i = 0; i < 6; ++i) {
      double t = par < 0 ? 0.0 : s->dTt[6 * par + i];
      double dt = (par < 0 ? 0.0 : s->ddT[6 * par + i]) + dc[i];
      for (j = 0; j < k->nv; ++j) {
        double dw = in[n - k->nv + j];
        t += dS[6 * j + i] * s->v[va + j] + S[6 * j + i] * dw;
        dt += dS[6 * j + i] * s->a[va + j];
      }
      s->dTt[6 * b + i] = t;
      s->ddT[6 * b + i] = dt;
    }
    ncgen_tree_body_input(T, s, b, in);
    memcpy(in + 37, s->dR + 9 * b, 9 * sizeof(double));
    memcpy(in + 46, s->dp + 3 * b, 3 * sizeof(double));
    memcpy(in + 49, s->dTt + 6 * b, 6 * sizeof(double));
    memcpy(in + 55, s->ddT + 6 * b, 6 * sizeof(double));
    if (ncgen_tree_call(K->body_fwd, in, out, s->kw)) return NCGEN_TREE_KERNEL;
    memcpy(s->dW + 6 * b, out + 36, 6 * sizeof(double));
  }
  /* dτ_j = dS_jᵀ W + S_jᵀ dW, W and dW summed over subtrees (s->W summed by the caller) */
  ncgen_tree_backward(K, T, s->dW, s->S, s->dtau);
  for (b = 0; b < T->nb; ++b) {
    const ncgen_tree_joint_kind *k = &K->joint[T->kind[b]];
    int va = T->v_at[b];
    for (j = 0; j < k->nv; ++j)
      for (i = 0; i < 6; ++i) s->dtau[va + j] += s->dS[6 * (va + j) + i] * s->W[6 * b + i];
  }
  ncgen_tree_project(T, s->dtau, dtau_i);
  return 0;
}

/* The derivatives at the state of the last forward pass, with s->W summed: ∂τ_i/∂q and
 * ∂τ_i/∂v (ni × ni, column-major). */
static int ncgen_tree_tangents(const ncgen_tree_kinds *K, const ncgen_tree *T, ncgen_tree_work *s, double *dq,
                               double *dv) {
  int d, ni = T->ni;
  for (d = 0; d < 2 * ni; ++d)
    if (ncgen_tree_tangent(K, T, s, d, d < ni ? dq + (long)ni * d : dv + (long)ni * (d - ni)))
      return NCGEN_TREE_KERNEL;
  return 0;
}

/* (τ_i, ∂τ_i/∂q, ∂τ_i/∂v, ∂τ_i/∂a = M_i): RNEA and its derivatives by tangent recursions. */
static int ncgen_tree_rnea_derivatives(const ncgen_tree_kinds *K, const ncgen_tree *T, const double *q,
                                       const double *v, const double *a, double *tau_i, double *dq, double *dv,
                                       double *Mi, double *work) {
  ncgen_tree_work s;
  ncgen_tree_layout(K, T, work, &s);
  ncgen_tree_expand(T, &s, q, v, a);
  if (ncgen_tree_forward(K, T, &s)) return NCGEN_TREE_KERNEL;
  ncgen_tree_backward(K, T, s.W, s.S, s.tau);
  ncgen_tree_project(T, s.tau, tau_i);
  if (ncgen_tree_tangents(K, T, &s, dq, dv)) return NCGEN_TREE_KERNEL;
  ncgen_tree_composite(K, T, &s, Mi);
  return 0;
}

/* (aj, ∂a_i/∂q, ∂a_i/∂v, ∂a_i/∂τ = M_i⁻¹, check): ∂a/∂x = −M_i⁻¹ ∂τ_rnea/∂x at a = a(q, v, τ). */
static int ncgen_tree_aba_derivatives(const ncgen_tree_kinds *K, const ncgen_tree *T, const double *q,
                                      const double *v, const double *tau_i, double *aj, double *da_dq,
                                      double *da_dv, double *Minv, double *check, double *work) {
  ncgen_tree_work s;
  int i, ni = T->ni;
  ncgen_tree_layout(K, T, work, &s);
  if (ncgen_tree_factored_aba(K, T, &s, q, v, tau_i, aj, check)) return NCGEN_TREE_KERNEL;
  ncgen_tree_expand(T, &s, q, v, aj);
  if (ncgen_tree_forward(K, T, &s)) return NCGEN_TREE_KERNEL;
  ncgen_tree_backward(K, T, s.W, s.S, s.tau);
  if (ncgen_tree_tangents(K, T, &s, da_dq, da_dv)) return NCGEN_TREE_KERNEL;
  for (i = 0; i < ni * ni; ++i) {
    da_dq[i] = -da_dq[i];
    da_dv[i] = -da_dv[i];
    Minv[i] = i % (ni + 1) == 0 ? 1.0 : 0.0;
  }
  ncgen_tree_solve(ni, s.L, da_dq, ni);
  ncgen_tree_solve(ni, s.L, da_dv, ni);
  ncgen_tree_solve(ni, s.L, Minv, ni);
  return 0;
}

/* The joint-space ODE: x = [q_j; v_j] -> ẋ = [q̇_j(q_j, v_j); a_j(q_j, v_j, τ_i)] with the
 * efforts τ_i = E w of the inputs w (E: ni × nu, column-major); check as ncgen_tree_aba; in the
 * work s (ncgen_tree_layout: laid out once for a loop's run). */
static int ncgen_tree_ode_at(const ncgen_tree_kinds *K, const ncgen_tree *T, ncgen_tree_work *s, const double *E,
                             int nu, const double *x, const double *w, double *xdot, double *check) {
  int b, i, j;
  for (b = 0; b < T->nb; ++b) {
    const ncgen_tree_joint_kind *k = &K->joint[T->kind[b]];
    if (!k->nq) continue;
    if (!k->qdot) {                             /* q̇ = w */
      for (i = 0; i < k->nv; ++i) xdot[T->q_at[b] + i] = x[T->nq + T->v_at[b] + i];
      continue;
    }
    for (i = 0; i < k->nq; ++i) s->in[i] = x[T->q_at[b] + i];
    for (i = 0; i < k->nv; ++i) s->in[k->nq + i] = x[T->nq + T->v_at[b] + i];
    if (ncgen_tree_call(k->qdot, s->in, xdot + T->q_at[b], s->kw)) return NCGEN_TREE_KERNEL;
  }
  for (i = 0; i < T->ni; ++i) {
    double t = 0.0;
    for (j = 0; j < nu; ++j) t += E[i + (long)T->ni * j] * w[j];
    s->taui[i] = t;
  }
  return ncgen_tree_aba_at(K, T, s, x, x + T->nq, s->taui, xdot + T->nq, check);
}

#endif

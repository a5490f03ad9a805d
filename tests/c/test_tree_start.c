/* Unit tests of a run's start on a tree (ncgen_tree_start.h) on a hand-made tree:
 *
 *   body 0 turns about the z axis of its joint frame xin_0 (a rotation about x and an offset) on the ground (θ),
 *   body 1 slides along the z axis of xin_1 on body 0 (s), body 2 is welded to body 1 by xin_2;
 *   each member's "natural coordinates" are q_m = 2 [vec R; p] + c of its joint frame's pose (P, L inverse
 *   affine maps), body 0's origin slots fixed (the hinge's origin does not move: their constants).
 *
 * Checked against the forward map written again here (poses by matrix products) and its rates by central
 * differences: the joint state recovered (also near θ = π), the distances at round-off on the tree, equal to a
 * move off it along a slot, a NaN seen by the sum, a joint kind the check does not take refused; with the slider
 * made a mimic of the hinge (s = k θ + c, ṡ = k θ̇), a start with the follower where the map puts it accepted and
 * one with it elsewhere (or moving otherwise) refused, by the distance it is off.  Built and
 * run by tests/test_stepper_runtime_c.py under AddressSanitizer and UndefinedBehaviorSanitizer. */
#include "check.h"
#if defined(__GNUC__)
#pragma GCC diagnostic ignored "-Wunused-function"  /* the header's algorithms: not used here */
#endif
#include "ncgen_tree_tables.h"
#include "ncgen_tree_start.h"

static const double XIN[36] = {1, 0, 0, 0, 0.8, 0.6, 0, -0.6, 0.8, 0.1, 0.2, 0.3,       /* Rx, offset */
                               0, 1, 0, -1, 0, 0, 0, 0, 1, 0.5, 0.0, -0.2,             /* Rz(π/2), offset */
                               1, 0, 0, 0, 1, 0, 0, 0, 1, 0.0, 0.3, 0.0};              /* a translation */
static const double C0[12] = {0.1, -0.2, 0.3, 0.4, 0.5, -0.6, 0.7, 0.8, 0.9, 1.0, -1.1, 1.2};

/* The members' coordinates (36) at θ, s: the forward map written again. */
static void members_at(double th, double s, double *q) {
  double J0[12] = {0}, J1[12] = {1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0}, H[12], F[12], G[12];
  int b, i;
  J0[0] = cos(th), J0[1] = sin(th), J0[3] = -sin(th), J0[4] = cos(th), J0[8] = 1.0;
  J1[11] = s;
  ncgen_start_compose(XIN, J0, H);                       /* f_0 = xin_0 Rz(θ) */
  ncgen_start_compose(H, XIN + 12, F);
  ncgen_start_compose(F, J1, G);                         /* f_1 = f_0 xin_1 Tz(s) */
  ncgen_start_compose(G, XIN + 24, F);                   /* f_2 = f_1 xin_2 */
  for (b = 0; b < 3; ++b)
    for (i = 0; i < 12; ++i) q[12 * b + i] = 2.0 * (b == 0 ? H : b == 1 ? G : F)[i] + C0[i];
}

int main(void) {
  ncgen_tree_joint_kind joint[3] = {{0, 0, 0, 0, 0, 0, 0, 3}, {0, 0, 0, 0, 1, 1, 0, 1}, {0, 0, 0, 0, 1, 1, 0, 2}};
  ncgen_tree_kinds K = {joint, 3, 0, 0, 0};
  int parent[3] = {-1, 0, 1}, kind[3] = {1, 2, 0}, q_at[3] = {0, 1, 0}, v_at[3] = {0, 1, 0}, how[3] = {1, 2, 3};
  int idx[36], nz_ptr[7], nz[72], i, b, k;
  int q_src[2] = {-1, 0}, rate_src[2] = {0, 0};                   /* the mimic case: s = k θ + c, ṡ = k θ̇ */
  const double K_MIMIC = -0.4, C_MIMIC = 0.05, q_coef[2] = {1.0, K_MIMIC}, q_off[2] = {0.0, C_MIMIC};
  const double rate_coef[2] = {1.0, K_MIMIC};
  double num[3 * NCGEN_TREE_START_NUM] = {0}, q[33], v[33], qm[36], qp[36], qn[36], qj[2], vj[2], check[5], w[256];
  const double ths[2] = {0.7, 3.1}, s = -0.35, th_dot = 1.3, s_dot = -0.8, h = 1e-6;
  ncgen_tree T;
  ncgen_tree_start S;
  memset(&T, 0, sizeof T);
  T.nb = 3, T.nq = 2, T.nv = 2, T.ni = 2, T.parent = parent, T.kind = kind, T.q_at = q_at, T.v_at = v_at;
  T.xin = XIN;
  S.T = &T, S.idx = idx, S.how = how, S.nz_ptr = nz_ptr, S.nz = nz, S.num = num, S.n = 33, S.q = q, S.v = v;
  S.qj = qj, S.vj = vj, S.check = check, S.w = w;
  for (b = 0; b < 3; ++b) {
    double *cst = num + NCGEN_TREE_START_NUM * b, *P = cst + 12, *L = P + 156;
    for (i = 0; i < 12; ++i) {
      P[i + 12 * i] = 0.5, P[144 + i] = -0.5 * C0[i];
      L[i + 12 * i] = 2.0, L[144 + i] = C0[i];
      nz[24 * b + i] = nz[24 * b + 12 + i] = i | i << 4;
    }
    nz_ptr[2 * b] = 24 * b, nz_ptr[2 * b + 1] = 24 * b + 12;
  }
  nz_ptr[6] = 72;
  for (k = 0; k < 2; ++k) {
    members_at(ths[k], s, qm);
    members_at(ths[k] + h * th_dot, s + h * s_dot, qp);
    members_at(ths[k] - h * th_dot, s - h * s_dot, qn);
    for (i = 0, b = 0; i < 36; ++i) {                   /* body 0's origin slots fixed: q holds the other 33 */
      if (i >= 9 && i < 12) {
        idx[i] = -1, num[i] = qm[i];
        continue;
      }
      idx[i] = b, q[b] = qm[i], v[b] = (qp[i] - qn[i]) / (2 * h), ++b;
    }
    CHECK(ncgen_tree_start_state(&K, &S) == 0, "status");
    CHECK(fabs(qj[0] - ths[k]) < 1e-14 && fabs(qj[1] - s) < 1e-14, "q_j = (%g, %g)", qj[0], qj[1]);
    CHECK(fabs(vj[0] - th_dot) < 1e-8 && fabs(vj[1] - s_dot) < 1e-8, "v_j = (%g, %g)", vj[0], vj[1]);
    CHECK(check[0] < 1e-14 && check[1] < 1e-8, "distances %g %g on the tree", check[0], check[1]);
    CHECK(isfinite(check[4]) && check[2] > 1.0 && check[3] > 0.1, "magnitudes %g %g", check[2], check[3]);
  }
  q[20] += 1e-7;                                        /* a slot of body 1 moved off the tree */
  ncgen_tree_start_state(&K, &S);
  CHECK(check[0] > 3e-8 && check[0] < 2e-7, "distance %g of a move of 1e-7", check[0]);
  v[5] += 1e-3;
  ncgen_tree_start_state(&K, &S);
  CHECK(check[1] > 3e-4 && check[1] < 2e-3, "rate distance %g of a move of 1e-3", check[1]);
  v[7] = NAN;
  ncgen_tree_start_state(&K, &S);
  CHECK(!isfinite(check[4]), "a NaN in v: the sum %g", check[4]);
  {                                                      /* the slider a mimic of the hinge */
    const double th = 0.9, th_rate = 0.7, off[2] = {0.0, 2e-6};
    T.q_src = q_src, T.q_coef = q_coef, T.q_off = q_off, T.rate_src = rate_src, T.rate_coef = rate_coef;
    for (k = 0; k < 2; ++k) {                            /* the follower where the map puts it, then 2e-6 off */
      double s_k = K_MIMIC * th + C_MIMIC + off[k];
      members_at(th, s_k, qm);
      members_at(th + h * th_rate, s_k + h * K_MIMIC * th_rate, qp);
      members_at(th - h * th_rate, s_k - h * K_MIMIC * th_rate, qn);
      for (i = 0, b = 0; i < 36; ++i) {
        if (i >= 9 && i < 12) {
          num[i] = qm[i];
          continue;
        }
        q[b] = qm[i], v[b] = (qp[i] - qn[i]) / (2 * h), ++b;
      }
      CHECK(ncgen_tree_start_state(&K, &S) == 0, "status (mimic)");
      CHECK(fabs(qj[1] - s_k) < 1e-14, "the follower read off: %g, expected %g", qj[1], s_k);
      if (k == 0)
        CHECK(check[0] < 1e-14 && check[1] < 1e-8, "on the mimic map: distances %g %g", check[0], check[1]);
      else
        CHECK(fabs(check[0] - 2e-6) < 1e-12, "the follower 2e-6 off its map: distance %g", check[0]);
    }
    members_at(th, K_MIMIC * th + C_MIMIC, qm);          /* the follower at its place, moving at the wrong rate */
    members_at(th + h * th_rate, K_MIMIC * th + C_MIMIC + h * (K_MIMIC * th_rate + 1e-3), qp);
    members_at(th - h * th_rate, K_MIMIC * th + C_MIMIC - h * (K_MIMIC * th_rate + 1e-3), qn);
    for (i = 0, b = 0; i < 36; ++i)
      if (i < 9 || i >= 12) q[b] = qm[i], v[b] = (qp[i] - qn[i]) / (2 * h), ++b;
    ncgen_tree_start_state(&K, &S);
    CHECK(check[0] < 1e-14 && fabs(check[1] - 1e-3) < 1e-8, "the follower's rate 1e-3 off: distances %g %g",
          check[0], check[1]);
    T.q_src = 0, T.rate_src = 0;
  }
  CHECK(NCGEN_TREE_START_WORK_SIZE(&K, &T) <= 256, "work %ld", NCGEN_TREE_START_WORK_SIZE(&K, &T));
  joint[2].mode = 0;                                     /* a kind taken by its kernel: not this check's */
  CHECK(ncgen_tree_start_state(&K, &S) == 1, "kind refused");
  joint[2].mode = 3, how[2] = 7;                          /* read off as a kind of other sizes: refused */
  CHECK(ncgen_tree_start_state(&K, &S) == 1, "a reading of other sizes refused");
  return report("test_tree_start");
}

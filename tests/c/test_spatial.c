/* Unit tests of the spatial algebra of the local tree recursion (ncgen_spatial.h) by its
 * identities, on a pose, twists, wrenches and inertias of no special form:
 *   power:    W_aᵀ T_a = W_bᵀ T_b for T_b = Ad(H_ab)⁻¹ T_a and W_a = Ad(H_ab)⁻ᵀ W_b;
 *   duality:  (−ad(T)ᵀ W)ᵀ X = −Wᵀ ad(T) X;
 *   inertia:  M T of the 13 numbers equals the 6 × 6 matrix's; a rigid inertia moved from b
 *             to a gives W_a = Ad(H_ab)⁻ᵀ M_b Ad(H_ab)⁻¹ T_a;
 *   twists:   Ad(H_ab) T_b = T_a for T_b = Ad(H_ab)⁻¹ T_a.
 * tests/test_spatial_c.py checks each function against ncgen.rigid_motion's forms.  Built and
 * run by tests/test_stepper_runtime_c.py under AddressSanitizer and UndefinedBehaviorSanitizer. */
#include "check.h"
#include "ncgen_spatial.h"

static double close_to(double a, double b) { return fabs(a - b) <= 1e-12 * (1.0 + fabs(b)); }

static double dot6(const double *a, const double *b) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3] + a[4] * b[4] + a[5] * b[5];
}

static void mat6(const double *M, const double *x, double *y) {
  int i, j;
  for (i = 0; i < 6; ++i) {
    y[i] = 0.0;
    for (j = 0; j < 6; ++j) y[i] += M[i + 6 * j] * x[j];
  }
}

int main(void) {
  /* R: rotation by 0.7 rad about (1, 2, 2)/3 (column-major) */
  const double u[3] = {1.0 / 3, 2.0 / 3, 2.0 / 3}, th = 0.7, p[3] = {0.3, -1.2, 0.5};
  const double Ta[6] = {0.4, -0.3, 1.1, 2.0, -0.7, 0.2}, Wb[6] = {-0.5, 0.8, 0.3, 1.5, 0.1, -2.2};
  const double Ib[13] = {2.5, 0.3, -0.2, 0.4, 0.9, 0.05, -0.1, 0.05, 1.1, 0.02, -0.1, 0.02, 0.7};
  double R[9], Tb[6], Wa[6] = {0, 0, 0, 0, 0, 0}, Y[6], X[6], Z[6], M[36], Ia[13], W1[6], W2[6];
  double c = cos(th), s = sin(th), zero6[6] = {0, 0, 0, 0, 0, 0};
  int i, j;
  for (i = 0; i < 3; ++i)
    for (j = 0; j < 3; ++j) {
      double skew = (i == j) ? 0.0 : ((j == (i + 1) % 3) ? -u[3 - i - j] : u[3 - i - j]);
      R[i + 3 * j] = (i == j ? c : 0.0) + s * skew + (1 - c) * u[i] * u[j];
    }

  sp_rot_t(R, Ta, X);
  sp_rot(R, X, Y);
  for (i = 0; i < 3; ++i) CHECK(close_to(Y[i], Ta[i]), "R Rᵀ x = x: %g, %g", Y[i], Ta[i]);

  sp_twist_in(R, p, Ta, Tb);
  sp_wrench_out_add(R, p, Wb, Wa);
  CHECK(close_to(dot6(Wa, Ta), dot6(Wb, Tb)), "power: %.17g, %.17g", dot6(Wa, Ta), dot6(Wb, Tb));

  sp_ad_star(Ta, Wb, Y);
  sp_ad(Ta, Tb, X);
  CHECK(close_to(dot6(Y, Tb), -dot6(Wb, X)), "duality: %.17g, %.17g", dot6(Y, Tb), -dot6(Wb, X));
  sp_ad(Ta, Ta, X);
  for (i = 0; i < 6; ++i) CHECK(fabs(X[i]) < 1e-15, "ad(T) T = 0: %g", X[i]);

  sp_inertia_apply(Ib, Tb, W1);
  sp_inertia_matrix(Ib, M);
  mat6(M, Tb, W2);
  for (i = 0; i < 6; ++i) CHECK(close_to(W1[i], W2[i]), "M T: %g, %g", W1[i], W2[i]);
  for (i = 0; i < 6; ++i)
    for (j = 0; j < 6; ++j) CHECK(M[i + 6 * j] == M[j + 6 * i], "M symmetric at (%d, %d)", i, j);

  /* a rigid inertia moved from b to a: M_a T_a = Ad⁻ᵀ (M_b T_b) */
  for (i = 0; i < 13; ++i) Ia[i] = 0.0;
  sp_inertia_out_add(R, p, Ib, Ia);
  sp_inertia_apply(Ia, Ta, W2);
  memcpy(Z, zero6, sizeof Z);
  sp_wrench_out_add(R, p, W1, Z);
  for (i = 0; i < 6; ++i) CHECK(close_to(W2[i], Z[i]), "rigid inertia moved: %g, %g", W2[i], Z[i]);

  /* a twist moved out and back in: Ad(H_ab)⁻¹ Ad(H_ab) T = T */
  sp_twist_out(R, p, Tb, X);
  sp_twist_in(R, p, X, Y);
  for (i = 0; i < 6; ++i) CHECK(close_to(Y[i], Tb[i]), "Ad⁻¹ Ad T = T: %g, %g", Y[i], Tb[i]);
  for (i = 0; i < 6; ++i) CHECK(close_to(X[i], Ta[i]), "Ad T_b = T_a: %g, %g", X[i], Ta[i]);
  return report("test_spatial");
}

/* Shared pieces of the unit tests of the stepper's plain C (templates/c/runtime/) on
 * hand-written kernels: the checks of check.h, the declarations of stepper_decls.h, and the
 * helpers every test model's kernels share.  Each test program defines its model's sizes
 * and hand-written kernels (no CasADi), then includes the runtime files. */
#include "check.h"
#include "stepper_decls.h"

/* NULL inputs read as zeros (CasADi's convention). */
static casadi_real at(const casadi_real *x, int i) {
  return x ? x[i] : 0;
}

/* Work sizes of every test kernel: nine inputs, three outputs at most, no work arrays. */
static int test_work(casadi_int *sz_arg, casadi_int *sz_res, casadi_int *sz_iw, casadi_int *sz_w) {
  *sz_arg = 9;
  *sz_res = 3;
  *sz_iw = 0;
  *sz_w = 1;
  return 0;
}
#define KERNEL_WORKS test_work

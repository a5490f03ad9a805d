/* Shared pieces of the unit tests of the stepper's plain C (templates/c/runtime/): the
 * CasADi types and calling convention the runtime expects, the checks of check.h, and the
 * contract macros every test model shares.  Each test program defines its model's sizes
 * and hand-written kernels (no CasADi), then includes the runtime files. */
#include "check.h"

typedef double casadi_real;
typedef long long casadi_int;

#define STEP_OK 0
#define STEP_NO_CONVERGENCE 1
#define STEP_NOT_FINITE 2
#define STEP_VELOCITY 3
#define STEP_KERNEL 4
#define STEP_BAD_INPUT 5
#define STEP_TOO_MANY_STEPS 6
#define STEP_TOO_SMALL 7
#define STEP_INTERRUPTED 8
#define SCHEME_RATTLE4 1

typedef struct {
  casadi_real tol;
  int max_iter;
  int max_halvings;
  int scheme;
  volatile int *stop;
} step_options;

static step_options test_default_options(void) {
  step_options o;
  o.tol = 1e-10;
  o.max_iter = 12;
  o.max_halvings = 4;
  o.scheme = 0;
  o.stop = 0;
  return o;
}
#define DEFAULT_OPTIONS test_default_options

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

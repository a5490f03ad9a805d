/* What the stepper's plain C (templates/c/runtime/) expects its glue to declare, as
 * templates/c/stepper.c.j2 does for a model: the CasADi types, the status codes, the
 * schemes, step_options and its defaults.  Declarations only (no function), so that every
 * unit test can include it whichever runtime files it tests; harness.h adds the helpers of
 * the tests on hand-written kernels. */
#ifndef TESTS_C_STEPPER_DECLS_H
#define TESTS_C_STEPPER_DECLS_H

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

/* The options of a run (simulate_adaptive(); fixed steps: track_work, estimate), as <model>_run_options. */
typedef struct {
  casadi_real rtol;
  casadi_real atol;
  casadi_real h0;
  int extrapolate;
  long max_steps;
  int hold_linear;
  int track_work;
  int estimate;
} run_options;

/* run_options of rtol, atol, h0, extrapolate, max_steps, track_work (inputs held). */
#define RUN_OPTIONS(rtol_, atol_, h0_, extrapolate_, max_steps_, track_work_) \
  ((run_options){.rtol = (rtol_), .atol = (atol_), .h0 = (h0_), .extrapolate = (extrapolate_), \
                 .max_steps = (max_steps_), .hold_linear = 0, .track_work = (track_work_), .estimate = 0})

/* run_options of a fixed-step run (run_fixed()): its error estimate (ESTIMATE_*) and whether it tracks the work. */
#define FIXED_RUN(estimate_, track_work_) \
  ((run_options){.rtol = 0, .atol = 0, .h0 = 0, .extrapolate = 0, .max_steps = 0, .hold_linear = 0, \
                 .track_work = (track_work_), .estimate = (estimate_)})

/* The default step_options: Newton to 1e-10 in at most 12 iterations, at most 4 halvings of
 * a step, plain RATTLE, no stop flag. */
#define DEFAULT_OPTIONS() \
  ((step_options){.tol = 1e-10, .max_iter = 12, .max_halvings = 4, .scheme = 0, .stop = 0})

#endif

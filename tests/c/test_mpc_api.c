/* The exported MPC's C API (templates/c/mpc/) called from C with bad and good input: a null
 * pointer, a non-finite state or time, a negative iteration count are refused with
 * CARTPOLE_MPC_BAD_INPUT before any work, leave the controller as it was, and never poison
 * later steps (the inputs after the refused calls are bit-identical to a controller that
 * never saw them).  Built against an exported cart-pole package (tests/test_reliability_mpc.py)
 * under AddressSanitizer and UndefinedBehaviorSanitizer.
 *
 *     ./test_mpc_api x_1 ... x_16     (a consistent state of the cart-pole at rest)
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cartpole.h"

#define NX CARTPOLE_MPC_NX
#define NU CARTPOLE_MPC_NU

static int checks, failures;

static void check(int ok, const char* what) {
    ++checks;
    if (!ok) {
        ++failures;
        fprintf(stderr, "FAILED: %s\n", what);
    }
}

static int finite(const casadi_real* v, int n) {
    for (int i = 0; i < n; ++i) if (!isfinite(v[i])) return 0;
    return 1;
}

int main(int argc, char** argv) {
    static cartpole_mpc m, reference, fresh;
    casadi_real x[NX], bad[NX], u[NU], u_ref[NU], x1[NX];
    const casadi_real specials[3] = { NAN, INFINITY, -INFINITY };
    if (argc != 1 + NX) {
        fprintf(stderr, "usage: %s x_1 ... x_%d\n", argv[0], NX);
        return 2;
    }
    for (int i = 0; i < NX; ++i) x[i] = strtod(argv[1 + i], NULL);

    /* init: every bad argument refused, the struct untouched */
    memset(&fresh, 0x5a, sizeof fresh);
    memcpy(&m, &fresh, sizeof m);
    for (int s = 0; s < 3; ++s) {
        for (int i = 0; i < NX; i += 5) {
            memcpy(bad, x, sizeof x);
            bad[i] = specials[s];
            check(cartpole_mpc_init(&m, bad, 0.0, 10) == CARTPOLE_MPC_BAD_INPUT, "init: non-finite x refused");
        }
        check(cartpole_mpc_init(&m, x, specials[s], 10) == CARTPOLE_MPC_BAD_INPUT, "init: non-finite t refused");
    }
    check(cartpole_mpc_init(&m, x, 0.0, -1) == CARTPOLE_MPC_BAD_INPUT, "init: iterations < 0 refused");
    check(cartpole_mpc_init(NULL, x, 0.0, 10) == CARTPOLE_MPC_BAD_INPUT, "init: null controller refused");
    check(cartpole_mpc_init(&m, NULL, 0.0, 10) == CARTPOLE_MPC_BAD_INPUT, "init: null state refused");
    check(memcmp(&m, &fresh, sizeof m) == 0, "init: a refused call leaves the controller untouched");

    /* after the refused inits, a good init; the reference never sees bad input */
    check(cartpole_mpc_init(&m, x, 0.0, 10) == CARTPOLE_MPC_OK, "init from a good state succeeds");
    check(cartpole_mpc_init(&reference, x, 0.0, 10) == CARTPOLE_MPC_OK, "reference init succeeds");

    for (int k = 0; k < 5; ++k) {
        casadi_real t = k * CARTPOLE_MPC_H;
        /* bad measurements between good ones: refused, u_out and the guess untouched */
        for (int s = 0; s < 3; ++s) {
            memcpy(bad, x, sizeof x);
            bad[(k * 3 + s) % NX] = specials[s];
            for (int i = 0; i < NU; ++i) u[i] = 12345.0;
            check(cartpole_mpc_step(&m, bad, t, u) == CARTPOLE_MPC_BAD_INPUT, "step: non-finite x refused");
            check(cartpole_mpc_step(&m, x, specials[s], u) == CARTPOLE_MPC_BAD_INPUT, "step: non-finite t refused");
            check(u[0] == 12345.0, "step: a refused call leaves u_out untouched");
        }
        check(cartpole_mpc_step(&m, x, t, NULL) == CARTPOLE_MPC_BAD_INPUT, "step: null u_out refused");
        check(cartpole_mpc_step(NULL, x, t, u) == CARTPOLE_MPC_BAD_INPUT, "step: null controller refused");
        check(cartpole_mpc_step(&m, NULL, t, u) == CARTPOLE_MPC_BAD_INPUT, "step: null state refused");
        /* the good step answers exactly as the controller that saw only good input */
        check(cartpole_mpc_step(&m, x, t, u) == CARTPOLE_MPC_OK, "step from a good state succeeds");
        check(cartpole_mpc_step(&reference, x, t, u_ref) == CARTPOLE_MPC_OK, "reference step succeeds");
        check(finite(u, NU) && memcmp(u, u_ref, sizeof u) == 0, "no poisoning: u equals the reference's bit for bit");
        check(k > 0 || fabs(u[0]) > 1e-3, "the controller acts on the tilted pole");
        /* the plant: bad input refused, good input steps */
        memcpy(bad, x, sizeof x);
        bad[k] = NAN;
        check(cartpole_plant(bad, u, t, x1) == 2, "plant: non-finite x refused");
        u_ref[0] = INFINITY;
        check(cartpole_plant(x, u_ref, t, x1) == 2, "plant: non-finite u refused");
        check(cartpole_plant(x, u, NAN, x1) == 2, "plant: non-finite t refused");
        for (int s = 0; s < CARTPOLE_PLANT_SUBSTEPS; ++s) {
            check(cartpole_plant(x, u, t + s * (CARTPOLE_MPC_H / CARTPOLE_PLANT_SUBSTEPS), x) == 0, "plant step succeeds");
        }
        check(finite(x, NX), "plant state finite");
    }
    cartpole_mpc_free(&m);
    cartpole_mpc_free(&reference);
    if (failures) {
        fprintf(stderr, "%d of %d checks failed\n", failures, checks);
        return 1;
    }
    printf("all %d checks passed\n", checks);
    return 0;
}

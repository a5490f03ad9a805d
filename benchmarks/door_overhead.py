"""Every door of issue 37's first deliverable against its kernel alone in a C loop: the cost
of a call from Python above the compiled work (target: about 1 µs).

Doors, each at one state with fresh outputs and with ``out=``, and the tree algorithms also
over rows of states in one call (``--rows``, default 100):

* the UR10 of example-robot-data (fixed base, 6 joints): ``nc.rnea``, ``nc.aba``, ``nc.crba``,
  ``nc.rnea_derivatives``, ``nc.aba_derivatives``, ``nc.inverse_dynamics``,
  ``nc.joint_forward_dynamics``; ``nc.JointStep(model, h)`` called (its kernel: ABA) and its
  ``.jacobians`` (its kernels: the ABA derivatives and the step's assembly, both timed);
* the chain of ``examples/chain.toml`` (5 bars, natural coordinates): ``nc.forward_dynamics(...,
  backend="compiled")`` (its kernel: the KKT solve), ``nc.step_function(model, h)`` called and
  its ``.jacobians`` (the table stepper's step, with and without Jacobians, called by a C loop).

Per door, in ``--rounds`` interleaved rounds: a batch of ``--calls`` calls of the door
(``time.process_time``), then the kernel alone in a C loop of as many calls
(``benchmarks/kernel_alone.py``; the table step through its own C signature), on the same
buffers with the same inputs as the door's last call.  Printed: the door's CPU µs per call
and the kernel's ns per call (min and median over the rounds), and ``OVERHEAD`` = door −
kernel alone per round (min and median of the rounds' differences; per state for rows).  CPU model and load
average are printed before and after: the figures are CPU times, but a shared machine's caches
and frequency still move them.

    python benchmarks/door_overhead.py [--calls 2000] [--rounds 9] [--rows 100] [--smoke]
"""
from __future__ import annotations

import argparse
import ctypes
import os
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))

from common import machine, terminal_sigint  # noqa: E402
from kernel_alone import _built, kernel_ns  # noqa: E402

terminal_sigint()

UR10 = "ur_description/urdf/ur10_robot.urdf"

#: A C loop of the table stepper's ``ncgen_elements_step_jacobians`` (``ncgen/runtime/table_step.py``'s signature).
STEP_LOOP = r"""
#include <time.h>
typedef int (*step_fn)(const void *, const double *, const double *, double, const double *, const double *, double,
                       const void *, const int *, const int *, const double *, double *, double *, double *, double *,
                       double *, int *);
static double now(void) { struct timespec t; clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t); return t.tv_sec + 1e-9 * t.tv_nsec; }
double ncgen_step_seconds(void *fn, const void *S, const double *q, const double *v, double t, const double *u,
                          const double *p, double h, const void *opt, const int *ci, const int *row, const double *val,
                          double *q1, double *v1, double *Jx, double *Ju, double *res, int *it, long n) {
    double t0 = now();
    for (long i = 0; i < n; i++)
        if (((step_fn)fn)(S, q, v, t, u, p, h, opt, ci, row, val, q1, v1, Jx, Ju, res, it)) return -1.0;
    return now() - t0;
}
"""


def step_ns(table, x: np.ndarray, u: np.ndarray, t: float, jacobians: bool, calls: int,
            rounds: int) -> tuple[float, float]:
    """``(min, median)`` CPU ns per call of the table step ``table`` (a
    :class:`~ncgen.runtime.table_step.TableStep`) at ``(x, u, t)`` in a C loop."""
    lib = ctypes.CDLL(str(_built(STEP_LOOP, ".so", lambda s, o: ["cc", "-O2", "-shared", "-fPIC", s, "-o", o])))
    f = lib.ncgen_step_seconds
    f.restype = ctypes.c_double
    V = ctypes.c_void_p
    f.argtypes = [V, V, V, V, ctypes.c_double, V, V, ctypes.c_double, V, V, V, V, V, V, V, V, V, V, ctypes.c_long]
    x = np.ascontiguousarray(x, dtype=float)
    u = np.ascontiguousarray(u, dtype=float) if table.nu else table._p
    fn = ctypes.cast(table._fn, ctypes.c_void_p).value
    jac = table._jac if jacobians else (None, None)
    times = []
    for _ in range(rounds):
        s = f(fn, table._S, x.ctypes.data, x.ctypes.data + 8 * table.nq, float(t), u.ctypes.data, table._p_at, table.h,
              table._opt, *table._fixed, *jac, *table._out, calls)
        if s < 0:
            raise RuntimeError("the table step returned an error in the C loop")
        times.append(s / calls * 1e9)
    return min(times), float(np.median(times))


def interleaved(f, kernel, rows: int, calls: int, rounds: int) -> dict:
    """Rounds of a batch of ``calls`` calls of the door ``f`` (``rows`` states a call) and of
    ``kernel`` alone (``calls * rows`` calls in C): CPU µs per call of the door, ns per call of
    the kernel and the door's overhead per state, µs, each as ``(min, median)`` over the rounds."""
    for _ in range(max(1, calls // 10)):
        f()
    door, alone, over = [], [], []
    for _ in range(rounds):
        t = time.process_time()
        for _ in range(calls):
            f()
        d = (time.process_time() - t) / calls * 1e6
        k = kernel(max(calls * rows, 200), 1)[0]
        door.append(d)
        alone.append(k)
        over.append(d / rows - k / 1e3)
    stat = lambda x: (min(x), float(np.median(x)))      # noqa: E731
    return {"door": stat(door), "kernel": stat(alone), "overhead": stat(over)}


def tree_doors(rows: int):
    """``[(label, door, kernel timer, states per call)]`` on the UR10 (module docstring).  A
    kernel timer is ``timer(calls, rounds) -> (min, median) ns`` of one state's kernel."""
    import importlib.metadata as md

    import ncgen as nc
    from ncgen.control import joint_step
    from ncgen.runtime.tree_algorithm_kernels import door

    path = next(f.locate() for f in md.files("example-robot-data") if str(f).endswith(UR10))
    model = nc.System.from_urdf(Path(path).read_text()).build()
    n = model.joint_space.nv
    rng = np.random.default_rng(0)
    q, v, a, tau = (rng.uniform(-1, 1, n) for _ in range(4))
    Q, V, A, T = (np.tile(x, (rows, 1)) for x in (q, v, a, tau))
    args = {"rnea": (q, v, a), "aba": (q, v, tau), "crba": (q,), "rnea_derivatives": (q, v, a),
            "aba_derivatives": (q, v, tau)}
    out = []

    def alone(k):
        direct = getattr(k, "direct", None) or k._shim
        return lambda calls, rounds: kernel_ns(direct, calls, rounds)

    for name, xs in args.items():
        f = getattr(nc, name)
        fresh = f(model, *xs)
        buffers = tuple(np.empty(np.shape(o)) for o in fresh) if isinstance(fresh, tuple) else np.empty(fresh.shape)
        batch = f(model, *(np.tile(x, (rows, 1)) for x in xs))
        bbuf = tuple(np.empty(np.shape(o)) for o in batch) if isinstance(batch, tuple) else np.empty(batch.shape)
        k = alone(door(model, name).kernel)
        big = tuple(np.tile(x, (rows, 1)) for x in xs)
        out += [(f"nc.{name}", lambda f=f, xs=xs: f(model, *xs), k, 1),
                (f"nc.{name}, out=", lambda f=f, xs=xs, b=buffers: f(model, *xs, out=b), k, 1),
                (f"nc.{name}, {rows} rows", lambda f=f, big=big: f(model, *big), k, rows),
                (f"nc.{name}, {rows} rows, out=", lambda f=f, big=big, b=bbuf: f(model, *big, out=b), k, rows)]
    rnea_k = alone(door(model, "rnea").kernel)
    tau_b = np.empty(n)
    out += [("nc.inverse_dynamics", lambda: nc.inverse_dynamics(model, q, v, a), rnea_k, 1),
            ("nc.inverse_dynamics, out=", lambda: nc.inverse_dynamics(model, q, v, a, out=tau_b), rnea_k, 1)]
    nc.joint_forward_dynamics(model, q, v, tau)
    fd_k = alone(model.data.tree_kernel)
    a_b = np.empty(n)
    out += [("nc.joint_forward_dynamics", lambda: nc.joint_forward_dynamics(model, q, v, tau), fd_k, 1),
            ("nc.joint_forward_dynamics, out=", lambda: nc.joint_forward_dynamics(model, q, v, tau, out=a_b), fd_k, 1)]
    st = nc.JointStep(model, 0.01)
    x = np.concatenate([q, v])
    st(x, tau)
    jac = st.jacobians(x, tau)
    jbuf = tuple(np.empty(np.shape(o)) for o in jac)
    assembly = joint_step._COMPILED[(n, os.environ.get("NCGEN_CFLAGS"))]
    aba_k, der_k = alone(st._aba), alone(st._derivatives)

    def call_alone(calls, rounds):
        st._aba(q, v, tau)                           # the kernel's inputs: this state
        return aba_k(calls, rounds)

    def jac_alone(calls, rounds):
        st._derivatives(q, v, tau)                   # the kernel's inputs: this state
        d, s = der_k(calls, rounds), kernel_ns(assembly, calls, rounds)
        return d[0] + s[0], d[1] + s[1]

    assembly.inputs[0][0] = st.h
    for i, o in enumerate(st._derivatives.direct.outputs[:4]):
        assembly.inputs[1 + i][:] = o
    assembly.inputs[5][:] = x
    out += [("JointStep call", lambda: st(x, tau), call_alone, 1),
            ("JointStep call, out=", lambda b=np.empty(2 * n): st(x, tau, out=b), call_alone, 1),
            ("JointStep.jacobians", lambda: st.jacobians(x, tau), jac_alone, 1),
            ("JointStep.jacobians, out=", lambda: st.jacobians(x, tau, out=jbuf), jac_alone, 1)]
    return out


def chain_doors():
    """``[(label, door, kernel timer, 1)]`` on the chain of examples/chain.toml (module docstring)."""
    import ncgen as nc
    from ncgen.runtime.dynamics_at_state import forward_dynamics_kernel

    model = nc.System.from_toml(HERE.parent / "examples" / "chain.toml").build()
    q, v = np.array(model.q0, dtype=float), np.array(model.v0, dtype=float)
    a, lam = nc.forward_dynamics(model, q, v, backend="compiled")
    fd = model.data.forward_dynamics_door.kernel if model.data.forward_dynamics_door else forward_dynamics_kernel(model)
    fd.inputs[1][:], fd.inputs[2][:] = q, v                     # the door's kernel at this state
    fd_buf = (np.empty_like(a), np.empty_like(lam))
    fd_k = lambda calls, rounds: kernel_ns(fd, calls, rounds)    # noqa: E731
    st = nc.step_function(model, 0.01)
    x = np.concatenate([q, v])
    u = np.zeros(model.nu)
    x1 = st(x, u)
    x1_b = np.empty_like(x1)
    jac_b = tuple(np.empty(np.shape(o)) for o in st.jacobians(x, u))
    out = [("nc.forward_dynamics compiled", lambda: nc.forward_dynamics(model, q, v, backend="compiled"), fd_k, 1),
           ("nc.forward_dynamics compiled, out=",
            lambda: nc.forward_dynamics(model, q, v, backend="compiled", out=fd_buf), fd_k, 1)]
    if st.kernels != "tables":
        raise RuntimeError(f"the chain's step runs on {st.kernels!r} kernels: this script times the tables' step")
    step_k = lambda calls, rounds: step_ns(st._table, x, u, model.t0, False, calls, rounds)      # noqa: E731
    jac_k = lambda calls, rounds: step_ns(st._table, x, u, model.t0, True, calls, rounds)       # noqa: E731
    out += [("StepFunction call (chain, tables)", lambda: st(x, u), step_k, 1),
            ("StepFunction call, out=", lambda: st(x, u, out=x1_b), step_k, 1),
            ("StepFunction.jacobians", lambda: st.jacobians(x, u), jac_k, 1),
            ("StepFunction.jacobians, out=", lambda: st.jacobians(x, u, out=jac_b), jac_k, 1)]
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--calls", type=int, default=2000, help="calls per timed batch of one state (default 2000)")
    ap.add_argument("--rounds", type=int, default=9, help="timed batches (default 9)")
    ap.add_argument("--rows", type=int, default=100, help="states per call of the batched doors (default 100)")
    ap.add_argument("--only", help="time only the doors whose label contains this text")
    ap.add_argument("--smoke", action="store_true", help="few calls, to check the script works")
    a = ap.parse_args(argv)
    if a.smoke:
        a.calls, a.rounds, a.rows = 20, 2, 4
    print(machine())
    print(f"load average: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    print(f"\n=== doors against their kernels alone in a C loop (CPU time; {a.calls} calls a batch, {a.rounds} "
          f"batches; UR10 and examples/chain.toml)")
    print(f"  {'door':<40} {'door µs min/med':>17} {'kernel ns min/med':>19} {'OVERHEAD µs min/med':>21}")
    for label, f, kernel, rows in [*tree_doors(a.rows), *chain_doors()]:
        if a.only and a.only not in label:
            continue
        f()
        r = interleaved(f, kernel, rows, max(2, a.calls // rows), a.rounds)
        (d0, d1), (k0, k1), (o0, o1) = r["door"], r["kernel"], r["overhead"]
        per = " per state" if rows > 1 else ""
        print(f"  {label:<40} {d0 / rows:8.2f} {d1 / rows:8.2f} {k0:9.0f} {k1:9.0f}   OVERHEAD {o0:6.2f} {o1:6.2f}{per}")
    print(f"\nload average at the end: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

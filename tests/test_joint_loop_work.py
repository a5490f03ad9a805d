"""The joint-space loops on memory kept between runs (issue 37): the tree library's loop on the
model's tables and the model's own compiled (flat) loop.  Each thread's work array
(``loop.work``, :class:`~ncgen.codegen.c_binding.ThreadWork`) is made once and reused, never
zeroed again, so a run must not depend on what an earlier run left in it.  Checked bit
for bit against the same run on fresh, zeroed memory (a new loop object: what a new process
allocates), after other runs (another state, length, tolerance and integrator) and on work
filled with NaN or huge values (a read of any stale value would show), and on two threads at
once (each its own array).  A tree with a free root (quaternions renormalised), a ball joint and
a mimic pair (the constrained forward dynamics' work); the runs' energy is conserved (the
independent check that they integrate the dynamics at all)."""
from __future__ import annotations

import os
import shutil
import threading

import numpy as np
import pytest

import ncgen as nc
from ncgen.codegen.compiler import CANDIDATES
from ncgen.codegen.joint_loop import joint_options, run_options
from ncgen.runtime.joint_simulation import JointLoop, joint_loop
from ncgen.runtime.tree_library import TableJointLoop

pytestmark = pytest.mark.skipif(not any(shutil.which(c) for c in CANDIDATES) and not os.environ.get("CC"),
                                reason="no C compiler to build the tree library")


@pytest.fixture(scope="module")
def model():
    """A free body, a hinge, a ball joint and two hinges coupled by a mimic joint."""
    s = nc.System("loop_work_tree", gravity=(0.3, 0.0, -9.81))
    b = [s.add_body(f"b{k}", mass=1.0 + 0.2 * k, inertia=np.diag([0.1, 0.2, 0.25]) * (1 + 0.1 * k),
                    position=(k + 0.5, 0.1 * k, 0.0)) for k in range(5)]
    s.add_joint(nc.Free(s.ground, b[0], at=(0.5, 0.0, 0.0), rotation=np.eye(3), name="root"))
    s.add_joint(nc.Revolute(b[0], b[1], at=(1.0, 0.0, 0.0), axis=(0.0, 0.6, 0.8), name="hinge"))
    s.add_joint(nc.Spherical(b[1], b[2], at=(2.0, 0.1, 0.0), name="ball"))
    j1 = s.add_joint(nc.Revolute(b[2], b[3], at=(3.0, 0.2, 0.0), axis=(0.0, 0.0, 1.0), name="f1"))
    j2 = s.add_joint(nc.Revolute(b[2], b[4], at=(4.0, 0.3, 0.0), axis=(1.0, 0.0, 0.0), name="f2"))
    s.add_joint(nc.Mimic(j1, j2, multiplier=-2.0, offset=0.1, name="link"))
    return s.build(assemble=True)


def start(model, k: int) -> np.ndarray:
    """Joint state k: the built pose moved by random joint coordinates, random joint rates."""
    rng = np.random.default_rng(k)
    qj, vj = model.to_joint_space(model.q0, np.zeros(len(model.q0)))
    return np.concatenate([qj + 0.3 * rng.standard_normal(qj.size), rng.standard_normal(vj.size)])


def run(loop, model, x0, t_end: float, n: int, integrator: str, tol: float):
    """``(X, stats, status)`` of one run of ``loop`` over n output intervals up to ``t_end``."""
    t = np.linspace(0.0, t_end, n + 1)
    X = np.zeros((n + 1, x0.size))
    X[0] = x0
    stats = np.zeros(5)
    options = run_options(joint_options(integrator, tol, tol, 4, 100_000), False)
    status, done = loop.run(options, t, X, np.zeros((n, model.nu)), None, model.p0, stats)
    assert (status, done) == (0, n)
    return X, stats


#: The loops: the tables' (the tree library, compiled once for every model) and the model's own
#: (its ODE compiled with the loop: slow on a fresh cache).
KERNELS = ["tables", pytest.param("flat", marks=pytest.mark.slow)]


def fresh_loop(model, kernels: str):
    """A new loop object of ``model`` with the kernels ``kernels`` (its work not made yet: zeroed
    at its first run, as a new process's), beside the one the model keeps."""
    if kernels == "tables":
        return TableJointLoop(model)
    kept = joint_loop(model, kernels="flat")
    return JointLoop(model, kept.library, kept.ode, f"{model.name}_jsim")


@pytest.mark.parametrize("kernels", KERNELS)
def test_a_run_after_other_runs_equals_a_run_on_fresh_memory(model, kernels):
    """The same run on fresh zeroed work, after other runs on kept work, and on work filled
    with NaN or 1e300: bit-equal states and statistics; ``nc.simulate`` on the model's own
    loop the same after those runs, conserving energy."""
    case = (start(model, 1), 0.3, 6, "dopri5", 1e-6)
    fresh = run(fresh_loop(model, kernels), model, *case)
    loop = joint_loop(model, kernels=kernels)
    fall = lambda: nc.simulate(model, 0.3, 0.05, method="joint", kernels=kernels, rtol=1e-9, atol=1e-9)
    first = fall()
    run(loop, model, start(model, 2), 0.5, 3, "rk4", 0.0)
    run(loop, model, start(model, 3), 0.05, 1, "dopri5", 1e-3)
    after = run(loop, model, *case)
    work = loop.work.array
    for stale in (np.nan, 1e300):
        work[:] = stale
        again = run(loop, model, *case)
        for a, b in zip(again, fresh):
            assert np.array_equal(a, b), f"a run on work filled with {stale} differs from fresh memory"
    for a, b in zip(after, fresh):
        assert np.array_equal(a, b), "a run after other runs differs from fresh memory"
    assert fresh[1][0] > 5 and np.all(np.isfinite(fresh[0]))
    later = fall()
    assert np.array_equal(later.qj, first.qj) and np.array_equal(later.vj, first.vj)
    assert first.info["kernels"] == kernels and np.ptp(first.qj, axis=0).max() > 0.1
    assert first.energy_drift <= 1e-6 * max(1.0, first.energy_scale)


@pytest.mark.parametrize("kernels", KERNELS)
def test_runs_on_two_threads_have_their_own_work(model, kernels):
    """Runs of one loop on two threads at once (other starts, other lengths) equal the same
    runs one after the other bit for bit; each thread has its own work array (each kept by the
    test, so that a thread's end cannot free its array for the other's to take the address)."""
    loop = fresh_loop(model, kernels)
    cases = {i: [(start(model, 10 * i + k), 0.1 + 0.05 * k, 2 + k, "dopri5", 1e-7) for k in range(6)]
             for i in range(2)}
    serial = {i: [run(loop, model, *c) for c in cs] for i, cs in cases.items()}
    threaded, works, barrier = {}, {}, threading.Barrier(2)

    def worker(i):
        barrier.wait()
        threaded[i] = [run(loop, model, *c) for c in cases[i] for _ in range(3)][::3]
        works[i] = loop.work.array
    threads = [threading.Thread(target=worker, args=(i,)) for i in range(2)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    addresses = {w.ctypes.data for w in works.values()}
    assert len(addresses) == 2 and loop.work.address not in addresses
    for i in range(2):
        for (Xa, sa), (Xb, sb) in zip(threaded[i], serial[i]):
            assert np.array_equal(Xa, Xb) and np.array_equal(sa, sb)

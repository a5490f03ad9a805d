"""``nc.simulate``'s fixed cost on a tree (issue 37): what depends only on the model and the
options is done once per model (a second run redoes none of it: calls counted), the run's
start calls no CasADi virtual machine and starts no thread, the derived outputs are computed
on first access and equal the model's functions evaluated row by row, and a failing run still
fails at ``simulate``.  Ctrl-C through the watcher thread (:func:`ncgen.interrupts.call_interruptibly`):
in-process here, in a child process stopped in a long C loop in tests/test_stepper_interrupt.py."""
from __future__ import annotations

import ctypes
import os
import pickle
import signal
import threading
import time

import casadi as ca
import numpy as np
import pytest

import ncgen as nc
import ncgen.codegen.compiler as compiler
import ncgen.codegen.joint_loop as joint_loop_module
import ncgen.codegen.model_cache as model_cache
import ncgen.model.buffered_call as buffered_call
import ncgen.runtime.joint_loop_options as joint_loop_options
import ncgen.runtime.joint_simulation as js_module
import ncgen.runtime.tree_library as tree_library
from ncgen.errors import SimulationError
from ncgen.interrupts import call_interruptibly, raise_if_interrupted, sticky_interrupt

DERIVED = ("q", "v", "lam", "u", "kinetic", "potential", "constraint_residual", "velocity_residual", "markers")


def spatial_chain() -> nc.Model:
    """Three rigid links on revolute joints about three different axes (a 3D tree the tree
    tables cover), with a marker on the last link."""
    s = nc.System("chain3", gravity=(0.0, 0.0, -9.81))
    parent, at = s.ground, np.zeros(3)
    for k, axis in enumerate(((0, 0, 1), (0, 1, 0), (1, 0, 0))):
        b = s.add_body(f"l{k}", mass=1.0 + 0.3 * k, inertia=np.diag([0.02, 0.03, 0.025 + 0.01 * k]),
                       position=at + (0.25, 0.05 * k, 0.0))
        s.add_joint(nc.Revolute(parent, b, at=tuple(at), axis=axis, name=f"j{k}"))
        parent, at = b, at + (0.5, 0.1 * k, 0.0)
    parent.add_marker("tip", (0.25, 0.0, 0.0))
    return s.build()


@pytest.fixture(scope="module")
def chain():
    model = spatial_chain()
    q0, v0 = model.from_joint_space(np.array([0.3, -0.7, 1.1]), np.array([1.5, -0.4, 2.0]))
    return model, q0, v0


def test_derived_outputs_are_lazy_and_equal_eager_and_the_model_functions_row_by_row(chain):
    """A joint-space run computes no derived output before it is read; read one by one (lazy)
    they equal the arrays a pickle computes all at once (eager), bit for bit, and each equals
    the model's own functions called row by row on the joint states: the natural state from
    ``from_joint_space``, the multipliers from ``accel``, ``T = ½ vᵀ M v``, the drift from
    ``phi`` and ``A``, the energy constant (no forces but gravity) to the run's tolerance."""
    model, q0, v0 = chain
    run = lambda: nc.simulate(model, 0.5, 0.05, q0=q0, v0=v0, method="joint", rtol=1e-10, atol=1e-12)  # noqa: E731
    lazy, eager = run(), pickle.loads(pickle.dumps(run()))
    assert not any(isinstance(lazy._arrays.get(k), np.ndarray) for k in DERIVED)     # none computed yet
    for key in reversed(DERIVED):
        np.testing.assert_array_equal(getattr(lazy, key), getattr(eager, key), err_msg=key)
    np.testing.assert_array_equal(lazy.qj, eager.qj)
    for k in range(len(lazy)):
        q, v = model.from_joint_space(lazy.qj[k], lazy.vj[k])
        np.testing.assert_allclose(lazy.q[k], q, rtol=0, atol=1e-12)
        np.testing.assert_allclose(lazy.v[k], v, rtol=0, atol=1e-12)
        np.testing.assert_allclose(lazy.lam[k], model.accel(q, v, t=lazy.t[k])[1], rtol=1e-10, atol=1e-9)
        assert lazy.kinetic[k] == pytest.approx(0.5 * v @ np.asarray(model.M) @ v, rel=1e-12, abs=1e-12)
        assert lazy.constraint_residual[k] == pytest.approx(np.abs(model.phi(q)).max(), abs=1e-15)
        assert lazy.velocity_residual[k] == pytest.approx(np.abs(model.A(q) @ v).max(), abs=1e-14)
    assert lazy.energy_drift <= 1e-8 * lazy.energy_scale


def _count(monkeypatch, module, name: str, calls: dict) -> None:
    f = getattr(module, name)

    def counted(*args, **kwargs):
        calls[name] = calls.get(name, 0) + 1
        return f(*args, **kwargs)
    monkeypatch.setattr(module, name, counted)


def test_a_second_run_redoes_nothing_that_depends_on_the_model_alone(chain, monkeypatch):
    """The kernel choice's inputs (the tree tables' kinds and input map, the tree library's units
    on disk, the model's own loop on disk, the compiler), the buffered functions of the start
    and the C options are found at the first run; a second run calls none of them, calls
    CasADi's virtual machine zero times and starts no thread (Ctrl-C is watched by one thread
    per process)."""
    model, q0, v0 = chain
    calls: dict = {}
    for module, name in ((js_module, "input_efforts"), (js_module, "tree_tables"), (tree_library, "missing_units"),
                         (model_cache, "stored_function"),
                         (joint_loop_module, "cached_joint_loop"), (buffered_call, "BufferedFunction"),
                         (compiler.shutil, "which"), (joint_loop_options, "joint_options")):
        _count(monkeypatch, module, name, calls)
    fresh = spatial_chain()                      # nothing cached for it yet
    first = nc.simulate(fresh, 1e-3, 1e-3, q0=q0, v0=v0, method="joint", rtol=1e-6, atol=1e-6)
    assert first.info["kernels"] == "tables"
    assert calls.get("input_efforts", 0) >= 1 and calls.get("BufferedFunction", 0) >= 1     # the start check
    calls.clear()
    vm, threads = [0], [0]
    call, start = ca.Function.call, threading.Thread.start

    def vm_call(self, *args, **kwargs):
        vm[0] += 1
        return call(self, *args, **kwargs)

    def thread_start(self):
        threads[0] += 1
        return start(self)
    monkeypatch.setattr(ca.Function, "call", vm_call)
    monkeypatch.setattr(threading.Thread, "start", thread_start)
    second = nc.simulate(fresh, 1e-3, 1e-3, q0=q0, v0=v0, method="joint", rtol=1e-6, atol=1e-6)
    assert calls == {} and vm[0] == 0 and threads[0] == 0
    np.testing.assert_array_equal(second.qj, first.qj)
    assert second.info["kernels"] == "tables"
    second.q                                     # the outputs, on first access, are the VM's
    assert vm[0] >= 1


def test_a_run_that_fails_still_fails_at_simulate(chain):
    """The loop's failures are raised by ``simulate`` itself (the outputs are lazy, the checks
    are not): too few steps allowed raises :class:`SimulationError` with the rows reached, whose
    derived outputs then compute."""
    model, q0, v0 = chain
    with pytest.raises(SimulationError, match="more than max_steps") as e:
        nc.simulate(model, 0.5, 0.25, q0=q0, v0=v0, method="joint", rtol=1e-12, atol=1e-12, max_steps=2)
    part = e.value.trajectory
    assert not part.complete and len(part) >= 1 and part.q.shape == (len(part), model.nq)


def _holds_by_numpy(model, q, v) -> bool:
    """The start's acceptance rule written again from the model's own ``phi`` and ``A`` (no
    drives, no time dependence: ``Φ_t = 0``) in NumPy: finite, of magnitude at most
    ``MAX_MAGNITUDE``, ``|Φ|∞ ≤ TOL s²`` and ``|A v|∞ ≤ 1e-10 s (1 + |v|∞)``, ``s = max(1, |q|∞)``."""
    from ncgen.assembly.manifold import NEWTON_TOL
    from ncgen.validation import MAX_MAGNITUDE

    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(v))):
        return False
    if max(np.abs(q).max(), np.abs(v).max()) > MAX_MAGNITUDE:
        return False
    s = max(1.0, np.abs(q).max())
    phi = np.abs(np.asarray(model.phi(q), float)).max()
    vel = np.abs(np.asarray(model.A(q), float) @ v).max()
    return bool(phi <= NEWTON_TOL * s**2 and vel <= 1e-10 * s * (1.0 + np.abs(v).max()))


def test_the_start_check_decides_as_the_model_functions_do(chain):
    """``JointSpace._holds`` (one call of ``state_check_function``) accepts exactly the states
    the rule written again in NumPy on ``model.phi`` and ``model.A`` accepts: consistent states,
    states moved off either constraint level, a NaN or an infinity in any entry of q or v (which
    CasADi's ``norm_inf`` alone would skip), a magnitude above the limit; ``_checked_state`` (the
    joint run's start: the check and the joint state in one call) decides the same and maps as
    ``JointSpace.state``."""
    model, q0, v0 = chain
    js = model.joint_space
    rng = np.random.default_rng(37)
    states = [(q0, v0), (q0, np.zeros(model.nq))]
    for k in range(4):
        q, v = model.from_joint_space(rng.uniform(-2, 2, 3), rng.uniform(-3, 3, 3))
        states += [(q, v), (q + 1e-6 * rng.standard_normal(model.nq), v), (q, v + 1e-6 * rng.standard_normal(model.nq))]
        for bad in (np.nan, np.inf, -np.inf, 1e101):
            for which in ("q", "v"):
                x = (q if which == "q" else v).copy()
                x[rng.integers(model.nq)] = bad
                states.append((x, v) if which == "q" else (q, x))
    verdicts = [js._holds(model, q, v, model.t0, model.p0) for q, v in states]
    assert verdicts == [_holds_by_numpy(model, q, v) for q, v in states]
    assert sum(verdicts) == 6                    # the six consistent states, none of the others
    for (q, v), holds in zip(states, verdicts):  # a joint run's start: the same verdict and js.state's values
        state = js._checked_state(model, q, v, model.t0, model.p0)
        assert (state is not None) == holds
        if holds:
            for got, want in zip(state, js.state(model, q, v)):
                np.testing.assert_array_equal(got, want)


def test_a_non_finite_q0_or_v0_is_refused_naming_it_and_the_fast_start_runs_as_the_checked_one(chain, monkeypatch):
    """q0 or v0 given as float64 arrays take the fast start (one C call decides, no Python check
    called: counted); a NaN, an infinity or a huge entry is still refused with the argument
    named, as through the checked path (q0 given as a list); a consistent start gives bit-equal
    trajectories both ways, and so does a start off the constraints (both project it the same way)."""
    import ncgen.runtime.run_start as run_start

    model, q0, v0 = chain
    calls: dict = {}
    _count(monkeypatch, run_start, "as_vector", calls)
    nc.simulate(model, 1e-3, 1e-3, q0=q0, v0=v0, method="joint")
    assert calls == {}
    nc.simulate(model, 1e-3, 1e-3, q0=list(q0), v0=v0, method="joint")
    assert calls == {"as_vector": 2}
    for name, bad in (("q0", np.nan), ("v0", np.inf), ("q0", 1e200)):
        for form in (np.array, list):
            q, v = q0.copy(), v0.copy()
            (q if name == "q0" else v)[1] = bad
            with pytest.raises(nc.NcgenError, match=f"^{name}: expected") as e:
                nc.simulate(model, 1e-3, 1e-3, q0=form(q), v0=form(v), method="joint")
            assert name in str(e.value)
    for q in (q0, q0 + 1e-7):                    # consistent; off Φ = 0 (projected)
        fast = nc.simulate(model, 0.1, 0.05, q0=q, v0=v0, method="joint", rtol=1e-8, atol=1e-10)
        checked = nc.simulate(model, 0.1, 0.05, q0=list(q), v0=list(v0), method="joint", rtol=1e-8, atol=1e-10)
        for key in ("t", "qj", "vj", "q", "v", "lam", "kinetic", "markers"):
            np.testing.assert_array_equal(getattr(fast, key), getattr(checked, key), err_msg=key)


def test_a_start_that_held_is_kept_by_its_bytes_and_a_changed_or_bad_start_is_checked_again(chain, monkeypatch):
    """The joint run's start check: a start that held is answered from the kept starts (no
    VM call: counted) with the values the call gave (copies: editing them changes nothing
    kept); the same array edited in place (other bytes) is checked again — off the
    constraints by 0.5 m it is refused by ``simulate`` naming the initial state — and so is
    a NaN, every time (never kept); at most ``KEPT_STARTS`` starts are kept per model."""
    from ncgen.assembly.joint_space import KEPT_STARTS

    model = spatial_chain()
    js = model.joint_space
    q0, v0 = model.from_joint_space(np.array([0.2, 0.4, -0.9]), np.array([0.3, 1.1, -0.5]))
    calls = [0]
    call = buffered_call.BufferedFunction.call

    def counted(self, *args):
        calls[0] += self.f.name() == "start_check"
        return call(self, *args)
    monkeypatch.setattr(buffered_call.BufferedFunction, "call", counted)
    first = js._checked_state(model, q0, v0, model.t0, model.p0)
    assert calls[0] == 1
    first[0][:] = 99.0                            # the caller's copy
    again = js._checked_state(model, q0.copy(), v0.copy(), model.t0, model.p0)
    assert calls[0] == 1
    for got, want in zip(again, js.state(model, q0, v0)):
        np.testing.assert_array_equal(got, want)
    run = nc.simulate(model, 0.1, 0.05, q0=q0, v0=v0, method="joint")
    assert calls[0] == 1 and run.complete
    q0[1] += 0.5                                  # the same array, now off Φ = 0
    with pytest.raises(nc.NcgenError, match="initial state of 'chain3'"):
        nc.simulate(model, 0.1, 0.05, q0=q0, v0=v0, method="joint")
    assert calls[0] == 2
    q0[1] = np.nan
    for _ in range(2):
        with pytest.raises(nc.NcgenError, match="^q0: expected"):
            nc.simulate(model, 0.1, 0.05, q0=q0, v0=v0, method="joint")
    assert calls[0] == 4
    starts = js_module.model_data(model).checked_starts
    for k in range(KEPT_STARTS + 3):
        q, v = model.from_joint_space(np.array([0.01 * k, 0.0, 0.0]), np.zeros(3))
        assert js._checked_state(model, q, v, model.t0, model.p0) is not None
        assert 1 <= len(starts) <= KEPT_STARTS


def test_the_trajectory_names_are_its_own_lists_also_after_a_pickle(chain):
    """A run's lists of names (copied on first read) equal the model's and are each run's own:
    editing one run's list changes no other run's, nor a pickled copy's."""
    model, q0, v0 = chain
    a, b = (nc.simulate(model, 0.01, 0.01, q0=q0, v0=v0, method="joint") for _ in range(2))
    assert a.coordinate_names == list(model.coordinate_names) and a.joint_names == list(model.joint_space.joint_names)
    assert a.contact_names == [] and a.gap.shape == (2, 0) and a.contact_state.dtype.kind == "i"
    copy = pickle.loads(pickle.dumps(b))
    a.coordinate_names.append("extra")
    assert b.coordinate_names == copy.coordinate_names == list(model.coordinate_names)
    assert copy.joint_position_names == list(model.joint_space.position_names)


@pytest.mark.skipif(threading.current_thread() is not threading.main_thread(), reason="signals: main thread only")
@pytest.mark.parametrize("action", [signal.SIG_IGN, signal.SIG_DFL])
def test_where_sigint_is_ignored_or_default_the_loop_is_called_directly(chain, monkeypatch, action):
    """A process whose SIGINT is ignored (a shell's background job, ``nohup``) or has its
    default action starts no thread per run (there is no Ctrl-C for one to catch: a thread
    per call cost ~50 µs); the run equals the one under Python's handler, bit for bit."""
    model, q0, v0 = chain
    run = lambda: nc.simulate(model, 0.05, 0.01, q0=q0, v0=v0, method="joint")  # noqa: E731
    reference = run()
    threads = [0]
    start = threading.Thread.start

    def thread_start(self):
        threads[0] += 1
        return start(self)
    monkeypatch.setattr(threading.Thread, "start", thread_start)
    previous = signal.signal(signal.SIGINT, action)
    try:
        got = run()
        assert call_interruptibly(lambda: 3, stop=ctypes.c_int(0)) == (3, False)
    finally:
        signal.signal(signal.SIGINT, previous)
    assert threads[0] == 0
    np.testing.assert_array_equal(got.qj, reference.qj)


def test_the_time_grid_is_fresh_per_run_and_the_formula_of_the_docs():
    """The grid is computed once per ``(t0, t_end, n)`` but every call returns its own array
    (editing a run's ``t`` changes no later grid), ``t0 + k (t_end − t0) / n``."""
    from ncgen.runtime.inputs import time_grid

    a = time_grid(0.5, 1.25, 0.1)
    a[3] = -1.0
    b = time_grid(0.5, 1.25, 0.1)
    np.testing.assert_array_equal(b, 0.5 + 0.75 * np.arange(9) / 8)
    assert b is not time_grid(0.5, 1.25, 0.1)


def test_a_kept_grid_still_honours_a_changed_allocation_limit(monkeypatch):
    """The checked grid is kept per arguments and ``$NCGEN_MAX_BYTES``: a grid computed under
    the default limit is refused once the limit is lowered below its size (naming the grid and
    the variable), and computed again when the limit is lifted."""
    from ncgen.runtime.inputs import time_grid

    assert len(time_grid(0.0, 1.0, 1e-3, bytes_per_point=100.0)) == 1001
    monkeypatch.setenv("NCGEN_MAX_BYTES", "1000")
    with pytest.raises(nc.NcgenError, match=r"output grid t0 = 0 \.\.\. t_end = 1 s .*NCGEN_MAX_BYTES"):
        time_grid(0.0, 1.0, 1e-3, bytes_per_point=100.0)
    monkeypatch.delenv("NCGEN_MAX_BYTES")
    assert len(time_grid(0.0, 1.0, 1e-3, bytes_per_point=100.0)) == 1001


def test_environment_variables_read_fast_equal_os_environ_and_follow_its_changes(monkeypatch):
    """``ncgen.environment.getenv`` answers as ``os.environ.get`` for a set, a changed, a
    removed and a non-ASCII value, and the compiler follows a change of ``$CC`` made through
    ``os.environ`` (a missing one is refused naming ``$CC``)."""
    from ncgen.codegen.compiler import find_compiler
    from ncgen.environment import getenv
    from ncgen.errors import CompilerNotFound

    name = "NCGEN_TEST_START38"
    monkeypatch.delenv(name, raising=False)
    assert getenv(name) is None and getenv(name, "d") == "d"
    for value in ("1", "", "caf\u00e9 \u2192 x", "2"):
        monkeypatch.setenv(name, value)
        assert getenv(name) == os.environ.get(name) == value
    monkeypatch.delenv(name)
    assert getenv(name, "gone") == "gone"
    assert getenv("PATH") == os.environ.get("PATH")
    monkeypatch.setenv("CC", "ncgen-no-such-compiler")
    with pytest.raises(CompilerNotFound, match=r"'ncgen-no-such-compiler' from \$CC"):
        find_compiler()
    monkeypatch.delenv("CC")
    find_compiler()                               # the default compiler again (the suite needs one)


def _raise_sigint_and_wait(stop, after: float = 0.0, seconds: float = 5.0) -> int:
    """SIGINT to this process ``after`` s, then wait (GIL released) until ``stop`` is set: 7 if
    it was."""
    time.sleep(after)
    os.kill(os.getpid(), signal.SIGINT)
    end = time.monotonic() + seconds
    while stop.value == 0 and time.monotonic() < end:
        time.sleep(0.001)
    return 7 if stop.value else 0


@pytest.mark.skipif(threading.current_thread() is not threading.main_thread(), reason="signals: main thread only")
def test_ctrl_c_during_a_call_sets_the_stop_flag_and_the_handler_runs_after():
    """Under Python's handler and under ``sticky_interrupt``, SIGINT while the call runs sets
    its stop flag (through the watcher thread), the call returns its result, ``interrupted`` is
    True, no ``KeyboardInterrupt`` escapes, the sticky handler remembers it, and the wakeup
    descriptor is restored; under an application's handler (a worker thread) the same."""
    if signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        pytest.skip("SIGINT is not Python's default handler here")
    before = signal.set_wakeup_fd(-1)
    signal.set_wakeup_fd(before)
    stop = ctypes.c_int(0)
    assert call_interruptibly(_raise_sigint_and_wait, stop, stop=stop) == (7, True)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    assert signal.set_wakeup_fd(before) == before
    stop = ctypes.c_int(0)
    with sticky_interrupt():
        assert call_interruptibly(_raise_sigint_and_wait, stop, stop=stop) == (7, True)
        with pytest.raises(KeyboardInterrupt):
            raise_if_interrupted()

    def application(signum, frame):
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGINT, application)
    try:
        stop = ctypes.c_int(0)                  # (SIGINT once the main thread waits for the worker)
        assert call_interruptibly(_raise_sigint_and_wait, stop, 0.2, stop=stop) == (7, True)
    finally:
        signal.signal(signal.SIGINT, previous)
    assert call_interruptibly(lambda: 3, stop=ctypes.c_int(0)) == (3, False)


def test_a_prepared_run_is_reused_and_a_changed_option_grid_tolerance_or_compiler_makes_a_new_one(monkeypatch):
    """What a joint run derives from its arguments but not from its start
    (:func:`~ncgen.runtime.joint_simulation.prepared_run`) is made once per options, output
    count, controller and compiler: each run equals, bit for bit and in its ``info``, the same
    run with a prepared run made afresh, and a changed tolerance, grid, integrator, substeps or
    ``$CC`` is honoured (the info says it, the grid is the one asked for)."""
    model = spatial_chain()
    q0, v0 = model.from_joint_space(np.array([0.3, -0.7, 1.1]), np.array([1.5, -0.4, 2.0]))
    kept = js_module.model_data(model).prepared_runs
    cases = [dict(t_end=0.2, dt=0.05, rtol=1e-6, atol=1e-6), dict(t_end=0.2, dt=0.05, rtol=1e-6, atol=1e-6),
             dict(t_end=0.2, dt=0.05, rtol=1e-9, atol=1e-11), dict(t_end=0.3, dt=0.05, rtol=1e-6, atol=1e-6),
             dict(t_end=0.2, dt=0.04, rtol=1e-6, atol=1e-6), dict(t_end=0.2, dt=0.05, integrator="rk4", substeps=4),
             dict(t_end=0.2, dt=0.05, integrator="rk4", substeps=9)]
    runs = [nc.simulate(model, q0=q0, v0=v0, method="joint", **c) for c in cases]
    assert len(kept) == len(cases) - 1                  # the repeated case reused its prepared run
    monkeypatch.setattr(js_module, "prepared_run", js_module.PreparedRun)
    for c, run in zip(cases, runs):
        ref = nc.simulate(model, q0=q0, v0=v0, method="joint", **c)
        np.testing.assert_array_equal(run.qj, ref.qj)
        np.testing.assert_array_equal(run.t, ref.t)
        np.testing.assert_allclose(run.t, np.arange(len(run.t)) * c["dt"], rtol=0, atol=1e-15)
        assert run.t[-1] == c["t_end"]
        drop = ("build_time", "wall_time")
        assert {k: v for k, v in run.info.items() if k not in drop} == \
            {k: v for k, v in ref.info.items() if k not in drop}
        assert list(run.info) == list(ref.info)
        if "rtol" in c:
            assert (run.info["rtol"], run.info["atol"]) == (c["rtol"], c["atol"])
        else:
            assert run.info["substeps"] == c["substeps"] and run.info["h"] == pytest.approx(c["dt"] / c["substeps"])
    monkeypatch.undo()
    monkeypatch.setenv("CC", "no-such-compiler-ncgen")
    compiler._find.cache_clear()
    without = nc.simulate(model, q0=q0, v0=v0, method="joint", **cases[0])
    assert without.info["kernels_reason"] == "no C compiler"
    np.testing.assert_array_equal(without.qj, runs[0].qj)
    monkeypatch.delenv("CC")
    assert nc.simulate(model, q0=q0, v0=v0, method="joint", **cases[0]).info["kernels_reason"] == \
        runs[0].info["kernels_reason"] != "no C compiler"


def test_the_joint_states_are_copies_made_when_read_and_editing_them_changes_nothing_else(chain):
    """``traj.qj``/``traj.vj`` of a joint run are made when first read, as copies: edited
    before the natural coordinates are derived, those still equal ``from_joint_space`` of the
    run's joint states (a second run's), and a pickle keeps the edit."""
    model, q0, v0 = chain
    run = lambda: nc.simulate(model, 0.2, 0.05, q0=q0, v0=v0, method="joint", rtol=1e-8, atol=1e-10)  # noqa: E731
    edited, reference = run(), run()
    assert callable(edited._arrays["qj"])                   # not made yet
    edited.qj[:] += 1.0
    edited.vj[:] -= 2.0
    np.testing.assert_array_equal(edited.qj, reference.qj + 1.0)
    np.testing.assert_array_equal(edited.q, reference.q)
    np.testing.assert_array_equal(edited.v, reference.v)
    q, v = model.from_joint_space(reference.qj[-1], reference.vj[-1])
    np.testing.assert_allclose(edited.q[-1], q, rtol=0, atol=1e-12)
    np.testing.assert_allclose(edited.v[-1], v, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(pickle.loads(pickle.dumps(edited)).vj, reference.vj - 2.0)


def test_a_kept_plan_is_reused_and_a_changed_argument_option_t0_or_limit_makes_a_new_one(monkeypatch):
    """What ``simulate`` derives from its arguments in the call without ``u``, ``p`` and ``t0``
    (:class:`~ncgen.runtime.simulation.Plan`: options, method, integrator, grid, zero inputs) is
    kept per model and arguments: a repeated call makes none (the options are not resolved
    again: counted), and each case — repeated, another ``t_end``, ``dt``, tolerance, integrator,
    options object, ``t_end`` as an int — equals, bit for bit and in its
    ``info``, the same run with every plan made afresh; a lowered ``$NCGEN_MAX_BYTES`` still
    refuses a kept grid; the plan's grid stays unchanged when a run's ``t`` is edited, its
    inputs are the run's own; a run with ``p`` or ``t0`` given keeps no plan."""
    import ncgen.runtime.simulation as simulation

    model = spatial_chain()
    q0, v0 = model.from_joint_space(np.array([0.3, -0.7, 1.1]), np.array([1.5, -0.4, 2.0]))
    plans = js_module.model_data(model).simulate_plans
    strict = nc.SimulationOptions(method="joint", rtol=1e-9, atol=1e-11)
    cases = [(0.2, 0.05, None, dict(rtol=1e-6, atol=1e-6)), (0.2, 0.05, None, dict(rtol=1e-6, atol=1e-6)),
             (0.3, 0.05, None, dict(rtol=1e-6, atol=1e-6)), (0.2, 0.04, None, dict(rtol=1e-6, atol=1e-6)),
             (0.2, 0.05, None, dict(rtol=1e-9, atol=1e-11)), (0.2, 0.05, None, dict(integrator="rk4", substeps=4)),
             (0.2, 0.05, strict, {}), (1, 0.25, None, dict(rtol=1e-6, atol=1e-6)), (1.0, 0.25, None, dict(rtol=1e-6, atol=1e-6))]
    resolved = [0]
    resolve = nc.SimulationOptions.resolve.__func__

    def counted(cls, *args, **kwargs):
        resolved[0] += 1
        return resolve(cls, *args, **kwargs)
    monkeypatch.setattr(nc.SimulationOptions, "resolve", classmethod(counted))
    runs = []
    for k, (t_end, dt, options, keywords) in enumerate(cases):
        before = resolved[0]
        runs.append(nc.simulate(model, t_end, dt, q0=q0, v0=v0, options=options, **{"method": "joint", **keywords}))
        assert resolved[0] == before + (k != 1)        # the repeated case: none
    assert len(plans) == len(cases) - 1
    runs[0].t[:] = -1.0
    monkeypatch.setattr(simulation, "_kept_plan", lambda *args: None)
    for (t_end, dt, options, keywords), run in zip(cases, runs):
        ref = nc.simulate(model, t_end, dt, q0=q0, v0=v0, options=options, **{"method": "joint", **keywords})
        np.testing.assert_array_equal(run.qj, ref.qj)
        np.testing.assert_array_equal(run.lam, ref.lam)
        assert run is runs[0] or (np.array_equal(run.t, ref.t) and np.array_equal(run.u, ref.u))
        drop = ("build_time", "wall_time")
        assert {k: v for k, v in run.info.items() if k not in drop} == \
            {k: v for k, v in ref.info.items() if k not in drop}
    monkeypatch.undo()
    again = nc.simulate(model, 0.2, 0.05, q0=q0, v0=v0, method="joint", rtol=1e-6, atol=1e-6)
    np.testing.assert_array_equal(again.t, np.arange(5) * 0.05)
    assert not again.u.any() and again.u.flags.writeable
    np.testing.assert_array_equal(again.qj, runs[1].qj)
    monkeypatch.setenv("NCGEN_MAX_BYTES", "100")
    with pytest.raises(nc.NcgenError, match="output grid t0 = 0"):
        nc.simulate(model, 0.2, 0.05, q0=q0, v0=v0, method="joint", rtol=1e-6, atol=1e-6)
    monkeypatch.delenv("NCGEN_MAX_BYTES")
    plans.clear()
    nc.simulate(model, 0.2, 0.05, p=model.p0, q0=q0, v0=v0, method="joint")
    nc.simulate(model, 0.2, 0.05, t0=0.0, q0=q0, v0=v0, method="joint")
    assert plans == {}


def test_a_float64_start_of_another_dtype_instance_takes_the_fast_start(chain, monkeypatch):
    """A start given as float64 arrays whose dtype is an equal but distinct instance (as NumPy
    makes for some results, e.g. ``newbyteorder("=")``) takes the fast start like any other
    (no ``as_vector``: counted), with a bit-equal run."""
    import ncgen.runtime.run_start as run_start

    model, q0, v0 = chain
    other = np.dtype(np.float64).newbyteorder("=")
    assert other is not np.dtype(np.float64)
    q, v = q0.astype(other), v0.astype(other)
    calls: dict = {}
    _count(monkeypatch, run_start, "as_vector", calls)
    got = nc.simulate(model, 0.05, 0.05, q0=q, v0=v, method="joint")
    assert calls == {}
    np.testing.assert_array_equal(got.qj, nc.simulate(model, 0.05, 0.05, q0=q0, v0=v0, method="joint").qj)

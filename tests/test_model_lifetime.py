"""A model goes when its last user reference goes, whatever was called on it: its run-time
data lives on it (``model._data``, :mod:`ncgen.model.data`), so the doors, kernels and loops
that hold it form cycles Python's cyclic GC collects, and no module dictionary keeps it.

Each case calls one entry point on a pendulum (a URDF hinge of length ``L1``), checks the
result, deletes the model, collects, and asserts the model's weak reference is dead; then
builds a pendulum of another length ``L2`` and checks the same entry point on it (a kernel or
door of the first model kept by the object's ``id`` would give the first length's numbers).

Reference: the compound pendulum's closed form, ``J θ̈ = τ − m g L sin θ`` with
``J = I + m L²`` (inertia ``I`` about the centre of mass at ``L`` below the hinge), its
derivatives, its linearisation, modes and hinge reaction at rest, and for runs the Taylor
series of ``θ(t)`` from rest to ``t⁴``; the optimal one-interval control of the joint-space
step (linear in the effort) in closed form; a ball rolling on a plane under a constant push
``P``, whose centre moves by ``½ (5 P / 7 m) t²``.

Besides the model, its data, every object in the data's slots that takes a weak reference
(the doors, kernels, loops and libraries bound to it) and whatever the entry point returned
(a step, a controller) must go; and a loop creating and dropping models must not grow the
process's resident memory beyond a bound."""
from __future__ import annotations

import dataclasses
import gc
import os
import weakref

import numpy as np
import pytest

import ncgen as nc

MASS, INERTIA, G = 2.0, 0.01, 9.81
L1, L2 = 0.5, 0.3
TH, V, TAU = 0.7, 0.4, 0.3


def pendulum(length: float):
    """A hinge about y with the mass ``MASS`` at ``length`` below it, actuated by ``tau``."""
    urdf = f"""<robot name="lifetime_pendulum"><link name="base"/>
      <link name="arm"><inertial><mass value="{MASS}"/><origin xyz="0 0 -{length}"/>
        <inertia ixx="{INERTIA}" iyy="{INERTIA}" izz="{INERTIA}" ixy="0" ixz="0" iyz="0"/></inertial></link>
      <joint name="hinge" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0 1 0"/>
        <limit effort="50" velocity="30" lower="-10" upper="10"/></joint></robot>"""
    return nc.System.from_urdf(urdf, gravity=(0, 0, -G)).build()


def closed_form(length: float, th: float = TH, tau: float = TAU):
    """``(J, m g L sin θ, m g L cos θ, θ̈)`` of the pendulum of ``length``."""
    J = INERTIA + MASS * length ** 2
    mgl = MASS * G * length
    return J, mgl * np.sin(th), mgl * np.cos(th), (tau - mgl * np.sin(th)) / J


def run_end(length: float, t: float) -> float:
    """``θ(t)`` from rest at ``TH`` without effort: ``θ₀ − k s t²/2 + k² s c t⁴/24`` with
    ``k = m g L / J``, ``s, c = sin θ₀, cos θ₀`` (the next term is O(k³ t⁶))."""
    J, *_ = closed_form(length)
    k = MASS * G * length / J
    return TH - k * np.sin(TH) * t ** 2 / 2 + k ** 2 * np.sin(TH) * np.cos(TH) * t ** 4 / 24


q, v, tau = np.array([TH]), np.array([V]), np.array([TAU])


def check_aba(m, length):
    np.testing.assert_allclose(nc.aba(m, q, v, tau), [closed_form(length)[3]], rtol=1e-10)


def check_rnea(m, length):
    J, gs, _, a = closed_form(length)
    np.testing.assert_allclose(nc.rnea(m, q, v, [a]), tau, rtol=1e-10)


def check_crba(m, length):
    np.testing.assert_allclose(nc.crba(m, q), [[closed_form(length)[0]]], rtol=1e-10)


def check_inverse_dynamics(m, length):
    J, gs, _, a = closed_form(length)
    np.testing.assert_allclose(nc.inverse_dynamics(m, q, v, [a]), tau, rtol=1e-10)


def check_forward_dynamics(m, length):
    qn, vn = m.from_joint_space(q, v)
    a, _ = nc.forward_dynamics(m, qn, vn, u=tau)
    np.testing.assert_allclose(m.to_joint_space(qn, vn, a)[2], [closed_form(length)[3]], rtol=1e-9)


def check_joint_forward_dynamics(m, length):
    np.testing.assert_allclose(nc.joint_forward_dynamics(m, q, v, tau), [closed_form(length)[3]], rtol=1e-10)


def check_aba_derivatives(m, length):
    J, _, gc_, a = closed_form(length)
    out = nc.aba_derivatives(m, q, v, tau)
    for got, want in zip(out, ([a], [[-gc_ / J]], [[0.0]], [[1 / J]])):
        np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-12)


def check_rnea_derivatives(m, length):
    J, _, gc_, a = closed_form(length)
    out = nc.rnea_derivatives(m, q, v, [a])
    for got, want in zip(out, (tau, [[gc_]], [[0.0]], [[J]])):
        np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-12)


def check_joint_step(m, length):
    h = 0.01
    a = closed_form(length)[3]
    np.testing.assert_allclose(nc.JointStep(m, h)(np.array([TH, V]), tau), [TH + h * (V + h * a), V + h * a],
                               rtol=1e-12)


def simulate_check(**options):
    def check(m, length):
        t_end = 0.02
        q0, v0 = m.from_joint_space(q, [0.0])
        traj = nc.simulate(m, t_end, 0.01, q0=q0, v0=v0, **options)
        assert traj.t[-1] == pytest.approx(t_end)
        np.testing.assert_allclose(traj.joint("hinge")[0][-1], run_end(length, t_end), atol=1e-7)
    return check


def check_simulate_batch(m, length):
    t_end = 0.02
    q0, v0 = m.from_joint_space(q, [0.0])
    res = nc.simulate_batch(m, t_end, 0.01, q0=q0[None], v0=v0[None], workers=1, substeps=20)
    assert res.status.tolist() == [0]
    np.testing.assert_allclose(m.to_joint_space(res.q[0, -1])[0], run_end(length, t_end), atol=1e-7)


def at_rest(m):
    """The hanging pendulum found by ``nc.equilibrium`` from ``TH``, checked: hinge angle 0, stable."""
    eq = nc.equilibrium(m, m.from_joint_space(q)[0])
    np.testing.assert_allclose(m.to_joint_space(eq.q)[0], [0.0], atol=1e-9)
    assert eq.stability == "stable"
    return eq


def check_equilibrium(m, length):
    return at_rest(m)


def check_modes(m, length):
    J, *_ = closed_form(length)
    np.testing.assert_allclose(nc.modes(m, at_rest(m)).omega2, [MASS * G * length / J], rtol=1e-8)


def check_linearize(m, length):
    """The linearisation about the hanging pendulum oscillates at ``ω² = m g L / J``."""
    J, *_ = closed_form(length)
    lin = nc.linearize(m, at_rest(m))
    np.testing.assert_allclose(sorted(np.linalg.eigvals(lin.A).imag), np.array([-1, 1]) * np.sqrt(MASS * G * length / J),
                               rtol=1e-8)
    return lin


def check_joint_linearization(m, length):
    """``A = [[0, 1], [−m g L cos θ / J, 0]]``, ``B = [0, 1/J]`` at ``(TH, V)``."""
    J, _, gcos, _ = closed_form(length)
    lin = nc.linearize(m, q, v, tau, space="joint")
    np.testing.assert_allclose(lin.A, [[0, 1], [-gcos / J, 0]], atol=1e-10)
    np.testing.assert_allclose(lin.B, [[0], [1 / J]], atol=1e-10)


def check_joint_reactions(m, length):
    """At rest the base holds the arm up with ``m g`` and no moment about the hinge."""
    eq = at_rest(m)
    r = nc.joint_reactions(m, eq.q, eq.lam)["hinge"]
    np.testing.assert_allclose(r.force, [0, 0, MASS * G], atol=1e-9)
    np.testing.assert_allclose(r.moment, np.zeros(3), atol=1e-9)


def check_step_function(kernels):
    """One RATTLE step of 2 ms from rest at ``TH`` without effort: the Taylor series of
    ``θ(h)`` (RATTLE's error from rest is O(k² h⁴), ~3e-10 here; the two lengths' steps differ
    by 2e-5)."""
    def check(m, length):
        h = 0.002
        st = nc.step_function(m, h, kernels=kernels)
        assert st.kernels == kernels
        q0, v0 = m.from_joint_space(q, [0.0])
        x1 = st(np.concatenate([q0, v0]), [0.0])
        np.testing.assert_allclose(m.to_joint_space(x1[:m.nq])[0], [run_end(length, h)], atol=1e-8)
        return st
    return check


def one_interval(length: float, h: float, r: float, w: float, target: float) -> float:
    """The effort minimising ``r τ² + w (θ⁺ − target)²`` over one joint step from ``(TH, V)``,
    whose angle is ``θ⁺ = c + b τ`` (``b = h²/J``, ``c = TH + h V − b m g L sin TH``)."""
    J, gs, _, _ = closed_form(length, tau=0.0)
    b = h * h / J
    c = TH + h * V - b * gs
    return -w * b * (c - target) / (r + w * b * b)


def check_ilqr(m, length):
    """iLQR on one interval of the joint step, cost ``r τ² + w (θ⁺ − TH)²``: the step is
    linear in ``τ``, so the optimum is :func:`one_interval`'s."""
    h, r, w = 0.01, 1.0, 1e8
    st = nc.JointStep(m, h)
    res = nc.ilqr(st, np.array([TH, V]), np.zeros((1, 1)), (lambda x, u: r * u[0] ** 2,
                                                           lambda x: w * (x[0] - TH) ** 2), tol=1e-10)
    assert res.converged, res.message
    np.testing.assert_allclose(res.U, [[one_interval(length, h, r, w, TH)]], rtol=1e-9)
    return st


def check_joint_mpc(m, length):
    """``nc.JointMPC`` over one interval tracking rest at θ = 0 (holding effort 0): its
    Gauss–Newton iteration on the linear step is exact, ``τ* = −w B·W f / (w BᵀWB + r)``
    with ``x⁺ = f + B τ``, ``B = [h²/J, h/J]``."""
    h, w, r, (wq, wv) = 0.01, 10.0, 1.0, (1.0, 0.01)
    J, gs, _, _ = closed_form(length, tau=0.0)
    mpc = nc.JointMPC(m, h, 1, lambda t: np.zeros(1), state_weight=(wq, wv), input_weight=r, terminal_weight=w)
    v1 = V - h * gs / J
    f, B, W = np.array([TH + h * v1, v1]), np.array([h * h / J, h / J]), np.array([wq, wv])
    np.testing.assert_allclose(mpc(np.array([TH, V])), [-w * (B * W) @ f / (w * (B * W) @ B + r)], rtol=1e-6)
    return mpc


def check_sweep(m, length):
    """Two starts on two threads (``nc.sweep``, the compiled stepper): each run's end."""
    t_end = 0.02
    starts = np.array([TH, TH / 2])
    q0 = np.array([m.from_joint_space([a])[0] for a in starts])
    res = nc.sweep(m, None, t_end=t_end, dt=0.01, q0=q0, workers=2, chunk=1, substeps=20, outputs=("q",),
                   progress=False)
    assert res.summary["status"].tolist() == [0, 0]
    ends = [m.to_joint_space(res["q"][i, -1])[0] for i in range(2)]
    J, *_ = closed_form(length)
    k = MASS * G * length / J
    want = [a - k * np.sin(a) * t_end ** 2 / 2 + k ** 2 * np.sin(a) * np.cos(a) * t_end ** 4 / 24 for a in starts]
    np.testing.assert_allclose(ends, want, atol=1e-7)


PUSH = 3.0


def rolling_ball(mass: float, radius: float = 0.1):
    """A solid ball of ``mass`` rolling without slipping on the plane z = 0, pushed along x
    at its centre by the input ``push``."""
    import casadi as ca

    s = nc.System("lifetime_ball", gravity=(0, 0, -G))
    ball = s.add_body("ball", mass=mass, inertia=0.4 * mass * radius ** 2 * np.eye(3), position=(0, 0, radius))
    push = s.add_input("push")
    s.add_force(nc.PointForce(ball, (0, 0, 0), force=ca.vertcat(push, 0, 0)))
    s.add_rolling(nc.RollingSphere(ball, radius=radius))
    return s.build()


def rolling_check(**options):
    def check(m, mass):
        traj = nc.simulate(m, 0.2, 0.05, u=lambda t: [PUSH], **options)
        np.testing.assert_allclose(traj.point("ball", (0, 0, 0))[:, 0], 0.5 * 5 * PUSH / (7 * mass) * traj.t ** 2,
                                   rtol=0, atol=1e-7)
    return check


FAST = {"aba": check_aba, "rnea": check_rnea, "crba": check_crba, "inverse_dynamics": check_inverse_dynamics,
        "forward_dynamics": check_forward_dynamics, "joint_forward_dynamics": check_joint_forward_dynamics,
        "aba_derivatives": check_aba_derivatives, "rnea_derivatives": check_rnea_derivatives,
        "simulate_joint": simulate_check(method="joint"),
        "simulate_idas": simulate_check(method="idas"),
        "equilibrium": check_equilibrium, "modes": check_modes, "linearize": check_linearize,
        "joint_linearization": check_joint_linearization, "joint_reactions": check_joint_reactions,
        "step_function_tables": check_step_function("tables")}
#: Entry points that compile a package of their own on a fresh cache (the stepper's elements,
#: the step's Jacobians, the model's own step).
SLOW = {"JointStep": check_joint_step, "simulate_stepper": simulate_check(method="stepper", substeps=20),
        "simulate_batch": check_simulate_batch, "sweep_threads": check_sweep,
        "step_function_flat": check_step_function("flat"), "ilqr": check_ilqr, "JointMPC": check_joint_mpc}
#: The rolling ball's runs, by method (the compiled stepper compiles the ball's package).
ROLLING = {"rolling": rolling_check(method="rolling", rtol=1e-10, atol=1e-12),
           "idas": rolling_check(method="idas", rtol=1e-10, atol=1e-12)}
ROLLING_SLOW = {"stepper": rolling_check(method="stepper", substeps=10, backend="compiled")}


def held(model) -> dict[str, weakref.ref]:
    """Weak references to ``model``, its data and every object in the data's slots (dict
    values and tuple items included) that takes one, by where it sits."""
    data = model._data
    refs = {"model": weakref.ref(model), "data": weakref.ref(data)}
    for f in dataclasses.fields(data):
        slot = getattr(data, f.name)
        for key, value in (slot.items() if isinstance(slot, dict) else [(None, slot)]):
            for i, x in enumerate(value if isinstance(value, tuple) else (value,)):
                try:
                    refs[f"{f.name}[{key!r}][{i}] {type(x).__name__}"] = weakref.ref(x)
                except TypeError:
                    pass
    return refs


def collected_then_fresh(check, build=pendulum, sizes=(L1, L2)):
    model = build(sizes[0])
    made = check(model, sizes[0])
    refs = held(model)
    if made is not None:
        refs[f"returned {type(made).__name__}"] = weakref.ref(made)
    del model, made
    gc.collect()
    alive = [name for name, ref in refs.items() if ref() is not None]
    assert not alive, f"outlived the model's last reference: {alive} (something keeps them: gc.get_referrers)"
    check(build(sizes[1]), sizes[1])


@pytest.mark.parametrize("entry", sorted(FAST))
def test_model_goes_with_its_last_reference(entry):
    collected_then_fresh(FAST[entry])


@pytest.mark.slow
@pytest.mark.parametrize("entry", sorted(SLOW))
def test_model_goes_with_its_last_reference_after_a_compiled_run(entry):
    collected_then_fresh(SLOW[entry])


@pytest.mark.parametrize("method", sorted(ROLLING))
def test_rolling_model_goes_with_its_last_reference(method):
    collected_then_fresh(ROLLING[method], rolling_ball, (1.0, 2.0))


@pytest.mark.slow
@pytest.mark.parametrize("method", sorted(ROLLING_SLOW))
def test_rolling_model_goes_with_its_last_reference_after_a_compiled_run(method):
    collected_then_fresh(ROLLING_SLOW[method], rolling_ball, (1.0, 2.0))


@pytest.mark.slow
def test_model_goes_with_its_mpc():
    """``nc.MPC`` on the cart-pole (tests/cartpole_mpc.py): the model, its problem and the
    controller go together; the control of the upright pole tilted right pushes the cart right."""
    from cartpole_mpc import cartpole, cartpole_problem, tilted

    def check(model, _):
        mpc = nc.MPC(cartpole_problem(model))
        assert mpc(tilted(0.1, model=model))[0] > 0
        return mpc
    collected_then_fresh(check, lambda _: cartpole(), (None, None))


def resident_mb() -> float:
    """The process's resident set (MB, Linux's /proc/self/statm)."""
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2 ** 20


def memory_growth(entries, models: int) -> float:
    """The growth (MB) of the resident set over a loop of ``models`` pendulums, each built,
    checked on ``entries`` and dropped (no collection asked for inside the loop: the cyclic
    GC's own), after a first such loop that loads the libraries, fills the process's caches
    and lifts the heap to the high-water mark of the garbage the GC lets pile up."""
    def loop():
        for _ in range(models):
            m = pendulum(L1)
            for check in entries:
                check(m, L1)
        gc.collect()

    loop()
    before = resident_mb()
    loop()
    return resident_mb() - before


@pytest.mark.skipif(not os.path.exists("/proc/self/statm"), reason="reads the resident set from /proc")
def test_a_loop_of_models_does_not_grow_memory():
    """25 pendulums through ``rnea``: measured −4.4 to 0.0 MB; 2.4 MB when each is kept."""
    assert memory_growth([check_rnea], 25) <= 1.0


@pytest.mark.slow
@pytest.mark.skipif(not os.path.exists("/proc/self/statm"), reason="reads the resident set from /proc")
def test_a_loop_of_models_through_every_entry_point_does_not_grow_memory():
    """8 pendulums through every entry point above: measured 0.07-0.66 MB; 6.9 MB when each is kept."""
    assert memory_growth([*FAST.values(), *SLOW.values()], 8) <= 2.0

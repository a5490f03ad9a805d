"""A model goes when its last user reference goes, whatever was called on it: its run-time
data lives on it (``model._data``, :mod:`ncgen.model.data`), so the doors, kernels and loops
that hold it form cycles Python's cyclic GC collects, and no module dictionary keeps it.

Each case calls one entry point on a pendulum (a URDF hinge of length ``L1``), checks the
result, deletes the model, collects, and asserts the model's weak reference is dead; then
builds a pendulum of another length ``L2`` and checks the same entry point on it (a kernel or
door of the first model kept by the object's ``id`` would give the first length's numbers).

Reference: the compound pendulum's closed form, ``J θ̈ = τ − m g L sin θ`` with
``J = I + m L²`` (inertia ``I`` about the centre of mass at ``L`` below the hinge), its
derivatives, and for runs the Taylor series of ``θ(t)`` from rest to ``t⁴``."""
from __future__ import annotations

import gc
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


FAST = {"aba": check_aba, "rnea": check_rnea, "crba": check_crba, "inverse_dynamics": check_inverse_dynamics,
        "forward_dynamics": check_forward_dynamics, "joint_forward_dynamics": check_joint_forward_dynamics,
        "aba_derivatives": check_aba_derivatives, "rnea_derivatives": check_rnea_derivatives,
        "simulate_joint": simulate_check(method="joint"),
        "simulate_idas": simulate_check(method="idas")}
#: Entry points that compile a package of their own on a fresh cache (the stepper's elements,
#: the step's Jacobians).
SLOW = {"JointStep": check_joint_step, "simulate_stepper": simulate_check(method="stepper", substeps=20),
        "simulate_batch": check_simulate_batch}


def collected_then_fresh(check):
    model = pendulum(L1)
    check(model, L1)
    ref = weakref.ref(model)
    del model
    gc.collect()
    assert ref() is None, "the model outlived its last reference (something keeps it: gc.get_referrers)"
    check(pendulum(L2), L2)


@pytest.mark.parametrize("entry", sorted(FAST))
def test_model_goes_with_its_last_reference(entry):
    collected_then_fresh(FAST[entry])


@pytest.mark.slow
@pytest.mark.parametrize("entry", sorted(SLOW))
def test_model_goes_with_its_last_reference_after_a_compiled_run(entry):
    collected_then_fresh(SLOW[entry])


@pytest.mark.slow
def test_model_goes_with_its_mpc():
    """``nc.MPC`` on the cart-pole (tests/cartpole_mpc.py): the model, its problem and the
    controller go together; the control of the upright pole tilted right pushes the cart right."""
    from cartpole_mpc import cartpole, cartpole_problem, tilted
    model = cartpole()
    mpc = nc.MPC(cartpole_problem(model))
    assert mpc(tilted(0.1, model=model))[0] > 0
    ref = weakref.ref(model)
    del model, mpc
    gc.collect()
    assert ref() is None

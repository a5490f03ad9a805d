"""Compiled RNEA, CRBA, ABA and the derivatives of RNEA and ABA
(:mod:`ncgen.runtime.tree_algorithm_kernels`) against Pinocchio, an independent engine, on
example-robot-data's URDFs as shipped: the Panda (its second finger mimics the first), the
UR5, Solo12 (free flyer) and Talos (free flyer, 38 joint rates), at random states, 1e-9
relative to the largest entry of the reference.

References: Pinocchio's ``rnea`` and ``crba`` on its model with mimic joints; its ``aba``,
``computeRNEADerivatives`` and ``computeABADerivatives`` (which refuse mimic joints) on the
model without them, projected on the independent rates (``v = G v_i``): ``M_i = Gᵀ M G``,
``τ_i = Gᵀ τ``, ``a_i = M_i⁻¹ Gᵀ (τ − b)`` and ``∂a/∂x = −M_i⁻¹ Gᵀ (∂τ/∂x) G`` — the chain rule
on Pinocchio's analytic derivatives.  Without mimic joints ``G = 1`` and Pinocchio's
``computeABADerivatives`` is compared directly.  Position derivatives are in the tangent
space on both sides (a free flyer: Pinocchio's ``q ⊕ δ``).
"""
from __future__ import annotations

import numpy as np
import pytest

from pinocchio_robots import ROBOTS, JointMap, pin, pinocchio_models, random_configuration, urdf_text

import ncgen as nc  # noqa: E402
from ncgen.assembly.tree_dynamics import MimicMap  # noqa: E402
from ncgen.runtime import tree_algorithm_kernels as rta  # noqa: E402

QUICK_COMPILE = True             # its time is gcc compiling the robots' kernels (Solo12's derivatives: 115 CPU-s at
#                                 their default -O1/-O2, a correctness check on 5 states): -O0 (tests/conftest.py)
TOL = 1e-9
N_STATES = 5


def symmetric(A):
    """Pinocchio fills only the upper triangle of M and M⁻¹."""
    return np.triu(A) + np.triu(A, 1).T


def close(x, ref, what):
    scale = max(1.0, float(np.max(np.abs(ref))))
    err = float(np.max(np.abs(np.asarray(x) - ref)))
    assert err <= TOL * scale, f"{what}: max error {err:.3g} (scale {scale:.3g})"


def model_of(name):
    return nc.System.from_urdf(urdf_text(name), floating_base=ROBOTS[name][1]).build()


def states(model, pm, jm, mimic, seed):
    """``(qj, qp, v_i, a_i, τ_i)`` at random states (followers set from their leaders)."""
    rng = np.random.default_rng(seed)
    n_i = mimic.G.shape[1]
    for _ in range(N_STATES):
        qj = jm.q_to_ncgen(random_configuration(pm, rng))
        for i, (lead, k, offset) in mimic.position.items():
            qj[i] = k * qj[lead] + offset
        yield qj, jm.q_to_pin(qj, pm.nq), rng.normal(size=n_i), 5 * rng.normal(size=n_i), rng.normal(size=n_i)


def check_robot(name, algorithms=tuple(rta.ALGORITHMS)):
    model = model_of(name)
    pm_mimic, pm = pinocchio_models(name)
    jm, mimic = JointMap(model, pm), MimicMap(model)
    G = mimic.G
    P = jm.P @ G                     # Pinocchio's rates (model without mimic) from the independent ones
    d, dm = pm.createData(), pm_mimic.createData()
    for qj, qp, v_i, a_i, tau_i in states(model, pm, jm, mimic, seed=len(name)):
        vj, aj, vp, ap = G @ v_i, G @ a_i, P @ v_i, P @ a_i
        M = P.T @ symmetric(pin.crba(pm, d, qp)) @ P
        b = P.T @ pin.rnea(pm, d, qp, vp, np.zeros(pm.nv))
        a_ref = np.linalg.solve(M, tau_i - b)
        Minv = np.linalg.inv(M)
        if "rnea" in algorithms:
            tau = rta.rnea(model, qj, vj, aj)
            close(tau, P.T @ pin.rnea(pm, d, qp, vp, ap), f"{name} rnea")
            if mimic.relations:            # Pinocchio's own mimic joints agree
                Pm = _mimic_rates(pm_mimic, model, mimic)
                close(tau, Pm.T @ pin.rnea(pm_mimic, dm, _mimic_q(pm_mimic, pm, qp), Pm @ v_i, Pm @ a_i),
                      f"{name} rnea (Pinocchio mimic)")
        if "crba" in algorithms:
            Mj = rta.crba(model, qj)
            close(Mj, M, f"{name} crba")
            if mimic.relations:
                Pm = _mimic_rates(pm_mimic, model, mimic)
                close(Mj, Pm.T @ symmetric(pin.crba(pm_mimic, dm, _mimic_q(pm_mimic, pm, qp))) @ Pm,
                      f"{name} crba (Pinocchio mimic)")
        if "aba" in algorithms:
            close(rta.aba(model, qj, vj, tau_i), G @ a_ref, f"{name} aba")
        if "rnea_derivatives" in algorithms:
            tau, dq, dv, da = rta.rnea_derivatives(model, qj, vj, aj)
            rdq, rdv, _ = pin.computeRNEADerivatives(pm, d, qp, vp, ap)
            close(tau, P.T @ pin.rnea(pm, d, qp, vp, ap), f"{name} rnea_derivatives: tau")
            close(dq, P.T @ rdq @ P, f"{name} dtau/dq")
            close(dv, P.T @ rdv @ P, f"{name} dtau/dv")
            close(da, M, f"{name} dtau/da")
        if "aba_derivatives" in algorithms:
            a, dq, dv, dtau = rta.aba_derivatives(model, qj, vj, tau_i)
            rdq, rdv, _ = pin.computeRNEADerivatives(pm, d, qp, vp, P @ a_ref)
            close(a, G @ a_ref, f"{name} aba_derivatives: a")
            close(dq, -Minv @ P.T @ rdq @ P, f"{name} da/dq")
            close(dv, -Minv @ P.T @ rdv @ P, f"{name} da/dv")
            close(dtau, Minv, f"{name} da/dtau")
            if not mimic.relations:
                adq, adv, aM = pin.computeABADerivatives(pm, d, qp, vp, jm.P @ tau_i)
                close(dq, jm.P.T @ adq @ jm.P, f"{name} da/dq (computeABADerivatives)")
                close(dv, jm.P.T @ adv @ jm.P, f"{name} da/dv (computeABADerivatives)")
                close(dtau, jm.P.T @ symmetric(aM) @ jm.P, f"{name} da/dtau (computeABADerivatives)")


def _mimic_rates(pm_mimic, model, mimic):
    """``Pm``: Pinocchio's rates of the model with mimic joints from ncgen's independent ones."""
    from pinocchio_robots import ident

    sv = model.joint_space.slices(rates=True)
    col = {i: c for c, i in enumerate(mimic.independent)}
    Pm = np.zeros((pm_mimic.nv, len(col)))
    for jid in range(1, pm_mimic.njoints):
        jm = pm_mimic.joints[jid]
        if jm.nv:
            n = "root" if jm.shortname() == "JointModelFreeFlyer" else ident(pm_mimic.names[jid])
            for k in range(jm.nv):
                Pm[jm.idx_v + k, col[sv[n].start + k]] = 1.0
    return Pm


def _mimic_q(pm_mimic, pm, qp):
    """Pinocchio's configuration of the model with mimic joints (followers have none)."""
    q = np.zeros(pm_mimic.nq)
    for jid in range(1, pm_mimic.njoints):
        jm = pm_mimic.joints[jid]
        if jm.nq:
            full = pm.joints[pm.getJointId(pm_mimic.names[jid])]
            q[jm.idx_q:jm.idx_q + jm.nq] = qp[full.idx_q:full.idx_q + full.nq]
    return q


# the derivative kernels of the Panda and Solo12 are robot-scale compiles (200 s and 281 s at
# load 12-16 on 2 cores): the slow tier; UR5 (62 s there) checks the same code in the fast one
@pytest.mark.parametrize("name", [pytest.param("panda", marks=pytest.mark.slow), "ur5",
                                  pytest.param("solo12", marks=pytest.mark.slow)])
def test_algorithms_and_derivatives_match_pinocchio(name):
    check_robot(name)


@pytest.mark.slow                                  # robot scale: Talos's kernels compiled
def test_talos_algorithms_match_pinocchio():
    """Talos (38 joint rates): RNEA, CRBA and ABA.  Its derivative kernels are long C
    functions (see benchmarks/joint_space.py for their build times), so they are tested on
    the three smaller robots, which exercise the same code."""
    check_robot("talos", ("rnea", "crba", "aba"))


def test_panda_as_shipped_gets_the_forward_dynamics_kernel():
    """The mimic finger is handled inside the kernel: ``joint_forward_dynamics_kernel`` (the
    interface of the simulation path) accepts the stock Panda and agrees with ABA."""
    model = model_of("panda")
    k = nc.joint_forward_dynamics_kernel(model)
    mimic = MimicMap(model)
    rng = np.random.default_rng(3)
    qj = rng.uniform(-1, 1, model.joint_space.nq)
    for i, (lead, kk, offset) in mimic.position.items():
        qj[i] = kk * qj[lead] + offset
    vj = mimic.G @ rng.normal(size=mimic.G.shape[1])
    u = rng.normal(size=model.nu)
    actuated = [model.joint_names.index(n) for n in model.actuated_joints]
    independent = mimic.independent
    tau = np.zeros(len(independent))
    tau[[independent.index(i) for i in actuated]] = u
    close(k(qj, vj, u), rta.aba(model, qj, vj, tau), "forward dynamics kernel vs aba")


def test_bad_input_is_named():
    model = model_of("ur5")
    with pytest.raises(nc.NcgenError, match="qj"):
        rta.rnea(model, np.zeros(3), np.zeros(6), np.zeros(6))
    with pytest.raises(nc.ModelError, match="name"):
        rta.algorithm_kernel(model, "featherstone")


@pytest.mark.parametrize("name", ["ur5", pytest.param("solo12", marks=pytest.mark.slow)])   # UR5: the same code
def test_joint_space_linearization_matches_pinocchio_away_from_equilibrium(name):
    """``nc.linearize(..., space="joint")`` at a moving, non-equilibrium state: the dynamic
    rows are ``computeABADerivatives``' (B: ``M⁻¹`` on the actuated rates); the kinematic rows
    ``[K, 1]`` against central differences of Pinocchio's ``integrate``/``difference``: the
    tangent deviation ``δ(t)`` between ``q(t) = q ⊕ vt`` and ``q'(t) = (q ⊕ δ₀) ⊕ (v + δv)t``."""
    model = model_of(name)
    _, pm = pinocchio_models(name)
    jm = JointMap(model, pm)
    d = pm.createData()
    rng = np.random.default_rng(11)
    qp = random_configuration(pm, rng)
    qj = jm.q_to_ncgen(qp)
    vj = rng.normal(size=model.joint_space.nv)
    u = rng.normal(size=model.nu)
    lin = nc.linearize(model, qj, vj, u, space="joint")
    n = model.joint_space.nv
    P = jm.P
    tau = np.zeros(n)
    act = [i for name_ in model.actuated_joints for i in range(*model.joint_space.slices(rates=True)[name_].indices(n))]
    tau[act] = u
    ddq_dq, ddq_dv, Minv = pin.computeABADerivatives(pm, d, qp, P @ vj, P @ tau)
    close(lin.A[n:, :n], P.T @ ddq_dq @ P, f"{name} A (da/dq)")
    close(lin.A[n:, n:], P.T @ ddq_dv @ P, f"{name} A (da/dv)")
    close(lin.B[n:], (P.T @ symmetric(Minv) @ P)[:, act], f"{name} B")
    close(lin.xdot[n:], P.T @ pin.aba(pm, d, qp, P @ vj, P @ tau), f"{name} xdot")
    np.testing.assert_array_equal(lin.A[:n, n:], np.eye(n))
    np.testing.assert_array_equal(lin.B[:n], 0.0)
    h = eps = 1e-4
    delta0, dv = rng.normal(size=n), rng.normal(size=n)
    vp, dvp, d0 = P @ vj, P @ dv, P @ delta0

    def deviation(s, e):
        q1 = pin.integrate(pm, qp, vp * s)
        q2 = pin.integrate(pm, pin.integrate(pm, qp, d0 * e), (vp + e * dvp) * s)
        return P.T @ pin.difference(pm, q1, q2)

    def rate(e):
        return (deviation(h, e) - deviation(-h, e)) / (2 * h)

    fd = (rate(eps) - rate(-eps)) / (2 * eps)           # central in time and in the perturbation: O(h², ε²)
    np.testing.assert_allclose(lin.A[:n] @ np.concatenate([delta0, dv]), fd, atol=1e-6 * max(1, np.abs(fd).max()))


def test_linearize_space_is_checked():
    model = model_of("ur5")
    with pytest.raises(nc.NcgenError, match="space"):
        nc.linearize(model, np.zeros(6), space="cartesian")


@pytest.mark.parametrize("share", [True, False])
def test_an_arm_with_a_nearly_coplanar_wrist_builds_with_defaults_and_gets_the_kernel(share):
    """The SO-101 (6 joints): at its zero pose the wrist's roll axis, flex axis and the line
    between its joint points are coplanar to 2e-6 rad, which made the shared coordinates'
    rigidity equations dependent ("initial configuration is singular"); now the body's own axes
    complete its basis.  Both forms get the forward-dynamics kernel, which agrees with
    ``pinocchio.aba`` at random states."""
    model = nc.System.from_urdf(urdf_text("so101")).build(share=share)
    _, pm = pinocchio_models("so101")
    jm = JointMap(model, pm)
    d = pm.createData()
    k = nc.joint_forward_dynamics_kernel(model)
    rng = np.random.default_rng(5)
    for _ in range(N_STATES):
        qp = random_configuration(pm, rng)
        vj, u = rng.normal(size=pm.nv), rng.normal(size=model.nu)
        close(k(jm.q_to_ncgen(qp), vj, u), jm.P.T @ pin.aba(pm, d, qp, jm.P @ vj, jm.P @ u), "so101 aba")


def test_the_fast_call_and_the_ctypes_path_agree(monkeypatch):
    """The CPython accelerator (:mod:`ncgen.codegen.fast_call`) and the plain ctypes path
    give the same numbers and the same errors (a copy made without the accelerator)."""
    from ncgen.codegen import fast_call

    model = model_of("ur5")
    fast = nc.algorithm_kernel(model, "rnea")
    fd = nc.joint_forward_dynamics_kernel(model)
    monkeypatch.setattr(fast_call, "_MODULE", [None])
    slow, fd_slow = fast.copy(), fd.copy()
    assert slow._fast is None and fd_slow._fast is None
    rng = np.random.default_rng(2)
    for _ in range(3):
        qj, vj, aj = rng.normal(size=6), rng.normal(size=6), rng.normal(size=6)
        np.testing.assert_array_equal(fast(qj, vj, aj), slow(qj, vj, aj))
        np.testing.assert_array_equal(fd(qj, vj, aj), fd_slow(qj, vj, aj))
        np.testing.assert_array_equal(fast(list(qj), list(vj), list(aj)), slow(qj, vj, aj))
    for k in (fast, slow):
        with pytest.raises(nc.ModelError, match="expected 3 arguments"):
            k(np.zeros(5), np.zeros(6), np.zeros(6))
    for k in (fd, fd_slow):
        with pytest.raises(nc.ModelError, match="expected qj of 6"):
            k(np.zeros(5), np.zeros(6), np.zeros(6))
        with pytest.raises(nc.ModelError, match="not finite"):
            k(np.zeros(6), np.full(6, np.inf), np.zeros(6))


@pytest.mark.slow                                  # robot scale: the Panda under IDAS at tight tolerance
def test_panda_as_shipped_simulates_in_joint_space_with_its_mimic_finger():
    """The stock Panda (mimic finger) now gets the joint-space simulation: the fingers stay
    equal and the arm agrees with IDAS on the natural coordinates (the constrained DAE,
    mimic equation included) at tight tolerance."""
    model = model_of("panda")
    tj = nc.simulate(model, 0.2, 0.01, method="joint")
    ti = nc.simulate(model, 0.2, 0.01, method="idas", rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(tj.joint("panda_finger_joint2")[0], tj.joint("panda_finger_joint1")[0], atol=1e-14)
    for name in ("panda_joint2", "panda_joint4", "panda_joint6"):
        np.testing.assert_allclose(tj.joint(name)[0], ti.joint(name)[0], atol=1e-8)

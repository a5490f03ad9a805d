"""The force kinds of the table stepper beyond gravity and spring-dampers (issue 34): cables,
torsional spring-dampers, constant point forces, torques and generalised forces, checked
against closed forms (a damped torsional oscillator in 2D and 3D, a mass dropped on a slack
cable, a free body, bar and point pushed by constant loads) and against the flat stepper
(slow tier, equal to ~1e-12); their kernels' derivatives against central differences; the
refusal naming a force the tables do not cover."""
from __future__ import annotations

import os
import shutil

import casadi as ca
import numpy as np
import pytest
from table_models import every_force

import ncgen as nc
from ncgen.codegen.compiler import CANDIDATES
from ncgen.codegen.element_kernels import FEATURE_FORCE_KINDS, TORQUE_KINDS, feature_force_kind, torque_kind
from ncgen.codegen.model_tables import UnsupportedElements
from ncgen.model.cables import ClusteredCable
from ncgen.model.layout import make_layout
from ncgen.runtime.table_library import load_element_library

pytestmark = pytest.mark.skipif(not any(shutil.which(c) for c in CANDIDATES) and not os.environ.get("CC"),
                                reason="no C compiler to build the element library")


@pytest.fixture(scope="module")
def library():
    return load_element_library()


def _damped(t, w, zeta, x0, v0):
    """x(t) of ẍ + 2ζω ẋ + ω² x = 0 (ζ < 1)."""
    wd = w * np.sqrt(1 - zeta ** 2)
    return np.exp(-zeta * w * t) * (x0 * np.cos(wd * t) + (v0 + zeta * w * x0) / wd * np.sin(wd * t))


@pytest.mark.parametrize("dim", [2, 3])
def test_torsional_oscillator_equals_its_closed_form(dim, library):
    """A body hinged at its centre of mass to the ground, a torsional spring-damper on the
    hinge, no gravity: I θ̈ = −k (θ − θ_r) − c θ̇ from rest at θ = 0."""
    I, k, c, rest = 0.05, 2.0, 0.04, 0.3
    s = nc.System(f"torsion{dim}", gravity=(0.0,) * dim)
    if dim == 3:
        body = s.add_body("disc", coords="ruvw", mass=0.8, inertia=np.diag([0.07, 0.09, I]), position=(0.0, 0.0, 0.0))
        hinge = nc.Revolute(s.ground, body, at=(0.0, 0.0, 0.0), axis=(0.0, 0.0, 1.0))
    else:
        body = s.add_body("disc", coords="ruv", mass=0.8, inertia=I, position=(0.0, 0.0))
        hinge = nc.Revolute(s.ground, body, at=(0.0, 0.0))
    s.add_joint(hinge)
    s.add_force(nc.TorsionalSpring(hinge, k=k, damping=c, rest_angle=rest))
    model = s.build()
    traj = nc.simulate(model, 2.0, 0.01, method="stepper", substeps=2)
    assert traj.info["kernels"] == "tables"
    tip = traj.point("disc", (1.0,) + (0.0,) * (dim - 1))
    theta = np.unwrap(np.arctan2(tip[:, 1], tip[:, 0]))
    w, zeta = np.sqrt(k / I), c / (2 * np.sqrt(k * I))
    np.testing.assert_allclose(theta, rest + _damped(traj.t, w, zeta, -rest, 0.0), rtol=0, atol=1e-8)


def test_mass_on_a_slack_cable_falls_and_bounces_as_the_closed_form(library):
    """A point mass 0.2 m below the anchor of a cable of rest length 0.5 m: free fall to the
    taut length, a harmonic half-swing about m g / k below it, free flight back up to the
    start (no damping); its height over one period from those three pieces."""
    m, k, l0, z0, g = 0.4, 60.0, 0.5, -0.3, 9.81
    s = nc.System("cable_drop", gravity=(0.0, 0.0, -g))
    p = s.add_point("mass", mass=m, position=(0.0, 0.0, z0))
    s.add_force(nc.Spring(s.ground, (0.0, 0.0, 0.0), p, (0.0, 0.0, 0.0), k=k, rest_length=l0, cable=True))
    model = s.build()
    t_fall = np.sqrt(2 * (l0 + z0) / g)
    w, s_eq, v1 = np.sqrt(k / m), m * g / k, g * t_fall
    R = np.hypot(s_eq, v1 / w)
    alpha = np.arcsin(-s_eq / R)
    t_taut = (np.pi - 2 * alpha) / w
    period = 2 * t_fall + t_taut
    traj = nc.simulate(model, period, 0.0005, method="stepper", scheme="rattle4")
    assert traj.info["kernels"] == "tables"
    t = traj.t
    fall = z0 - g * t ** 2 / 2
    tt = t - t_fall
    taut = -l0 - s_eq - R * np.sin(w * tt + alpha)
    tr = period - t
    rise = z0 - g * tr ** 2 / 2
    exact = np.where(t < t_fall, fall, np.where(t < t_fall + t_taut, taut, rise))
    np.testing.assert_allclose(traj.q[:, 2], exact, rtol=0, atol=2e-6)
    np.testing.assert_allclose(traj.q[:, :2], 0.0, atol=1e-14)


def test_free_members_under_constant_loads_follow_the_closed_form(library):
    """No gravity, no joints: a body pushed at its centre of mass by a constant force and
    turned by a constant torque about a principal axis, a bar turned by a torque normal to
    it, a point under a constant generalised force: x = F t²/(2m), θ = τ t²/(2I)."""
    s = nc.System("loads", gravity=(0.0, 0.0, 0.0))
    Izz, F, tau = 0.04, np.array([0.3, -0.2, 0.5]), 0.07
    body = s.add_body("body", coords="ruvw", mass=1.5, inertia=np.diag([0.02, 0.03, Izz]), position=(0.0, 0.0, 0.0))
    L, mb, tb = 0.6, 0.5, 0.02
    bar = s.add_bar("bar", coords="rr", mass=mb, ends=[(1.0, 0.0, 0.0), (1.0 + L, 0.0, 0.0)])
    s.add_point("point", mass=0.25, position=(0.0, 2.0, 0.0))
    s.add_force(nc.PointForce(body, (0.0, 0.0, 0.0), force=tuple(F)))
    s.add_force(nc.Torque(body, (0.0, 0.0, tau)))
    s.add_force(nc.Torque(bar, (0.0, tb, 0.0)))
    G = np.array([0.1, 0.2, -0.4])
    lay = make_layout(3, list(s.members.values()))
    value = np.zeros(lay.nq)
    value[list(lay.member_indices("point"))] = G
    s.add_force(nc.GeneralizedForce(value))
    model = s.build()
    traj = nc.simulate(model, 1.0, 0.01, method="stepper")
    assert traj.info["kernels"] == "tables"
    t = traj.t[:, None]
    np.testing.assert_allclose(traj.point("body", (0.0, 0.0, 0.0)), F * t ** 2 / (2 * 1.5), atol=1e-10)
    x_axis = traj.point("body", (1.0, 0.0, 0.0)) - traj.point("body", (0.0, 0.0, 0.0))
    theta = np.arctan2(x_axis[:, 1], x_axis[:, 0])
    np.testing.assert_allclose(theta, tau * traj.t ** 2 / (2 * Izz), atol=1e-9)
    np.testing.assert_allclose(traj.point("point", (0.0, 0.0, 0.0)), [0.0, 2.0, 0.0] + G * t ** 2 / (2 * 0.25),
                               atol=1e-10)
    d = traj.point("bar", (L / 2, 0.0, 0.0)) - traj.point("bar", (-L / 2, 0.0, 0.0))
    phi = np.arctan2(-d[:, 2], d[:, 0])          # a torque along +y turns x towards −z
    np.testing.assert_allclose(phi, tb * traj.t ** 2 / (2 * mb * L ** 2 / 12), atol=1e-9)
    np.testing.assert_allclose(traj.point("bar", (0.0, 0.0, 0.0)), np.tile([1.0 + L / 2, 0.0, 0.0], (len(t), 1)),
                               atol=1e-12)


@pytest.mark.parametrize("force, dim", FEATURE_FORCE_KINDS)
def test_feature_force_kernels_equal_central_differences(force, dim):
    """J = ∂g/∂ḟ of each force kernel over features against central differences of g, and
    P = ḟ·(g + ∇V) against a difference of V along ḟ."""
    kind = feature_force_kind(force, dim)
    rng = np.random.default_rng(3)
    nd = kind.n_feat * dim
    pars = {"cable": [40.0, 0.2, 0.7], "torsion": [3.0, 0.4, 0.3, -1.0]}[force]
    x = np.concatenate([rng.normal(size=nd), rng.normal(size=nd), pars])
    y, J = (np.asarray(o) for o in kind.function(x))
    h = 1e-6
    Jfd = np.zeros((nd, nd))
    for i in range(nd):
        e = np.zeros_like(x)
        e[nd + i] = h
        Jfd[:, i] = (np.asarray(kind.function(x + e)[0])[:nd, 0] - np.asarray(kind.function(x - e)[0])[:nd, 0]) / (2 * h)
    np.testing.assert_allclose(J, Jfd, rtol=0, atol=1e-7 * (1 + np.abs(J).max()))
    e = np.zeros_like(x)
    e[:nd] = x[nd:2 * nd] * h
    dV = (float(kind.function(x + e)[0][nd]) - float(kind.function(x - e)[0][nd])) / (2 * h)
    g = y[:nd, 0]
    assert abs(float(y[nd + 1, 0]) - (x[nd:2 * nd] @ g + dV)) < 1e-6 * (1 + abs(dV))


@pytest.mark.parametrize("dim, ctype", TORQUE_KINDS)
def test_torque_kernels_give_the_couples_power(dim, ctype):
    """Q = W(q)ᵀ τ: its power v·Q equals τ·ω with ω = W(q) v from the derivation."""
    from ncgen.codegen.element_kernels import torque_constants
    from ncgen.model.sym2casadi import to_casadi
    from ncgen.symbolic.coordinates import coordinate_type

    D = coordinate_type(ctype, dim).derivation
    consts = torque_constants(dim, ctype)
    rng = np.random.default_rng(5)
    q, v, c = rng.normal(size=len(D.q)), rng.normal(size=len(D.q)), rng.normal(size=len(consts))
    tau = rng.normal(size=3 if dim == 3 else 1)
    Q = np.asarray(torque_kind(dim, ctype)(np.concatenate([q, c, tau]))).ravel()
    vals = {s: float(x) for s, x in zip(list(D.q) + list(D.qd) + list(consts), [*q, *v, *c])}
    omega = np.asarray(ca.evalf(to_casadi(D.omega, vals)), float).ravel()
    assert abs(Q @ v - tau @ omega) < 1e-12 * (1 + np.abs(Q).max() * np.abs(v).max())


def test_uncovered_forces_are_named(library):
    """kernels="tables" on a model with a force the tables do not cover names it and its kind."""
    s = every_force(3, name="uncovered")
    s.add_force(nc.PointForce(s.members["body"], (0.0, 0.0, 0.0), force=("0", "sin(t)", "0"), name="shaken"))
    m0 = s.members["puck"]
    s.add_force(ClusteredCable([(s.ground, (0.0, 0.0, 1.0)), (m0, (0.0, 0.0, 0.0)), (s.ground, (1.0, 0.0, 1.0))],
                               k=10.0, rest_length=1.0, name="pulley"))
    model = s.build()
    with pytest.raises(UnsupportedElements, match=r"ClusteredCable \(force 'pulley'\).*PointForce of t, inputs or "
                                                  r"parameters \(force 'shaken'\)"):
        nc.simulate(model, 0.1, 0.01, method="stepper", kernels="tables")


def _compare(model, tol=1e-12, **options):
    runs = {k: nc.simulate(model, 0.5, 0.01, method="stepper", kernels=k, check=False, **options)
            for k in ("tables", "flat")}
    a, b = runs["tables"], runs["flat"]
    assert a.info["kernels"] == "tables" and b.info["kernels"] == "flat"
    assert a.info["stats"] == b.info["stats"]
    np.testing.assert_allclose(a.q, b.q, rtol=0, atol=tol * (1.0 + np.max(np.abs(b.q))))
    np.testing.assert_allclose(a.v, b.v, rtol=0, atol=10 * tol * (1.0 + np.max(np.abs(b.v))))
    np.testing.assert_allclose(a.energy, b.energy, rtol=0, atol=10 * tol * (1.0 + np.max(np.abs(b.energy))))
    np.testing.assert_allclose(a.potential, b.potential, rtol=0, atol=10 * tol * (1.0 + np.max(np.abs(b.potential))))


@pytest.mark.slow
@pytest.mark.parametrize("dim", [3, 2])
@pytest.mark.parametrize("options", [{"scheme": "rattle", "substeps": 4}, {"rtol": 1e-6}], ids=["rattle", "rtol"])
def test_every_force_equals_the_flat_stepper(dim, options, library):
    """Every force kind of the tables in one model: the tables' run equals the flat package's
    (to 1e-11 of the scale of q: the two sum the forces in different orders, and the error
    control's step choices carry that round-off; measured 2.4e-12 in 3D at rtol = 1e-6)."""
    _compare(every_force(dim).build(), 1e-11, **options)


class _Blocked(dict):
    """A model's ``functions`` that refuses every flat function."""

    def __getitem__(self, name):
        raise AssertionError(f"the table run asked for the flat function {name!r}")

    get = __getitem__


@pytest.mark.parametrize("options", [{}, {"rtol": 1e-6}], ids=["fixed", "rtol"])
def test_a_table_run_builds_no_flat_function(options, library, monkeypatch):
    """A checked stepper run on the tables (initial multipliers, outputs, energies, energy
    balance, the conservative test) asks for no function of ``model.functions`` and no flat
    potential: both are replaced by refusals.  Its λ0, F and the conservative flag equal the
    flat functions' (computed before)."""
    from ncgen.model import function_set
    from ncgen.model.data import model_data
    from ncgen.runtime.stepper_checks import _is_conservative
    from ncgen.runtime.table_stepper import table_stepper

    model = every_force(3, name=f"blocked_{len(options)}").build()
    rng = np.random.default_rng(2)
    stepper = table_stepper(model)
    for _ in range(3):
        q, v = model.q0 + 0.05 * rng.normal(size=model.nq), rng.normal(size=model.nq)
        F = np.asarray(model.functions["F"](0.0, q, v, [], [])).ravel()
        np.testing.assert_allclose(stepper.forces(q, v), F, rtol=0, atol=1e-12 * (1 + np.abs(F).max()))
    lam0 = np.asarray(model.functions["accel"](0.0, model.q0, model.v0, [], [])[1]).ravel()
    np.testing.assert_allclose(stepper.multipliers(model.q0, model.v0), lam0, rtol=0,
                               atol=1e-10 * (1 + np.abs(lam0).max()))
    assert model_data(model).conservative is _is_conservative(model) is False
    made = []
    monkeypatch.setattr(function_set, "HOOKS", [made.append])
    monkeypatch.setitem(model.__dict__, "functions", _Blocked())       # the model is frozen: its dict
    monkeypatch.setitem(model.__dict__, "potential_terms", _Blocked().__getitem__)
    traj = nc.simulate(model, 0.3, 0.01, method="stepper", **options)
    assert traj.info["kernels"] == "tables" and traj.info["complete"] and made == []
    np.testing.assert_allclose(traj.lam[0], lam0, rtol=0, atol=1e-10 * (1 + np.abs(lam0).max()))
    assert traj.info["energy"]["relative"] < 1e-4


def test_batch_and_sweep_run_on_the_tables_without_compiling(library, monkeypatch):
    """simulate_batch and sweep of a covered model run on the element library with the
    compiler blocked: each run equals the single run of nc.simulate bit for bit (the same
    loops, the same λ0); a sweep over initial velocities completes every run."""
    import ncgen.codegen.compile_cache as cc

    def no_compile(*args, **kwargs):
        raise AssertionError("the compiler was called")

    model = every_force(3, name="batch_forces").build()
    monkeypatch.setattr(cc, "compile_package", no_compile)
    single = nc.simulate(model, 0.3, 0.01, method="stepper")
    for check, project in ((True, True), (False, False)):
        b = nc.simulate_batch(model, 0.3, 0.01, v0=np.tile(model.v0, (3, 1)), check=check, project=project, workers=2)
        assert b.info["kernels"] == "tables" and np.all(b.ok), b.message
        for k in range(3):
            np.testing.assert_array_equal(b.q[k], single.q)
            np.testing.assert_array_equal(b.lam[k], single.lam)
            np.testing.assert_array_equal(b.potential[k], single.potential)
    rng = np.random.default_rng(4)
    puck = list(model.layout.member_indices("puck"))
    v0 = np.tile(model.v0, (4, 1))
    v0[:, puck] += 0.2 * rng.normal(size=(4, 3))
    swept = nc.sweep(model, None, t_end=0.2, dt=0.01, v0=v0, workers=1, progress=False)
    assert np.all(swept.summary["status"] == 0), swept.summary["message"]
    np.testing.assert_allclose(swept["q"][:, -1, puck[0]] - model.q0[puck[0]],
                               0.2 * v0[:, puck[0]] + 0.5 * 0.4 / 0.3 * 0.2 ** 2, atol=1e-9)

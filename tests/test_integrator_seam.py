"""The integrator seam (ncgen/runtime/integrator.py): one class per method, prepared for a
model and its options, run on a consistent Run; simulate only dispatches. The refusals that
belong to one integrator's options keep their messages."""
from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import NcgenError
from ncgen.runtime import simulation
from ncgen.runtime.options import METHODS, SimulationOptions

G = 9.81


def pendulum():
    """A uniform rod (a body, 0.8 m, 2 kg) on a hinge at the origin, its torque the input."""
    s = nc.System("seam", gravity=(0, 0, -G))
    rod = s.add_body("rod", mass=2.0, inertia=np.diag([1e-4, 0.1067, 0.1067]), position=(0.4, 0, 0))
    s.add_joint(nc.Revolute(s.ground, rod, at=(0, 0, 0), axis=(0, 1, 0), name="hinge",
                            effort=s.add_input("tau", 1)[0]))
    return s


def test_every_method_has_an_integrator_and_every_option_a_reader():
    assert set(simulation.INTEGRATORS) == set(METHODS) - {"auto"}
    fields = {f.name: f for f in dataclasses.fields(SimulationOptions)}
    read = {"method", "ic_tolerance"}                       # read by simulate itself
    for method, cls in simulation.INTEGRATORS.items():
        assert cls.METHOD == method == cls.Options.METHOD and callable(cls.run)
        group = {f.name: f for f in dataclasses.fields(cls.Options)}
        assert set(group) <= set(fields), (method, set(group) - set(fields))
        assert all(group[n].type == fields[n].type for n in group), method       # the same field, typed alike
        assert cls.Options.__dataclass_params__.frozen
        read |= set(group)
    assert read == set(fields), f"options no integrator reads: {set(fields) - read}"


def test_each_integrator_takes_its_group_whole():
    """An integrator keeps its group of the options (the fields it reads, as given), and the
    group goes down: a field outside it is not there to be read."""
    model = pendulum().build()
    opts = SimulationOptions(rtol=1e-7, substeps=3, newton_tol=1e-11, project=False)
    for method, cls in simulation.INTEGRATORS.items():
        if method == "rolling":
            continue                                        # needs rolling elements
        group = cls(model, opts).opts
        assert type(group) is cls.Options
        assert {n: getattr(group, n) for n in cls.Options.names()} == {n: getattr(opts, n) for n in cls.Options.names()}
    assert not hasattr(simulation.INTEGRATORS["idas"](model, opts).opts, "newton_tol")


@pytest.mark.parametrize("kwargs, method, match", [
    ({"max_halvings": 11}, "stepper", "max_halvings: expected 0 to 10 step halvings, got 11"),
    ({"newton_tol": -1.0}, "stepper", "newton_tol: expected a positive Newton tolerance, got -1.0"),
    ({"estimate": "global"}, "stepper", "estimate: expected True, False, 'local' or 'shadow', got 'global'"),
    ({"scheme": "rk4"}, "stepper", "scheme: expected one of auto, rattle, rattle4"),
    ({"project": "yes"}, "idas", "project: expected True, False or 'auto', got 'yes'"),
    ({"linear_solver": 3}, "idas", "linear_solver: expected the name of a CasADi linear solver, got 3"),
])
def test_a_bad_option_is_named_with_its_integrator(kwargs, method, match):
    """Checked by the integrator's group when the options are made, whichever method they
    choose, and by the group itself."""
    said = re.escape(match) + r".*\(an option of method=" + repr(method) + r"\)"
    for chosen in ("auto", "idas", "joint", "stepper"):
        with pytest.raises(NcgenError, match=said):
            SimulationOptions(method=chosen, **kwargs)
    group = simulation.INTEGRATORS[method].Options
    good = group.of(SimulationOptions())
    with pytest.raises(NcgenError, match=said):
        dataclasses.replace(good, **kwargs)


def test_the_stepper_s_rule_between_options_is_its_own():
    """estimate='shadow' with rtol: refused when the stepper is prepared, not when another
    method is chosen (IDAS ignores both)."""
    model = pendulum().build()
    opts = SimulationOptions(estimate="shadow", rtol=1e-8)
    simulation.INTEGRATORS["idas"](model, opts)
    with pytest.raises(NcgenError, match="estimate: 'shadow' is the fixed-step run's shadow run"):
        simulation.INTEGRATORS["stepper"](model, opts)


def test_simulate_prepares_once_and_runs_a_consistent_run(monkeypatch):
    """A stand-in integrator sees what simulate hands every integrator: the grid, the
    inputs, a state on the constraints and multipliers that solve the KKT system."""
    model = pendulum().build()
    seen = {}

    class Recorder:
        METHOD, Options = "idas", simulation.INTEGRATORS["idas"].Options

        def __init__(self, m, opts):
            seen["prepared"] = seen.get("prepared", 0) + 1
            seen["opts"] = opts

        def run(self, run):
            seen["run"] = run
            return "ran"

    monkeypatch.setitem(simulation.INTEGRATORS, "idas", Recorder)
    q0 = model.q0 + 0.01                                     # off the constraints: projected
    assert nc.simulate(model, 0.5, 0.1, method="idas", q0=q0, u=[0.3], rtol=1e-9, ic_tolerance=None) == "ran"
    run = seen["run"]
    assert seen["prepared"] == 1 and seen["opts"].rtol == 1e-9
    np.testing.assert_allclose(run.t, np.linspace(0.0, 0.5, 6), atol=1e-15)
    assert run.U.shape == (6, 1) and np.all(run.U == 0.3)
    assert np.max(np.abs(model.phi(run.q))) < 1e-10
    assert np.max(np.abs(model.A(run.q) @ run.v)) < 1e-10
    lam = run.multipliers(0.0, run.q, run.v, run.U[0])
    np.testing.assert_allclose(lam, nc.forward_dynamics(model, run.q, run.v, u=run.U[0])[1], rtol=1e-9, atol=1e-9)
    assert run.controller is None and run.feedback is None and run.why_not is None


def test_a_python_feedback_reaches_the_run_as_inputs_at_a_state(monkeypatch):
    model = pendulum().build()
    seen = {}

    class Recorder:
        METHOD, Options = "stepper", simulation.INTEGRATORS["stepper"].Options

        def __init__(self, m, opts):
            pass

        def run(self, run):
            seen["run"] = run

    monkeypatch.setitem(simulation.INTEGRATORS, "stepper", Recorder)
    nc.simulate(model, 0.2, 0.1, method="stepper", u=lambda t, q, v: [t + q[0] + 2 * v[0]])
    run = seen["run"]
    assert run.feedback[0] == "natural"
    q, v = run.q, run.v + 1.0
    np.testing.assert_allclose(run.feedback_input(0.5, q, v), [0.5 + q[0] + 2 * v[0]])


def test_auto_names_why_the_joint_loop_was_not_used():
    model = pendulum().build()
    traj = nc.simulate(model, 0.1, 0.05, backend="vm")
    assert traj.info["method"] == "idas" and traj.info["auto"] == "backend='vm' compiles nothing"


@pytest.mark.parametrize("method", ["idas", "stepper"])
def test_the_joint_loops_integrator_option_is_refused_elsewhere(method):
    with pytest.raises(NcgenError, match=rf"integrator: only method='joint' or 'rolling' takes an integrator \(got 'rk4' "
                                         rf"with method='{method}'\)"):
        nc.simulate(pendulum().build(), 0.1, 0.05, method=method, integrator="rk4")


def test_the_stepper_refuses_a_compiled_controller_and_joint_dynamics():
    model = pendulum().build()
    said = "method='stepper' does not take a compiled controller or joint_dynamics=True"
    with pytest.raises(NcgenError, match=said):
        nc.simulate(model, 0.1, 0.05, method="stepper", joint_dynamics=True)
    with pytest.raises(NcgenError, match=said):
        nc.simulate(model, 0.1, 0.05, method="stepper", u=nc.PD(10.0, 1.0, target=0.0))


def test_idas_refuses_nonsmooth_contacts_by_name():
    s = nc.System("drop")
    b = s.add_body("b", mass=1.0, inertia=np.eye(3) * 0.004, position=(0, 0, 1))
    s.add_contact(nc.SpherePlane(b, radius=0.1))
    model = s.build(contacts="nonsmooth")
    for method in ("idas", "auto"):
        with pytest.raises(NcgenError, match=r"model 'drop' was built with contacts='nonsmooth', which only the "
                                             r"compiled stepper handles"):
            nc.simulate(model, 0.1, 0.05, method=method)


def test_each_integrator_runs_the_pendulum_like_its_closed_form_energy():
    """The three integrators on a frictionless pendulum: total energy is conserved (an
    independent check of each run through the seam)."""
    model = pendulum().build()
    q0, _ = model.from_joint_space([math.pi / 3])                 # 60° from horizontal
    for method in ("joint", "idas", "stepper"):
        traj = nc.simulate(model, 1.0, 0.05, method=method, q0=q0, **({"substeps": 20} if method == "stepper" else {}))
        assert traj.info["method"] == method
        e = traj.energy
        assert np.ptp(e) < 1e-5 * (1 + np.abs(e).max()), (method, np.ptp(e))


def test_a_stepper_warning_names_the_callers_line(monkeypatch):
    """Warnings raised deep in the stepper's checks name the line that called simulate,
    whatever the depth of the integrator seam (errors.user_stacklevel)."""
    import ncgen.codegen.stepper_package as package

    s = nc.System("one_sweep")
    p = s.add_point("p", mass=1.0, position=(0, 0, 0.05))
    s.add_contact(nc.SpherePlane(p, radius=0.0, name="floor"))
    s.add_contact(nc.SpherePlane(p, radius=0.0, point=(0, 0, 0), normal=(0, 0.6, 0.8), name="slope"))
    monkeypatch.setattr(package, "PGS_MAX_ITER", 1)            # solves that stop early: warned
    model = s.build(contacts="nonsmooth")
    with pytest.warns(UserWarning, match="stopped at") as caught:   # the package's limit: the flat kernels
        nc.simulate(model, 0.2, 0.01, method="stepper", substeps=10, check=False, kernels="flat")
    assert {w.filename for w in caught if "stopped at" in str(w.message)} == {__file__}

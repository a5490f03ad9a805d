"""``nc.SimulationOptions``: one frozen, validated object; ``simulate``'s keyword arguments are
shortcuts for its fields."""
import dataclasses

import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import NcgenError


def pendulum():
    s = nc.System("pendulum", gravity=(0, -9.81))
    b = s.add_bar("b", coords="rr", mass=1.0, ends=[(0, 0), (1, 0)])
    s.add_joint(nc.Revolute(s.ground, b, at=(0, 0)))
    return s.build()


def test_defaults_are_those_of_simulate():
    o = nc.SimulationOptions()
    assert (o.method, o.rtol, o.atol, o.hold, o.max_steps, o.project) == ("auto", None, None, "zoh", 50_000, "auto")
    assert (o.substeps, o.order, o.check, o.estimate) == (1, 4, True, True)


def test_frozen():
    with pytest.raises(dataclasses.FrozenInstanceError):
        nc.SimulationOptions().rtol = 1e-3


@pytest.mark.parametrize("kwargs, match", [
    ({"method": "euler"}, "method: expected one of auto, joint, idas, stepper"),
    ({"rtol": -1.0}, "rtol: expected a positive tolerance"),
    ({"atol": float("nan")}, "atol: expected a positive tolerance"),
    ({"hold": "cubic"}, "hold: expected one of"),
    ({"backend": "gpu"}, "backend: expected one of"),
    ({"project": "yes"}, "project: expected True, False or 'auto'"),
    ({"substeps": 0}, "substeps: expected a positive number"),
    ({"substeps": 1.5}, "substeps: expected a positive number"),
    ({"newton_tol": 0.0}, "newton_tol: expected a positive Newton tolerance"),
    ({"max_newton": 0}, "max_newton: expected at least one Newton iteration"),
    ({"max_halvings": 11}, "max_halvings: expected 0 to 10"),
    ({"order": 3}, "order: expected 2"),
    ({"max_steps": 0}, "max_steps: expected a positive number"),
    ({"check": "no"}, "check: expected True or False"),
    ({"integrator": "euler"}, "integrator: expected one of dopri5, rk4"),
    ({"joint_dynamics": "yes"}, "joint_dynamics: expected True or False"),
])
def test_bad_values_name_the_option(kwargs, match):
    with pytest.raises(NcgenError, match=match):
        nc.SimulationOptions(**kwargs)
    with pytest.raises(NcgenError, match=match):         # the shortcut is validated the same way
        nc.simulate(pendulum(), 0.1, 0.01, **kwargs)


def test_integral_values_are_accepted_as_counts():
    o = nc.SimulationOptions(substeps=np.int64(4), max_steps=100.0)
    assert o.substeps == 4 and isinstance(o.substeps, int) and o.max_steps == 100


def test_unknown_shortcut_is_an_error_naming_the_options():
    with pytest.raises(NcgenError, match="no option named 'substep'.*substeps"):
        nc.simulate(pendulum(), 0.1, 0.01, substep=2)
    with pytest.raises(NcgenError, match="options: expected an nc.SimulationOptions"):
        nc.simulate(pendulum(), 0.1, 0.01, options={"rtol": 1e-6})


def test_options_object_and_shortcuts_give_the_same_run():
    model = pendulum()
    opts = nc.SimulationOptions(rtol=1e-9, atol=1e-11)
    a = nc.simulate(model, 0.5, 0.05, options=opts)
    b = nc.simulate(model, 0.5, 0.05, rtol=1e-9, atol=1e-11)
    np.testing.assert_array_equal(a.q, b.q)
    assert a.info["rtol"] == 1e-9 and a.info["atol"] == 1e-11
    c = nc.simulate(model, 0.5, 0.05, options=opts, rtol=1e-6)        # a shortcut overrides the object
    assert c.info["rtol"] == 1e-6 and c.info["atol"] == 1e-11
    assert opts.rtol == 1e-9                                            # which is left as it was
    E = a.energy                                   # a conservative run: energy kept to the tolerance
    assert np.max(np.abs(E - E[0])) < 1e-6 * max(1.0, abs(E[0]))


def test_simulate_signature_lists_every_option():
    import inspect
    params = inspect.signature(nc.simulate).parameters
    for f in dataclasses.fields(nc.SimulationOptions):
        assert params[f.name].default == f.default and params[f.name].kind is inspect.Parameter.KEYWORD_ONLY

"""The compiled stepper (RATTLE, generated C): constraints at every step, second order,
agreement with IDAS on every shipped example and on a spring-damper system, bounded energy,
inputs and parameters, failures naming the time, and the C-only example program."""
from __future__ import annotations

import shutil
import subprocess
import warnings
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import NcgenError, SimulationError
from ncgen.runtime.stepper import step_inputs

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples"
TOL = 1e-10
needs_cc = pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None,
                              reason="no C compiler")
pytestmark = needs_cc


def example_models() -> list[Path]:
    """The model files among ``examples/*.toml`` (problem files have no [[members]])."""
    return [p for p in sorted(EXAMPLES.glob("*.toml")) if "[[members]]" in p.read_text()]


def example(path: Path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return nc.System.from_toml(path).build()


def pendulum():
    """A bar hanging from a ground point by a shared end (spherical joint), horizontal at rest."""
    s = nc.System("pendulum", gravity=(0.0, 0.0, -9.81))
    s.add_bar("bar", "rr", mass=1.0, ends=[s.ground.point((0.0, 0.0, 0.0)), (1.0, 0.0, 0.0)])
    return s.build()


def chain(n: int = 3):
    s = nc.System(f"chain{n}", gravity=(0.0, 0.0, -9.81))
    start = s.ground.point((0.0, 0.0, 0.0))
    for k in range(n):
        start = s.add_bar(f"b{k}", "rr", mass=1.0, ends=[start, (k + 1.0, 0.0, 0.2 * k)]).end(1)
    return s.build()


def spring_damper():
    """A bar pendulum whose tip is tied to a point mass by a damped spring, the mass hanging
    from the ground by another damped spring whose stiffness is a parameter, pushed along y
    by an input force: velocity-dependent forces, a parameter and an input."""
    s = nc.System("spring_damper", gravity=(0.0, 0.0, -9.81))
    bar = s.add_bar("bar", "rr", mass=1.0, ends=[s.ground.point((0.0, 0.0, 0.0)), (1.0, 0.0, 0.0)])
    mass = s.add_point("mass", mass=0.5, position=(1.0, 0.3, -0.5), velocity=(0.0, 0.5, 0.0))
    k = s.add_parameter("k", 40.0)
    push = s.add_input("push")
    s.add_force(nc.Spring(bar, (0.5, 0.0, 0.0), mass, (0.0, 0.0, 0.0), k=80.0, rest_length=0.4, damping=2.0))
    s.add_force(nc.Spring(s.ground, (1.0, 0.0, 0.5), mass, (0.0, 0.0, 0.0), k=k, rest_length=0.8, damping=1.5))
    s.add_force(nc.PointForce(mass, (0.0, 0.0, 0.0), force=ca.vertcat(0, push, 0)))
    return s.build()


# ------------------------------------------------------------------ constraints
def test_both_constraint_levels_hold_at_every_step():
    model = spring_damper()
    traj = nc.simulate(model, 1.0, 0.002, method="stepper", u=lambda t: [np.sin(5 * t)])
    assert traj.info["complete"] and traj.info["stats"]["nsteps"] == 500
    assert np.all(traj.constraint_residual <= TOL)
    scale = 1.0 + np.max(np.abs(traj.v), axis=1)
    assert np.all(traj.velocity_residual <= TOL * scale)


# ------------------------------------------------------------------ accuracy
def test_second_order_convergence_against_idas():
    model = chain(3)
    ref = nc.simulate(model, 0.5, 0.05, rtol=1e-12, atol=1e-12)
    errors = [np.max(np.abs(nc.simulate(model, 0.5, 0.05, method="stepper", substeps=s, scheme="rattle").q - ref.q))
              for s in (10, 20, 40)]
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert np.all((3.6 < ratios) & (ratios < 4.4)), (errors, ratios)


def test_second_order_with_dampers_parameters_and_linear_inputs():
    model = spring_damper()
    u = lambda t: [np.sin(4 * t)]  # noqa: E731
    opts = dict(u=u, hold="linear", p={"k": 60.0})
    ref = nc.simulate(model, 0.6, 0.05, rtol=1e-12, atol=1e-12, **opts)
    errors = [np.max(np.abs(nc.simulate(model, 0.6, 0.05, method="stepper", substeps=s, scheme="rattle", **opts).q
                            - ref.q))
              for s in (10, 20, 40)]
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert np.all((3.5 < ratios) & (ratios < 4.5)), (errors, ratios)


def test_step_inputs_hold():
    t = np.array([0.0, 1.0, 2.0])
    U = np.array([[0.0], [2.0], [6.0]])
    assert step_inputs(U, t, "zoh", 2).ravel().tolist() == [0.0, 0.0, 2.0, 2.0]
    assert step_inputs(U, t, "linear", 2).ravel().tolist() == [0.5, 1.5, 3.0, 5.0]
    assert step_inputs(np.zeros((3, 0)), t, "zoh", 2) is None


#: Steps (s) per example: fine enough for ~1e-3 agreement over the span; the heavy top
#: spins at 150 rad/s, so its step resolves the spin.  The capstan winch's rope material (1 g
#: per drum) sticks by the law tanh(ṡ/v_s), v_s = 1e-4 m/s: a damper of slope F_max/v_s on
#: 1 g, far stiffer than any step resolves.  RATTLE's second half-kick takes it at the
#: half-step rate w, so the material's end-of-step rate rings (v⁺ ≈ 2w − v: the scheme does
#: not damp stiff dampers) and the load growing over a step kicks it by ≈ h Ṗ h / 2m; once
#: |v| passes ≈ v_s, the next step's Newton starts on the flat part of the tanh and cycles
#: (a Python replay of the Newton iteration with the kernels: at h = 1 ms the first step kicks
#: the material to 0.26 m/s, the second's iterates then alternate between ±2e-2 m/s; at
#: h = 2e-5 s they grow from ±1.2e-4 to ±1e-2 m/s at t = 1.46 ms).  Below h ≈ √(2 m v_s / Ṗ)
#: ≈ 2e-5 s the kicks stay inside the tanh's linear part: 1e-5 s runs the 0.3 s, 2e-5 s fails
#: at t = 1.6 ms (halving does not help: the halves start from the same ringing rate).
STEP = {"heavy_top": 1e-4, "capstan_winch": 5e-6}


#: Examples of the slow tier: capstan_winch (60 000 steps of 5 µs; fast: the other examples,
#: tests/test_capstan_winch.py), tensegrity (the largest model, its package compiled; fast: the other
#: examples, the cables' compiled stepper against closed forms in tests/test_clustered_cable.py and
#: tests/test_capstan_cable.py).
SLOW_EXAMPLES = {"capstan_winch", "tensegrity"}


@pytest.mark.parametrize("path", [pytest.param(p, marks=pytest.mark.slow) if p.stem in SLOW_EXAMPLES else p
                                  for p in example_models()], ids=lambda p: p.stem)
def test_agrees_with_idas_on_shipped_examples(path):
    if "[[contacts]]" in path.read_text():
        pytest.skip("a contact scene: its smooth law (what IDAS integrates) is stiff at impact; the contact "
                    "examples are checked against closed forms in test_contact*.py and run by the sanitizer test")
    model = example(path)
    t_end, dt = model.t0 + 0.3, 0.01
    u = (lambda t: [0.5 * np.sin(3 * t)] * model.nu) if model.nu else None
    ref = nc.simulate(model, t_end, dt, rtol=1e-10, atol=1e-10, u=u)
    sub = round(dt / STEP.get(model.name, 1e-3))
    fine = nc.simulate(model, t_end, dt, method="stepper", substeps=sub, u=u, scheme="rattle")
    coarse = nc.simulate(model, t_end, dt, method="stepper", substeps=sub // 2, u=u, scheme="rattle")
    err_fine, err_coarse = (np.max(np.abs(tr.q - ref.q)) for tr in (fine, coarse))
    size = 1.0 + np.max(np.abs(ref.q))
    assert err_fine <= 2e-3 * size, (model.name, err_fine)
    assert err_fine <= max(0.35 * err_coarse, 1e-7 * size), (model.name, err_fine, err_coarse)
    assert np.all(fine.constraint_residual <= TOL)


def test_pendulum_matches_idas_and_its_multipliers():
    model = pendulum()
    ref = nc.simulate(model, 1.0, 0.01, rtol=1e-11, atol=1e-11)
    traj = nc.simulate(model, 1.0, 0.01, method="stepper", substeps=20)
    assert np.max(np.abs(traj.q - ref.q)) < 1e-5
    assert np.max(np.abs(traj.lam - ref.lam)) < 2e-2 * np.max(np.abs(ref.lam))  # first order in h


# ------------------------------------------------------------------ long runs
def test_energy_of_a_conservative_system_stays_bounded():
    """A spherical pendulum swinging and turning for 200 s (20 000 steps): the energy error
    oscillates (RATTLE is symplectic) instead of drifting.  (The phase error grows, so the
    run is unchecked: checked, it stops where the estimated error passes 1 % of the size.)"""
    s = nc.System("spherical_pendulum", gravity=(0.0, 0.0, -9.81))
    s.add_bar("bar", "rr", mass=1.0, ends=[s.ground.point((0.0, 0.0, 0.0)), (1.0, 0.0, 0.0)],
              velocity=(0.0, 1.0, 0.0), angular_velocity=(0.0, 0.0, 2.0))
    traj = nc.simulate(s.build(), 200.0, 0.01, method="stepper", check=False)
    error = np.abs(traj.energy - traj.energy[0]) / traj.energy_scale
    quarter = len(error) // 4
    assert np.max(error) < 1e-3
    assert np.mean(error[-quarter:]) < 1.1 * np.mean(error[:quarter])
    assert np.all(traj.constraint_residual <= TOL)


# ------------------------------------------------------------------ failures
def test_newton_failure_names_the_time_and_keeps_the_trajectory():
    model = pendulum()
    with pytest.raises(SimulationError, match=r"step from t = 0\.3 s.*did not converge") as info:
        nc.simulate(model, 1.0, 0.1, method="stepper", max_newton=1, newton_tol=1e-300,
                    q0=model.q0, t0=0.3)
    assert info.value.time == pytest.approx(0.3)
    assert info.value.trajectory is not None and len(info.value.trajectory) == 1


def test_a_failing_step_is_split_into_two_half_steps():
    """The double pendulum's first step of 0.3 s fails (Newton diverges); split once, it is
    exactly the two steps of 0.15 s a finer run takes (same cold start, same predictor)."""
    from ncgen.runtime.stepper_library import load_stepper

    model = example(EXAMPLES / "double_pendulum.toml")
    stepper = load_stepper(model)
    args = (None, model.p0, TOL, 12)
    *_, status, done, splits = stepper.simulate(model.q0, model.v0, 0.0, 0.3, 1, 1, *args, 0)
    assert (status, done, splits) == (1, 0, 0)
    Q, V, _, ITER, status, done, splits = stepper.simulate(model.q0, model.v0, 0.0, 0.3, 1, 1, *args, 1)
    assert (status, done, splits) == (0, 1, 1)
    Q2, V2, _, ITER2, status, done, splits = stepper.simulate(model.q0, model.v0, 0.0, 0.15, 2, 2, *args, 0)
    assert (status, done, splits) == (0, 2, 0)
    np.testing.assert_array_equal(Q, Q2)
    np.testing.assert_array_equal(V, V2)
    assert ITER[0] > ITER2[0]


def test_split_steps_keep_the_grid_and_the_constraints():
    """At dt = 0.2 s the double pendulum needs split steps (and fails without them); the
    trajectory stays on the 0.2 s grid and on both constraint levels; after the first step
    it is within the error such a coarse step makes (5 % of the motion) of IDAS."""
    model = example(EXAMPLES / "double_pendulum.toml")
    with pytest.raises(SimulationError, match="did not converge"):
        nc.simulate(model, 1.2, 0.2, method="stepper", max_halvings=0, scheme="rattle")
    with pytest.raises(SimulationError, match=r"not trustworthy: .*substeps=") as failure:
        nc.simulate(model, 1.2, 0.2, method="stepper", scheme="rattle")
    assert failure.value.trajectory.t[-1] == 0.0
    traj = nc.simulate(model, 1.2, 0.2, method="stepper", check=False, scheme="rattle")
    assert traj.info["stats"]["step_splits"] > 0
    np.testing.assert_allclose(traj.t, np.linspace(0.0, 1.2, 7), atol=1e-12)
    assert np.all(traj.constraint_residual <= TOL)
    reference = nc.simulate(model, 1.2, 0.2, rtol=1e-10, atol=1e-12)
    assert np.max(np.abs(traj.q[1] - reference.q[1])) < 0.05 * np.max(np.abs(reference.q - reference.q[0]))


def test_bad_stepper_options():
    model = pendulum()
    for kwargs, match in (({"substeps": 0}, "substeps"), ({"newton_tol": -1.0}, "tol"),
                          ({"max_newton": 0}, "max_iter"), ({"hold": "cubic"}, "hold"),
                          ({"max_halvings": -1}, "max_halvings"), ({"max_halvings": 11}, "max_halvings")):
        with pytest.raises(NcgenError, match=match):
            nc.simulate(model, 0.1, 0.01, method="stepper", **kwargs)


# ------------------------------------------------------------------ C only
def parse_demo(text: str) -> dict[str, np.ndarray]:
    values: dict[str, list[float]] = {}
    for line in text.splitlines():
        key, _, value = line.partition(" = ")
        name = key.split("[")[0]
        values.setdefault(name, []).append(float(value))
    return {k: np.array(v) for k, v in values.items()}


@pytest.mark.slow      # make builds and runs an example's C program; fast:
#                       tests/test_model_package.py::test_main_c_builds_without_constraints_parameters_or_markers
@pytest.mark.skipif(shutil.which("make") is None, reason="make not installed")
def test_c_example_program_prints_the_python_final_state(tmp_path):
    model = spring_damper()
    pkg = nc.generate(model, tmp_path / model.name)
    subprocess.run(["make", "-s"], cwd=pkg.path, check=True, capture_output=True)
    out = subprocess.run([str(pkg.path / f"{model.name}_simulate"), "0.5", "0.001"], cwd=pkg.path,
                         capture_output=True, text=True, check=True).stdout
    demo = parse_demo(out)
    traj = nc.simulate(model, 0.5, 0.5, method="stepper", substeps=500)
    assert demo["steps"][0] == 500 and demo["t"][0] == 0.5
    assert demo["newton_iterations"][0] == traj.info["stats"]["newton_iterations"]
    np.testing.assert_allclose(demo["q"], traj.q[-1], rtol=0, atol=1e-12)
    np.testing.assert_allclose(demo["v"], traj.v[-1], rtol=0, atol=1e-12)
    # the program prints the last step's μ (first order in h = 1 ms); Python reports the KKT
    # multipliers of the final state
    np.testing.assert_allclose(demo["lam"], traj.lam[-1], rtol=0, atol=1e-2 * (1 + np.max(np.abs(traj.lam[-1]))))
    bad = subprocess.run([str(pkg.path / f"{model.name}_simulate"), "-1"], capture_output=True, text=True)
    assert bad.returncode == 2 and "usage" in bad.stderr

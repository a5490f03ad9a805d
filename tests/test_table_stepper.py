"""The compiled stepper driven by element tables (``kernels="tables"``, issue 34): checked
against closed forms and conservation laws (a pendulum's exact period, a damped oscillator,
energy conserved on a conservative chain, the energy a chain of spring-dampers loses equal to
its dampers' dissipation computed here from the trajectory), against the flat stepper (the
same scheme, equal to ~1e-12) on every covered shipped example and on a chain with springs
and dampers, and stepped in a process with no compiler on PATH; the automatic choice, the
override, and the refusal naming the element that is not covered."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.special import ellipk
from table_models import chain_system

import ncgen as nc
from ncgen.codegen.compiler import CANDIDATES
from ncgen.codegen.model_tables import UnsupportedElements
from ncgen.errors import NcgenError
from ncgen.runtime.table_library import load_element_library
from ncgen.runtime.table_stepper import stepper_kernels
from no_compiler import run_without_compiler

ROOT = Path(__file__).resolve().parent.parent
#: Shipped examples whose every element is covered, and the agreement of the two forms (relative
#: to the scale of q).  The heavy top spins fast (its KKT matrices are ill-conditioned at these
#: steps): the two forms' round-off (their QR factorisations differ in column order and
#: reflector details) grows to 2.6e-9 (RATTLE4) and 3.6e-8 (rtol = 1e-6) over 0.5 s.
COVERED = {"chain": 1e-12, "double_pendulum": 1e-12, "fourbar_3d": 1e-12, "heavy_top": 1e-7}

pytestmark = pytest.mark.skipif(not any(shutil.which(c) for c in CANDIDATES) and not os.environ.get("CC"),
                                reason="no C compiler to build the element library")


@pytest.fixture(scope="module")
def library():
    return load_element_library()


def pendulum(theta0: float, length: float = 0.8, mass: float = 1.3):
    """A planar uniform bar hinged at the origin (a ground point), released at rest at
    ``theta0`` from the downward vertical."""
    s = nc.System("bar_pendulum", gravity=(0.0, -9.81))
    tip = (length * np.sin(theta0), -length * np.cos(theta0))
    s.add_bar("bar", coords="rr", mass=mass, ends=[s.ground.point((0.0, 0.0)), tip])
    return s


def test_pendulum_period_equals_the_exact_one(library):
    """A bar pendulum released at 0.6 rad: the period from the tip's crossings of the
    vertical equals 4 √(I_O / (m g d)) K(sin(θ0/2)), I_O = m L²/3, d = L/2."""
    L, theta0, g = 0.8, 0.6, 9.81
    model = pendulum(theta0, L).build()
    traj = nc.simulate(model, 3.0, 0.002, method="stepper", substeps=2)
    assert traj.info["kernels"] == "tables"
    x = traj.point("bar", (L / 2, 0.0))[:, 0]
    i = np.nonzero((x[:-1] > 0) & (x[1:] <= 0))[0]          # crossings from right to left
    crossings = traj.t[i] + x[i] / (x[i] - x[i + 1]) * (traj.t[i + 1] - traj.t[i])
    periods = np.diff(crossings)
    exact = 4 * np.sqrt((L ** 2 / 3) / (g * L / 2)) * ellipk(np.sin(theta0 / 2) ** 2)
    assert len(periods) >= 1
    np.testing.assert_allclose(periods, exact, rtol=2e-6)


def test_damped_oscillator_equals_its_closed_form(library):
    """A point mass on a spring-damper to a ground point, moving along the spring (nc = 0):
    x(t) = l0 + e^{−ζωt} (x0 cos ω_d t + ζω x0 / ω_d sin ω_d t)."""
    m, k, c, l0, x0 = 0.7, 40.0, 0.9, 0.5, 0.12
    s = nc.System("oscillator", gravity=(0.0, 0.0, 0.0))
    p = s.add_point("p", mass=m, position=(l0 + x0, 0.0, 0.0))
    s.add_force(nc.Spring(s.ground, (0.0, 0.0, 0.0), p, (0.0, 0.0, 0.0), k=k, rest_length=l0, damping=c))
    traj = nc.simulate(s.build(), 2.0, 0.01, method="stepper", substeps=5)
    assert traj.info["kernels"] == "tables"
    w = np.sqrt(k / m)
    zeta = c / (2 * np.sqrt(k * m))
    wd = w * np.sqrt(1 - zeta ** 2)
    t = traj.t
    exact = l0 + np.exp(-zeta * w * t) * (x0 * np.cos(wd * t) + zeta * w * x0 / wd * np.sin(wd * t))
    np.testing.assert_allclose(traj.q[:, 0], exact, rtol=0, atol=1e-8)
    np.testing.assert_allclose(traj.q[:, 1:], 0.0, atol=1e-14)


def test_conservative_chain_keeps_its_energy(library):
    """A 6-bar chain under gravity: RATTLE4's energy stays within 1e-7 of its start."""
    model = chain_system(6).build()
    traj = nc.simulate(model, 2.0, 0.01, method="stepper", substeps=4)
    assert traj.info["kernels"] == "tables" and traj.info["complete"]
    scale = np.max(np.abs(traj.kinetic)) + 1.0
    assert np.max(np.abs(traj.energy - traj.energy[0])) < 1e-7 * scale
    assert np.max(traj.constraint_residual) < 1e-9


def test_spring_damper_chain_loses_what_its_dampers_dissipate(library):
    """E(t) − E(0) = −∫ Σ c l̇² dt, the dissipation computed here from the spring lengths of
    the trajectory (l̇ by central differences of a fine output grid)."""
    s = chain_system(4, springs=True)
    model = s.build()
    traj = nc.simulate(model, 1.0, 0.001, method="stepper", scheme="rattle4")
    assert traj.info["kernels"] == "tables"
    loss = np.zeros(len(traj.t))
    for f in s.forces:
        a = traj.point(f.a.name, f.at_a)
        b = np.asarray(f.at_b, float)
        lengths = np.linalg.norm(a - b, axis=1)
        rate = np.gradient(lengths, traj.t, edge_order=2)
        loss += f.damping * rate ** 2
    dissipated = np.concatenate([[0.0], np.cumsum((loss[1:] + loss[:-1]) / 2 * np.diff(traj.t))])
    assert dissipated[-1] > 0.05
    np.testing.assert_allclose(traj.energy - traj.energy[0], -dissipated, rtol=0, atol=2e-4 * dissipated[-1])


def test_auto_choice_override_and_refusal(library):
    """kernels="auto" picks the tables for a covered model and flat for one that is not;
    kernels="tables" on that one names the element not covered; a bad value is refused."""
    covered = chain_system(3).build()
    assert stepper_kernels(covered, "auto") == "tables"
    assert stepper_kernels(covered, "flat") == "flat"
    s = chain_system(3, name="pushed")
    s.add_force(nc.PointForce(s.members["b2"], (0.0, 0.0, 0.0), force=(0.0, "sin(t)", 0.0), name="push"))
    pushed = s.build()
    assert stepper_kernels(pushed, "auto") == "flat"
    with pytest.raises(UnsupportedElements, match=r"PointForce of t, inputs or parameters \(force 'push'\)"):
        nc.simulate(pushed, 0.1, 0.01, method="stepper", kernels="tables")
    with pytest.raises(NcgenError, match="kernels: expected one of 'auto', 'tables', 'flat'"):
        nc.SimulationOptions(kernels="fast")


CHILD = r"""
import json, sys, time
import numpy as np
import ncgen as nc
from no_compiler import chain, forbid_compiler, fourbar
from ncgen.runtime.table_library import load_element_library
from table_models import every_force

forbid_compiler()
load_element_library()              # the library found in the cache, loaded
out = {}
for system in (chain("nocc_chain13", 13, (0.29, 0.13, -0.04)), fourbar("nocc_fourbar"), every_force(3, "nocc_forces3d"),
               every_force(2, "nocc_forces2d")):
    t = time.perf_counter()
    model = system.build()
    built = time.perf_counter()
    traj = nc.simulate(model, 0.5, 0.01, method="stepper", substeps=2)
    work = traj.info["energy"].get("work", 0.0)
    out[model.name] = {"kernels": traj.info["kernels"], "complete": traj.info["complete"],
                       "drift": float(abs(traj.energy[-1] - traj.energy[0] - work)
                                      / (1.0 + np.max(np.abs(traj.kinetic)))),
                       "phi": float(np.max(traj.constraint_residual)), "build": built - t,
                       "simulate": time.perf_counter() - built}
model = every_force(3, "nocc_batch").build()
batch = nc.simulate_batch(model, 0.2, 0.01, v0=np.tile(model.v0, (3, 1)), workers=2)
out["batch"] = {"kernels": batch.info["kernels"], "ok": bool(np.all(batch.ok))}
out["sympy"] = "sympy" in sys.modules
print(json.dumps(out))
"""


def test_new_models_step_with_no_compiler(library, tmp_path):
    """Once the element library is cached, a new 13-bar chain, a new four-bar and a model
    with every force kind of the tables (3D and planar) are built and stepped in a process
    with no compiler on PATH (and compile_package replaced by a failure), and a batch of
    runs of a new one: the tables' stepper, the energy balance (E − E0 − W, the work of the non-conservative forces;
    relative to the largest kinetic energy) and the constraints kept; SymPy is not imported
    (the tables are packed from the shipped forms)."""
    runs = run_without_compiler(CHILD, tmp_path)
    assert runs.pop("sympy") is False
    assert set(runs) == {"nocc_chain13", "nocc_fourbar", "nocc_forces3d", "nocc_forces2d", "batch"}
    assert runs.pop("batch") == {"kernels": "tables", "ok": True}
    for name, r in runs.items():
        assert r["kernels"] == "tables" and r["complete"], (name, r)
        # the models with dampers and loads: W is accumulated step by step in the C loop (the
        # trapezoidal rule of their power over each step), and the planar one's cable goes slack and taut (its balance: 8e-6)
        assert r["drift"] < (5e-5 if "forces" in name else 1e-5) and r["phi"] < 1e-9, (name, r)


def _compare(model, tol=1e-12, **options):
    """The same run from the tables and from the flat package (unchecked: the scheme's
    accuracy is not the question): equal to ``tol`` relative to the scale of q, the same
    steps and Newton iterations."""
    runs = {k: nc.simulate(model, 0.5, 0.01, method="stepper", kernels=k, check=False, **options)
            for k in ("tables", "flat")}
    a, b = runs["tables"], runs["flat"]
    assert a.info["kernels"] == "tables" and b.info["kernels"] == "flat"
    assert a.info["stats"] == b.info["stats"]
    scale = 1.0 + np.max(np.abs(b.q))
    np.testing.assert_allclose(a.q, b.q, rtol=0, atol=tol * scale)
    np.testing.assert_allclose(a.v, b.v, rtol=0, atol=10 * tol * (1.0 + np.max(np.abs(b.v))))
    np.testing.assert_allclose(a.energy, b.energy, rtol=0, atol=10 * tol * (1.0 + np.max(np.abs(b.energy))))
    np.testing.assert_allclose(a.markers, b.markers, rtol=0, atol=tol * scale)


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(COVERED))
@pytest.mark.parametrize("options", [{"scheme": "rattle", "substeps": 4}, {"scheme": "rattle4"},
                                     {"rtol": 1e-6}], ids=["rattle", "rattle4", "rtol"])
def test_covered_examples_equal_the_flat_stepper(name, options, library):
    """The same scheme from the tables and from the model's flat package: equal to ~1e-12."""
    _compare(nc.System.from_toml(ROOT / "examples" / f"{name}.toml").build(), COVERED[name], **options)


@pytest.mark.slow
def test_auto_runs_a_small_loaded_model_flat(library):
    """A small covered model whose flat package this process has loaded runs flat under
    "auto" (faster per step, nothing to compile); a fresh one of the same kinds, tables."""
    model = chain_system(3, name="loaded3").build()
    assert nc.simulate(model, 0.05, 0.01, method="stepper").info["kernels"] == "tables"
    assert nc.simulate(model, 0.05, 0.01, method="stepper", kernels="flat").info["kernels"] == "flat"
    assert nc.simulate(model, 0.05, 0.01, method="stepper").info["kernels"] == "flat"
    assert nc.simulate(chain_system(3, name="fresh3").build(), 0.05, 0.01,
                       method="stepper").info["kernels"] == "tables"


@pytest.mark.slow
@pytest.mark.parametrize("options", [{"scheme": "rattle", "substeps": 4}, {"rtol": 1e-6}], ids=["rattle", "rtol"])
def test_spring_damper_chain_equals_the_flat_stepper(options, library):
    _compare(chain_system(5, springs=True).build(), **options)


@pytest.mark.slow
@pytest.mark.timeout(1800)
def test_benchmark_smoke(tmp_path):
    """benchmarks/table_stepper.py --smoke runs and prints its comparisons."""
    env = {**os.environ, "NCGEN_CACHE_DIR": str(tmp_path / "cache"),
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    out = subprocess.run([sys.executable, "table_stepper.py", "--smoke"], cwd=ROOT / "benchmarks", env=env,
                         capture_output=True, text=True, timeout=1800)
    assert out.returncode == 0, out.stderr[-3000:]
    for line in ("CPU:", "=== chain of N = 6 bars", "tables, empty cache: library + pack + step",
                 "flat, cached: generate + find + step", "RATIO tables / flat, time per step, N = 6",
                 "load average at the end"):
        assert line in out.stdout, (line, out.stdout[-3000:])

"""The verification ladder: runs the external cases ncgen checks itself against and writes,
for each, the reference, ncgen's value, its error, the tolerance the tests hold it to and
the time, as one Markdown page (docs/verification.md).

The references are those of the tests (imported from them, so the page and the tests
cannot drift apart) or computed by the independent engine in the same run: the Whipple
bicycle's published benchmark (tests/test_whipple.py), rolling discs and the Chaplygin
sleigh against closed forms (tests/test_rolling.py, tests/test_rolling_system.py; on IDAS and
the RATTLE stepper: tests/test_rolling_idas.py, tests/test_rolling_rattle.py), a torus wheel
(tests/test_rolling_torus.py), a ball on a
moving plane (tests/test_rolling_drives.py), the heavy top's steady precession
(tests/test_heavy_top.py), thin bodies against Euler's and the pendulum equation
(tests/test_thin_bodies.py), the IFToMM A02 four-bar through its flat positions
(tests/test_singular_positions.py), the IFToMM A01 pendulum, A03 Andrews' squeezer, A04
Bricard mechanism and A05 flyball governor (tests/test_iftomm.py), arboris' rigid-motion values
(tests/test_rigid_motion.py),
Pinocchio on example-robot-data robots (tests/test_urdf_pinocchio.py), MuJoCo on a falling
chain, on shipped MJCF files and on a contact twin (tests/test_simulate_mujoco.py,
tests/test_mjcf.py, tests/test_contact.py), contact closed forms (tests/test_contact.py, tests/test_contact_shapes.py) and
tensegrity closed forms (tests/test_formfinding.py, tests/test_self_stress.py).  A group whose
engine (Pinocchio, MuJoCo) or robot data is not installed is left out.

Run:  python benchmarks/verification.py [--smoke] [--only GROUP,...] [-o docs/verification.md]
(``--smoke``: shorter runs and fewer cases, the smoke test's mode; ``--only``: the groups, the
functions of ``CASES``, by name.)
"""
from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT / "tests"), str(ROOT / "examples"), str(Path(__file__).resolve().parent)]

from common import machine  # noqa: E402

from ncgen.files import atomic_path  # noqa: E402


@dataclass
class Row:
    case: str
    reference: str
    quantity: str
    value: float | complex
    expected: float | complex
    tolerance: float
    seconds: float = 0.0

    @property
    def error(self) -> float:
        return float(abs(self.value - self.expected))

    @property
    def passed(self) -> bool:
        return self.error <= self.tolerance


def _timed(rows_of):
    """Run ``rows_of()``; spread its wall time over its rows."""
    start = time.perf_counter()
    rows = rows_of()
    for r in rows:
        r.seconds = (time.perf_counter() - start) / max(1, len(rows))
    return rows


def whipple(smoke: bool) -> list[Row]:
    from test_whipple import CAPSIZE, PUBLISHED, TABLE_2, WEAVE
    from whipple_bicycle import BENCHMARK

    from ncgen.analysis.whipple import WhippleBicycle
    ref = "Meijaard et al. 2007, Proc. R. Soc. A 463"
    bike = WhippleBicycle(BENCHMARK)
    rows = []
    for name, got in zip(("M", "C1", "K0", "K2"), bike.matrices()):
        err = np.abs(got - np.array(PUBLISHED[name]))
        i, j = np.unravel_index(np.argmax(err), err.shape)
        rows.append(Row("Whipple bicycle", f"{ref}, benchmark values", f"{name}[{i},{j}] (worst entry)",
                        got[i, j], PUBLISHED[name][i][j], 1e-10))
    lam = np.sort_complex(bike.linearize(5.0).eigenvalues())
    for got, want in zip(lam, np.sort_complex(np.array(TABLE_2[5.0]))):
        rows.append(Row("Whipple bicycle", f"{ref}, Table 2", "eigenvalue at 5 m/s (1/s)", got, want, 1e-10))
    rows.append(Row("Whipple bicycle", f"{ref}, Table 2", "weave speed (m/s)", bike.weave_speed(), WEAVE, 1e-10))
    rows.append(Row("Whipple bicycle", f"{ref}, Table 2", "capsize speed (m/s)", bike.capsize_speed(),
                    CAPSIZE, 1e-10))
    return rows


def rolling_disc(smoke: bool) -> list[Row]:
    from scipy.optimize import brentq
    from test_rolling import A_d, C_d, a, axle, disc, g, m, steady_precession, upright_linearisation

    from ncgen.runtime.rolling_integrator import simulate_rolling
    beta, w3 = 0.2, 30.0
    omega = steady_precession(beta, w3)
    rs = disc(beta, w3, omega)
    t_end = 0.5 if smoke else 2.0
    tr = simulate_rolling(rs, t_end, 0.02, rtol=1e-9, atol=1e-11)
    k = axle(rs, tr.q)
    heading = np.unwrap(np.arctan2(-k[:, 0], k[:, 1]))
    closed = "closed form (Euler's equations about the centre, steady rolling)"
    rows = [Row("rolling disc, steady precession", closed, "precession rate / closed form",
                np.polyfit(tr.t, heading, 1)[0] / omega, 1.0, 1e-7),
            Row("rolling disc, steady precession", closed, "tilt (rad), largest deviation",
                beta + np.max(np.abs(np.arcsin(k[:, 2]) - beta)), beta, 1e-8),
            Row("rolling disc, steady precession", "the constraints", f"residual over {t_end:g} s",
                float(np.max(tr.residual)), 0.0, 1e-10)]

    def stiffness(speed):
        L = upright_linearisation(speed)
        return (L.K[0, 0] - L.C[0, 1] * L.C[1, 0] / L.M[1, 1]) / L.M[0, 0]
    v_c = a * np.sqrt(m * g * a * A_d / (C_d * (C_d + m * a * a)))
    rows.append(Row("rolling disc, upright", "closed form: v_c = a √(m g a A / (C (C + m a²)))",
                    "stability limit (m/s)", brentq(stiffness, 0.1, 2.0, xtol=1e-14), v_c, 1e-10))
    return rows


def rolling_disc_model(smoke: bool) -> list[Row]:
    import ncgen as nc
    from test_rolling_system import BETA, W3, axle, disc_toml
    from test_rolling import steady_precession
    model = nc.System.from_toml(disc_toml()).build()
    t_end = 1.0 if smoke else 10.0
    tr = nc.simulate(model, t_end, 0.05, rtol=1e-8, atol=1e-10)
    k = axle(model, tr.q)
    heading = np.unwrap(np.arctan2(-k[:, 0], k[:, 1]))
    case = f"rolling disc from TOML, nc.simulate at rtol 1e-8 ({tr.info['backend']})"
    closed = "closed form (Euler's equations about the centre, steady rolling)"
    return [Row(case, closed, "precession rate / closed form",
                np.polyfit(tr.t, heading, 1)[0] / steady_precession(BETA, W3), 1.0, 1e-7),
            Row(case, "the constraints", f"both levels' residual over {t_end:g} s",
                float(max(tr.constraint_residual.max(), tr.velocity_residual.max())), 0.0, 1e-10),
            Row(case, "conservation (no dissipation)", f"energy change / energy over {t_end:g} s",
                float(np.ptp(tr.energy) / np.max(np.abs(tr.energy))), 0.0, 1e-7)]


def rolling_idas_stepper(smoke: bool) -> list[Row]:
    """The precessing disc on IDAS (the issue's target: 10 s at rtol 1e-8) and on RATTLE with
    velocity constraints (its order between step sizes, tests/test_rolling_idas.py,
    tests/test_rolling_rattle.py)."""
    import ncgen as nc
    from test_rolling_system import BETA, W3, axle, disc_toml
    from test_rolling import steady_precession
    model = nc.System.from_toml(disc_toml()).build()
    t_end = 1.0 if smoke else 10.0
    tr = nc.simulate(model, t_end, 0.05, method="idas", rtol=1e-8, atol=1e-10)
    k = axle(model, tr.q)
    rate = np.polyfit(tr.t, np.unwrap(np.arctan2(-k[:, 0], k[:, 1])), 1)[0] / steady_precession(BETA, W3)
    closed = "closed form (Euler's equations about the centre, steady rolling)"
    case = "rolling disc, nc.simulate method='idas' at rtol 1e-8"
    rows = [Row(case, closed, "precession rate / closed form", rate, 1.0, 1e-5),
            Row(case, "the constraints", f"both levels' residual over {t_end:g} s",
                float(max(tr.constraint_residual.max(), tr.velocity_residual.max())), 0.0, 1e-10),
            Row(case, "conservation (no dissipation)", f"energy change / energy over {t_end:g} s",
                float(np.ptp(tr.energy) / np.max(np.abs(tr.energy))), 0.0, 1e-5)]
    wobbly = nc.System.from_toml(disc_toml(0.3, 25.0, 0.0, wobble=1.0)).build()
    ref = nc.simulate(wobbly, 0.2, 0.2, method="rolling", rtol=1e-13, atol=1e-15)
    err = [np.max(np.abs(nc.simulate(wobbly, 0.2, 0.2, method="stepper", substeps=n, check=False).q[-1] - ref.q[-1]))
           for n in (20, 40)]
    case = "wobbling rolling disc, RATTLE with velocity constraints (method='stepper')"
    rows.append(Row(case, "DOPRI5 at rtol 1e-13 (method='rolling'), h = 10 and 5 ms",
                    "order: log2 of the error ratio at 0.2 s", float(np.log2(err[0] / err[1])), 2.0, 0.2))
    t_end = 0.2 if smoke else 1.0
    ref = nc.simulate(wobbly, t_end, 0.05, method="rolling", rtol=1e-12, atol=1e-14)
    tr = nc.simulate(wobbly, t_end, 0.05, method="stepper", substeps=16, check=False)
    rows.append(Row(case, "DOPRI5 at rtol 1e-12, h = 3.1 ms",
                    f"error estimate (shadow run, Richardson) / true error in q at {t_end:g} s",
                    tr.info["error_estimate"]["q"] / float(np.max(np.abs(tr.q[-1] - ref.q[-1]))), 1.0, 0.3))
    return rows


def rolling_torus(smoke: bool) -> list[Row]:
    """A torus wheel (tube radius r) turning steadily and rolling upright, on the projected
    DOPRI5 and the compiled RATTLE stepper, and its upright stability limit
    (tests/test_rolling_torus.py)."""
    import ncgen as nc
    from scipy.optimize import brentq
    from test_rolling_torus import (A_t, BETA, C_t, R, W3, axle, g, m, r, torus_precession, torus_wheel,
                                    upright_linearisation)
    model = torus_wheel().build()
    t_end = 0.5 if smoke else 2.0
    closed = "closed form (Newton–Euler of steady turning, tube included)"
    rows = []
    for label, kw, tol in (("method='rolling' at rtol 1e-10",
                            {"method": "rolling", "rtol": 1e-10, "atol": 1e-12}, 1e-7),
                           ("RATTLE (method='stepper', compiled), h = 1 ms",
                            {"method": "stepper", "substeps": 20, "backend": "compiled"}, 1e-4)):
        tr = nc.simulate(model, t_end, 0.02, **kw)
        k = axle(model, tr.q)
        case = f"torus wheel (R = {R:g} m, r = {r:g} m), steady turning, {label}"
        rows += [Row(case, closed, "precession rate / closed form",
                     np.polyfit(tr.t, np.unwrap(np.arctan2(-k[:, 0], k[:, 1])), 1)[0] / torus_precession(BETA, W3),
                     1.0, tol),
                 Row(case, "the constraints", f"both levels' residual over {t_end:g} s",
                     float(max(tr.constraint_residual.max(), tr.velocity_residual.max())), 0.0, 1e-12)]
    def stiffness(speed):
        L = upright_linearisation(speed)
        return (L.K[0, 0] - L.C[0, 1] * L.C[1, 0] / L.M[1, 1]) / L.M[0, 0]
    rho = R + r
    v_c = rho * np.sqrt(m * g * R * A_t / (C_t * (C_t + m * rho ** 2)))
    rows.append(Row("torus wheel, upright", "closed form: v_c = (R + r) √(m g R A / (C (C + m (R + r)²)))",
                    "stability limit (m/s)", brentq(stiffness, 0.1, 2.0, xtol=1e-14), v_c, 1e-10))
    upright = torus_wheel(0.0, 20.0, 0.0).build()
    t_end = 0.5 if smoke else 1.0                    # the test's run: DOPRI5's error grows with the distance
    tr = nc.simulate(upright, t_end, 0.05, method="rolling", rtol=1e-10, atol=1e-12)
    rows.append(Row("torus wheel, upright rolling", "closed form: x = w3 (R + r) t",
                    f"centre x (m), worst over {t_end:g} s",
                    *_worst(tr.point("wheel", (0, 0, 0))[:, 0], 20.0 * (R + r) * tr.t), 1e-9))
    return rows


def rolling_moving_plane(smoke: bool) -> list[Row]:
    import ncgen as nc
    from test_rolling_drives import A_P, M, ball_on_treadmill, drive_work

    from ncgen.assembly.nonholonomic import rolling_system
    model = ball_on_treadmill().build()
    t_end = 0.5 if smoke else 1.0
    traj = nc.simulate(model, t_end, 0.01, rtol=1e-10, atol=1e-12)
    rs = rolling_system(model)
    c = np.array([np.asarray(rs.rate(q, t)).ravel() for q, t in zip(traj.q, traj.t)])
    case = f"ball on a plane accelerating at {A_P:g} m/s² (B v = c(t)), nc.simulate at rtol 1e-10"
    closed = "closed form: f = 2/7 m a_p, x = a_p t² / 7, T = m a_p² t² / 7"
    friction = -traj.lam[:, traj.constraint_names.index("ball.rolling.x")]
    return [Row(case, closed, f"centre x (m), worst over {t_end:g} s",
                *_worst(traj.point("ball", (0, 0, 0))[:, 0], A_P * traj.t ** 2 / 7), 1e-9),
            Row(case, closed, "friction force (N), worst output",
                *_worst(friction, np.full(len(traj.t), 2 * M * A_P / 7)), 1e-8 * 2 * M * A_P / 7),
            Row(case, "energy balance: E(t) − E(0) = ∫ −λᵀc dt (the plane's work, Simpson on the outputs)",
                "energy change (J), worst output", *_worst(traj.energy - traj.energy[0], drive_work(traj, c)), 1e-9),
            Row(case, "the constraints", f"‖B v − c(t)‖∞ over {t_end:g} s", float(traj.velocity_residual.max()),
                0.0, 1e-12)] + [
            Row(f"ball on a plane accelerating at {A_P:g} m/s², {how}", closed,
                "the plane's work in info['energy'] (J), worst output",
                *_worst(run.info["energy"]["works"]["drives"], M * A_P ** 2 * run.t ** 2 / 7), 1e-8)
            for how, run in (("IDAS at rtol 1e-10 (quadratures)",
                              nc.simulate(model, t_end, 0.01, method="idas", rtol=1e-10, atol=1e-12)),
                             ("the stepper at h = 2 ms (trapezoidal rule)",
                              nc.simulate(model, t_end, 0.01, method="stepper", substeps=5)))]


def chaplygin_sleigh(smoke: bool) -> list[Row]:
    from test_rolling import sleigh
    tr, got, want = sleigh(t_end=1.0 if smoke else 3.0)
    closed = "closed form (tanh / sech laws)"
    return [Row("Chaplygin sleigh", closed, "blade speed u (m/s), worst output",
                *_worst(got[:, 0], want[:, 0]), 1e-8),
            Row("Chaplygin sleigh", closed, "turning rate ω (rad/s), worst output",
                *_worst(got[:, 1], want[:, 1]), 1e-8),
            Row("Chaplygin sleigh", closed, "energy change (J)", float(np.ptp(tr.energy)), 0.0, 1e-9)]


def heavy_top(smoke: bool) -> list[Row]:
    import ncgen as nc
    from ncgen.cli.demo_job import Top, invariants
    top = Top(spin=150.0)
    model = nc.System.from_toml(ROOT / "examples" / "heavy_top.toml").build()
    t_end = 1.0 if smoke else 3.0
    traj = nc.simulate(model, t_end=t_end, dt=0.01, rtol=1e-10, atol=1e-12, backend="vm")
    inv = invariants(top, model, traj)
    ref = "closed form (Goldstein §5.7), IDAS"
    return [Row("heavy top, steady precession", ref, "precession rate / closed form",
                np.polyfit(traj.t, inv["phi"], 1)[0] / top.steady_precession(), 1.0, 1e-5),
            Row("heavy top, steady precession", ref, "tilt (rad), largest deviation",
                top.tilt + np.max(np.abs(inv["tilt"] - top.tilt)), top.tilt, 1e-6)]


def thin_bodies(smoke: bool) -> list[Row]:
    import ncgen as nc
    from test_thin_bodies import axes, euler_reference, free_disc, pendulum_reference, plate_pendulum, rot_x
    t_end = 0.5 if smoke else 1.0
    R0, wb = rot_x(0.4), np.array([0.5, -0.3, 10.0])
    model = free_disc(R0, wb)
    traj = nc.simulate(model, t_end=t_end, dt=0.01, rtol=1e-10, atol=1e-12)
    err = float(np.max(np.abs(axes(model, traj, "disc") - euler_reference(R0, wb, traj.t))))
    plate = plate_pendulum(0.3)
    run = nc.simulate(plate, t_end=2 * t_end, dt=0.01, rtol=1e-10, atol=1e-12)
    theta = 0.3 + np.array([np.ravel(plate.to_joint_space(q))[0] for q in run.q])
    return [Row("free thin disc (singular natural-coordinate M), IDAS",
                "Euler's equations and Ṙ = R ω̂ by DOP853 at 1e-12", f"attitude R, worst entry over {t_end:g} s",
                err, 0.0, 1e-7),
            Row("thin plate pendulum (singular natural-coordinate M), IDAS", "the pendulum equation by DOP853 at 1e-12",
                f"angle (rad), worst over {2 * t_end:g} s",
                float(np.max(np.abs(theta - pendulum_reference(0.3, run.t)[0]))), 0.0, 1e-7)]


def iftomm_a02(smoke: bool) -> list[Row]:
    import ncgen as nc
    from test_singular_positions import n_fourbar, tip_error
    t_end = 2.0 if smoke else 20.0
    traj = nc.simulate(n_fourbar(1), t_end, 0.01, rtol=1e-10, atol=1e-10)
    return [Row("IFToMM A02 four-bar (N = 1), through flat positions",
                "exact motion: one pendulum's ODE by DOP853 at 1e-13", f"crank tip (m), worst over {t_end:g} s",
                tip_error(traj, 1), 0.0, 1e-6)]


def iftomm_a01_a03_a04(smoke: bool) -> list[Row]:
    from test_iftomm import (ANDREWS_ACCEL0, ANDREWS_REFERENCE, ANDREWS_T, ANDREWS_TOL, andrews_initial_accelerations,
                             andrews_run, bricard_reference, bricard_run, pendulum_run)
    from andrews_squeezer import squeezer
    rows = []
    closed = "closed form: θ = 2 arcsin(k sn(K − √(g/L) t; k²)), k = sin(π/4)"
    t_end = 10.0 if smoke else 2000.0
    options = dict(rtol=1e-10, atol=1e-12) if smoke else dict(method="stepper", order=4, substeps=500, estimate=False)
    traj, err, cpu = pendulum_run(t_end, **options)
    how = "IDAS at rtol 1e-10" if smoke else "4th-order stepper, h = 1 ms"
    rows.append(Row(f"IFToMM A01 simple pendulum ({how})", closed, f"P1 (m), worst of 4000 outputs over {t_end:g} s",
                    err, 0.0, 1e-6 if smoke else 5e-6))
    accel = andrews_initial_accelerations(squeezer().build())
    test_set = "Test Set for IVP solvers (Mazzia et al.), andrews"
    rows.append(Row("IFToMM A03 Andrews' squeezer (Hairer & Wanner VII.7)", f"{test_set}: consistent initial values",
                    "β̈(0) (rad/s²)", accel[0], ANDREWS_ACCEL0[0], 1e-9 * abs(ANDREWS_ACCEL0[0])))
    rows.append(Row("IFToMM A03 Andrews' squeezer (Hairer & Wanner VII.7)", f"{test_set}: consistent initial values",
                    "Θ̈(0) (rad/s²)", accel[1], ANDREWS_ACCEL0[1], 1e-9 * abs(ANDREWS_ACCEL0[0])))
    _, got, cpu = andrews_run()
    for k, name in enumerate(("β", "Θ", "γ", "Φ", "δ", "Ω", "ε")):
        rows.append(Row("IFToMM A03 Andrews' squeezer, IDAS at rtol 1e-12",
                        f"{test_set}: reference solution (PSIDE at 1e-14)", f"{name} at t = {ANDREWS_T:g} s (rad)",
                        got[k], ANDREWS_REFERENCE[k], ANDREWS_TOL))
    t_end = 2.5 if smoke else 10.0
    traj, p3, cpu = bricard_run(t_end)
    case = "IFToMM A04 Bricard mechanism (overconstrained, 1 DOF), IDAS at rtol 1e-12"
    rows.append(Row(case, "independent: Lagrange's equation in one hinge angle, SciPy DOP853 at 1e-12 (the "
                    "benchmark's published history not reachable here)", f"P3 (m), worst over {t_end:g} s",
                    float(np.max(np.linalg.norm(p3 - bricard_reference(traj.t), axis=1))), 0.0, 1e-7))
    rows.append(Row(case, "conservation (no dissipation)", f"energy change over {t_end:g} s (J)",
                    float(np.ptp(traj.energy)), 0.0, 1e-8))
    return rows


def iftomm_a05(smoke: bool) -> list[Row]:
    from test_iftomm import governor_reference, governor_run
    t_end, rtol = (2.0, 1e-10) if smoke else (10.0, 1e-12)
    traj, s, psi, cpu = governor_run(t_end, rtol=rtol, atol=1e-2 * rtol)
    ref = governor_reference(traj.t)
    case = f"IFToMM A05 stiff flyball governor (k = 8e5 N/m, c = 4e4 N s/m), IDAS at rtol {rtol:g}"
    independent = ("independent: Lagrange's equations in the 4 minimal coordinates, SciPy LSODA at 1e-11 (the "
                   "benchmark's published s(t) is a plot, not numbers reachable here)")
    return [Row(case, independent, f"sleeve height s (m), worst over {t_end:g} s", *_worst(s, ref["s"]), 1e-8),
            Row(case, independent, f"shaft angle (rad), worst over {t_end:g} s", *_worst(psi, ref["psi"]), 1e-8),
            Row(case, "energy balance: E(t) − E(0) = −(dampers' dissipation, from the reference)",
                f"energy change (J), worst over {t_end:g} s", *_worst(traj.energy - traj.energy[0],
                                                                       -ref["dissipated"]), 1e-6 if smoke else 1e-7)]


def mujoco_chain(smoke: bool) -> list[Row]:
    try:
        import mujoco  # noqa: F401
    except ImportError:
        return []
    from test_simulate_mujoco import mujoco_tip, ncgen_chain

    from ncgen.runtime import simulate
    traj = simulate(ncgen_chain(), 1.0, 0.01, rtol=1e-10, atol=1e-12)
    err = np.max(np.linalg.norm(traj.marker("b2.tip") - mujoco_tip(1.0, every=100), axis=1))
    return [Row("falling 3D chain of 3 bars (ball joints)", "MuJoCo, RK4 at 1e-4 s, equivalent MJCF",
                "tip (m), worst over 1 s", float(err), 0.0, 1e-6)]


def iftomm_a02_larger(smoke: bool) -> list[Row]:
    import warnings

    import ncgen as nc
    from test_singular_positions import n_fourbar, n_fourbar_3d, tip_error
    t_end = 2.0 if smoke else 20.0
    rows = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)       # the 3D loops' implied hinge rows, dropped
        cases = (("N = 10", n_fourbar(10)),) + (() if smoke else (("3D, N = 1", n_fourbar_3d(1)),))
    for label, model in cases:
        traj = nc.simulate(model, t_end, 0.01, rtol=1e-10, atol=1e-10)
        rows.append(Row(f"IFToMM A02 four-bar ({label}), through flat positions",
                        "exact motion: one pendulum's ODE by DOP853 at 1e-13",
                        f"crank tip (m), worst over {t_end:g} s", tip_error(traj, 10 if "10" in label else 1),
                        0.0, 1e-6))
    return rows


def arboris(smoke: bool) -> list[Row]:
    from test_rigid_motion import ARBORIS_EXP, ARBORIS_M_B, ARBORIS_M_C, ARBORIS_OFFSET, ARBORIS_TWIST

    import ncgen.rigid_motion as rm
    ref = "arboris-python (Salini, Barthélemy, Bidaud), published values"
    rows = []
    for quantity, got, want, tol in (
            ("exp of the twist (1, 2, 3, 10, 11, 12), worst entry", rm.exp_se3(ARBORIS_TWIST), ARBORIS_EXP, 1e-8),
            ("mass matrix moved by (1, 3, 0), worst entry",
             rm.transport_mass_matrix(ARBORIS_M_C, rm.translation(ARBORIS_OFFSET)), ARBORIS_M_B, 1e-14)):
        rows.append(Row("rigid-motion algebra", ref, quantity, *_worst(np.ravel(got), np.ravel(want)), tol))
    return rows


def pinocchio(smoke: bool) -> list[Row]:
    try:
        import pinocchio as pin
        from test_urdf_pinocchio import ident, pin_joints, rates_to_pin, robot, states, to_ncgen
    except ImportError:
        return []
    import ncgen as nc
    rows = []
    for name in ("ur5",) if smoke else ("ur5", "panda", "solo12"):
        try:
            model, pm = robot(name)
        except BaseException as why:            # pytest.skip: example-robot-data lacks the robot
            print(f"    {name}: left out ({why})")
            continue
        pd, floating = pm.createData(), name == "solo12"
        err = {"aba": 0.0, "rnea": 0.0, "frames": 0.0}
        frames = [f for f in pm.frames if f.type == pin.FrameType.BODY]
        for k, (qp, vp, taup, ap) in enumerate(states(pm, seed=len(name))):
            if smoke and k == 5:
                break
            if floating:
                taup[:6] = 0.0
            qj, vj = to_ncgen(model, pm, qp, vp)
            q, v = model.from_joint_space(qj, vj)
            tau = nc.inverse_dynamics(model, qj, vj, to_ncgen(model, pm, qp, ap)[1], joints="all")
            tau_pin = pin.rnea(pm, pd, qp, vp, ap)
            err["rnea"] = max(err["rnea"], np.max(np.abs(rates_to_pin(model, pm, tau) - tau_pin))
                              / max(1.0, np.max(np.abs(tau_pin))))
            order = {n: i for i, n in enumerate(model.joint_names)}
            actuated = sorted(((n, jm) for n, jm in pin_joints(model, pm) if n != "root"), key=lambda x: order[x[0]])
            a, _ = nc.forward_dynamics(model, q, v, u=np.concatenate([taup[jm.idx_v:jm.idx_v + jm.nv]
                                                                       for _, jm in actuated]))
            a_pin = pin.aba(pm, pd, qp, vp, taup)
            err["aba"] = max(err["aba"], np.max(np.abs(rates_to_pin(model, pm, model.to_joint_space(q, v, a)[2])
                                                       - a_pin)) / max(1.0, np.max(np.abs(a_pin))))
            pin.framesForwardKinematics(pm, pd, qp)
            for f in frames:
                R, pos = model.frame_pose(ident(f.name), q)
                oMf = pd.oMf[pm.getFrameId(f.name)]
                err["frames"] = max(err["frames"], np.max(np.abs(R - oMf.rotation)),
                                    np.max(np.abs(pos - oMf.translation)))
        n = 5 if smoke else 20
        case = f"{name} (example-robot-data URDF)"
        ref = "Pinocchio (Carpentier et al. 2019)"
        rows += [Row(case, f"{ref}, aba", f"joint accelerations, relative, worst of {n} states", err["aba"], 0.0, 1e-8),
                 Row(case, f"{ref}, rnea", f"joint efforts, relative, worst of {n} states", err["rnea"], 0.0, 1e-8),
                 Row(case, f"{ref}, framesForwardKinematics", f"link poses (m, -), worst of {n} states",
                     err["frames"], 0.0, 1e-10)]
    return rows


def mujoco_mjcf(smoke: bool) -> list[Row]:
    try:
        from test_mjcf import FAST, FILES, qacc_error
    except ImportError:
        return []
    rows = []
    for key in FAST[:2] if smoke else FAST:
        if key not in FILES:
            continue
        rows.append(Row(f"MJCF {key}", "MuJoCo mj_forward (contacts, limits, friction loss off)",
                        "joint accelerations, relative, worst of 2 random states", qacc_error(FILES[key], trials=2),
                        0.0, 1e-8))
    return rows


def contacts(smoke: bool) -> list[Row]:
    import ncgen as nc
    from test_contact import (DOWN, G, R_BALL, SOFT, TH, V0_SPIN, W0_SPIN, bounce_apexes,
                              drops_model, mujoco_backspin, slopes_run, soft_block_run)
    closed = "closed form (Coulomb friction, rigid contact)"
    model, tr = slopes_run()
    a_slide = np.diff(tr.v[:, :3] @ DOWN) / 0.01
    a_roll = np.diff(tr.v[:, 6:9] @ DOWN) / 0.01
    a_slip, friction, normal = G * (np.sin(TH) - 0.2 * np.cos(TH)), 2 * G * np.sin(TH), 2 * G * np.cos(TH)
    steps = len(tr.t) - 1
    rows = [Row("block sliding down a 0.3 rad incline (μ = 0.2), stepper", closed,
                "acceleration (m/s²), worst step", *_worst(a_slide, np.full(steps, a_slip)), 1e-6 * a_slip),
            Row("block resting on a 0.3 rad incline (μ = 0.5), stepper", closed, "friction force (N), worst step",
                *_worst(np.linalg.norm(tr.contact_tangent[1:, 1], axis=1), np.full(steps, friction)), 1e-9 * friction),
            Row("block resting on a 0.3 rad incline (μ = 0.5), stepper", closed, "normal force (N), worst step",
                *_worst(tr.contact_normal[1:, 1], np.full(steps, normal)), 1e-9 * normal),
            Row("ball rolling down a 0.3 rad incline (μ = 1), stepper", "closed form: a = 5/7 g sin θ",
                "acceleration (m/s²), worst step (O(h²) scheme)",
                *_worst(a_roll, np.full(steps, 5 / 7 * G * np.sin(TH))), 5e-5 * 5 / 7 * G * np.sin(TH))]
    v_spin = tr.v[:, 30]
    v_roll = (5 * V0_SPIN + 2 * R_BALL * W0_SPIN) / 7
    rows.append(Row("ball with backspin (slides, then rolls), stepper",
                    "closed form: v = (5 v0 + 2 R ω0) / 7 after t* = (v0 − R ω0) / (3.5 μ g)",
                    "final speed (m/s)", float(v_spin[-1]), v_roll, 1e-5 * abs(v_roll)))
    try:
        import mujoco
        x, v_end = mujoco_backspin(mujoco)
        rows.append(Row("ball with backspin (slides, then rolls), stepper",
                        "MuJoCo twin (elliptic cone, solref 0.002 s, h = 1e-4 s; its contact is soft)",
                        "position (m), worst over 1 s", *_worst(tr.q[1:, 30], x), 3e-4))
    except ImportError:
        pass
    if not smoke:
        drops = drops_model()
        apex = bounce_apexes(nc.simulate(drops, 3.0, 1e-4, method="stepper", substeps=10))[:3]
        rows.append(Row("point dropped from 1 m (e = 0.9), stepper", "closed form: apex k at e^(2k) m",
                        "apex heights 1–3 / closed form, worst", *_worst(apex / 0.81 ** np.arange(1, 4), np.ones(3)),
                        1e-3))
    from test_contact_shapes import M_BOX, MU, V0_SLIDE, _corner_forces, blocks_run
    _, tr = blocks_run()
    rows += [Row("box sliding to rest on the ground (v0 = 1.5 m/s, μ = 0.4), stepper",
                 "closed form: distance v0² / (2 μ g)", "distance (m)", float(tr.point("slide", (0, 0, 0))[-1, 0]),
                 V0_SLIDE ** 2 / (2 * MU * G), 2e-3 * V0_SLIDE ** 2 / (2 * MU * G)),
             Row("box sliding to rest on the ground (v0 = 1.5 m/s, μ = 0.4), stepper", "closed form: N = m g",
                 "bottom corners' normal forces, sum (N), worst step",
                 *_worst(_corner_forces(tr, "slide")[1:, :4].sum(axis=1), np.full(len(tr.t) - 1, M_BOX * G)),
                 1e-9 * M_BOX * G)]
    soft = soft_block_run()
    th, m, k, n_exp = SOFT["th"], SOFT["m"], SOFT["k"], SOFT["n_exp"]
    delta = (m * G * np.cos(th) / k) ** (1 / n_exp)
    rows += [Row("block on a 0.2 rad incline, smooth contact k δ^1.5, IDAS",
                 "closed form: δ = (m g cos θ / k)^(2/3)",
                 "penetration (m), last 0.2 s, worst", *_worst(-soft.gap[-20:, 0], np.full(20, delta)), 1e-4 * delta),
             Row("block on a 0.2 rad incline, smooth contact k δ^1.5, IDAS", "closed form: N = m g cos θ",
                 "normal force (N), last 0.2 s, worst",
                 *_worst(soft.contact_normal[-20:, 0], np.full(20, m * G * np.cos(th))), 1e-4 * m * G * np.cos(th))]
    return rows


def tensegrity(smoke: bool) -> list[Row]:
    import ncgen as nc
    from test_formfinding import SQ3, twists
    from test_formfinding import prism as three_prism

    from ncgen.analysis.self_stress import self_stress
    from ncgen.analysis.tensegrity_shapes import prism, prism_twist
    ref = "closed form (Tibert & Pellegrino 2003): struts twisted by 90° + 180°/n"
    turn_ref = "closed form (Tibert & Pellegrino 2003): vertical cables turn by 90° − 180°/n"
    density_ref = "closed form (Tibert & Pellegrino 2003): force densities 1 : 2 sin(π/n) : −2 sin(π/n)"
    rows = []
    res = nc.form_find(*three_prism(np.radians(120)), force_densities=[1.0] * 6 + [SQ3] * 3 + [-SQ3] * 3,
                       stiffness=1e4)
    rows.append(Row("3-prism form-found from force densities", ref, "twist (deg), worst strut",
                    *_worst(twists(res.nodes), np.full(3, 150.0)), 1e-7))
    for n in (4, 5) if smoke else (4, 5, 6, 8):
        nodes, struts, cables = prism(n, twist=prism_twist(n) - np.radians(12))
        r = 2 * np.sin(np.pi / n)
        res = nc.form_find(nodes, struts, cables, force_densities=[1.0] * 2 * n + [r] * n + [-r] * n,
                           stiffness=1e5)
        X = res.nodes - res.nodes.mean(axis=0)
        turn = [np.degrees(np.arctan2(X[b, 1], X[b, 0]) - np.arctan2(X[a, 1], X[a, 0])) % 360
                for a, b in cables[2 * n:]]
        rows.append(Row(f"{n}-prism form-found from a twist 12° off", turn_ref, "vertical cables' turn (deg), worst",
                        *_worst(np.array(turn), np.full(n, 90 - 180 / n)), 1e-7))
        an = self_stress(*prism(n, radius=0.4, height=0.7))
        q = an.self_stresses[:, 0] / an.framework.lengths()
        want = np.r_[np.ones(2 * n), np.full(n, r), np.full(n, -r)]
        rows.append(Row(f"{n}-prism's state of self-stress", density_ref, "force densities / ring's, worst member",
                        *_worst(q / q[0], want), 1e-10))
    return rows


def _worst(got, want):
    i = int(np.argmax(np.abs(got - want)))
    return float(got[i]), float(want[i])


CASES = (whipple, rolling_disc, rolling_disc_model, rolling_idas_stepper, rolling_torus, rolling_moving_plane, chaplygin_sleigh, heavy_top, thin_bodies,
         iftomm_a02,
         iftomm_a02_larger, iftomm_a01_a03_a04, iftomm_a05,
         arboris, pinocchio,
         mujoco_chain, mujoco_mjcf, contacts, tensegrity)
#: External checks the project's page lacks.
NOT_YET = [
    ("MuJoCo work-precision comparisons", "benchmarks/work_precision.py (timings, not a reference)"),
]


def _number(x) -> str:
    if isinstance(x, complex) or np.iscomplexobj(x):
        return f"{x.real:.14g} {'+' if x.imag >= 0 else '−'} {abs(x.imag):.14g}i"
    return f"{x:.14g}"


def page(rows: list[Row], smoke: bool) -> str:
    lines = ["# Verification ladder", "",
             "Generated by `python benchmarks/verification.py` (do not edit by hand): every external "
             "reference below is recomputed by ncgen, and its error compared with the tolerance the "
             "tests hold it to; the reference values are imported from those tests (`tests/test_whipple.py`, "
             "`tests/test_rolling.py`, `tests/test_rolling_system.py`, `tests/test_rolling_drives.py`, `tests/test_rolling_idas.py`, "
             "`tests/test_rolling_rattle.py`, `tests/test_rolling_torus.py`, "
             "`tests/test_heavy_top.py`, "
             "`tests/test_singular_positions.py`, `tests/test_iftomm.py`, `tests/test_thin_bodies.py`, "
             "`tests/test_rigid_motion.py`, `tests/test_urdf_pinocchio.py`, `tests/test_simulate_mujoco.py`, "
             "`tests/test_mjcf.py`, `tests/test_contact.py`, `tests/test_contact_shapes.py`, `tests/test_formfinding.py`, "
             "`tests/test_self_stress.py`) or computed by the independent engine (Pinocchio, MuJoCo, SciPy) in "
             "the same run. Times are wall-clock seconds of each case's group, spread over its rows."
             + (" Smoke run: shortened simulations." if smoke else ""), "",
             "```text", machine(), "```", "",
             "| case | reference | quantity | ncgen | reference value | error | tolerance | within | time (s) |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r.case} | {r.reference} | {r.quantity} | {_number(r.value)} | {_number(r.expected)} "
                     f"| {r.error:.1e} | {r.tolerance:.0e} | {'yes' if r.passed else '**NO**'} | {r.seconds:.2f} |")
    lines += ["", "Not on this page yet:", ""]
    lines += [f"- {name}: " + (f"`{where}`" if where else "no test or model in ncgen yet") for name, where in NOT_YET]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--smoke", action="store_true", help="shorter runs, the same cases")
    parser.add_argument("-o", "--output", default=str(ROOT / "docs" / "verification.md"))
    parser.add_argument("--only", default="", metavar="NAMES",
                        help=f"comma-separated groups to run (default all): {', '.join(c.__name__ for c in CASES)}")
    args = parser.parse_args(argv)
    names = [n.strip() for n in args.only.split(",") if n.strip()]
    unknown = sorted(set(names) - {c.__name__ for c in CASES})
    if unknown:
        parser.error(f"--only: unknown group(s) {', '.join(unknown)}; "
                     f"expected some of {', '.join(c.__name__ for c in CASES)}")
    rows = []
    for case in [c for c in CASES if not names or c.__name__ in names]:
        print(f"=== {case.__name__}", flush=True)
        rows += _timed(lambda: case(args.smoke))
    with atomic_path(args.output) as tmp:
        tmp.write_text(page(rows, args.smoke), encoding="utf-8")
    failed = [r for r in rows if not r.passed]
    print(f"{len(rows)} comparisons, {len(failed)} outside their tolerance; wrote {args.output}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())

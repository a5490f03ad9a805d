"""The verification ladder: runs the external cases ncgen checks itself against and writes,
for each, the reference, ncgen's value, its error, the tolerance the tests hold it to and
the time, as one Markdown page (docs/verification.md).

The references are those of the tests (imported from them, so the page and the tests
cannot drift apart): the Whipple bicycle's published benchmark (tests/test_whipple.py),
rolling discs and the Chaplygin sleigh against closed forms (tests/test_rolling.py), the
heavy top's steady precession (tests/test_heavy_top.py, ncgen.cli.demo_job.Top), the
IFToMM A02 four-bar through its flat positions (tests/test_singular_positions.py), a
falling chain against MuJoCo (tests/test_simulate_mujoco.py; left out when MuJoCo is absent).

Run:  python benchmarks/verification.py [--smoke] [-o docs/verification.md]
(``--smoke``: shorter runs, the same cases; the smoke test's mode.)
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


def iftomm_a02(smoke: bool) -> list[Row]:
    import ncgen as nc
    from test_singular_positions import n_fourbar, tip_error
    t_end = 2.0 if smoke else 20.0
    traj = nc.simulate(n_fourbar(1), t_end, 0.01, rtol=1e-10, atol=1e-10)
    return [Row("IFToMM A02 four-bar (N = 1), through flat positions",
                "exact motion: one pendulum's ODE by DOP853 at 1e-13", f"crank tip (m), worst over {t_end:g} s",
                tip_error(traj, 1), 0.0, 1e-6)]


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


def _worst(got, want):
    i = int(np.argmax(np.abs(got - want)))
    return float(got[i]), float(want[i])


CASES = (whipple, rolling_disc, chaplygin_sleigh, heavy_top, iftomm_a02, mujoco_chain)
#: External checks that live in the tests but are not on this page yet.
NOT_YET = [
    ("IFToMM A02 with N = 10, 40 and in 3D", "tests/test_singular_positions.py"),
    ("IFToMM A01–A05 matrix of output grids", "tests/test_singular_output_grid.py"),
    ("arboris rigid-motion values", "tests/test_rigid_motion.py"),
    ("Pinocchio on stock robots", "tests/test_tree_algorithms_pinocchio.py, tests/test_urdf_pinocchio.py"),
    ("MuJoCo work-precision comparisons", "benchmarks/work_precision.py, tests/test_benchmarks_smoke.py"),
    ("contact closed forms", "tests/test_contact*.py"),
    ("thin bodies (Euler's equations, Newton–Euler)", "tests/test_thin_bodies.py"),
]


def _number(x) -> str:
    if isinstance(x, complex) or np.iscomplexobj(x):
        return f"{x.real:.14g} {'+' if x.imag >= 0 else '−'} {abs(x.imag):.14g}i"
    return f"{x:.14g}"


def page(rows: list[Row], smoke: bool) -> str:
    lines = ["# Verification ladder", "",
             "Generated by `python benchmarks/verification.py` (do not edit by hand): every external "
             "reference below is recomputed by ncgen, and its error compared with the tolerance the "
             "tests hold it to (`tests/test_whipple.py`, `tests/test_rolling.py`, "
             "`tests/test_heavy_top.py`, `tests/test_singular_positions.py`, `tests/test_simulate_mujoco.py`). Times are wall-clock seconds of each case's group, "
             "spread over its rows." + (" Smoke run: shortened simulations." if smoke else ""), "",
             "```text", machine(), "```", "",
             "| case | reference | quantity | ncgen | reference value | error | tolerance | within | time (s) |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r.case} | {r.reference} | {r.quantity} | {_number(r.value)} | {_number(r.expected)} "
                     f"| {r.error:.1e} | {r.tolerance:.0e} | {'yes' if r.passed else '**NO**'} | {r.seconds:.2f} |")
    lines += ["", "Not on this page yet (checked by the tests named):", ""]
    lines += [f"- {name}: `{where}`" for name, where in NOT_YET]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--smoke", action="store_true", help="shorter runs, the same cases")
    parser.add_argument("-o", "--output", default=str(ROOT / "docs" / "verification.md"))
    args = parser.parse_args(argv)
    rows = []
    for case in CASES:
        print(f"=== {case.__name__}", flush=True)
        rows += _timed(lambda: case(args.smoke))
    with atomic_path(args.output) as tmp:
        tmp.write_text(page(rows, args.smoke), encoding="utf-8")
    failed = [r for r in rows if not r.passed]
    print(f"{len(rows)} comparisons, {len(failed)} outside their tolerance; wrote {args.output}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())

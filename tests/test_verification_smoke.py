"""The verification ladder (benchmarks/verification.py) runs end to end and writes its page
with every comparison within its tolerance: a quick subset of its groups in the fast tier,
the whole script in the slow one (the IFToMM groups there in their smoke runs: their full
runs are slow tests of their own, :data:`FULL_RUNS_ELSEWHERE`)."""
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
#: The ladder's groups whose full runs are slow tests with the same calls and tolerances (the
#: ladder imports them): A02 (N = 1, 10, 3D N = 1, 20 s) is
#: test_singular_positions.py::test_idas_through_sixteen_flat_positions_is_as_accurate_as_a_regular_run
#: [2d-1-20.0], [2d-10-20.0], [3d-1-20.0]; A01's 2000 s, A04's 10 s and A05's 10 s at 1e-12 are
#: test_iftomm.py::test_a01_pendulum_2000_s_within_the_benchmark_precision,
#: ::test_a04_bricard_against_its_lagrange_equation, ::test_a05_governor_10_s_at_tight_tolerance, and A03's
#: rows ::test_a03_andrews_initial_accelerations_as_published, ::test_a03_andrews_at_t_0_03_against_the_test_set.
#: The full ladder runs them in their smoke mode (each row's code and tolerance, shorter runs).
FULL_RUNS_ELSEWHERE = ("iftomm_a02", "iftomm_a02_larger", "iftomm_a01_a03_a04", "iftomm_a05")
#: The script's packages at -O0 (tests/conftest.py: it inherits ``$NCGEN_CFLAGS``): every row is a
#: comparison within a tolerance, which the level moves at round-off only.
QUICK_COMPILE = True


def ladder(tmp_path, *args, timeout):
    """Run the script with ``args``; its page and its standard output."""
    out = tmp_path / "verification.md"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    run = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "verification.py"), *args, "-o", str(out)],
                         capture_output=True, text=True, timeout=timeout, env=env)
    assert run.returncode == 0, run.stdout + run.stderr
    return out.read_text(), run.stdout


@pytest.mark.slow      # the ladder script in a subprocess; fast: test_an_unknown_group_is_named (the script),
#                       tests/test_whipple.py, tests/test_rigid_motion.py, tests/test_tensegrity*.py (each group's
#                       closed forms)
def test_quick_groups_of_the_ladder(tmp_path):
    """The closed forms that need no simulation (bicycle, arboris, tensegrity), each row
    within its tolerance; the groups not asked for are not run."""
    text, stdout = ladder(tmp_path, "--smoke", "--only", "whipple,arboris,tensegrity", timeout=300)
    for case in ("Whipple bicycle", "rigid-motion algebra", "3-prism form-found from force densities",
                 "4-prism's state of self-stress"):
        assert f"| {case} |" in text
    assert "| heavy top" not in text and "**NO**" not in text
    assert "17 comparisons, 0 outside their tolerance" in stdout


def test_an_unknown_group_is_named(tmp_path):
    run = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "verification.py"), "--only", "whipple,bicycle",
                          "-o", str(tmp_path / "v.md")], capture_output=True, text=True, timeout=120,
                         env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert run.returncode == 2 and "unknown group(s) bicycle" in run.stderr
    assert not (tmp_path / "v.md").exists()


def groups():
    """The ladder's groups (benchmarks/verification.py's ``CASES``), by name."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        from verification import CASES
    finally:
        sys.path.remove(str(ROOT / "benchmarks"))
    return [case.__name__ for case in CASES]


@pytest.mark.slow                       # the ladder but the IFToMM groups: a minute (compiles, IDAS at 1e-10, robots)
def test_verification_ladder_in_full(tmp_path):
    """Every group but :data:`FULL_RUNS_ELSEWHERE` in its full run, every row within its tolerance."""
    assert set(FULL_RUNS_ELSEWHERE) < set(groups())
    text, stdout = ladder(tmp_path, "--only", ",".join(g for g in groups() if g not in FULL_RUNS_ELSEWHERE),
                          timeout=1800)
    for case in ("Whipple bicycle", "rolling disc, steady precession", "rolling disc, upright", "torus wheel, upright rolling",
                 "ball on a plane accelerating at 1.5 m/s² (B v = c(t)), nc.simulate at rtol 1e-10",
                 "Chaplygin sleigh", "heavy top, steady precession",
                 "rigid-motion algebra", "4-prism's state of self-stress",
                 "box sliding to rest on the ground (v0 = 1.5 m/s, μ = 0.4), stepper"):
        assert f"| {case} |" in text
    assert "IFToMM" not in text
    assert "**NO**" not in text and " 0 outside their tolerance" in stdout


@pytest.mark.slow                       # IDAS at 1e-10 through flat positions, the Bricard reference (3000 closures)
def test_iftomm_groups_of_the_ladder(tmp_path):
    """:data:`FULL_RUNS_ELSEWHERE` in their smoke runs (their full runs: the slow tests named
    there), every row within its tolerance."""
    text, stdout = ladder(tmp_path, "--smoke", "--only", ",".join(FULL_RUNS_ELSEWHERE), timeout=1800)
    for case in ("IFToMM A02 four-bar (N = 1), through flat positions",
                 "IFToMM A02 four-bar (N = 10), through flat positions",
                 "IFToMM A01 simple pendulum (IDAS at rtol 1e-10)",
                 "IFToMM A03 Andrews' squeezer, IDAS at rtol 1e-12",
                 "IFToMM A04 Bricard mechanism (overconstrained, 1 DOF), IDAS at rtol 1e-12",
                 "IFToMM A05 stiff flyball governor (k = 8e5 N/m, c = 4e4 N s/m), IDAS at rtol 1e-10"):
        assert f"| {case} |" in text
    assert "**NO**" not in text and " 0 outside their tolerance" in stdout

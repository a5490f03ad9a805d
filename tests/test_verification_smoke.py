"""The verification ladder (benchmarks/verification.py) runs end to end and writes its page
with every comparison within its tolerance: a quick subset of its groups in the fast tier,
the whole script in the slow one."""
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


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


@pytest.mark.slow                       # the whole ladder: a few minutes (compiles, IDAS at 1e-10, robots)
def test_verification_ladder_in_full(tmp_path):
    text, stdout = ladder(tmp_path, timeout=1800)
    for case in ("Whipple bicycle", "rolling disc, steady precession", "rolling disc, upright", "torus wheel, upright rolling",
                 "ball on a plane accelerating at 1.5 m/s² (B v = c(t)), nc.simulate at rtol 1e-10",
                 "Chaplygin sleigh", "heavy top, steady precession",
                 "IFToMM A02 four-bar (N = 1), through flat positions",
                 "IFToMM A02 four-bar (N = 10), through flat positions",
                 "IFToMM A01 simple pendulum (4th-order stepper, h = 1 ms)",
                 "IFToMM A03 Andrews' squeezer, IDAS at rtol 1e-12",
                 "IFToMM A04 Bricard mechanism (overconstrained, 1 DOF), IDAS at rtol 1e-12",
                 "IFToMM A05 stiff flyball governor (k = 8e5 N/m, c = 4e4 N s/m), IDAS at rtol 1e-12",
                 "rigid-motion algebra", "4-prism's state of self-stress",
                 "box sliding to rest on the ground (v0 = 1.5 m/s, μ = 0.4), stepper"):
        assert f"| {case} |" in text
    assert "**NO**" not in text and " 0 outside their tolerance" in stdout

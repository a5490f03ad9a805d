"""The verification ladder (benchmarks/verification.py) runs end to end and writes its page
with every comparison within its tolerance."""
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.slow
def test_verification_ladder_smoke(tmp_path):
    out = tmp_path / "verification.md"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    run = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "verification.py"), "--smoke", "-o", str(out)],
                         capture_output=True, text=True, timeout=900, env=env)
    assert run.returncode == 0, run.stdout + run.stderr
    text = out.read_text()
    for case in ("Whipple bicycle", "rolling disc, steady precession", "rolling disc, upright",
                 "Chaplygin sleigh", "heavy top, steady precession",
                 "IFToMM A02 four-bar (N = 1), through flat positions"):
        assert f"| {case} |" in text
    assert "**NO**" not in text and "0 outside their tolerance" in run.stdout

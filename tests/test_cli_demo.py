"""``ncgen demo``: the whole pipeline from a clean compile cache in under a minute, its
summary, its files, and a cache hit the second time."""
import os
import resource
import subprocess
import sys

import numpy as np
import pytest

from ncgen.cli import main
from ncgen.cli.demo_job import Top, heavy_top, invariants
from ncgen.runtime import Trajectory

#: The demo must finish within this much CPU time (s; the process and the compilers it runs),
#: compile included: CPU, not wall time, so that a machine shared with other work passes too.
BUDGET = 60.0


@pytest.mark.slow      # compiles the heavy top from an empty cache; fast: test_demo_motion_matches_the_top_theory
def test_demo_from_a_clean_cache(tmp_path):
    env = {**os.environ, "NCGEN_CACHE_DIR": str(tmp_path / "cache"), "MPLBACKEND": "Agg"}
    env.pop("NCGEN_CFLAGS", None)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    first = subprocess.run([sys.executable, "-m", "ncgen.cli", "demo", "-o", str(tmp_path / "out")],
                           env=env, capture_output=True, text=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    assert first.returncode == 0, first.stderr
    assert cpu < BUDGET, f"ncgen demo took {cpu:.0f} s of CPU"
    out = first.stdout
    for stage in ("build", "generate", "compile", "simulate"):
        assert f"\n  {stage} " in out
    assert "cache miss: built" in out and "IDAS on the compiled DAE" in out
    assert "exact turning points 30.000 .. 37.925 deg" in out
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["heavy_top", "heavy_top.npz", "heavy_top.png"]
    assert (tmp_path / "out" / "heavy_top" / "heavy_top.h").is_file()

    second = subprocess.run([sys.executable, "-m", "ncgen.cli", "demo", "-o", str(tmp_path / "out")],
                            env=env, capture_output=True, text=True)
    assert second.returncode == 0 and "(cache hit)" in second.stdout


def test_demo_motion_matches_the_top_theory(tmp_path):
    """The saved trajectory: first integrals kept and the tilt between the exact turning points."""
    top = Top()
    saved = tmp_path / "heavy_top.npz"
    assert main(["demo", "-o", str(tmp_path), "--backend", "vm", "--t-end", "1"]) == 0
    model = heavy_top(top).build()
    traj = Trajectory.load(saved, model=model)
    inv = invariants(top, model, traj)
    low, high = top.nutation_limits()
    assert abs(inv["tilt"].min() - low) < 1e-5 and abs(inv["tilt"].max() - high) < 1e-4
    assert np.ptp(inv["L_z"]) < 1e-5 * abs(inv["L_z"][0])
    assert np.ptp(inv["spin"]) < 1e-5 * top.spin


def test_bad_output_directory(tmp_path, capsys):
    (tmp_path / "file").write_text("x")
    assert main(["demo", "-o", str(tmp_path / "file")]) == 2
    assert "is not a directory" in capsys.readouterr().err


def test_help_has_examples(capsys):
    assert main(["demo", "--help"]) == 0
    out = capsys.readouterr().out
    assert "examples:" in out and "--animate" in out

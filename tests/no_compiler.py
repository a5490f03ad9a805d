"""A process with no C compiler, for the element tables' promise (issue 34): once the element
library is in the compile cache, a new model of covered kinds needs no compiler.

``run_without_compiler(script, tmp_path)`` runs ``script`` in a Python process whose ``PATH``
holds no compiler (an empty directory) and returns the JSON the script prints last.  The
script calls ``forbid_compiler()`` first (``compile_package`` then fails if called) and builds
its models with ``chain`` and ``fourbar`` from this module."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

import ncgen as nc

ROOT = Path(__file__).resolve().parent.parent


def forbid_compiler() -> None:
    """Assert that no compiler is on ``PATH`` and make ``compile_package`` fail if called."""
    import ncgen.codegen.compile_cache as cc

    assert not any(shutil.which(c) for c in ("cc", "gcc", "clang")), "a compiler is on PATH"

    def no_compile(*args, **kwargs):
        raise AssertionError("the compiler was called")

    cc.compile_package = no_compile


def chain(name: str, n: int, step: tuple[float, float, float]) -> nc.System:
    """A spatial chain of ``n`` bars (``rr``) from a ground point, bar k's far end
    ``(step[0] + 0.01 k, step[1] (k mod 3), step[2])`` (m) beyond its near end, masses
    0.3 + 0.02 k (kg), each bar starting at the previous one's end, the first at a ground point
    at the origin."""
    s = nc.System(name)
    start = s.ground.point((0.0, 0.0, 0.0))
    pos = np.zeros(3)
    for k in range(n):
        pos = pos + np.array([step[0] + 0.01 * k, step[1] * (k % 3), step[2]])
        start = s.add_bar(f"link{k}", coords="rr", mass=0.3 + 0.02 * k, ends=[start, tuple(pos)]).end(1)
    return s


def fourbar(name: str) -> nc.System:
    """A planar four-bar of three ``rr`` bars between ground points (0, 0) and (2.6, 0) (m), its
    crank hinged to the ground by a ``Revolute``."""
    s = nc.System(name, gravity=(0.0, -9.81))
    crank = s.add_bar("crank", coords="rr", mass=0.4, ends=[(0.0, 0.0), (0.3, 0.7)])
    coupler = s.add_bar("coupler", coords="rr", mass=1.1, ends=[crank.end(1), (2.2, 1.9)])
    s.add_bar("rocker", coords="rr", mass=0.9, ends=[coupler.end(1), s.ground.point((2.6, 0.0))])
    s.add_joint(nc.Revolute(s.ground, crank, at=(0.0, 0.0)))
    return s


def run_without_compiler(script: str, tmp_path: Path):
    """Run ``script`` (Python source) with an empty ``PATH`` and no ``CC``, ncgen and this module
    importable; the JSON of its last line of output.  Fails with the child's error output."""
    empty = tmp_path / "bin"
    empty.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("CC", "PATH")}
    env["PATH"] = str(empty)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), str(ROOT / "tests"), env.get("PYTHONPATH", "")])
    out = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])

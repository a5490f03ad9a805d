"""The README's Python tour runs as written, and its two set-up commands are the ones CI uses."""
import re
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")


def test_readme_starts_with_the_two_commands_and_ci_runs_the_test_one():
    first_block = re.match(r"```\n(.*?)```", README, re.S).group(1).strip().splitlines()
    assert first_block == ["pip install . && ncgen demo", "pip install '.[test]' && pytest -q -n auto"]
    assert first_block[1] in (ROOT / ".ci" / "run").read_text(encoding="utf-8")


def test_python_tour_runs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code = re.search(r"```python\n(.*?)```", README, re.S).group(1)
    scope: dict = {}
    exec(compile(code, "README.md", "exec"), scope)
    traj, model = scope["traj"], scope["model"]
    assert (tmp_path / "chain.npz").exists() and (tmp_path / "chain_c" / "chain.h").exists()
    assert model.dof == 4            # two bars on ball joints: 2 + 2 (a bar does not spin)
    assert traj.constraint_residual.max() < 1e-6
    assert np.all(np.diff(traj.energy) < 1e-6)    # the damper only dissipates
    assert np.all(np.isfinite(scope["tip"]))

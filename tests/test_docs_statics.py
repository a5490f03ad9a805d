"""The Python snippets of docs/statics-and-modes.md run as written and print what they say."""
import re
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DOC = (ROOT / "docs" / "statics-and-modes.md").read_text(encoding="utf-8")


def test_snippets_run(tmp_path, monkeypatch):
    code = "\n".join(re.findall(r"```python\n(.*?)```", DOC, re.S))
    code = code.replace('"examples/', f'"{ROOT}/examples/')
    monkeypatch.chdir(tmp_path)
    scope: dict = {}
    exec(compile(code, "statics-and-modes.md", "exec"), scope)
    assert scope["eq"].stability == "stable" and scope["up"].stability == "unstable"
    m, M, lc = 0.2, 1.0, 0.25
    J = m * 0.5**2 / 12 + m * lc**2
    d = (M + m) * J - (m * lc) ** 2
    np.testing.assert_allclose(scope["lin"].A[3, 1], (M + m) * m * 9.81 * lc / d, rtol=1e-9)
    assert (tmp_path / "modes.csv").exists() and (tmp_path / "cartpole_lin" / "cartpole.h").exists()
    assert scope["prism"].stability == "stable"

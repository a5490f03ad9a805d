"""The Python snippets of docs/sweeps.md run as written (a spawn pool and a local Dask
cluster included) and give what they say."""
import re
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
DOC = (ROOT / "docs" / "sweeps.md").read_text(encoding="utf-8")


@pytest.mark.slow                                  # a spawn pool and a Dask cluster (90 s at load 12)
def test_snippets_run(tmp_path, monkeypatch, capsys):
    pytest.importorskip("distributed")
    code = "\n".join(re.findall(r"```python\n(.*?)```", DOC, re.S))
    code = code.replace('"examples/', f'"{ROOT}/examples/')
    monkeypatch.chdir(tmp_path)
    scope: dict = {"__name__": "__main__"}
    exec(compile(code, "sweeps.md", "exec"), scope)
    out = capsys.readouterr().out
    assert "(20, 201, 8)" in out and "True (20, 201, 1, 2)" in out and "(4, 201, 8)" in out
    assert scope["batch"].ok.all() and scope["grid"].info["failed"] == 0
    assert len(scope["trajectories"]) == 2 and scope["on_cluster"].info["where"] == "dask"
    assert np.array_equal(scope["on_cluster"]["q"][:], scope["grid"]["q"][:])       # cluster = local, bit for bit
    assert np.array_equal(scope["trajectories"][1].q, scope["grid"]["q"][1, :101])
    assert (tmp_path / "crank.zarr" / "summary").is_dir()

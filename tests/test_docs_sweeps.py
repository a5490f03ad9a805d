"""The Python snippets of docs/sweeps.md run as written (a spawn pool and a local Dask
cluster included) and give what they say."""
from pathlib import Path

import numpy as np
import pytest

from doc_snippets import run_section, sections

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow                                  # a spawn pool and a Dask cluster (90 s at load 12)
def test_snippets_run(tmp_path, monkeypatch):
    """As one script run as ``__main__`` (the page guards its work for spawn): every snippet
    runs and prints what the page shows (tests/doc_snippets.py compares each text block)."""
    pytest.importorskip("distributed")
    monkeypatch.chdir(tmp_path)
    scope: dict = {"__name__": "__main__"}
    for title, snippets in sections(ROOT / "docs" / "sweeps.md"):
        for s in snippets:
            s.code = s.code.replace('"examples/', f'"{ROOT}/examples/')
        run_section(f"docs/sweeps.md, section {title!r}", snippets, scope)
    assert scope["batch"].ok.all() and scope["grid"].info["failed"] == 0
    assert len(scope["trajectories"]) == 2 and scope["on_cluster"].info["where"] == "dask"
    assert np.array_equal(scope["on_cluster"]["q"][:], scope["grid"]["q"][:])       # cluster = local, bit for bit
    assert np.array_equal(scope["trajectories"][1].q, scope["grid"]["q"][1, :101])
    assert (tmp_path / "crank.zarr" / "summary").is_dir()

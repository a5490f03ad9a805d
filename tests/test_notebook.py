"""Notebooks: a Trajectory displays as its interactive 3D page in a static HTML cell and a
Model as a table of its sizes — checked by executing a notebook (nbclient) and, with
Chromium, by drawing the saved cell."""
from __future__ import annotations

import html
import json
import re
from pathlib import Path

import numpy as np
import pytest

import ncgen as nc

from test_viz_html import chromium, needs_chromium

ROOT = Path(__file__).resolve().parents[1]
MODEL = ROOT / "examples" / "double_pendulum.toml"


@pytest.fixture(scope="module")
def executed():
    """The two display cells' outputs of an executed notebook (nbformat, nbclient and ipykernel
    imported here, not at collection: every worker would import them)."""
    nbformat, nbclient = pytest.importorskip("nbformat"), pytest.importorskip("nbclient")
    pytest.importorskip("ipykernel")
    nb = nbformat.v4.new_notebook()
    nb.cells = [nbformat.v4.new_code_cell(f"import ncgen as nc\nmodel = nc.System.from_toml({str(MODEL)!r}).build()\n"
                                          "model"),
                nbformat.v4.new_code_cell("traj = nc.simulate(model, 1.0, 0.01, backend='vm')\ntraj")]
    nbclient.NotebookClient(nb, timeout=300, kernel_name="python3").execute()
    results = [[out for out in cell.outputs if out["output_type"] == "execute_result"] for cell in nb.cells]
    assert all(len(r) == 1 for r in results), [cell.outputs for cell in nb.cells]
    return [r[0]["data"] for r in results]


def test_a_model_shows_as_a_table_of_its_sizes(executed):
    model = nc.System.from_toml(MODEL).build()
    cell = executed[0]["text/html"]
    rows = dict(re.findall(r"<th[^>]*>([^<]+)</th><td[^>]*>([^<]*)</td>", cell))
    assert rows["name"] == model.name and rows["coordinates q"] == str(model.nq)
    assert rows["degrees of freedom"] == "2" == str(model.dof)          # a double pendulum: two angles
    assert executed[0]["text/plain"] == repr(model)


def test_a_trajectory_shows_as_its_page_in_the_cell(executed):
    cell = executed[1]["text/html"]
    found = re.fullmatch(r'<iframe srcdoc="([^"]*)" title="([^"]*)" style="[^"]*"></iframe>', cell)
    assert found, cell[:300]
    page = html.unescape(found.group(1))
    data = json.loads(re.search(r'<script type="application/json" id="scene-data">(.*?)</script>', page,
                                re.S).group(1).replace("<\\/", "</"))
    assert "double_pendulum" in html.unescape(found.group(2)) and "101 steps" in html.unescape(found.group(2))
    assert "three.js" in page.lower() and "<script type=\"module\">" in page     # offline: the library inlined
    assert data["members"] and len(data["members"]) == 2


def test_empty_or_modelless_trajectories_fall_back_to_text(tmp_path):
    model = nc.System.from_toml(MODEL).build()
    traj = nc.simulate(model, 0.1, 0.01, backend="vm")
    saved = nc.runtime.Trajectory.load(traj.save(tmp_path / "run.npz"))
    assert saved.model is None and saved._repr_html_() is None
    assert traj.head(0)._repr_html_() is None


@needs_chromium
def test_the_saved_cell_draws_the_motion(executed, tmp_path):
    host = tmp_path / "notebook_cell.html"
    host.write_text(f"<!doctype html><html><body style='margin:0;background:#fff'>{executed[1]['text/html']}"
                    "</body></html>", encoding="utf-8")
    png = tmp_path / "cell.png"
    _, console = chromium(host.as_uri(), tmp_path, f"--screenshot={png}")
    from PIL import Image
    shot = np.asarray(Image.open(png).convert("RGB")).astype(int)
    view = shot[20:480, 20:400]                         # the 3D view, left of the plot panel
    assert not [line for line in console if "Error" in line or "error" in line], console
    assert view.std() > 5.0 and len(np.unique(view.reshape(-1, 3), axis=0)) > 50   # drawn, not a blank frame

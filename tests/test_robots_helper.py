"""nc.robots finds example-robot-data's URDFs by name, or says which extra to install; the
Panda example runs as written and calls the zero-torque (conservative) robot conservative."""
import os
import subprocess
import sys
from importlib import metadata
from pathlib import Path

import pytest

import ncgen as nc

ROOT = Path(__file__).resolve().parents[1]


def test_missing_package_names_the_extra(monkeypatch):
    def missing(name):
        raise metadata.PackageNotFoundError(name)
    monkeypatch.setattr(metadata, "files", missing)
    with pytest.raises(nc.ModelError, match=r"pip install 'ncgen\[robots\]'"):
        nc.robots.urdf_path("panda")


def test_names_and_unknown_robot():
    pytest.importorskip("cmeel", reason="example-robot-data is not installed")
    path = nc.robots.urdf_path("panda")
    assert path.name == "panda.urdf" and path.is_file()
    assert nc.robots.urdf_path("ur5").name == "ur5_robot.urdf"
    assert "panda" in nc.robots.names()
    with pytest.raises(nc.ModelError, match=r"robot 'pandaa': .* close names: panda"):
        nc.robots.urdf_path("pandaa")


@pytest.mark.slow      # robot scale (examples/panda.py); fast: the helper's tests above, URDF robots in test_urdf*.py
def test_panda_example_runs_and_is_conservative(tmp_path, tmp_path_factory):
    pytest.importorskip("yourdfpy")
    pytest.importorskip("cmeel", reason="example-robot-data is not installed")
    env = {**os.environ, "PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg", "NCGEN_CACHE_DIR": str(tmp_path_factory.getbasetemp() / "cache")}
    out = subprocess.run([sys.executable, str(ROOT / "examples" / "panda.py")], cwd=tmp_path, env=env,
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    assert "energy (conservative" in out.stdout and "wrote panda.png" in out.stdout
    drift = float(out.stdout.split("max |E - E(t0)| = ")[1].split()[0])
    assert drift < 1e-4                                  # J, of ~90 J: energy conserved

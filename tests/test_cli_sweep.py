"""``ncgen sweep``: grid from the command line into a resumable Zarr store."""
from pathlib import Path

import numpy as np
import pytest

import ncgen as nc
from ncgen.cli import main

EXAMPLE = str(Path(__file__).resolve().parents[1] / "examples" / "slider_crank.toml")


def test_sweep_writes_a_grid_and_resumes(tmp_path, capsys):
    out = str(tmp_path / "sc.zarr")
    argv = ["sweep", EXAMPLE, "--param", "omega=3:5:1", "--t-end", "0.3", "--dt", "0.005", "-o", out,
            "--outputs", "q,kinetic", "--workers", "2"]
    assert main(argv) == 0
    said = capsys.readouterr().out
    assert "sweep of 'slider_crank': 3 runs, 0 failed, 3 computed" in said
    summary, arrays = nc.open_sweep(out)
    assert summary["omega"].tolist() == [3.0, 4.0, 5.0] and list(summary["status"]) == [0, 0, 0]
    model = nc.System.from_toml(EXAMPLE).build()
    traj = nc.simulate(model, 0.3, 0.005, method="stepper", p={"omega": 4.0})
    assert np.array_equal(arrays["q"][1], traj.q) and np.array_equal(arrays["kinetic"][1], traj.kinetic)
    assert main(argv[:-1] + ["1"]) == 0           # resumed, whatever the number of workers now
    assert "3 runs (3 already done), 0 failed, 0 computed" in capsys.readouterr().out


def test_sweep_reports_failed_runs_with_their_parameters(tmp_path, capsys):
    argv = ["sweep", EXAMPLE, "--param", "omega=4,150", "--t-end", "0.5", "--dt", "0.01", "-o",
            str(tmp_path / "f.zarr")]             # 150 rad/s: too fast for the default scheme at h = 10 ms
    assert main(argv) == 0
    said = capsys.readouterr().out
    assert "1 failed" in said and "run 1 (omega=150): not trustworthy" in said


def test_sweep_samples_and_usage_errors(tmp_path, capsys):
    out = str(tmp_path / "lhs.zarr")
    assert main(["sweep", EXAMPLE, "--param", "omega=3:6", "--samples", "lhs:4", "--seed", "3", "--t-end", "0.1",
                 "-o", out]) == 0
    summary, _ = nc.open_sweep(out)
    expected = nc.Samples.latin_hypercube(4, {"omega": (3.0, 6.0)}, seed=3).column("omega")
    assert np.array_equal(summary["omega"], expected)
    assert main(["sweep", EXAMPLE, "--param", "omega=3:1:1", "--t-end", "1", "-o", out]) == 2
    assert "START <= STOP" in capsys.readouterr().err
    assert main(["sweep", EXAMPLE, "--param", "omega=3:6", "--samples", "lhs", "--t-end", "1", "-o", out]) == 2
    assert "expected lhs:N, sobol:N or random:N" in capsys.readouterr().err
    assert main(["sweep", EXAMPLE, "--param", "k=1,2", "--t-end", "1", "-o", str(tmp_path / "k.zarr")]) == 1
    assert "'k' is not a parameter of model 'slider_crank' (parameters: omega)" in capsys.readouterr().err


def test_sweep_help_teaches(capsys):
    assert main(["sweep", "--help"]) == 0
    text = capsys.readouterr().out
    for needed in ("--scheduler", "resumes", "k=10:100:10", "lhs:N", "nc.open_sweep", "status"):
        assert needed in text


@pytest.mark.slow                                  # a Dask cluster of two processes
def test_sweep_on_a_dask_scheduler(tmp_path, capsys):
    distributed = pytest.importorskip("distributed")
    out = str(tmp_path / "dask.zarr")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        argv = ["sweep", EXAMPLE, "--param", "omega=3,5", "--t-end", "0.2", "--dt", "0.005", "-o", out,
                "--scheduler", cluster.scheduler_address, "--chunk", "1"]
        assert main(argv) == 0
    said = capsys.readouterr().out
    assert "2 runs, 0 failed, 2 computed" in said and "runs/s, dask)" in said
    summary, arrays = nc.open_sweep(out)
    model = nc.System.from_toml(EXAMPLE).build()
    assert np.array_equal(arrays["q"][1], nc.simulate(model, 0.2, 0.005, method="stepper", p={"omega": 5.0}).q)


@pytest.mark.slow                                  # Dask: its import and the connection attempt
def test_unreachable_scheduler_is_a_clear_error(tmp_path, capsys):
    argv = ["sweep", EXAMPLE, "--param", "omega=3", "--t-end", "0.1", "-o", str(tmp_path / "x.zarr"),
            "--scheduler", "tcp://127.0.0.1:9"]
    assert main(argv) == 1
    assert "cannot reach the Dask scheduler" in capsys.readouterr().err

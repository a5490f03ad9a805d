"""``nc.sweep``: local cores and a Dask cluster give the serial loop's numbers bit for bit;
results stream to Zarr + Parquet and a rerun resumes; a failing run is reported with its
parameters."""
import os
from pathlib import Path

import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import NcgenError
from ncgen.runtime import sweep as sweep_module
from ncgen.runtime.batch import STATUS_UNTRUSTED

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
T_END, DT = 0.4, 0.005


@pytest.fixture(scope="module")
def slider_crank():
    return nc.System.from_toml(EXAMPLES / "slider_crank.toml").build()


def serial(model, omegas, method="stepper"):
    return [nc.simulate(model, T_END, DT, method=method, p={"omega": w}) for w in omegas]


def test_local_sweep_equals_the_serial_loop(slider_crank):
    omegas = np.linspace(3.0, 7.0, 7)
    result = nc.sweep(slider_crank, {"omega": omegas}, t_end=T_END, dt=DT, outputs=["q", "v", "kinetic"],
                      workers=2, chunk=2, progress=False)
    assert result.info["where"] == "threads" and result.info["failed"] == 0
    assert list(result.summary["run"]) == list(range(7)) and np.array_equal(result.summary["omega"], omegas)
    for i, traj in enumerate(serial(slider_crank, omegas)):
        assert np.array_equal(result["q"][i], traj.q) and np.array_equal(result["v"][i], traj.v)
        assert np.array_equal(result["kinetic"][i], traj.kinetic)
        assert result.summary["energy_end"][i] == traj.kinetic[-1] + traj.potential[-1]
    assert np.all(result.summary["max_constraint_residual"] < 1e-9)


@pytest.mark.slow                                  # a Dask cluster of two processes
def test_dask_cluster_sweep_to_zarr_equals_the_serial_loop(slider_crank, tmp_path):
    distributed = pytest.importorskip("distributed")
    omegas = np.array([3.0, 4.0, 5.0, 6.0])
    table = nc.Samples.table({"omega": omegas})
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        result = nc.sweep(slider_crank, table, t_end=T_END, dt=DT, outputs=["q", "markers"], client=client,
                          chunk=1, path=tmp_path / "sweep.zarr", progress=False)
    assert result.info["where"] == "dask" and result.info["computed"] == 4
    assert all(not w.endswith(f":{os.getpid()}") for w in result.summary["worker"])      # ran on the workers
    for i, traj in enumerate(serial(slider_crank, omegas)):
        assert np.array_equal(result["q"][i], traj.q) and np.array_equal(result["markers"][i], traj.markers)
    summary, arrays = nc.open_sweep(tmp_path / "sweep.zarr")        # one tidy result on disk
    assert np.array_equal(summary["omega"], omegas) and np.array_equal(arrays["t"][:], result.t)
    import pandas as pd
    assert list(pd.read_parquet(tmp_path / "sweep.zarr" / "summary")["omega"]) == list(omegas)


def test_idas_sweep_in_spawned_processes_equals_the_serial_loop(slider_crank):
    omegas = [3.0, 5.0]
    result = nc.sweep(slider_crank, {"omega": omegas}, t_end=0.2, dt=0.01, method="idas", workers=2, chunk=1,
                      progress=False)
    assert result.info["where"] == "processes"
    for i, w in enumerate(omegas):
        assert np.array_equal(result["q"][i], nc.simulate(slider_crank, 0.2, 0.01, method="idas", p={"omega": w}).q)


def test_interrupted_sweep_resumes_without_repeating_runs(slider_crank, tmp_path, monkeypatch):
    omegas = np.linspace(3.0, 6.0, 6)
    path = tmp_path / "sweep.zarr"
    put, written = sweep_module._Store.put, []

    def dies_after_two(self, first, result):
        if len(written) == 2:
            raise KeyboardInterrupt("killed")
        put(self, first, result)
        written.append(first)

    monkeypatch.setattr(sweep_module._Store, "put", dies_after_two)
    with pytest.raises(KeyboardInterrupt):
        nc.sweep(slider_crank, {"omega": omegas}, t_end=T_END, dt=DT, path=path, workers=1, chunk=1, progress=False)
    monkeypatch.setattr(sweep_module._Store, "put", put)
    parts = {p.name: p.stat().st_mtime_ns for p in (path / "summary").glob("part-*.parquet")}
    assert len(parts) == 2
    ran = []
    run_chunk = sweep_module.run_chunk
    monkeypatch.setattr(sweep_module, "run_chunk",
                        lambda m, runs, *rest: ran.extend(runs) or run_chunk(m, runs, *rest))
    result = nc.sweep(slider_crank, {"omega": omegas}, t_end=T_END, dt=DT, path=path, workers=1, chunk=1,
                      progress=False)
    assert sorted(ran) == sorted(set(range(6)) - set(written)) and result.info["resumed"] == 2
    assert {p.name: p.stat().st_mtime_ns for p in (path / "summary").glob("part-*.parquet") if p.name in parts} == parts
    for i, traj in enumerate(serial(slider_crank, omegas)):
        assert np.array_equal(result["q"][i], traj.q)
    with pytest.raises(NcgenError, match="holds another sweep .*samples_sha256"):
        nc.sweep(slider_crank, {"omega": omegas + 1}, t_end=T_END, dt=DT, path=path, workers=1, chunk=1)


# idas: two spawned processes more; fast: the stepper's runs (the same arrays of states and inputs) and
# test_idas_sweep_in_spawned_processes_equals_the_serial_loop (IDAS runs in spawned processes)
@pytest.mark.parametrize("method", ["stepper", pytest.param("idas", marks=pytest.mark.slow)])
def test_monte_carlo_on_initial_states_and_inputs_equals_the_serial_loop(method):
    cartpole = nc.System.from_toml(EXAMPLES / "cartpole.toml").build()
    pushed = nc.simulate(cartpole, 0.3, 0.01, method="stepper", u=lambda t: [2.0])
    q0, v0 = pushed.q[::10], pushed.v[::10]                   # 4 consistent states
    U = np.random.default_rng(2).uniform(-1, 1, size=(4, 21, 1))
    result = nc.sweep(cartpole, None, t_end=0.2, dt=0.01, q0=q0, v0=v0, u=U, method=method, workers=2, chunk=1,
                      outputs=["q", "v"], progress=False)
    assert result.info["failed"] == 0 and list(result.summary["run"]) == [0, 1, 2, 3]
    for i in range(4):
        traj = nc.simulate(cartpole, 0.2, 0.01, method=method, q0=q0[i], v0=v0[i], u=U[i])
        assert np.array_equal(result["q"][i], traj.q) and np.array_equal(result["v"][i], traj.v)
    with pytest.raises(NcgenError, match=r"arrays of one number of runs \(found \[2, 4\]\)"):
        nc.sweep(cartpole, None, t_end=0.2, dt=0.01, q0=q0, u=U[:2])
    with pytest.raises(NcgenError, match=r"u: expected an array of shape \(len\(t\), nu\) or .* with 4 runs"):
        nc.sweep(cartpole, nc.Samples([], np.zeros((4, 0))), t_end=0.2, dt=0.01, u=U[:2])


def test_a_failing_run_is_reported_with_its_parameters(slider_crank):
    result = nc.sweep(slider_crank, {"omega": [4.0, 60.0, 5.0]}, t_end=0.5, dt=0.01, workers=2, progress=False,
                      scheme="rattle")                 # 60 rad/s is too fast for RATTLE at h = 10 ms
    assert list(result.summary["status"]) == [0, STATUS_UNTRUSTED, 0] and result.info["failed"] == 1
    [failure] = result.failures
    assert failure["run"] == 1 and failure["omega"] == 60.0 and "not trustworthy" in failure["message"]
    assert np.isnan(result["q"][1][-1]).all() and np.isfinite(result["q"][2]).all()


def test_samplers_and_tables():
    lhs = nc.Samples.latin_hypercube(8, {"k": (10.0, 100.0), "m": (0.5, 1.0)}, seed=4)
    again = nc.Samples.latin_hypercube(8, {"k": (10.0, 100.0), "m": (0.5, 1.0)}, seed=4)
    assert np.array_equal(lhs.values, again.values) and lhs.names == ["k", "m"]
    for j, (lo, hi) in enumerate([(10.0, 100.0), (0.5, 1.0)]):     # one sample per stratum
        strata = np.floor((lhs.values[:, j] - lo) / (hi - lo) * 8).astype(int)
        assert sorted(strata) == list(range(8))
    sob = nc.Samples.sobol(16, {"k": (0.0, 1.0)}, seed=1)
    assert len(sob) == 16 and np.all((sob.values >= 0) & (sob.values < 1))
    with pytest.raises(NcgenError, match="power of two"):
        nc.Samples.sobol(10, {"k": (0.0, 1.0)})
    rnd = nc.Samples.random(5, {"k": (2.0, 3.0)}, seed=0)
    assert np.all((rnd.values >= 2) & (rnd.values < 3))
    grid = nc.Samples.grid({"k": [10, 20, 30], "m": [0.5, 1]})
    assert grid.values.tolist() == [[10, 0.5], [10, 1], [20, 0.5], [20, 1], [30, 0.5], [30, 1]]
    pd = pytest.importorskip("pandas")
    frame = pd.DataFrame({"k": [1.0, 2.0], "m": [3.0, 4.0]})
    assert nc.Samples.table(frame).values.tolist() == [[1, 3], [2, 4]]
    with pytest.raises(NcgenError, match=r"differ in length"):
        nc.Samples.table({"k": [1, 2], "m": [1]})


def test_bad_sweep_arguments_are_named(slider_crank):
    with pytest.raises(NcgenError, match="'mass' is not a parameter of model 'slider_crank' \\(parameters: omega\\)"):
        nc.sweep(slider_crank, {"mass": [1, 2]}, t_end=0.1, dt=0.01)
    with pytest.raises(NcgenError, match="outputs: unknown 'x'"):
        nc.sweep(slider_crank, {"omega": [1]}, t_end=0.1, dt=0.01, outputs=["x"])
    with pytest.raises(NcgenError, match="method='stepper' takes no option 'rtol'"):
        nc.sweep(slider_crank, {"omega": [1]}, t_end=0.1, dt=0.01, rtol=1e-6)


KILLED_SWEEP = """
import sys
import numpy as np
import ncgen as nc
model = nc.System.from_toml(sys.argv[1]).build()
nc.sweep(model, {"omega": np.linspace(3.0, 6.0, 200)}, t_end=0.4, dt=0.005, path=sys.argv[2], workers=1, chunk=1,
         progress=False)
"""


@pytest.mark.slow      # a subprocess killed and run again; fast: test_interrupted_sweep_resumes_without_repeating_runs
#                         (the same resume from the runs stored)
def test_sweep_killed_by_sigkill_resumes(slider_crank, tmp_path):
    import signal
    import subprocess
    import sys
    import time

    path = tmp_path / "killed.zarr"
    nc.simulate(slider_crank, 0.1, 0.005, method="stepper")          # compiled before the child starts
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    child = subprocess.Popen([sys.executable, "-c", KILLED_SWEEP, str(EXAMPLES / "slider_crank.toml"), str(path)],
                             env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 240
    while len(list((path / "summary").glob("part-*.parquet"))) < 5 and time.monotonic() < deadline:
        assert child.poll() is None, "the sweep ended before it could be killed"
        time.sleep(0.01)
    child.send_signal(signal.SIGKILL)
    child.wait()
    before = {p.name: p.stat().st_mtime_ns for p in (path / "summary").glob("part-*.parquet")}
    assert 5 <= len(before) < 200
    omegas = np.linspace(3.0, 6.0, 200)
    result = nc.sweep(slider_crank, {"omega": omegas}, t_end=0.4, dt=0.005, path=path, workers=1, chunk=1,
                      progress=False)
    assert result.info["resumed"] == len(before) and result.info["computed"] == 200 - len(before)
    assert {p.name: p.stat().st_mtime_ns for p in (path / "summary").glob("part-*.parquet") if p.name in before} \
        == before
    assert list(result.summary["run"]) == list(range(200)) and result.info["failed"] == 0
    for i in (0, len(before) - 1, len(before), 199):          # finished before the kill, at it, after it
        traj = nc.simulate(slider_crank, 0.4, 0.005, method="stepper", p={"omega": omegas[i]})
        assert np.array_equal(result["q"][i], traj.q)

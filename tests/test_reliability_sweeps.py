"""Sweeps, batches and pickles (issue 35, classes 2, 3, 9, 10, 12 and the sweep half of 13):
a sweep never writes into a folder that is not an ncgen sweep, a closed Dask client and
non-finite or oversized grids are refused at once by name, a missing extra is found before
anything is compiled or run, blown-up runs keep only their trusted rows (checked against the
closed form) with the real cause named, ragged per-run parameters name ``p`` and the
parameter, and a pickle of another ncgen version says to rebuild."""
from __future__ import annotations

import pickle
import re
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import ncgen as nc
from ncgen.cli import main
from ncgen.errors import ModelError, NcgenError, SimulationError
from ncgen.runtime import sweep as sweep_module
from ncgen.runtime.samples import MAX_RUNS

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
K = 400.0          # the repelling stiffness of `repelled` (1/s²): the pair runs away as cosh(20 t)


@pytest.fixture(scope="module")
def slider_crank():
    return nc.System.from_toml(EXAMPLES / "slider_crank.toml").build()


@pytest.fixture(scope="module")
def repelled():
    """Two unit point masses 1 m apart (a distance constraint), each pushed by ``k q`` from
    the origin: the centre of mass c obeys ``c'' = k c + g``, so it runs away
    exponentially until the numbers overflow."""
    s = nc.System("repelled", gravity=(0.0, -9.81))
    a = s.add_point("a", mass=1.0, position=(1.0, 0.0))
    b = s.add_point("b", mass=1.0, position=(2.0, 0.0))
    s.add_joint(nc.Distance(a, b, at=[(1.0, 0.0), (2.0, 0.0)]))
    s.add_parameter("k", 1.0)
    s.add_force(nc.GeneralizedForce(lambda t, q, v, u, p: p[0] * q))
    return s.build()


# ------------------------------------------------------------------ the user's files
def test_sweep_refuses_a_zarr_store_that_is_not_an_ncgen_sweep(slider_crank, tmp_path, capsys):
    zarr = pytest.importorskip("zarr")
    store = tmp_path / "mine.zarr"
    group = zarr.open_group(str(store), mode="w")
    group.create_array("t", shape=(3,), dtype="f8")[:] = [1.0, 2.0, 3.0]
    group.create_array("q", shape=(2,), dtype="f8")[:] = [7.0, 8.0]
    before = {p: p.read_bytes() for p in store.rglob("*") if p.is_file()}
    with pytest.raises(NcgenError, match=f"{store.name}' exists and is not an ncgen sweep's store"):
        nc.sweep(slider_crank, {"omega": [3.0, 4.0]}, t_end=0.1, dt=0.01, path=store, progress=False)
    assert main(["sweep", str(EXAMPLES / "slider_crank.toml"), "--param", "omega=3,4", "--t-end", "0.1",
                 "-o", str(store)]) != 0
    assert "is not an ncgen sweep's store" in capsys.readouterr().err
    assert {p: p.read_bytes() for p in store.rglob("*") if p.is_file()} == before       # untouched
    assert list(zarr.open_group(str(store), mode="r")["q"][:]) == [7.0, 8.0]


def test_sweep_refuses_other_folders_and_files_but_takes_an_empty_one(slider_crank, tmp_path):
    pytest.importorskip("zarr")
    notes = tmp_path / "notes"
    notes.mkdir()
    (notes / "thesis.tex").write_text("precious")
    with pytest.raises(NcgenError, match="is not an ncgen sweep's store"):
        nc.sweep(slider_crank, {"omega": [3.0]}, t_end=0.1, dt=0.01, path=notes, progress=False)
    assert [p.name for p in notes.iterdir()] == ["thesis.tex"]
    file = tmp_path / "run.zarr"
    file.write_text("a file")
    with pytest.raises(NcgenError, match="is a file, not a sweep's folder"):
        nc.sweep(slider_crank, {"omega": [3.0]}, t_end=0.1, dt=0.01, path=file, progress=False)
    assert file.read_text() == "a file"
    empty = tmp_path / "empty"
    empty.mkdir()
    first = nc.sweep(slider_crank, {"omega": [3.0]}, t_end=0.1, dt=0.01, path=empty, progress=False)
    again = nc.sweep(slider_crank, {"omega": [3.0]}, t_end=0.1, dt=0.01, path=empty, progress=False)
    assert first.info["computed"] == 1 and again.info["resumed"] == 1           # its own store: resumed


def test_a_missing_extra_is_found_before_compiling(slider_crank, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "zarr", None)           # import zarr fails
    monkeypatch.setattr(sweep_module, "load_any_stepper", lambda model, **k: pytest.fail("compiled before the check"))
    with pytest.raises(NcgenError, match=r"sweep\(path='[^']*out\.zarr'\): writing results needs zarr and pyarrow "
                                         r"\(zarr is missing\)"):
        nc.sweep(slider_crank, {"omega": [3.0]}, t_end=0.1, dt=0.01, path=tmp_path / "out.zarr", progress=False)
    assert not (tmp_path / "out.zarr").exists()


# ------------------------------------------------------------------ where and what runs
def test_a_closed_dask_client_is_refused(slider_crank):
    distributed = pytest.importorskip("distributed")
    client = distributed.Client(processes=False, n_workers=1, threads_per_worker=1, dashboard_address=None)
    client.close()
    with pytest.raises(NcgenError, match="client: the Dask client is 'closed', not connected"):
        nc.sweep(slider_crank, {"omega": [3.0]}, t_end=0.1, dt=0.01, client=client, progress=False)


@pytest.mark.parametrize("values, said", [
    ([1.0, float("nan")], "grid: parameter 'omega': expected finite numbers, got nan"),
    ([float("inf")], "grid: parameter 'omega': expected finite numbers, got inf"),
    (["fast"], "grid: parameter 'omega': expected a non-empty list of numbers"),
])
def test_non_finite_grids_are_refused(slider_crank, values, said):
    with pytest.raises(NcgenError, match=said):
        nc.sweep(slider_crank, {"omega": values}, t_end=0.1, dt=0.01, progress=False)


def test_oversized_grids_and_samples_are_refused_at_once(slider_crank):
    start = time.process_time()
    with pytest.raises(NcgenError, match=r"grid: 1000000 \(omega\) × 1000000 \(k\) = 1e\+12 runs, more than"):
        nc.Samples.grid({"omega": np.arange(1e6), "k": np.arange(1e6)})
    for n in (1e12, MAX_RUNS + 1):
        with pytest.raises(NcgenError, match="n: .* runs, more than the limit"):
            nc.Samples.latin_hypercube(n, {"omega": (1.0, 2.0)})
    for n in (float("nan"), float("inf"), 0, 2.5, "10"):
        with pytest.raises(NcgenError, match="n: expected a positive number of runs"):
            nc.Samples.random(n, {"omega": (1.0, 2.0)})
    # CPU time, so the load does not count: the refusals take milliseconds, allocating the grid
    # (1e12 runs) or running the samples would take far more than 5 s
    assert time.process_time() - start < 5.0


@pytest.mark.parametrize("args, said", [
    (["--param", "omega=0:1:nan"], "--param 'omega=0:1:nan': expected finite numbers"),
    (["--param", "omega=0:inf:1"], "--param 'omega=0:inf:1': expected finite numbers"),
    (["--param", "omega=1,nan"], "--param 'omega=1,nan': expected finite numbers"),
    (["--param", "omega=0:-inf", "--samples", "lhs:4"], "--param 'omega=0:-inf': expected finite numbers"),
    (["--param", "omega=0:1e12:1"], "--param 'omega=0:1e12:1': 1e+12 values, more than the limit"),
    (["--param", "omega=0:1e4:1", "--param", "k=0:1e4:1"], "the grid has 10001 (omega) × 10001 (k)"),
    (["--param", "omega=0:1", "--samples", "random:100000000000"], "--samples random:100000000000: more than"),
])
def test_ncgen_sweep_names_the_bad_flag_at_once(tmp_path, capsys, args, said):
    start = time.process_time()
    assert main(["sweep", str(EXAMPLES / "slider_crank.toml"), "--t-end", "0.1", "-o", str(tmp_path / "s.zarr"),
                 *args]) == 2
    assert said in capsys.readouterr().err
    # CPU time (the load does not count): the refusal reads the arguments and the TOML text, tens
    # of milliseconds; building the model and running the sweep would take seconds
    assert time.process_time() - start < 5.0 and not (tmp_path / "s.zarr").exists()


@pytest.mark.parametrize("kw, said", [
    ({"substeps": 0}, "substeps: expected a positive number of steps per output interval, got 0"),
    ({"substeps": 2.5}, "substeps: expected a positive number of steps"),
    ({"newton_tol": float("nan")}, "newton_tol: "),
    ({"method": "idas", "rtol": float("nan")}, "rtol: expected a positive tolerance, got nan"),
    ({"method": "idas", "rtol": -1.0}, "rtol: expected a positive tolerance, got -1.0"),
    ({"method": "idas", "atol": float("inf")}, "atol: expected a positive tolerance, got inf"),
])
def test_bad_run_options_are_refused_before_a_store_is_made(slider_crank, tmp_path, kw, said):
    """An option value each run would refuse is refused once, before the store is created or
    a worker started (it used to leave an empty store behind, or, with IDAS, record every
    run as failed and answer success)."""
    pytest.importorskip("zarr")
    store = tmp_path / "s.zarr"
    with pytest.raises(NcgenError, match=re.escape(said)):
        nc.sweep(slider_crank, {"omega": [3.0, 4.0]}, t_end=0.1, dt=0.01, path=store, progress=False, **kw)
    assert not store.exists()


@pytest.mark.parametrize("args, said", [
    (["--substeps", "0"], "substeps: expected a positive number of steps per output interval, got 0"),
    (["--method", "idas", "--rtol", "nan"], "rtol: expected a positive tolerance, got nan"),
    (["--method", "idas", "--rtol", "-1"], "rtol: expected a positive tolerance, got -1.0"),
    (["--param", "omega=3:5", "--samples", "lhs:3", "--seed", "-1"],
     "--seed: expected None or an integer >= 0 (the same seed draws the same runs), got -1"),
])
def test_ncgen_sweep_refuses_bad_run_options_leaving_no_store(tmp_path, capsys, args, said):
    out = tmp_path / "s.zarr"
    params = [] if "--param" in args else ["--param", "omega=3,4"]
    code = main(["sweep", str(EXAMPLES / "slider_crank.toml"), "--t-end", "0.1", "-o", str(out), *params, *args])
    err = capsys.readouterr().err
    assert code in (1, 2) and said in err and "internal error" not in err, err
    assert not out.exists()


@pytest.mark.parametrize("seed", [-1, 1.5, "7", float("nan"), True])
def test_sampler_seeds_are_checked(seed):
    for make in (nc.Samples.latin_hypercube, nc.Samples.sobol, nc.Samples.random):
        with pytest.raises(NcgenError, match=r"seed: expected None or an integer >= 0 .* got " + re.escape(repr(seed))):
            make(4, {"omega": (1.0, 2.0)}, seed=seed)
    a = nc.Samples.latin_hypercube(4, {"omega": (1.0, 2.0)}, seed=np.int64(3))   # NumPy integers and generators
    b = nc.Samples.latin_hypercube(4, {"omega": (1.0, 2.0)}, seed=3)
    assert np.array_equal(a.values, b.values)
    nc.Samples.random(4, {"omega": (1.0, 2.0)}, seed=np.random.default_rng(1))


# ------------------------------------------------------------------ blown-up runs
def test_a_blown_up_batch_run_keeps_only_its_trusted_rows(repelled):
    """Unchecked, the run goes on to |q| ~ 1e15 m before its Newton update is not finite (the
    round-off of q swamps the unit distance: Newton fails or the KKT solve meets a zero
    constraint gradient, status 1 or 2, wherever the last bits take it); checked, only the
    rows before the error estimate passes 1 % of the size remain, they follow the closed form
    ``c_x = 1.5 cosh(20 t)``, ``c_y = (g/k)(1 − cosh(20 t))``, and the message names the
    estimate first, the failed step after it."""
    bare = nc.simulate_batch(repelled, 40.0, 0.01, p={"k": [K]}, check=False)
    assert bare.status[0] in (1, 2) and np.nanmax(np.abs(bare.q[0])) > 1e6     # what used to be kept
    run = nc.simulate_batch(repelled, 40.0, 0.01, p={"k": [K, 0.0]})
    assert run.status[0] == bare.status[0] and run.status[1] == 0               # k = 0: free fall, kept whole
    fall = run.q[1]
    assert np.allclose(0.5 * (fall[:, 1] + fall[:, 3]), -9.81 * run.t**2 / 2, rtol=1e-9, atol=1e-9)
    message = run.message[0]
    assert message.startswith("not trustworthy: the estimated error in q reached")     # the cause first
    assert ". Later, the stepper failed in the step from t = " in message
    kept = int(np.sum(~np.isnan(run.q[0, :, 0])))
    assert 10 < kept < 100 and np.isnan(run.q[0, kept:]).all() and np.isnan(run.v[0, kept:]).all()
    t, q = run.t[:kept], run.q[0, :kept]
    w, g = np.sqrt(K), 9.81
    cx, cy = 0.5 * (q[:, 0] + q[:, 2]), 0.5 * (q[:, 1] + q[:, 3])
    scale = 1.5 * np.cosh(w * t)
    assert np.max(np.abs(cx - scale) / scale) < 1e-4
    assert np.max(np.abs(cy - g / K * (1 - np.cosh(w * t)))) < 1e-3
    with pytest.raises(SimulationError, match="not trustworthy: the estimated error .* The stepper then failed at "
                                              "t = ") as err:
        nc.simulate(repelled, 40.0, 0.01, method="stepper", p={"k": K})
    single = err.value.trajectory
    assert np.array_equal(single.q, run.q[0, :len(single.t)]) and len(single.t) == kept


@pytest.mark.slow      # two error-controlled runs to failure; fast:
#                       test_a_blown_up_batch_run_keeps_only_its_trusted_rows (the same trusted-rows rule on the
#                       fixed-step stepper)
def test_a_failed_error_controlled_run_keeps_only_its_trusted_rows(repelled):
    """The error control accepts the run-away step by step until its steps shrink to nothing;
    checked, only the rows before the shadow run's global estimate passes 1 % of the size are
    attached, and they follow the closed form ``c_x = 1.5 cosh(20 t)``."""
    with pytest.raises(SimulationError, match="failed between t = ") as bare:
        nc.simulate(repelled, 40.0, 0.01, method="stepper", p={"k": K}, rtol=1e-8, check=False)
    with pytest.raises(SimulationError, match=r"Before that, its estimated global error in q \(against a shadow "
                                              r"run at 10x looser tolerances\) reached .* so only the rows before "
                                              r"it are kept") as checked:
        nc.simulate(repelled, 40.0, 0.01, method="stepper", p={"k": K}, rtol=1e-8)
    kept, whole = checked.value.trajectory, bare.value.trajectory
    assert 10 < len(kept.t) < len(whole.t) and checked.value.time == kept.t[-1] and not kept.complete
    assert np.array_equal(kept.q, whole.q[:len(kept.t)])
    cx = 0.5 * (kept.q[:, 0] + kept.q[:, 2])
    scale = 1.5 * np.cosh(np.sqrt(K) * kept.t)
    assert np.max(np.abs(cx - scale) / scale) < 1e-6


@pytest.fixture(scope="module")
def repelled_pushed():
    """``repelled`` (k = 400 1/s²) with a push on ``a`` along x, for a feedback law."""
    import casadi as ca
    s = nc.System("repelled_pushed", gravity=(0.0, -9.81))
    a = s.add_point("a", mass=1.0, position=(1.0, 0.0))
    b = s.add_point("b", mass=1.0, position=(2.0, 0.0))
    s.add_joint(nc.Distance(a, b, at=[(1.0, 0.0), (2.0, 0.0)]))
    push = s.add_input("push")
    s.add_force(nc.PointForce(a, (0, 0), force=ca.vertcat(push, 0)))
    s.add_parameter("k", K)
    s.add_force(nc.GeneralizedForce(lambda t, q, v, u, p: p[0] * q))
    return s.build()


@pytest.mark.slow      # a second model compiled and three runs to failure; fast:
#                       test_a_blown_up_batch_run_keeps_only_its_trusted_rows, tests/test_reliability_feedback.py (a
#                       failing feedback on the stepper)
def test_a_blown_up_feedback_run_keeps_only_its_trusted_rows(repelled_pushed):
    """One output interval at a time (a feedback), the stepper's rows are checked together
    as an open-loop run's are: the run away is stopped where steps had to be split, not
    kept up to |q| ~ 1e10 m where Newton finally fails (as it was); the rows kept follow the
    closed form ``c_x = 1.5 cosh(20 t)`` (the push is zero); a law that fails later attaches
    the same trusted rows.  ``check=False`` keeps the whole run."""
    zero = lambda t, q, v: [0.0]                                # noqa: E731
    with pytest.raises(SimulationError, match=r"failed in the step from") as bare:
        nc.simulate(repelled_pushed, 40.0, 0.01, method="stepper", u=zero, check=False)
    with pytest.raises(SimulationError, match=r"is not trustworthy: .*step\(s\) had to be split.* The stepper then "
                                              r"failed at t = ") as checked:
        nc.simulate(repelled_pushed, 40.0, 0.01, method="stepper", u=zero)
    whole, kept = bare.value.trajectory, checked.value.trajectory
    assert np.abs(whole.q).max() > 1e9 and 10 < len(kept.t) < len(whole.t)
    assert np.array_equal(kept.q, whole.q[:len(kept.t)]) and not kept.info["complete"]
    cx = 0.5 * (kept.q[:, 0] + kept.q[:, 2])
    scale = 1.5 * np.cosh(np.sqrt(K) * kept.t)
    assert np.max(np.abs(cx - scale) / scale) < 1e-3
    t_bad = float(whole.t[min(len(kept.t) + 5, len(whole.t) - 1)])   # after the trusted rows, before Newton fails

    def late(t, q, v):
        if t >= t_bad - 1e-12:
            raise RuntimeError("sensor lost")
        return [0.0]
    with pytest.raises(SimulationError, match=r"not trustworthy: .* Then the feedback u\(t, q, v\) called at "
                                              r"t = .* s raised RuntimeError: sensor lost\.") as failed:
        nc.simulate(repelled_pushed, 40.0, 0.01, method="stepper", u=late)
    assert np.array_equal(failed.value.trajectory.q, kept.q)


# ------------------------------------------------------------------ batches and pickles
@pytest.mark.parametrize("kw, said", [
    ({"p": {"omega": [1.0, [2.0, 3.0]]}}, r"simulate_batch: p\['omega'\]: the runs' values are ragged"),
    ({"p": [[4.0], [4.0, 5.0]]}, "simulate_batch: p: the runs' values are ragged"),
    ({"q0": [[0.0] * 8, [0.0] * 3]}, "simulate_batch: q0: the runs' values are ragged"),
])
def test_ragged_per_run_arguments_are_named(slider_crank, kw, said):
    with pytest.raises(NcgenError, match=said):
        nc.simulate_batch(slider_crank, 0.1, 0.01, **kw)


def test_a_misspelt_batch_parameter_is_refused_at_once(slider_crank):
    """A parameter name belongs to the call, not to one run: it used to make every run
    "could not start" and return; now it is refused with the name meant."""
    with pytest.raises(NcgenError, match=r"simulate_batch: p: model 'slider_crank' has no parameter 'omga' "
                                         r"\(did you mean 'omega'\?\) \(parameters: omega\)"):
        nc.simulate_batch(slider_crank, 0.1, 0.01, p={"omga": [1.0, 2.0]})
    run = nc.simulate_batch(slider_crank, 0.1, 0.01, p={"omega": [1.0, float("nan")]})      # a run's value: its own
    assert list(run.status) == [0, -1] and "parameter 'omega': expected finite numbers" in run.message[1]


def test_a_pickle_of_another_ncgen_version_says_to_rebuild(slider_crank, monkeypatch):
    model_bytes, system_bytes = pickle.dumps(slider_crank), pickle.dumps(nc.System.from_toml(
        EXAMPLES / "slider_crank.toml"))
    from ncgen.model import model as model_module
    from ncgen.version import __version__ as current
    monkeypatch.setattr(model_module, "_known", {})          # as in a fresh process
    monkeypatch.setattr(model_module, "_rebuilt", type(model_module._rebuilt)())
    monkeypatch.setattr("ncgen.version.__version__", "0.0.1-other")
    for data, what in ((model_bytes, "model"), (system_bytes, "system")):
        with pytest.raises(ModelError, match=rf"this {what} was pickled by another ncgen version "
                                             rf"\(version {re.escape(current)}; "
                                             rf"this is 0.0.1-other\): rebuild the {what}"):
            pickle.loads(data)
    old_layout = nc.System.rebuilt_model                     # a pickle of the older three-field layout
    with pytest.raises(ModelError, match=r"pickled by another ncgen version \(an older version"):
        old_layout(("toml",), {}, "0" * 64)

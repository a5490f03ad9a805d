"""``nc.sweep``: one model run over many parameter sets, on the local cores or a Dask
cluster, results streamed to disk as they arrive, resumable.

Runs are cut into chunks (tasks); a task runs its chunk with :func:`~ncgen.runtime.batch.
simulate_batch` (``method="stepper"``) or one :func:`~ncgen.simulate` per run (``"idas"``)
and returns the chosen per-run arrays and one summary row per run.  Where tasks run:

* local, stepper: threads of this process (the compiled loop releases the GIL);
* local, IDAS: a pool of ``workers`` processes (spawn; the model travels pickled by its
  description, :meth:`ncgen.model.model.Model.__reduce__`);
* a ``dask.distributed.Client``: its workers (the model is scattered once).

A worker rebuilds the model once and loads its compiled library from the compile cache
(:mod:`ncgen.codegen.compile_cache`), compiling only if its machine has no entry yet.

With ``path`` the results go to a Zarr store (one array per output, ``(runs, time, ...)``,
chunked by task, and ``t``) whose folder also holds the summary as a Parquet dataset
(``summary/part-<first run>.parquet``, one file per finished task, written to a temporary
name then renamed).  A finished task's part is written after its arrays, so the parts say
which runs are done: a rerun with the same ``path`` and the same sweep skips them.  A run
that fails never stops the sweep: its row holds ``status`` != 0 and the ``message``.
"""
from __future__ import annotations

import inspect
import json
import math
import os
import socket
import sys
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, ThreadPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ncgen.assembly.nonholonomic import multiplier_count
from ncgen.errors import NcgenError
from ncgen.model.rolling import refuse_rolling
from ncgen.runtime.inputs import time_grid
from ncgen.runtime.samples import Samples, as_samples
from ncgen.runtime.table_stepper import load_any_stepper

METHODS = ("stepper", "idas")
#: Per-run arrays a sweep can keep, and their trailing shape.
OUTPUTS = ("q", "v", "lam", "kinetic", "potential", "constraint_residual", "markers")
#: Columns of the summary besides the parameters.
SUMMARY = ("run", "status", "message", "t_reached", "energy_start", "energy_end", "max_constraint_residual",
           "seconds", "worker")
#: ``status`` of a failed IDAS run (the stepper's codes are those of ``simulate_batch``).
STATUS_FAILED = 1
SUMMARY_DIR = "summary"
SPEC_KEY = "ncgen_sweep"


@dataclass
class SweepResult:
    """What a sweep produced: ``summary`` (columns as NumPy arrays, one row per run, in run
    order; ``to_pandas()``), ``arrays`` (``{output: array (runs, time, ...)}``: Zarr arrays
    with a ``path``, NumPy otherwise), ``t`` (s), ``samples`` and ``info`` (runs, resumed,
    failed, wall time, runs per second)."""

    summary: dict
    arrays: dict
    t: np.ndarray
    samples: Samples
    path: Path | None = None
    info: dict = field(default_factory=dict)

    def __getitem__(self, name: str):
        return self.arrays[name]

    @property
    def failures(self) -> list[dict]:
        """The failed runs: ``{"run", parameters..., "status", "message"}``."""
        bad = np.flatnonzero(self.summary["status"] != 0)
        keys = ["run", *self.samples.names, "status", "message"]
        return [{k: _plain(self.summary[k][i]) for k in keys} for i in bad]

    def to_pandas(self):
        """The summary as a pandas DataFrame (pandas must be installed)."""
        import pandas as pd
        return pd.DataFrame(self.summary)

    def report(self) -> str:
        """One line: runs, failures, time and rate."""
        i = self.info
        resumed = f" ({i['resumed']} already done)" if i.get("resumed") else ""
        return (f"sweep of {i['model']!r}: {i['runs']} runs{resumed}, {i['failed']} failed, "
                f"{i['computed']} computed in {i['wall_time']:.3g} s ({i['runs_per_s']:.3g} runs/s, "
                f"{i['where']})")


def sweep(model, params, *, t_end: float, dt: float, method: str = "stepper", outputs=("q",), path=None,
          client=None, workers: int | None = None, chunk: int | None = None, u=None, q0=None, v0=None,
          progress: bool | None = None, **options) -> SweepResult:
    """Run ``model`` once per parameter set of ``params`` from ``model.t0`` to ``t_end`` on
    the grid of step ``dt`` (s).

    * ``params``: None (only ``u``, ``q0`` or ``v0`` vary, one run per row), a dict
      ``{name: values}`` (the full grid), a pandas DataFrame or
      ``nc.Samples.table({...})`` (one run per row), or a sampler
      (``nc.Samples.latin_hypercube(n, bounds, seed=...)``, ``.sobol``, ``.random``); names
      are model parameters, the others keep their values.
    * ``method``: ``"stepper"`` (:func:`~ncgen.simulate_batch`, checked as a single run) or
      ``"idas"`` (:func:`~ncgen.simulate` per run); ``options`` go to them (``substeps``,
      ``rtol``, ...).  ``u``: inputs, samples on the grid ``(len(t), nu)`` for every run or
      ``(runs, len(t), nu)``; ``q0``, ``v0``: initial states, ``(nq,)`` or ``(runs, nq)``
      (Monte-Carlo on the initial state; projected onto the constraints as in ``simulate``).
    * ``outputs``: per-run arrays to keep, from :data:`OUTPUTS`; the summary always has one
      row per run: the parameters, ``status`` (0: complete), ``message``, ``t_reached``, the
      energy at start and end, the largest constraint residual, seconds and worker.
    * ``path``: a Zarr store (folder) to stream the results to; rerunning the same sweep
      with the same ``path`` resumes it (finished runs are not repeated).  None: in memory.
    * ``client``: a ``dask.distributed.Client`` (``pip install 'ncgen[dask]'``); else the
      local cores, ``workers`` of them (default: all).  ``chunk``: runs per task.
    * ``progress``: a progress bar (tqdm) on stderr, then the summary line
      (:meth:`SweepResult.report`: runs, failures, runs/s); None: when stderr is a terminal.
    """
    start = time.perf_counter()
    outputs = _check_method_and_outputs(model, method, outputs)
    t = time_grid(model.t0, t_end, dt)
    samples = as_samples(params) if params is not None else _state_samples(u, q0, v0)
    P = _parameter_rows(model, samples)
    n = len(samples)
    per_run = _per_run(model, n, u=u, q0=q0, v0=v0)
    _check_options(method, options)
    where, n_workers = _where(client, workers, method)
    if path is not None:
        check_store_path(Path(path))      # before any compile or run: the extras, the user's files
    if method == "stepper":        # compiled (or found in the cache) once, before the workers start; the
        load_any_stepper(model, kernels=options.get("kernels", "auto"))    # element tables need no compile
    chunk = _chunk(chunk if chunk is not None or path is None else _stored_chunk(path), n, n_workers)
    store = _Store(path, model, samples, t, method, outputs, options, chunk, per_run) if path is not None else None
    done = store.done() if store is not None else set()
    todo = [range(i, min(i + chunk, n)) for i in range(0, n, chunk) if i not in done]
    collected = _Collected(samples) if store is None else None
    bar = _bar(n, n - sum(len(c) for c in todo), progress, model.name)
    shown = not bar.disable
    job = dict(t_end=float(t_end), dt=float(dt), method=method, outputs=outputs, options=options,
               shared={k: v for k, (v, each) in per_run.items() if not each})
    per_task = {k: v for k, (v, each) in per_run.items() if each}
    try:
        for first, result in _execute(client, where, n_workers, model, P, per_task, todo, job):
            (store or collected).put(first, result)
            bar.update(len(result["summary"]["run"]))
    finally:
        bar.close()
    wall = time.perf_counter() - start
    summary, arrays = store.read() if store is not None else collected.read()
    computed = sum(len(c) for c in todo)
    info = dict(model=model.name, runs=n, computed=computed, resumed=n - computed,
                failed=int(np.sum(summary["status"] != 0)), wall_time=wall,
                runs_per_s=computed / wall if wall > 0 else float("nan"), where=where, workers=n_workers,
                chunk=chunk, method=method, reported=shown)
    result = SweepResult(summary=summary, arrays=arrays, t=t, samples=samples,
                         path=None if path is None else Path(path), info=info)
    if shown:                        # the bar was shown: its summary line under it
        print(result.report(), file=sys.stderr)
    return result


# ---------------------------------------------------------------- the runs of one task
def run_chunk(model, runs: range, P: np.ndarray, job: dict, each: dict | None = None) -> dict:
    """The runs ``runs`` (parameter rows ``P``; ``each``: their rows of the per-run ``u``,
    ``q0``, ``v0``) of a sweep: ``{"summary": columns, "arrays": {output: (len(runs), time,
    ...)}}``.  Runs on a worker; never raises for a failed run."""
    start = time.perf_counter()
    method, outputs, options = job["method"], job["outputs"], job["options"]
    given = {**job["shared"], **(each or {})}
    if method == "stepper":
        from ncgen.runtime.batch import simulate_batch
        b = simulate_batch(model, job["t_end"], job["dt"], p=P, workers=1, **given, **options)
        data = {"q": b.q, "v": b.v, "lam": b.lam, "kinetic": b.kinetic, "potential": b.potential,
                "constraint_residual": b.constraint_residual, "markers": b.markers}
        status, message, t = b.status, b.message, b.t
    else:
        data, status, message, t = _idas_runs(model, P, job, given, each or {})
    seconds = (time.perf_counter() - start) / len(runs)
    E = data["kinetic"] + data["potential"]
    finite = np.isfinite(E)
    last = np.array([np.flatnonzero(f)[-1] if f.any() else 0 for f in finite])
    k = np.arange(len(runs))
    summary = {"run": np.array(runs, dtype=np.int64), "status": np.asarray(status, dtype=np.int64),
               "message": [str(m) for m in message],
               "t_reached": np.where(finite.any(axis=1), t[last], np.nan),
               "energy_start": E[:, 0], "energy_end": E[k, last],
               "max_constraint_residual": np.nanmax(np.where(np.isfinite(data["constraint_residual"]),
                                                             data["constraint_residual"], -np.inf), axis=1),
               "seconds": np.full(len(runs), seconds), "worker": [f"{socket.gethostname()}:{os.getpid()}"] * len(runs)}
    summary["max_constraint_residual"][~finite.any(axis=1)] = np.nan
    return {"summary": summary, "arrays": {o: data[o] for o in outputs}}


def _idas_runs(model, P, job, given, each):
    """One :func:`~ncgen.simulate` per run (IDAS), failures caught."""
    from ncgen.runtime.simulation import simulate
    t = time_grid(model.t0, job["t_end"], job["dt"])
    n, T = len(P), len(t)
    data = {"q": np.full((n, T, model.nq), np.nan), "v": np.full((n, T, model.nq), np.nan),
            "lam": np.full((n, T, multiplier_count(model)), np.nan), "kinetic": np.full((n, T), np.nan),
            "potential": np.full((n, T), np.nan), "constraint_residual": np.full((n, T), np.nan),
            "markers": np.full((n, T, len(model.marker_names), model.dim), np.nan)}
    status, message = np.zeros(n, dtype=int), [""] * n
    for i in range(n):
        try:
            own = {k: (v[i] if k in each else v) for k, v in given.items()}
            traj = simulate(model, job["t_end"], job["dt"], method="idas", p=P[i], progress=False, **own,
                            **job["options"])
        except NcgenError as e:
            status[i], message[i] = STATUS_FAILED, str(e)
            traj = getattr(e, "trajectory", None)
            if traj is None:
                continue
        k = len(traj.t)
        for key in data:
            data[key][i, :k] = getattr(traj, key)
    return data, status, message, t


def _check_options(method: str, options: dict) -> None:
    """Options of the runs, named if ``simulate_batch`` / ``simulate`` does not take them."""
    import dataclasses

    from ncgen.runtime.batch import simulate_batch
    from ncgen.runtime.options import SimulationOptions
    if method == "stepper":
        taken = set(inspect.signature(simulate_batch).parameters)
    else:
        taken = {f.name for f in dataclasses.fields(SimulationOptions)} | {"t0"}
    taken -= {"model", "t_end", "dt", "p", "u", "q0", "v0", "workers", "method", "progress"}
    unknown = sorted(set(options) - taken)
    if unknown:
        raise NcgenError(f"sweep: method={method!r} takes no option {', '.join(map(repr, unknown))} "
                         f"(options: {', '.join(sorted(taken))})")
    fields = {f.name for f in dataclasses.fields(SimulationOptions)}
    SimulationOptions(method=method, **{k: v for k, v in options.items() if k in fields})   # values checked now,
    # as each run would (substeps=0, rtol=nan), before a store is made or a worker started


# ---------------------------------------------------------------- where tasks run
def _where(client, workers, method) -> tuple[str, int]:
    if client is not None:
        status = str(getattr(client, "status", "running"))
        if status not in ("running", "connecting", "newly-created"):
            raise NcgenError(f"client: the Dask client is {status!r}, not connected; give an open "
                             "dask.distributed.Client (or client=None to run on the local cores)")
        n = sum(client.nthreads().values()) if hasattr(client, "nthreads") else 1
        return "dask", max(1, n)
    if workers is None:
        workers = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    if int(workers) < 1:
        raise NcgenError(f"workers: expected a positive number of local workers, got {workers!r}")
    return ("threads" if method == "stepper" else "processes"), int(workers)


def _chunk(chunk, n: int, workers: int) -> int:
    if chunk is None:
        return max(1, min(64, math.ceil(n / (4 * workers))))
    if int(chunk) < 1:
        raise NcgenError(f"chunk: expected a positive number of runs per task, got {chunk!r}")
    return int(chunk)


def _execute(client, where, workers, model, P, per_task, todo, job):
    """``(first run, result)`` of every task as they finish."""

    def rows(c):
        return {k: v[c.start:c.stop] for k, v in per_task.items()}

    if not todo:
        return
    if where == "dask":
        from distributed import as_completed
        [remote_model] = client.scatter([model], broadcast=True)
        futures = {client.submit(run_chunk, remote_model, c, P[c.start:c.stop], job, rows(c), pure=False): c.start
                   for c in todo}
        for future in as_completed(futures):
            yield futures[future], future.result()
        return
    if where == "threads" or workers == 1:
        pool = ThreadPoolExecutor(max_workers=workers)
    else:
        import multiprocessing
        pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"))
    with pool:
        pending = {pool.submit(run_chunk, model, c, P[c.start:c.stop], job, rows(c)): c.start for c in todo}
        while pending:
            finished, _ = wait(pending, return_when=FIRST_COMPLETED)
            for future in finished:
                yield pending.pop(future), future.result()


# ---------------------------------------------------------------- parameters
def _per_run(model, n: int, **given) -> dict:
    """``{name: (array, per run?)}`` of the given ``u``, ``q0``, ``v0``, shapes checked."""
    one = {"u": 2, "q0": 1, "v0": 1}
    out = {}
    for name, value in given.items():
        if value is None:
            continue
        a = np.asarray(value, dtype=float)
        each = a.ndim == one[name] + 1
        if a.ndim not in (one[name], one[name] + 1) or (each and len(a) != n):
            shape = "(len(t), nu) or (runs, len(t), nu)" if name == "u" else "(nq,) or (runs, nq)"
            raise NcgenError(f"{name}: expected an array of shape {shape} with {n} runs, got shape {a.shape}")
        out[name] = (a, each)
    return out



def _check_method_and_outputs(model, method: str, outputs) -> list:
    """``outputs`` as a list, after refusing an unknown method or output (and the stepper for a
    model with rolling elements)."""
    if method not in METHODS:
        raise NcgenError(f"method: expected one of {', '.join(METHODS)}, got {method!r}")
    if method == "stepper":
        refuse_rolling(model, "sweep(method='stepper')", "give method='idas' (nc.simulate per run, which keeps them)")
    outputs = list(outputs)
    unknown = [o for o in outputs if o not in OUTPUTS]
    if unknown:
        raise NcgenError(f"outputs: unknown {', '.join(map(repr, unknown))}; expected some of {', '.join(OUTPUTS)}")
    return outputs


def _state_samples(u, q0, v0) -> Samples:
    """The samples of a sweep where only initial states or inputs vary (``params=None``): no
    parameter, one run per row of the per-run ``u``, ``q0`` or ``v0``."""
    runs = {len(a) for a, k in ((u, 3), (q0, 2), (v0, 2)) if a is not None and np.ndim(a) == k}
    if len(runs) != 1:
        raise NcgenError("params=None: give per-run u (runs, len(t), nu), q0 or v0 (runs, nq) arrays of one "
                         f"number of runs (found {sorted(runs) or 'none'})")
    return Samples([], np.zeros((runs.pop(), 0)))


def _parameter_rows(model, samples: Samples) -> np.ndarray:
    """The full parameter vector of every run (named entries replaced), checked up front."""
    sizes = dict(zip(model.parameter_names, model.parameter_sizes))
    offsets = dict(zip(model.parameter_names, np.cumsum([0, *model.parameter_sizes])))
    for name in samples.names:
        if name not in sizes:
            known = ", ".join(model.parameter_names) or "none"
            raise NcgenError(f"params: {name!r} is not a parameter of model {model.name!r} (parameters: {known})")
        if sizes[name] != 1:
            raise NcgenError(f"params: {name!r} is a vector parameter of {sizes[name]} values; a sweep varies "
                             f"scalar parameters")
    P = np.repeat(model.p0[None], len(samples), axis=0)
    for j, name in enumerate(samples.names):
        P[:, offsets[name]] = samples.values[:, j]
    return P


# ---------------------------------------------------------------- results
class _Collected:
    """Results kept in memory (no ``path``)."""

    def __init__(self, samples):
        self.samples = samples
        self.parts: dict[int, dict] = {}

    def put(self, first: int, result: dict) -> None:
        self.parts[first] = result

    def read(self):
        order = sorted(self.parts)
        summary = _summary_columns([self.parts[i]["summary"] for i in order], self.samples)
        arrays = {}
        for name in (self.parts[order[0]]["arrays"] if order else {}):
            arrays[name] = np.concatenate([self.parts[i]["arrays"][name] for i in order])
        return summary, arrays


def _summary_columns(parts: list[dict], samples: Samples) -> dict:
    out = {k: np.concatenate([np.asarray(p[k]) for p in parts]) if parts else np.zeros(0) for k in SUMMARY}
    runs = out["run"].astype(int)
    for j, name in enumerate(samples.names):
        out[name] = samples.values[runs, j]
    return {k: out[k] for k in ["run", *samples.names, *SUMMARY[1:]]}


def check_store_path(path: Path) -> None:
    """Refuse ``path`` unless zarr and pyarrow are installed and it is new, an empty folder or
    an ncgen sweep's store: a user's other files or Zarr stores are never written into."""
    try:
        import pyarrow  # noqa: F401  (the summary's Parquet writer, checked here)
        import zarr
    except ImportError as e:
        raise NcgenError(f"sweep(path={str(path)!r}): writing results needs zarr and pyarrow ({e.name} is "
                         f"missing): pip install 'ncgen[sweep]'") from None
    if not path.exists():
        return
    if not path.is_dir():
        raise NcgenError(f"sweep: path {str(path)!r} is a file, not a sweep's folder; give a new folder")
    if not any(path.iterdir()):
        return
    try:
        known = zarr.open_group(str(path), mode="r").attrs.get(SPEC_KEY)
    except Exception:          # not a Zarr group at all (any error of zarr's readers)
        known = None
    if known is None:
        raise NcgenError(f"sweep: {str(path)!r} exists and is not an ncgen sweep's store (no sweep description "
                         "in its attributes); it is left as it is: give a new or empty folder")


class _Store:
    """A sweep's Zarr store and Parquet summary parts (module docstring)."""

    def __init__(self, path, model, samples, t, method, outputs, options, chunk, per_run):
        import zarr
        check_store_path(Path(path))
        self.path, self.samples = Path(path), samples
        spec = {"model": model.name, "content_hash": model.content_hash, "runs": len(samples),
                "parameters": samples.names, "samples_sha256": _sha(samples.values), "t0": float(t[0]),
                "t_end": float(t[-1]), "n_times": len(t), "method": method, "outputs": outputs, "chunk": chunk,
                "options": json.loads(json.dumps(options, default=repr)),
                "per_run_sha256": {k: _sha(v) for k, (v, _) in sorted(per_run.items())}}
        group = zarr.open_group(str(self.path), mode="a")
        known = group.attrs.get(SPEC_KEY)
        if known is not None and known != spec:
            differ = [k for k in spec if known.get(k) != spec[k]]
            raise NcgenError(f"sweep: {self.path} holds another sweep (its {', '.join(differ)} differ); "
                             f"give another path, or delete it to start again")
        if known is None:
            shapes = _shapes(model, len(t))
            for name in outputs:
                group.create_array(name, shape=(len(samples), *shapes[name]), chunks=(chunk, *shapes[name]),
                                   dtype="f8", fill_value=np.nan, overwrite=True)
            group.create_array("t", shape=t.shape, dtype="f8", overwrite=True)[:] = t
            group.attrs[SPEC_KEY] = spec
        self.group = group
        (self.path / SUMMARY_DIR).mkdir(exist_ok=True)

    def done(self) -> set[int]:
        """First runs of the tasks already finished (their summary part exists)."""
        return {int(p.stem.split("-")[1]) for p in (self.path / SUMMARY_DIR).glob("part-*.parquet")}

    def put(self, first: int, result: dict) -> None:
        import pyarrow as pa
        import pyarrow.parquet as pq
        for name, values in result["arrays"].items():
            self.group[name][first:first + len(values)] = values
        columns = dict(result["summary"])
        runs = np.asarray(columns["run"])
        for j, name in enumerate(self.samples.names):
            columns[name] = self.samples.values[runs, j]
        table = pa.table({k: columns[k] for k in ["run", *self.samples.names, *SUMMARY[1:]]})
        final = self.path / SUMMARY_DIR / f"part-{first:09d}.parquet"
        tmp = final.with_name(f".{final.name}.{os.getpid()}.tmp")
        pq.write_table(table, tmp)
        with open(tmp, "rb") as f:
            os.fsync(f.fileno())
        os.replace(tmp, final)

    def read(self):
        import pyarrow.parquet as pq
        parts = sorted((self.path / SUMMARY_DIR).glob("part-*.parquet"))
        tables = [pq.read_table(p).to_pydict() for p in parts]
        summary = {k: np.concatenate([np.asarray(t[k]) for t in tables]) if tables else np.zeros(0)
                   for k in ["run", *self.samples.names, *SUMMARY[1:]]}
        arrays = {name: self.group[name] for name in self.group.attrs[SPEC_KEY]["outputs"]}
        return summary, arrays


def open_sweep(path) -> tuple[dict, dict]:
    """``(summary, arrays)`` of the sweep stored at ``path`` (summary columns as NumPy
    arrays in run order, Zarr arrays by output name)."""
    import pyarrow.parquet as pq
    import zarr
    group = zarr.open_group(str(path), mode="r")
    spec = group.attrs[SPEC_KEY]
    tables = [pq.read_table(p).to_pydict() for p in sorted((Path(path) / SUMMARY_DIR).glob("part-*.parquet"))]
    keys = list(tables[0]) if tables else []
    summary = {k: np.concatenate([np.asarray(t[k]) for t in tables]) for k in keys}
    return summary, {name: group[name] for name in [*spec["outputs"], "t"]}


def _stored_chunk(path) -> int | None:
    """The runs per task of the sweep already at ``path`` (a resumed sweep keeps its tasks,
    whatever the number of workers now), or None."""
    spec = Path(path) / "zarr.json"
    if not spec.is_file():
        return None
    try:
        return int(json.loads(spec.read_text())["attributes"][SPEC_KEY]["chunk"])
    except (ValueError, KeyError, TypeError):
        return None


def _shapes(model, n_t: int) -> dict:
    nq, nc = model.nq, multiplier_count(model)
    return {"q": (n_t, nq), "v": (n_t, nq), "lam": (n_t, nc), "kinetic": (n_t,), "potential": (n_t,),
            "constraint_residual": (n_t,), "markers": (n_t, len(model.marker_names), model.dim)}


def _sha(a: np.ndarray) -> str:
    import hashlib
    return hashlib.sha256(np.ascontiguousarray(a, dtype=float).tobytes()).hexdigest()


def _plain(x):
    return x.item() if hasattr(x, "item") else x


def _bar(total: int, initial: int, progress, name: str):
    """A tqdm bar of runs on stderr (``progress`` None: when stderr is a terminal)."""
    from tqdm.auto import tqdm
    return tqdm(total=total, initial=initial, unit="run", desc=f"sweep {name}",
                disable=None if progress is None else not progress, smoothing=0.1)

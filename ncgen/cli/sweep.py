"""``ncgen sweep``: a model run over a grid (or samples) of parameter values, on the local
cores or a Dask cluster, into a resumable Zarr store with a Parquet summary."""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from ncgen.cli.common import check_files, load_model, mjcf_contacts_argument
from ncgen.cli.registry import subcommand

SAMPLERS = ("lhs", "sobol", "random")


def _arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("model", metavar="MODEL.toml", help="model file: TOML, a URDF robot (.urdf) or an MJCF model (.xml)")
    mjcf_contacts_argument(p)
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUES", required=True,
                   help="a parameter to vary (repeatable). Grid: NAME=START:STOP:STEP (STOP included, "
                        "e.g. k=10:100:10) or NAME=V1,V2,... (e.g. m=0.5,1); every combination runs. "
                        "With --samples: NAME=LOW:HIGH, the bounds to sample in")
    p.add_argument("--samples", metavar="KIND:N", default=None,
                   help="instead of a grid, N runs sampled in the bounds: lhs:N (Latin hypercube), sobol:N "
                        "(scrambled Sobol, N a power of two) or random:N (uniform); see --seed")
    p.add_argument("--seed", type=int, default=None, help="seed of --samples (same seed, same runs)")
    p.add_argument("--t-end", type=float, required=True, metavar="T", help="final time of every run (s)")
    p.add_argument("--dt", type=float, default=0.01, metavar="DT", help="output step (s, default 0.01)")
    p.add_argument("-o", "--output", metavar="DIR.zarr", required=True,
                   help="Zarr store (a folder) for the per-run arrays, with the summary table as Parquet "
                        "in DIR.zarr/summary; running the same sweep again with the same folder resumes it")
    p.add_argument("--method", default="stepper", choices=("stepper", "idas"),
                   help="stepper: the compiled fixed-step stepper, every run checked as a single run "
                        "(default; fastest); idas: variable-step BDF with error control (--rtol)")
    p.add_argument("--substeps", type=int, default=None, metavar="N",
                   help="stepper: steps of DT/N per output interval (default 1); a run that its checks "
                        "find untrustworthy is reported in the summary with the N to use")
    p.add_argument("--rtol", type=float, default=None, help="idas: relative tolerance (default 1e-8)")
    p.add_argument("--outputs", default="q", metavar="LIST",
                   help="per-run arrays to store, comma-separated, from q, v, lam, kinetic, potential, "
                        "constraint_residual, markers (default: q)")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="local worker threads (stepper) or processes (idas); default: all cores")
    p.add_argument("--chunk", type=int, default=None, metavar="N", help="runs per task (default: automatic)")
    p.add_argument("--scheduler", metavar="ADDRESS", default=None,
                   help="run on a Dask cluster: the scheduler's address, e.g. tcp://10.0.0.5:8786 "
                        "(pip install 'ncgen[dask]'; see docs/sweeps.md)")
    p.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                   help="progress bar on stderr (default: when stderr is a terminal)")


@subcommand(
    "sweep",
    help="run a parameter grid or samples on all cores or Dask",
    description=(
        "Run the model in MODEL.toml once per parameter set, from its initial state to --t-end, and "
        "stream the results to a Zarr store: one array per output, shaped (runs, times, ...), and a "
        "summary table (Parquet, one row per run: the parameters, status (0 = complete), message, "
        "time reached, energy at start and end, largest constraint residual, seconds, worker). "
        "A run that fails never stops the sweep: its row says why. Interrupted (Ctrl-C, a crash, a "
        "lost cluster)? Run the same command again: finished runs are not repeated. Read the result "
        "in Python with nc.open_sweep('DIR.zarr') or pandas.read_parquet('DIR.zarr/summary')."),
    examples=(
        "ncgen sweep examples/slider_crank.toml --param omega=2:10:2 --t-end 1 --dt 0.005 -o sc.zarr\n"
        "ncgen sweep spring.toml --param k=10:100:10 --param m=0.5,1 --t-end 2 -o sweep.zarr\n"
        "ncgen sweep spring.toml --param k=10:100 --param m=0.5:1 --samples lhs:200 --seed 1 -o mc.zarr --t-end 2\n"
        "ncgen sweep spring.toml --param k=10:100:10 --t-end 2 -o sweep.zarr --scheduler tcp://10.0.0.5:8786"),
    arguments=_arguments,
)
def sweep(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    from ncgen.runtime.samples import Samples
    from ncgen.runtime.sweep import check_store_path
    from ncgen.runtime.sweep import sweep as run

    check_files(args, parser, None, directories=("output",))
    if args.seed is not None and args.samples is None:
        parser.error("--seed: only with --samples (a grid draws nothing at random)")
    params = _params(args, parser)
    check_store_path(Path(args.output))          # the extras and the user's files, before any work
    model = load_model(args.model, mjcf_contacts=args.mjcf_contacts)
    options = {}
    if args.substeps is not None:
        if args.method != "stepper":
            parser.error("--substeps: only with --method stepper")
        options["substeps"] = args.substeps
    if args.rtol is not None:
        if args.method != "idas":
            parser.error("--rtol: only with --method idas (the sweep's stepper takes fixed steps: --substeps)")
        options["rtol"] = args.rtol
    if args.samples is None:
        samples = Samples.grid(params)
    else:
        kind, n = args.samples
        make = {"lhs": Samples.latin_hypercube, "sobol": Samples.sobol, "random": Samples.random}[kind]
        samples = make(n, params, seed=args.seed)
    client = _client(args.scheduler) if args.scheduler else None
    try:
        result = run(model, samples, t_end=args.t_end, dt=args.dt, method=args.method,
                     outputs=[o.strip() for o in args.outputs.split(",") if o.strip()], path=args.output,
                     client=client, workers=args.workers, chunk=args.chunk, progress=args.progress, **options)
    finally:
        if client is not None:
            client.close()
    if not result.info["reported"]:         # else printed under the progress bar
        print(result.report())
    for failure in result.failures[:10]:
        values = ", ".join(f"{k}={failure[k]:g}" for k in samples.names)
        print(f"  run {failure['run']} ({values}): {failure['message']}")
    if len(result.failures) > 10:
        print(f"  ... and {len(result.failures) - 10} more failed runs: see the summary's status and message")
    print(f"wrote {args.output} (arrays: {', '.join(result.arrays)}; summary: {args.output}/summary)",
          file=sys.stderr)
    return 0


def _params(args, parser) -> dict:
    """``{name: values}`` (grid) or ``{name: (low, high)}`` (with --samples) from --param;
    finite numbers, at most ``MAX_RUNS`` runs in all."""
    from ncgen.runtime.samples import MAX_RUNS
    if args.samples is not None:
        kind, _, n = args.samples.partition(":")
        if kind not in SAMPLERS or not n.isdigit() or int(n) < 1:
            parser.error(f"--samples {args.samples!r}: expected lhs:N, sobol:N or random:N with N a positive integer")
        args.samples = (kind, int(n))
    out = {}
    for item in args.param:
        name, sep, text = item.partition("=")
        name = name.strip()
        if not sep or not name or not text:
            parser.error(f"--param {item!r}: expected NAME=START:STOP:STEP, NAME=V1,V2,... or (with --samples) "
                         "NAME=LOW:HIGH")
        if name in out:
            parser.error(f"--param {item!r}: {name!r} is given twice")
        try:
            fields = [float(x) for x in text.replace(":", ",").split(",")]
        except ValueError:
            parser.error(f"--param {item!r}: {text!r} is not a list of numbers")
        if not all(math.isfinite(x) for x in fields):
            parser.error(f"--param {item!r}: expected finite numbers, got {text!r}")
        if args.samples is not None:
            if ":" not in text or len(fields) != 2 or not fields[0] < fields[1]:
                parser.error(f"--param {item!r}: with --samples, expected the bounds NAME=LOW:HIGH with LOW < HIGH")
            out[name] = tuple(fields)
        elif ":" in text:
            if len(fields) != 3 or fields[2] <= 0 or fields[1] < fields[0]:
                parser.error(f"--param {item!r}: expected NAME=START:STOP:STEP with STEP > 0 and START <= STOP")
            start, stop, step = fields
            count = int((stop - start) / step * (1 + 1e-12)) + 1
            if count > MAX_RUNS:
                parser.error(f"--param {item!r}: {count:.3g} values, more than the limit of {MAX_RUNS:.0e} runs")
            out[name] = [start + k * step for k in range(count)]
        else:
            out[name] = fields
    if args.samples is None and math.prod(len(v) for v in out.values()) > MAX_RUNS:
        sizes = " × ".join(f"{len(v)} ({k})" for k, v in out.items())
        parser.error(f"--param: the grid has {sizes} = {math.prod(len(v) for v in out.values()):.3g} runs, more "
                     f"than the limit of {MAX_RUNS:.0e}; use fewer values or --samples")
    if args.samples is not None and args.samples[1] > MAX_RUNS:
        parser.error(f"--samples {args.samples[0]}:{args.samples[1]}: more than the limit of {MAX_RUNS:.0e} runs")
    return out


def _client(address: str):
    """A ``dask.distributed.Client`` connected to ``address`` (clear errors when the extra is
    missing or the scheduler cannot be reached)."""
    from ncgen.errors import NcgenError
    try:
        from distributed import Client
    except ImportError:
        raise NcgenError("--scheduler needs Dask's distributed scheduler: pip install 'ncgen[dask]'") from None
    try:
        return Client(address, timeout=10)
    except (OSError, TimeoutError) as e:
        raise NcgenError(f"--scheduler {address}: cannot reach the Dask scheduler ({e}); start one with "
                         "'dask scheduler' and workers with 'dask worker ADDRESS' (docs/sweeps.md)") from None

"""Every numeric flag of the command line refuses NaN, infinity and values out of range by
the flag's own name (issue 35, class 8 on every subcommand): ``--t-end nan`` says
``--t-end``, not the Python argument ``t_end``, a flag that means nothing without another
is named, and nothing is written."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from ncgen.cli import main

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
MODEL = str(EXAMPLES / "slider_crank.toml")
SWEEP = ["sweep", MODEL, "--param", "omega=3,4", "-o", "s.zarr"]


@pytest.mark.parametrize("argv, said", [
    *[(["simulate", MODEL, "--t-end", v], rf"--t-end: expected (a finite number|a time after t0 = 0 s), got {v}")
      for v in ("nan", "inf", "0", "-1")],
    *[(["simulate", MODEL, "--dt", v], rf"--dt: expected (a finite number|a positive output step \(s\)), got {v}")
      for v in ("nan", "inf", "0", "-1")],
    *[(["simulate", MODEL, flag, v], rf"{flag}: expected a positive tolerance, got {v}")
      for flag in ("--rtol", "--atol") for v in ("nan", "inf", "0.0", "-1.0")],
    (["simulate", MODEL, "--substeps", "0"], "--substeps: expected a positive number of steps per output interval"),
    (["simulate", MODEL, "--param", "omega=nan"], "--param 'omega=nan': expected 1 finite number"),
    *[(["check", MODEL, "--tolerance", v], rf"--tolerance: expected a positive finite number, got {v}")
      for v in ("nan", "inf", "0.0", "-1.0")],
    *[(["demo", "-o", "d", "--t-end", v], rf"--t-end: expected a positive finite time \(s\), got {v}")
      for v in ("nan", "inf", "0.0", "-1.0")],
    *[([*SWEEP, "--t-end", v], rf"--t-end: expected (a finite number|a time after t0 = 0 s), got {v}")
      for v in ("nan", "inf", "0", "-1")],
    *[([*SWEEP, "--t-end", "0.1", "--dt", v], rf"--dt: expected (a finite number|a positive output step)")
      for v in ("nan", "inf", "0", "-1")],
    ([*SWEEP, "--t-end", "0.1", "--substeps", "0"], "--substeps: expected a positive number of steps"),
    ([*SWEEP, "--t-end", "0.1", "--workers", "0"], "--workers: expected a positive number of local workers, got 0"),
    ([*SWEEP, "--t-end", "0.1", "--chunk", "-1"], "--chunk: expected a positive number of runs per task, got -1"),
    ([*SWEEP, "--t-end", "0.1", "--method", "idas", "--rtol", "nan"], "--rtol: expected a positive tolerance, got nan"),
    ([*SWEEP, "--t-end", "0.1", "--seed", "1"], r"--seed: only with --samples"),
])
def test_numeric_flags_are_named(argv, said, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code = main(argv)
    err = capsys.readouterr().err
    assert code in (1, 2), err
    assert re.search(said, err) and "internal error" not in err and "Traceback" not in err, err
    assert not list(tmp_path.iterdir())                     # nothing written, not even an empty store


def test_the_python_api_keeps_its_argument_names():
    """Only the command line speaks in flags: the same error from Python names ``t_end``."""
    import ncgen as nc
    from ncgen.errors import NcgenError

    model = nc.System.from_toml(MODEL).build()
    with pytest.raises(NcgenError, match=r"^t_end: expected a finite number, got nan"):
        nc.simulate(model, float("nan"), 0.01)

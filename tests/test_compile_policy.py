"""One compile policy for nc.simulate and the CLI (ncgen.runtime.backend_policy), no -O0
for long functions, and the VM fallback without a C compiler (``ncgen demo`` included)."""
import shutil
from pathlib import Path

import pytest

import ncgen as nc
from ncgen.cli import main
from ncgen.codegen import compile_cache
from ncgen.runtime import backend_policy as policy
from ncgen.runtime.library import compiled_model

needs_gcc = pytest.mark.skipif(shutil.which("gcc") is None, reason="gcc not installed")


@pytest.fixture(autouse=True)
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("NCGEN_CACHE_DIR", str(tmp_path / "cache"))


@pytest.fixture
def no_compiler(monkeypatch):
    monkeypatch.setenv("CC", "/nonexistent/cc")
    monkeypatch.setattr("ncgen.codegen.load._warned_no_compiler", False)


def pendulum():
    s = nc.System("policy_pendulum", gravity=(0, -9.81))
    s.add_bar("bar", mass=1.0, ends=[s.ground.point((0, 0)), (1.0, 0.0)])
    return s.build()


def test_short_runs_start_on_the_vm_long_runs_compile():
    model = pendulum()
    short = policy.choose_backend(model, 200)
    assert short.backend == "vm" and "would save" in short.reason
    cost = policy.estimated_compile_seconds(model)
    per_output = policy.estimated_saving_seconds(model, 1)
    assert 0 < per_output and cost >= policy.COMPILE_FIXED_SECONDS
    # exactly where the estimated saving passes the estimated compile time
    n = int(cost / per_output)
    assert policy.choose_backend(model, n - 1).backend == "vm"
    assert policy.choose_backend(model, n + 2).backend == "compiled"
    # a bigger model pays sooner per output step
    big = nc.System("policy_chain", gravity=(0, -9.81))
    start = big.ground.point((0, 0))
    for k in range(6):
        start = big.add_bar(f"b{k}", mass=1.0, ends=[start, (k + 1.0, 0.0)]).end(1)
    big = big.build()
    assert policy.estimated_saving_seconds(big, 1) > per_output


def test_explicit_choices_and_the_stepper_are_kept():
    model = pendulum()
    assert policy.choose_backend(model, 10, "compiled").backend == "compiled"
    assert policy.choose_backend(model, 10**9, "vm").backend == "vm"
    assert policy.choose_backend(model, 1, method="stepper").backend == "compiled"
    with pytest.raises(nc.NcgenError, match="backend: expected one of auto, vm, compiled, got 'fast'"):
        policy.choose_backend(model, 1, "fast")


def test_simulate_default_is_the_policy():
    model = pendulum()
    traj = nc.simulate(model, 0.5, 0.01)
    assert traj.info["backend"] == "vm" and "would save" in traj.info["backend_reason"]


@needs_gcc
def test_a_library_compiled_in_this_process_is_used():
    model = pendulum()
    compiled_model(model)
    assert policy.choose_backend(model, 10).backend == "compiled"
    traj = nc.simulate(model, 0.2, 0.01)
    assert traj.info["backend"] == "compiled"


def test_long_functions_are_never_compiled_at_O0():
    assert "-O0" not in compile_cache.LARGE_CFLAGS and "-O0" not in compile_cache.DEFAULT_CFLAGS
    assert compile_cache.LARGE_CFLAGS == ("-O1",)


def test_demo_without_compiler_runs_on_the_vm_saying_so_in_one_line(no_compiler, tmp_path, capsys):
    assert main(["demo", "-o", str(tmp_path / "demo"), "--t-end", "0.2"]) == 0
    out, err = capsys.readouterr()
    assert "IDAS on the vm DAE" in out and "skipped: vm backend" in out
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and "no C compiler found" in lines[0] and "virtual machine" in lines[0]


def test_stepper_without_compiler_names_the_cli_flag(no_compiler, tmp_path, capsys):
    model = Path(__file__).resolve().parents[1] / "examples" / "double_pendulum.toml"
    code = main(["simulate", str(model), "--t-end", "0.1", "-o", str(tmp_path / "p.npz"), "--method", "stepper"])
    err = capsys.readouterr().err
    assert code == 1 and "--method idas" in err and "method='" not in err

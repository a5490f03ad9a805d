"""The compile cache never loads a damaged library (issue 13, class 1): every kind of damage
(truncated, zeroed, garbage, empty, record lost) is found by the hash recorded when the entry
was published, the entry is rebuilt, and the result is the same numbers as CasADi's VM.
Each damaged load runs in a subprocess, so a SIGBUS/SIGSEGV would fail the test instead of
killing pytest.  Killed builds' temporary folders are swept."""
import hashlib
import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from ncgen import files
from ncgen.codegen import compile_package, write_package
from ncgen.codegen.compile_cache import build_key, entry_problem, recorded_flags, source_cflags
from test_codegen_samples import chain_doc, chain_functions

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="gcc not installed")
ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(autouse=True)
def cache(tmp_path, monkeypatch) -> Path:
    monkeypatch.setenv("NCGEN_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv("NCGEN_CFLAGS", raising=False)
    monkeypatch.delenv("CC", raising=False)
    return tmp_path / "cache"


@pytest.fixture(scope="module")
def built_pkg(tmp_path_factory):
    out = tmp_path_factory.mktemp("pkg") / "chain"
    return write_package("chain", chain_functions(), out, doc=chain_doc(), max_file_instructions=None)


def _damage(lib: Path, how: str) -> None:
    data = lib.read_bytes()
    if how == "truncated":
        lib.write_bytes(data[: len(data) // 2])
    elif how == "zeroed":
        lib.write_bytes(data[:4096] + bytes(len(data) - 8192) + data[-4096:])
    elif how == "garbage":
        lib.write_bytes(os.urandom(len(data)))
    elif how == "empty":
        lib.write_bytes(b"")
    elif how == "one byte":
        lib.write_bytes(data[:100] + bytes([data[100] ^ 1]) + data[101:])


LOAD = textwrap.dedent("""
    import sys, numpy as np
    from ncgen.codegen import load_functions, Package
    f = load_functions(Package.open(sys.argv[1]), ["phi"], backend="compiled")["phi"]
    args = [np.linspace(0.1, 1, f.nnz_in(i)) for i in range(f.n_in())]
    print(repr(np.array(f.call(args)[0]).ravel().tolist()))
""")


@pytest.mark.parametrize("how", ["truncated", "zeroed", "garbage", "empty", "one byte"])
def test_damaged_library_is_rebuilt_never_loaded(built_pkg, cache, how):
    first = compile_package(built_pkg)
    assert not first.cached and entry_problem(first.path.parent, first.path) is None
    _damage(first.path, how)
    assert entry_problem(first.path.parent, first.path) is not None
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    run = subprocess.run([sys.executable, "-c", LOAD, str(built_pkg.path)], capture_output=True,
                         text=True, env=env, cwd=ROOT, timeout=120)
    assert run.returncode == 0, run.stderr           # a crash would be a negative return code
    assert "damaged" in run.stderr and "rebuilding" in run.stderr
    assert "Traceback" not in run.stderr
    # the healed library computes what CasADi's VM computes
    vm = chain_functions()[0]
    assert vm.name() == "phi"
    args = [np.linspace(0.1, 1, vm.nnz_in(i)) for i in range(vm.n_in())]
    np.testing.assert_allclose(eval(run.stdout), np.array(vm.call(args)[0]).ravel(), rtol=1e-12, atol=1e-14)
    again = compile_package(built_pkg)
    assert again.cached and entry_problem(again.path.parent, again.path) is None


def test_lost_build_record_or_library_rebuilds(built_pkg):
    first = compile_package(built_pkg)
    (first.path.parent / "build.json").unlink()
    assert not compile_package(built_pkg).cached
    first.path.unlink()
    second = compile_package(built_pkg)
    assert not second.cached and second.path.is_file()
    record = json.loads((second.path.parent / "build.json").read_text())
    assert record["library_sha256"] == hashlib.sha256(second.path.read_bytes()).hexdigest()


def test_killed_build_leftovers_are_swept(built_pkg, cache):
    cache.mkdir(parents=True, exist_ok=True)
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True).stdout.strip()
    leftover = cache / f"{files.temporary_name('chain-abc')[:-1].rsplit('-', 1)[0]}-{dead}-x1y2z3"
    leftover.mkdir()
    (leftover / "kernels.c.o").write_bytes(b"partial")
    mine = cache / f"{files.temporary_name('chain-def')}live"      # this process: alive
    mine.mkdir()
    unrelated = cache / ".notes.tmp"                                 # not an ncgen temporary
    unrelated.write_text("user")
    compile_package(built_pkg)
    assert not leftover.exists()
    assert mine.exists() and unrelated.exists()
    leftover.mkdir()                                                 # swept by a cache hit too
    assert compile_package(built_pkg).cached and not leftover.exists()


def test_unwritable_cache_is_a_clear_error(built_pkg, tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("")
    monkeypatch.setenv("NCGEN_CACHE_DIR", str(blocker / "cache"))
    from ncgen.errors import CodegenError
    with pytest.raises(CodegenError, match="compile cache"):
        compile_package(built_pkg)


@pytest.mark.slow      # two CLI subprocesses compiling from an empty cache; fast:
#                       test_damaged_library_is_rebuilt_never_loaded (the same healing in-process, every kind of
#                       damage)
def test_cli_stepper_heals_a_truncated_cache(tmp_path, cache):
    """``ncgen simulate --method stepper`` (library loaded with ctypes) after the cached
    library was truncated: a note, a rebuild and the same result, not SIGBUS."""
    env = {**os.environ, "PYTHONPATH": str(ROOT), "NCGEN_CACHE_DIR": str(cache), "NCGEN_CFLAGS": "-O0"}
    cmd = [sys.executable, "-m", "ncgen.cli", "simulate", str(ROOT / "examples" / "fourbar_planar.toml"),
           "--t-end", "0.05", "--dt", "0.05", "--method", "stepper"]
    first = subprocess.run(cmd + ["-o", str(tmp_path / "a.npz")], capture_output=True, text=True, env=env, timeout=300)
    assert first.returncode == 0, first.stderr
    libraries = list(cache.glob("*/lib*.so"))
    assert libraries
    for lib in libraries:
        _damage(lib, "truncated")
    second = subprocess.run(cmd + ["-o", str(tmp_path / "b.npz")], capture_output=True, text=True, env=env, timeout=300)
    assert second.returncode == 0, second.stderr
    assert "is damaged" in second.stderr and "Traceback" not in second.stderr
    a, b = np.load(tmp_path / "a.npz"), np.load(tmp_path / "b.npz")
    np.testing.assert_array_equal(a["q"], b["q"])


def test_an_entry_recording_other_flags_is_rebuilt_never_loaded(built_pkg, cache):
    """A build at -O0 put under the default build's name (copied by hand, or by a tool that
    keys entries differently) is never taken for the default build: its record's key differs,
    so the entry is rebuilt with ncgen's flags."""
    slow = compile_package(built_pkg, cflags="-O0")
    default_entry = cache / f"chain-{build_key(built_pkg, slow.compiler, source_cflags(built_pkg, None))[:24]}"
    shutil.copytree(slow.path.parent, default_entry)
    assert entry_problem(default_entry, default_entry / slow.path.name) is None        # intact, but of -O0
    built = compile_package(built_pkg)
    assert built.path.parent == default_entry and not built.cached
    record = json.loads((default_entry / "build.json").read_text())
    assert record["key"] == built.key and recorded_flags(record) == ["-O2"]

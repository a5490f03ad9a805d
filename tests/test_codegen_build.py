"""compile_package and load_functions: correctness, cache, concurrency, errors, VM fallback."""
import json
import os
import shutil
import stat
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import ncgen.codegen.load as load_module
from ncgen.codegen import (ExtraSource, NoCompilerWarning, Package, compile_package, load_functions,
                           write_package)
from ncgen.errors import CodegenError, CompilerNotFound
from test_codegen_samples import chain_doc, chain_functions, random_inputs

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="gcc not installed")
TESTS = Path(__file__).parent


@pytest.fixture(autouse=True)
def cache(tmp_path, monkeypatch) -> Path:
    monkeypatch.setenv("NCGEN_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv("NCGEN_CFLAGS", raising=False)
    monkeypatch.delenv("CC", raising=False)
    return tmp_path / "cache"


@pytest.fixture
def pkg(tmp_path) -> Package:
    return write_package("chain", chain_functions(), tmp_path / "chain", doc=chain_doc(),
                         max_file_instructions=100)


def logging_compiler(tmp_path: Path, delay: float = 0.0) -> tuple[str, Path]:
    """A `cc` wrapper that records its command lines (to count compiler runs) and sleeps
    ``delay`` seconds before each compilation (to make builds overlap)."""
    log = tmp_path / "cc.log"
    script = tmp_path / "logcc"
    script.write_text(f'#!/bin/sh\necho "$@" >> {log}\n'
                      f'case "$*" in *" -c "*) sleep {delay};; esac\nexec gcc "$@"\n')
    script.chmod(script.stat().st_mode | stat.S_IEXEC)
    return str(script), log


def test_compiled_equals_vm(pkg):
    compiled = load_functions(pkg, backend="compiled")
    vm = load_functions(pkg, backend="vm")
    assert set(compiled) == set(vm) == {"phi", "gamma", "force", "mass"}
    rng = np.random.default_rng(0)
    for name, f in vm.items():
        g = compiled[name]
        assert g.name() == f"chain_{name}" and g.is_a("External")
        for _ in range(5):
            args = random_inputs(f, rng)
            for i, (a, b) in enumerate(zip(f.call(args), g.call(args))):
                assert a.sparsity() == b.sparsity() == f.sparsity_out(i)
                np.testing.assert_allclose(np.array(b.nonzeros()), np.array(a.nonzeros()),
                                           rtol=1e-12, atol=1e-12)


def test_cache_hit_does_not_recompile(tmp_path, pkg):
    cc, log = logging_compiler(tmp_path)
    first = compile_package(pkg, cc=cc)
    runs = [line for line in log.read_text().splitlines() if "-c " in line or "-shared" in line]
    assert not first.cached and len(runs) == len(pkg.manifest["build"]["sources"]) + 1
    mtime = first.path.stat().st_mtime_ns
    second = compile_package(Package.open(pkg.path), cc=cc)
    assert second.cached and second.path == first.path and second.key == first.key
    assert second.path.stat().st_mtime_ns == mtime
    runs_after = [line for line in log.read_text().splitlines() if "-c " in line or "-shared" in line]
    assert runs_after == runs


def test_key_depends_on_flags_and_sources(tmp_path, pkg, monkeypatch):
    base = compile_package(pkg)
    monkeypatch.setenv("NCGEN_CFLAGS", "-O1")
    o1 = compile_package(pkg)
    assert not o1.cached and o1.key != base.key and o1.cflags == ("-O1",)
    assert compile_package(pkg, cflags="-O0 -g").cflags == ("-O0", "-g")
    monkeypatch.delenv("NCGEN_CFLAGS")
    smaller = write_package("chain", chain_functions()[:1], tmp_path / "other")
    assert compile_package(smaller).key != base.key
    assert compile_package(pkg).cached


def test_model_independent_libraries_are_keyed_by_the_environment_s_flags(tmp_path, pkg, monkeypatch):
    """``$NCGEN_CFLAGS`` reaches ncgen's per-version libraries too
    (:func:`ncgen.runtime.table_library.cached_library`), keyed by it: a library built with it
    is another library than the default one (-O2), each found again without a compile; flags
    passed by name still apply to packages whatever the environment (``env_flags=False``)."""
    from ncgen.runtime.table_library import cached_library

    def library():
        path, compiled = cached_library("test-library", "0" * 64, lambda out: write_package(
            "chain", chain_functions()[:1], out), "chain")
        return path, compiled, json.loads((path.parent / "build.json").read_text())["commands"]

    monkeypatch.setenv("NCGEN_CFLAGS", "-O0")
    assert compile_package(pkg).cflags == ("-O0",)
    assert compile_package(pkg, env_flags=False).cflags == ("-O2",)
    assert compile_package(pkg, cflags="-O1", env_flags=False).cflags == ("-O1",)
    quick, compiled, commands = library()
    assert compiled and all("-O0" in cmd and "-O2" not in cmd for cmd in commands)
    assert library()[:2] == (quick, False)
    monkeypatch.delenv("NCGEN_CFLAGS")
    default, compiled, commands = library()
    assert compiled and default != quick and all("-O2" in cmd and "-O0" not in cmd for cmd in commands)
    assert library()[:2] == (default, False)


def test_very_long_functions_compile_at_O1_never_O0(tmp_path, monkeypatch):
    """Files holding a function longer than LARGE_FUNCTION_INSTRUCTIONS are listed in the
    manifest and compiled with -O1 by default (compile_package, Makefile, CMake; -O0 would run
    them ~3x slower); flags the
    user chooses apply to every file."""
    import ncgen.codegen.package as package_module

    functions = chain_functions()
    longest = max(f.n_instructions() for f in functions)
    monkeypatch.setattr(package_module, "LARGE_FUNCTION_INSTRUCTIONS", longest - 1)
    pkg = write_package("chain", functions, tmp_path / "chain", doc=chain_doc(), max_file_instructions=0)
    large = pkg.manifest["build"]["large_sources"]
    assert len(large) == 1 and large[0] in pkg.manifest["build"]["sources"]
    cc, log = logging_compiler(tmp_path)
    built = compile_package(pkg, cc=cc)
    runs = [line.split() for line in log.read_text().splitlines() if " -c " in line]
    assert {r[r.index("-c") + 1]: r[0] for r in runs} == {
        src: ("-O1" if src in large else "-O2") for src in pkg.manifest["build"]["sources"]}
    assert built.cflags == ("-O2",)
    chosen = compile_package(pkg, cc=cc, cflags="-O3")
    assert chosen.key != built.key
    again = [line.split() for line in log.read_text().splitlines()[len(runs) + 1:] if " -c " in line]
    assert len(again) == len(runs) and all(r[0] == "-O3" for r in again)
    makefile = (pkg.path / "Makefile").read_text()
    assert "LARGE_CFLAGS ?= -O1" in makefile and large[0][:-2] + ".o" in makefile
    assert f"set_source_files_properties({large[0]} PROPERTIES COMPILE_OPTIONS \"-O1\")" in \
        (pkg.path / "CMakeLists.txt").read_text()
    out = subprocess.run(["make", "-n"], cwd=pkg.path, capture_output=True, text=True, check=True).stdout
    compiles = {line.split(" -o ")[1].split()[0]: line for line in out.splitlines() if " -c " in line}
    assert "-O1" in compiles[large[0][:-2] + ".o"] and "-O2" not in compiles[large[0][:-2] + ".o"]
    assert all("-O2" in cmd for obj, cmd in compiles.items() if obj != large[0][:-2] + ".o")
    total = sum(f.n_instructions() for f in functions)
    monkeypatch.setattr(package_module, "LARGE_PACKAGE_INSTRUCTIONS", total - 1)
    huge = write_package("chain", functions, tmp_path / "huge", doc=chain_doc(), max_file_instructions=0)
    kernels = [src for src in huge.manifest["build"]["sources"] if "_kernels_" in src]
    assert huge.manifest["build"]["large_sources"] == kernels and len(kernels) == len(functions)


def test_long_functions_called_through_mx_count_as_long(tmp_path, monkeypatch):
    """An MX function (a wrapper kept as MX: longer than ``reroll_instructions``) whose own
    nodes are few but which calls a long SX function puts its file in ``large_sources``."""
    import casadi as ca

    import ncgen.codegen.package as package_module

    x = ca.SX.sym("x", 4)
    y = x
    for k in range(60):
        y = ca.sin(y * (1.0 + 0.01 * k)) + ca.cos(y[::-1])
    g = ca.Function("g", [x], [y])
    X = ca.MX.sym("X", 4)
    f = ca.Function("f", [X], [g(X) * 2.0])
    assert f.n_instructions() < 10 < g.n_instructions()
    monkeypatch.setattr(package_module, "LARGE_FUNCTION_INSTRUCTIONS", g.n_instructions() - 1)
    pkg = write_package("wrapped", [f], tmp_path / "wrapped", reroll_instructions=10)
    assert pkg.manifest["build"]["large_sources"] == ["wrapped_kernels_0.c"]
    monkeypatch.setattr(package_module, "LARGE_FUNCTION_INSTRUCTIONS", g.n_instructions())
    assert write_package("wrapped", [f], tmp_path / "again", reroll_instructions=10).manifest["build"]["large_sources"] == []


def test_two_processes_build_at_once(tmp_path, pkg, cache):
    cc, _ = logging_compiler(tmp_path, delay=1.5)  # long enough to overlap
    script = ("import sys; from ncgen.codegen import compile_cache, compile_package, load_functions\n"
              "compile_cache.PROGRESS_DELAY = 0.0\n"       # progress shown however fast the compile
              "r = compile_package(sys.argv[1], cc=sys.argv[2]); load_functions(r, ['phi'])\n"
              "print(r.path, r.cached)\n")
    procs = [subprocess.Popen([sys.executable, "-c", script, str(pkg.path), cc], stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True, env=os.environ.copy()) for _ in range(2)]
    outs = [p.communicate(timeout=120) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], outs
    paths, cached = zip(*(out.split() for out, _ in outs))
    assert paths[0] == paths[1] and sorted(cached) == ["False", "True"]
    builder = outs[cached.index("False")][1]
    assert "ncgen: compiling C package 'chain'" in builder and "done in" in builder
    entries = [p for p in cache.iterdir() if not p.name.endswith(".lock")]
    assert [p.name for p in entries] == [Path(paths[0]).parent.name]
    assert sorted(p.name for p in entries[0].iterdir()) == ["build.json", "libchain.so", "manifest.json"]
    assert compile_package(pkg, cc=cc).cached


def test_compiler_error_is_clear(tmp_path, cache):
    (tmp_path / "tpl").mkdir()
    (tmp_path / "tpl" / "bad.c.j2").write_text("int {{ name }}_bad(void) { return undeclared_thing; }\n")
    bad = write_package("chain", chain_functions()[:1], tmp_path / "bad", template_dirs=[tmp_path / "tpl"],
                        extra_sources=[ExtraSource("bad.c.j2", "chain_bad.c")])
    with pytest.raises(CodegenError) as info:
        compile_package(bad)
    msg = str(info.value)
    assert "C compilation failed" in msg and "command: " in msg and "chain_bad.c" in msg
    assert "undeclared_thing" in msg and "error" in msg
    assert [p.name for p in cache.iterdir() if not p.name.endswith(".lock")] == []


def test_load_from_library_and_directory(pkg):
    built = compile_package(pkg)
    by_path = load_functions(built.path, ["gamma"])
    assert list(by_path) == ["gamma"] and by_path["gamma"].name() == "chain_gamma"
    assert set(load_functions(str(pkg.path), backend="compiled")) == set(pkg.function_names)
    with pytest.raises(CodegenError, match="has no function"):
        load_functions(pkg, ["nope"])
    with pytest.raises(CodegenError, match="opened from disk"):
        load_functions(Package.open(pkg.path), backend="vm")
    with pytest.raises(CodegenError, match="backend must be"):
        load_functions(pkg, backend="fast")


def test_missing_compiler(pkg, monkeypatch):
    monkeypatch.setattr(load_module, "_warned_no_compiler", False)
    monkeypatch.setenv("CC", "/nonexistent/cc")
    monkeypatch.setenv("PATH", "")
    with pytest.raises(CompilerNotFound, match="/nonexistent/cc"):
        compile_package(pkg)
    with pytest.raises(CompilerNotFound):
        load_functions(pkg, backend="compiled")
    with pytest.warns(NoCompilerWarning, match="falling back to CasADi's virtual machine"):
        fns = load_functions(pkg, backend="auto")
    assert all(fns[n] is pkg.functions[n] for n in pkg.function_names)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_functions(pkg)  # warned once per process only
    monkeypatch.delenv("CC")
    with pytest.raises(CompilerNotFound, match=r"looked for \$CC, cc, gcc, clang"):
        compile_package(pkg)

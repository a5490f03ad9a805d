"""ncgen's libraries built at install (``ncgen/runtime/installed_libraries.py``,
``ncgen/runtime/install_commands.py``): the runtime takes an installed library only when its
keys, flags and sha256 match, with no call of the compiler; any other falls back to the
compile cache.  The slow test builds the wheel and runs from it with no compiler on ``PATH``."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

import ncgen.codegen.compile_cache as compile_cache
from ncgen.codegen import c_binding, compile_package, write_package
from ncgen.codegen.fsutil import sha256_file
from ncgen.errors import CompilerNotFound
from ncgen.runtime import install_build as ib, installed_libraries as il, table_library as tl, tree_library as tr
from ncgen.version import __version__
from test_codegen_samples import chain_functions

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="gcc not installed")
ROOT = Path(__file__).resolve().parent.parent
SOURCE = "0" * 64


@pytest.fixture(autouse=True)
def env(tmp_path, monkeypatch):
    monkeypatch.setenv("NCGEN_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv("NCGEN_CFLAGS", raising=False)
    monkeypatch.delenv("CC", raising=False)


def write(out):
    return write_package("chain", chain_functions()[:1], out)


def plant(tmp_path, monkeypatch, **changes) -> Path:
    """A library of :func:`write` compiled and planted as installed (``index.json`` as the
    install writes it, its fields overridden by ``changes``); the installed folder."""
    built = compile_package(write(tmp_path / "pkg"), env_flags=False)
    folder = tmp_path / "installed"
    folder.mkdir(exist_ok=True)
    shutil.copyfile(built.path, folder / built.path.name)
    entry = {"prefix": "test-library", "sources": SOURCE, "compiler": tl.compiler_path(), "cflags": None,
             "file": built.path.name, "sha256": sha256_file(folder / built.path.name), **changes}
    (folder / il.INDEX).write_text(json.dumps({"ncgen": changes.pop("ncgen", __version__), "libraries": [entry]}))
    monkeypatch.setattr(il, "installed_dir", lambda: folder)
    return folder


def library(source=SOURCE):
    return tl.cached_library("test-library", source, write, "chain")


def no_compile(monkeypatch):
    def refuse(*args, **kwargs):
        raise AssertionError("the compiler was called")

    monkeypatch.setattr(compile_cache, "compile_package", refuse)


def test_a_matching_installed_library_is_loaded_without_the_compiler(tmp_path, monkeypatch):
    folder = plant(tmp_path, monkeypatch)
    with monkeypatch.context() as mp:
        no_compile(mp)
        path, compiled = library()
        assert (path, compiled) == (folder / "libchain.so", False)
        assert tl.library_ready("test-library", SOURCE)
        assert hasattr(c_binding.open_library(path), "chain_phi")       # a library of the package's functions
        mp.setenv("PATH", str(tmp_path / "empty"))                      # no compiler at all: taken too
        assert library() == (folder / "libchain.so", False)


@pytest.mark.parametrize("what", ["sources", "flags", "compiler", "version", "corrupt", "missing"])
def test_a_stale_foreign_or_damaged_installed_library_is_ignored(tmp_path, monkeypatch, capsys, what):
    """Each mismatch falls back to the compile cache (compiled there at first use, then found
    there); never the installed file."""
    changes = {"compiler": "/opt/other/cc"} if what == "compiler" else {"ncgen": "0.0.0"} if what == "version" else {}
    folder = plant(tmp_path, monkeypatch, **changes)
    if what == "flags":
        monkeypatch.setenv("NCGEN_CFLAGS", "-O0")
    if what == "corrupt":
        with open(folder / "libchain.so", "ab") as f:
            f.write(b"\0")
    if what == "missing":
        (folder / "libchain.so").unlink()
    source = "1" * 64 if what == "sources" else SOURCE
    assert not tl.library_ready("test-library", source)
    path, compiled = library(source)
    assert compiled and folder not in path.parents
    assert library(source) == (path, False)
    if what == "corrupt":
        assert "is damaged" in capsys.readouterr().err
    if what in ("sources", "version"):             # with no compiler: not taken either
        monkeypatch.setenv("PATH", str(tmp_path / "empty"))
        monkeypatch.setenv("NCGEN_CACHE_DIR", str(tmp_path / "other"))
        with pytest.raises(CompilerNotFound):
            library(source)


def test_the_install_builds_what_the_runtime_asks_for(monkeypatch):
    """:func:`~ncgen.runtime.install_build.library_specs` names each library as the
    element, contact and tree libraries look it up (prefix, sources key, package, flags), with
    and without ``$NCGEN_CFLAGS``."""
    asked = []

    def record(prefix, source, write, package, cflags=None):
        asked.append((prefix, source, package, tl.effective_cflags(cflags)))
        return Path("/nonexistent"), False

    monkeypatch.setattr(tl, "cached_library", record)
    monkeypatch.setattr(tr, "cached_library", record)
    for flags in (None, "-O0"):
        if flags:
            monkeypatch.setenv("NCGEN_CFLAGS", flags)
        asked.clear()
        tl.element_library(), tl.contact_library()
        for unit in (*tr.ALGORITHM_UNITS, *tr.kernel_units()):
            tr.unit_library(unit)
        assert [(s.prefix, s.source, s.package, s.cflags) for s in ib.library_specs()] == \
            [asked[1], asked[0], *asked[2:]]
        assert {s.cflags for s in ib.library_specs()} == ({None, *tr.UNIT_CFLAGS.values()} if flags is None else {flags})



def test_the_install_commands_import_without_setuptools():
    """An installed ncgen's every module imports (CI's base install checks it): without
    setuptools (no run-time dependency) the install's command classes are inert (that they are
    setuptools' commands in a build: ``test_the_wheel_carries_the_libraries_...``)."""
    blocked = ("import sys; sys.modules['setuptools'] = None; "
               "import ncgen.runtime.install_commands as m; print(m.BuildPy.__mro__[1].__name__)")
    out = subprocess.run([sys.executable, "-c", blocked], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "object"

CHILD = """
import json, sys
from pathlib import Path
import ncgen
from ncgen.runtime import install_build as ib, installed_libraries as il, table_library as tl, tree_library as tr
folder = il.installed_dir()
assert folder.parent == Path(ncgen.__file__).parent and Path(sys.argv[1]) in folder.parents, folder
paths = [tl.element_library()[0], tl.contact_library()[0]] + [tr.unit_library(u)[0] for u in ("forward", "body")]
assert all(p.parent == folder for p in paths), paths
import numpy as np
model = ncgen.System.from_toml(sys.argv[2]).build()
f = tl.table_functions(model)
q = np.array(model.q0) + 0.1
ref = np.array(model.functions["phi"](0.0, q, model.p0)).ravel()
print(json.dumps({"phi": f.phi(q).tolist(), "ref": ref.tolist()}))
"""


@pytest.mark.slow
def test_the_wheel_carries_the_libraries_and_runs_without_a_compiler(tmp_path):
    """``pip wheel .`` (the install's build, ``$NCGEN_CFLAGS=-O0`` to keep it short) gives a
    ``py3-none-<platform>`` wheel with the libraries; installed on its own (``--target``) and
    run with no compiler on ``PATH`` and an empty compile cache, the element, contact and tree
    libraries come from it, and the double pendulum's table ``Φ`` equals CasADi's flat ``Φ``."""
    env = {**os.environ, "NCGEN_CFLAGS": "-O0", "NCGEN_CACHE_DIR": str(tmp_path / "build-cache")}
    env.pop("PYTHONPATH", None)
    subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", str(tmp_path / "dist"),
                    str(ROOT)], check=True, env=env, cwd=tmp_path, timeout=900)
    wheel, = (tmp_path / "dist").glob("ncgen-*.whl")
    platform = sysconfig.get_platform().replace("-", "_").replace(".", "_")
    assert wheel.name.endswith(f"-py3-none-{platform}.whl"), wheel.name
    site = tmp_path / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--target", str(site), str(wheel)],
                   check=True, env=env, cwd=tmp_path)
    (tmp_path / "empty").mkdir()
    run = {**env, "PYTHONPATH": str(site), "PATH": str(tmp_path / "empty"), "NCGEN_CACHE_DIR": str(tmp_path / "cache")}
    out = subprocess.run([sys.executable, "-c", CHILD, str(site), str(ROOT / "examples" / "double_pendulum.toml")],
                         capture_output=True, text=True, env=run, cwd=tmp_path)
    assert out.returncode == 0, out.stderr[-3000:]
    res = json.loads(out.stdout.splitlines()[-1])
    assert max(abs(a - b) for a, b in zip(res["phi"], res["ref"])) < 1e-12 and len(res["phi"]) == len(res["ref"])
    assert {p.name for p in (tmp_path / "cache").iterdir()} <= {"derivations", "models"}    # nothing compiled

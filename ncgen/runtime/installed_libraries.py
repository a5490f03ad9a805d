"""ncgen's model-independent libraries built at install: the element library, the contact
library and every unit of the tree library, compiled by ``pip install .`` (a non-editable
install, ``build_hooks.py`` at the repository's root) into the installed package's
``_libraries/`` folder, so that the first run of any model finds them.

The folder holds the libraries and ``index.json``: per library its index prefix (as the
compile cache's index files name it: ``element-tables``, ``contact-tables``,
``tree-tables-<unit>``), its sources key (:func:`ncgen.runtime.table_library.sources_key`,
:func:`ncgen.runtime.tree_library.sources_key`: ncgen's and CasADi's versions, the files it is
made of), the compiler's path (:func:`~ncgen.runtime.table_library.compiler_path`), the flags
it was built with (None: ncgen's defaults; ``$NCGEN_CFLAGS`` if it was set at install) and
its sha256.  :func:`installed_library` returns one only when all of them match the run's (a
process with no compiler takes one of any compiler, as the compile cache does) and the file's
sha256 is the one recorded: a stale library (another CasADi, an edited source), a foreign
one (another compiler or flags) or a damaged one is never loaded, and the run falls back to
the compile cache (compiled at first use).  Editable installs (``pip install -e .``) and
source checkouts build nothing here: they compile at first use.

:func:`build_installed` is what the install runs: every library written and compiled in a
temporary compile cache (in parallel, one compiler per core), copied to the target folder, the
index written last.
"""
from __future__ import annotations

import json
import os
import shutil
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from functools import lru_cache, partial
from pathlib import Path
from typing import Callable

from ncgen.codegen import fsutil
from ncgen.version import __version__

#: The installed libraries' folder name in the package, and its index file.
FOLDER, INDEX = "_libraries", "index.json"


def installed_dir() -> Path:
    """Where an install put ncgen's libraries (the folder may be missing)."""
    return Path(__file__).resolve().parents[1] / FOLDER


@dataclass(frozen=True)
class LibrarySpec:
    """One of ncgen's libraries: its index prefix, sources key, package writer
    (``write(out_dir)``), package name and flags (None: ncgen's defaults)."""

    prefix: str
    source: str
    write: Callable
    package: str
    cflags: str | None


def library_specs() -> list[LibrarySpec]:
    """The libraries an install builds, as the runtime asks for them (each with the flags its
    first use would compile it with, ``$NCGEN_CFLAGS`` included)."""
    from ncgen.codegen.element_kernels import CONTACT_PACKAGE, PACKAGE, write_element_package
    from ncgen.codegen.tree_kernels import ALGORITHM_UNITS, PACKAGE as TREES, kernel_units, write_tree_unit
    from ncgen.runtime import table_library as tl, tree_library as tr

    tree_key = tr.sources_key()
    return [LibrarySpec(tl.CONTACT_INDEX_PREFIX, tl.sources_key(contacts=True),
                        partial(write_element_package, contacts=True), CONTACT_PACKAGE, tl.effective_cflags(None)),
            LibrarySpec(tl.INDEX_PREFIX, tl.sources_key(), write_element_package, PACKAGE, tl.effective_cflags(None)),
            *(LibrarySpec(tr.index_prefix(u), tree_key, partial(write_tree_unit, u), f"{TREES}_{u}",
                          tl.effective_cflags(tr.unit_cflags(u))) for u in (*ALGORITHM_UNITS, *kernel_units()))]


def installed_library(prefix: str, source: str, compiler: str | None, cflags: str | None) -> Path | None:
    """The installed library of index prefix ``prefix`` and sources key ``source`` built by
    ``compiler`` (None: no compiler in this process, any will do) with ``cflags``, verified by
    its sha256; None when there is none that matches (module docstring)."""
    folder = installed_dir()
    index = folder / INDEX
    try:
        st = index.stat()
    except OSError:
        return None
    for entry in _entries(str(index), st.st_size, st.st_mtime_ns):
        if (entry.get("prefix"), entry.get("sources"), entry.get("cflags")) != (prefix, source, cflags) or \
                (compiler is not None and entry.get("compiler") != compiler):
            continue
        library = folder / str(entry.get("file"))
        if _intact(str(library), str(entry.get("sha256"))):
            return library
    return None


@lru_cache(maxsize=4)
def _entries(index: str, size: int, mtime_ns: int) -> tuple[dict, ...]:
    """The entries of the index file ``index`` (read again when its size or time changes)."""
    try:
        data = json.loads(Path(index).read_text())
        return tuple(e for e in data["libraries"] if isinstance(e, dict)) if data.get("ncgen") == __version__ else ()
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return ()


def _intact(library: str, sha256: str) -> bool:
    """Whether ``library`` has the sha256 recorded at install (a note on stderr once if not)."""
    try:
        st = os.stat(library)
    except OSError:
        return False
    return _verified(library, sha256, st.st_size, st.st_mtime_ns)


@lru_cache(maxsize=64)
def _verified(library: str, sha256: str, size: int, mtime_ns: int) -> bool:
    try:
        actual = fsutil.sha256_file(Path(library))
    except OSError:
        actual = None
    if actual != sha256:
        print(f"ncgen: the installed library {library} is damaged (sha256 differs from the one recorded at "
              "install); ignored, the compile cache is used instead", file=sys.stderr)
    return actual == sha256


def build_installed(target: Path, jobs: int | None = None, log=print) -> list[Path]:
    """Compile every library of :func:`library_specs` into the folder ``target`` (written with
    its ``index.json``); raises :class:`~ncgen.errors.CompilerNotFound` or
    :class:`~ncgen.errors.CodegenError` when compiling fails (nothing is written then).  The
    packages are written one after the other while the compiler runs on those written before."""
    from ncgen.codegen.compile_cache import compile_package
    from ncgen.codegen.compiler import find_compiler
    from ncgen.runtime.table_library import compiler_path

    find_compiler()                         # no compiler: fail before generating anything
    compiler = compiler_path()
    specs = library_specs()
    target = Path(target)
    with tempfile.TemporaryDirectory(prefix="ncgen-install-") as tmp:
        cache = os.environ.get("NCGEN_CACHE_DIR")
        os.environ["NCGEN_CACHE_DIR"] = str(Path(tmp) / "cache")        # nothing of the user's cache
        try:
            with ThreadPoolExecutor(max_workers=jobs or os.cpu_count() or 1) as pool:
                futures = [pool.submit(compile_package, spec.write(Path(tmp) / spec.package), cflags=spec.cflags,
                                       jobs=1, env_flags=False) for spec in specs]
                built = [f.result() for f in futures]
        finally:
            if cache is None:
                os.environ.pop("NCGEN_CACHE_DIR")
            else:
                os.environ["NCGEN_CACHE_DIR"] = cache
        target.mkdir(parents=True, exist_ok=True)
        entries = []
        for spec, result in zip(specs, built):
            shutil.copyfile(result.path, target / result.path.name)
            entries.append({"prefix": spec.prefix, "sources": spec.source, "compiler": compiler,
                            "compiler_version": result.compiler.version, "cflags": spec.cflags,
                            "file": result.path.name, "sha256": fsutil.sha256_file(target / result.path.name)})
    (target / INDEX).write_text(json.dumps({"ncgen": __version__, "libraries": entries}, indent=1) + "\n")
    log(f"ncgen: {len(entries)} libraries compiled into {target} ({compiler})")
    return [target / e["file"] for e in entries]

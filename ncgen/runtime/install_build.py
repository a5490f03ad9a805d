"""ncgen's model-independent libraries compiled for an install (the setuptools command of
:mod:`ncgen.runtime.install_commands` calls :func:`build_installed`): every library as the runtime asks for it
(:func:`library_specs`), written and compiled in a temporary compile cache (in parallel, one
compiler per core), copied to the target folder, the index written last
(:mod:`ncgen.runtime.installed_libraries` reads it).
"""
from __future__ import annotations

import json
import os
import shutil
import tempfile
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Callable

from ncgen.codegen import fsutil
from ncgen.codegen.compile_cache import compile_package
from ncgen.codegen.compiler import find_compiler
from ncgen.codegen.element_kernels import CONTACT_PACKAGE, PACKAGE, write_element_package
from ncgen.codegen.tree_kernels import ALGORITHM_UNITS, PACKAGE as TREES, kernel_units, write_tree_unit
from ncgen.runtime import table_library as tl, tree_library as tr
from ncgen.runtime.installed_libraries import INDEX
from ncgen.version import __version__


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
    tree_key = tr.sources_key()
    return [LibrarySpec(tl.CONTACT_INDEX_PREFIX, tl.sources_key(contacts=True),
                        partial(write_element_package, contacts=True), CONTACT_PACKAGE, tl.effective_cflags(None)),
            LibrarySpec(tl.INDEX_PREFIX, tl.sources_key(), write_element_package, PACKAGE, tl.effective_cflags(None)),
            *(LibrarySpec(tr.index_prefix(u), tree_key, partial(write_tree_unit, u), f"{TREES}_{u}",
                          tl.effective_cflags(tr.unit_cflags(u))) for u in (*ALGORITHM_UNITS, *kernel_units()))]


def build_installed(target: Path, jobs: int | None = None, log=print) -> list[Path]:
    """Compile every library of :func:`library_specs` into the folder ``target`` (written with
    its ``index.json``); raises :class:`~ncgen.errors.CompilerNotFound` or
    :class:`~ncgen.errors.CodegenError` when compiling fails (nothing is written then).  The
    packages are written one after the other while the compiler runs on those written before."""
    find_compiler()                         # no compiler: fail before generating anything
    compiler = tl.compiler_path()
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

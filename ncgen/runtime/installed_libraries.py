"""ncgen's model-independent libraries built at install: the element library, the contact
library and every unit of the tree library, compiled by ``pip install .`` (a non-editable
install, the setuptools command of :mod:`ncgen.runtime.install_commands`) into the installed
package's ``_libraries/`` folder, so that the first run of any model finds them.

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

:func:`ncgen.runtime.install_build.build_installed` is what the install runs.
"""
from __future__ import annotations

import json
import os
import sys
from functools import lru_cache
from pathlib import Path

from ncgen.codegen import fsutil
from ncgen.version import __version__

#: The installed libraries' folder name in the package, and its index file.
FOLDER, INDEX = "_libraries", "index.json"


def installed_dir() -> Path:
    """Where an install put ncgen's libraries (the folder may be missing)."""
    return Path(__file__).resolve().parents[1] / FOLDER


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

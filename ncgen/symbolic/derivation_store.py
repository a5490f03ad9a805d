"""Derivations of coordinate types kept on disk, so that a process that builds a model does
not derive them with SymPy again (about a second per type; issue 34: first runs).

An entry is ``<cache_dir>/derivations/<type>-<dim>d-<key>.derivation``
(:func:`ncgen.files.cache_dir`): one line of JSON (format, ncgen's version, the key, the type,
the payload's size and sha256; :func:`ncgen.files.write_entry`), then the pickled
:class:`~ncgen.symbolic.coordinates.Derivation` (SymPy matrices and symbols; its coordinate
type by name), unpickled only when the header and the checksum match.  The key hashes what a
derivation is made of: ncgen's version, SymPy's and Python's, and the bytes of the symbolic
layer's sources, so an edited formula is derived again.  Entries are written atomically
(:func:`ncgen.files.atomic_path`); one that cannot be read back (damaged, or not a derivation
of this type) is removed, with a note on stderr, and derived again; writing an entry removes
the entries of the same type made from other sources.  ``NCGEN_MODEL_CACHE=0``
(the switch of the store of built models) turns this store off too.
"""
from __future__ import annotations

import hashlib
import pickle
import sys
from functools import lru_cache
from pathlib import Path
from typing import Callable

from ncgen.files import cache_dir, model_cache_enabled, read_entry, write_entry
from ncgen.version import __version__

#: Bump when the layout of an entry changes.
FORMAT = "derivation-1"
SUFFIX = ".derivation"

@lru_cache(maxsize=1)
def source_key() -> str:
    """sha256 of the versions and of the symbolic layer's sources (module docstring)."""
    import sympy

    h = hashlib.sha256(f"{__version__} {sympy.__version__} {sys.version_info[:3]}".encode())
    for path in sorted(Path(__file__).resolve().parent.glob("*.py")):
        h.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()


def entry_path(name: str, dim: int) -> Path:
    """The entry of the derivation of coordinate type ``name`` in ``dim`` dimensions."""
    return cache_dir() / "derivations" / f"{name}-{dim}d-{source_key()[:24]}{SUFFIX}"


def stored_derivation(ctype, derive: Callable):
    """The derivation of ``ctype`` read from the store, else ``derive(ctype)`` stored."""
    if not model_cache_enabled():
        return derive(ctype)
    path = entry_path(ctype.name, ctype.dim)
    header = {"format": FORMAT, "ncgen": __version__, "key": source_key(), "type": f"{ctype.name}-{ctype.dim}d"}

    def decode(payload: bytes):
        found = pickle.loads(payload)
        if type(found) is not derive or found.ctype is not ctype:
            raise TypeError(f"expected the derivation of {ctype!r}, found {type(found).__name__}")
        return found

    found = read_entry(path, header, decode, "derivation", redo="deriving it again")
    if found is not None:
        return found
    found = derive(ctype)
    try:
        payload = pickle.dumps(found, protocol=pickle.HIGHEST_PROTOCOL)
    except pickle.PicklingError:
        return found                      # not stored: derived again next time
    if write_entry(path, header, payload):
        for old in path.parent.glob(f"{ctype.name}-{ctype.dim}d-*"):
            if old != path:               # of other sources or an older layout: would only pile up
                old.unlink(missing_ok=True)
    return found

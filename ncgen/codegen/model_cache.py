"""Built models kept on disk by content, so that loading the same model again skips URDF
parsing and ``build()`` (SymPy derivations, CasADi assembly, the consistent initial state).

An entry is ``<cache_dir>/models/<key>.model`` (:func:`ncgen.codegen.fsutil.cache_dir`):
one line of JSON (the format, ncgen's version, the key, the sha256 and size of the payload),
then the payload, a pickle of the model's attributes (:func:`ncgen.model.model.model_state`;
CasADi expressions and functions through CasADi's own serialisation) and of the warnings its
build gave, which a read gives again.  The key hashes what the model is made from — a model
file's bytes and the path it was read from, or the content digest of a
:class:`~ncgen.model.system.System` (every value it holds, :mod:`ncgen.model.digest`) — the
build options, and ncgen itself: its version and the bytes of its Python
sources (so an edited checkout never loads a model built by other code), CasADi's, NumPy's
and Python's versions.

Entries are written to a temporary sibling and renamed into place
(:func:`ncgen.files.atomic_path`).  An entry is loaded only if its header names this format,
version and key and its payload has the recorded sha256; anything else (truncated, garbage,
another version) is ignored, removed and rebuilt, with a note on stderr.

A model is stored with the functions its build made; the others stay lazy (their makers
pickled, :mod:`ncgen.model.function_set`) and each, made on first use in any process, is
stored beside the model (``<key>-fn-<name>.model``, its CasADi serialisation) and read from
there by the next process (:class:`FunctionStore`): a later run makes nothing that an earlier
one made, and a run pays only for the functions it uses.

Beyond :data:`MAX_BYTES` the least recently used entries are removed after a write.
``NCGEN_MODEL_CACHE=0`` (or ``off``, ``no``, ``false``) bypasses the store (nothing is read or
written); :func:`clear` empties it, as ``rm -r <cache_dir>/models`` does.
"""
from __future__ import annotations

import hashlib
import io
import json
import os
import pickle
import shutil
import sys
import types
import warnings
from functools import lru_cache
from pathlib import Path
from typing import Callable

import numpy as np

from ncgen.files import MODEL_CACHE_ENV, model_cache_enabled, read_entry, write_entry
from ncgen.version import __version__

#: Bump when the layout of an entry or of the pickled state changes.
FORMAT = 3          # 3: large mostly zero arrays pickled by their nonzeros
#: The environment variable that turns the store off.
ENV = MODEL_CACHE_ENV
SUFFIX = ".model"
#: Size of the store (bytes) beyond which the least recently used entries are removed after a
#: write (every edit of ncgen's sources makes new keys; old entries would pile up).
MAX_BYTES = 512 * 2**20


#: Whether built models are read from and written to the store (``$NCGEN_MODEL_CACHE``).
enabled = model_cache_enabled


def store_dir() -> Path:
    """``<cache_dir>/models``, beside the compiled libraries."""
    from ncgen.codegen.fsutil import cache_dir
    return cache_dir() / "models"


def clear() -> int:
    """Remove every stored model (and what is stored beside them); returns how many entries
    there were."""
    directory = store_dir()
    count = len(list(directory.glob(f"*{SUFFIX}"))) if directory.is_dir() else 0
    shutil.rmtree(directory, ignore_errors=True)
    return count


@lru_cache(maxsize=1)
def code_identity() -> str:
    """sha256 of ncgen's version, its Python sources and the versions of what the pickled
    state depends on (CasADi, NumPy, Python)."""
    import casadi

    h = hashlib.sha256(f"{FORMAT} {__version__} {casadi.__version__} {np.__version__} "
                       f"{sys.version_info[:3]}".encode())
    root = Path(__file__).resolve().parent.parent
    for path in sorted(root.rglob("*.py")):
        h.update(str(path.relative_to(root)).encode())
        h.update(hashlib.sha256(path.read_bytes()).digest())
    return h.hexdigest()


def key_of(parts: dict) -> str:
    """The entry's key: sha256 of ``parts`` (JSON-able) and :func:`code_identity`."""
    text = json.dumps(parts, sort_keys=True, default=repr)
    return hashlib.sha256(f"{code_identity()}\n{text}".encode()).hexdigest()


def file_key(path: str | os.PathLike, **options) -> str:
    """The key of the model in file ``path`` (its bytes and the path as given) built with
    ``options`` (the loader's and the build's)."""
    data = Path(path).read_bytes()
    return key_of({"file": str(path), "sha256": hashlib.sha256(data).hexdigest(), "options": options})


def system_key(system, **options) -> str | None:
    """The key of ``system`` built with ``options``: the content digest of everything the
    system holds and of the options (:func:`ncgen.model.digest.system_digest`); None when it
    holds something that cannot be keyed reliably (a force given as a Python function, a
    SymPy expression, a class defined outside ncgen), so it is neither stored nor read."""
    from ncgen.model.digest import system_digest

    digest = system_digest(system, dict(sorted(options.items())))
    return None if digest is None else key_of({"system": digest})


def cached(key: str | None, build: Callable[[], object]):
    """The model stored under ``key``, else ``build()`` stored under it (nothing is stored
    or read with ``key`` None or the store off).  The warnings the build gave (e.g. redundant
    constraints dropped) are stored with the model and given again when it is read back.
    Functions of ``model.functions`` made later are stored beside it as they are made (see
    :func:`save`)."""
    return _through_store(key, build, lambda: load(key), lambda model, said: save(key, model, said), stacklevel=3)


def _through_store(key: str | None, make: Callable[[], object], read: Callable[[], tuple | None],
                   store: Callable[[object, list], None], stacklevel: int):
    """What :func:`cached` and :func:`cached_system` share: with ``key`` None or the store off,
    ``make()``; else ``read()``'s ``(value, warnings)`` with its warnings given again (at
    ``stacklevel`` from here), or, when it reads nothing, ``make()`` under a record of its
    warnings, given again as they came and passed to ``store(value, [(category, message)])``."""
    if key is None or not enabled():
        return make()
    hit = read()
    if hit is not None:
        value, said = hit
        for category, message in said:
            warnings.warn(message, category, stacklevel=stacklevel)
        return value
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        value = make()
    for w in caught:                      # given as the make gave them, under the caller's filters
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    store(value, [(w.category, str(w.message)) for w in caught])
    return value


def build_system(system, **options):
    """``system`` built with ``options`` (:func:`ncgen.assembly.build.build_model`), through
    the store (keyed by :func:`system_key`); what ``System.build()`` does."""
    def build():
        from ncgen.assembly.build import build_model
        return build_model(system, **options)

    return cached(system_key(system, **options) if enabled() else None, build)


def source_key(kind: str, path: str | os.PathLike, **options) -> str:
    """The key of the system that the reader ``kind`` (``"urdf"``, ``"toml"``) makes from the
    file ``path`` with ``options``: the file's bytes and resolved path."""
    data = Path(path).read_bytes()
    return key_of({"reader": kind, "file": str(Path(path).resolve()), "sha256": hashlib.sha256(data).hexdigest(),
                   "options": options})


def cached_system(key: str | None, load: Callable[[], object]):
    """The :class:`~ncgen.model.system.System` stored under ``key`` (a model file read before:
    no parsing, no SymPy), else ``load()`` stored under it; the warnings of the read are kept
    and given again, as :func:`cached` does for models."""
    def store(system, said):
        try:
            payload = _pickle({"system": system, "warnings": said})
        except Exception:                  # noqa: BLE001 — something in it does not pickle: not stored
            return
        _write(_path(key, "system"), key, payload)

    return _through_store(key, load, lambda: _read(_path(key, "system"), key, _decode_system), store, stacklevel=4)


def _decode_system(payload: bytes) -> tuple:
    import casadi

    with casadi.global_unpickle_context():
        stored = pickle.loads(payload)
    if not (isinstance(stored, dict) and _is_system(stored.get("system")) and isinstance(stored.get("warnings"), list)):
        raise TypeError(f"expected a system and its warnings, found {type(stored).__name__}")
    return stored["system"], stored["warnings"]


def _path(key: str, what: str = "") -> Path:
    return store_dir() / f"{key}{'-' + what if what else ''}{SUFFIX}"


def load(key: str) -> tuple | None:
    """``(model, warnings)`` stored under ``key`` (``warnings``: ``[(category, message)]`` of
    its build), or None (absent; a damaged or foreign entry is removed)."""
    from ncgen.model.model import restored_model

    def decode(payload):
        stored = _unpickle(payload)
        return restored_model(stored["state"]), list(stored["warnings"])

    hit = _read(_path(key), key, decode)
    if hit is not None:
        _keep(hit[0], key)
    return hit


def save(key: str, model, said=()) -> bool:
    """Store ``model`` under ``key`` with the warnings ``said`` by its build (``[(category,
    message)]``); False (and nothing written) if its state cannot be pickled, a made MX
    function cannot be read back from its serialisation (an SX function, a list of scalar
    instructions, always can: tests/test_model_cache.py checks it bit for bit), or the store
    cannot be written.  The functions already made are stored made; the others keep their
    makers (those that do not pickle are run first, :meth:`~ncgen.model.function_set.FunctionSet.reduced`)
    and are stored beside the model when first made, here or in a later process
    (:class:`FunctionStore`)."""
    from ncgen.model.model import model_state

    try:
        texts = {name: model.functions[name].serialize() for name in model.functions.made()}
        for name, text in texts.items():
            _read_back(model.functions[name], text)
        payload = _pickle({"state": model_state(model), "warnings": list(said)}, (model.functions, texts))
    except Exception:                      # noqa: BLE001 — e.g. a Python function inside a force
        return False
    if not _write(_path(key), key, payload):
        return False
    _keep(model, key)
    return True


def _read_back(f, text: str) -> None:
    """Raise if the MX function ``f`` cannot be read back from its serialisation ``text``
    (CasADi 3.8 writes some solves it cannot read back); an SX function always can."""
    import casadi

    if f.class_name() != "SXFunction":
        casadi.Function.deserialize(text)


def _keep(model, key: str) -> None:
    """``model`` came through the store under ``key``: its functions made from now on are stored beside it."""
    model.data.store_key = key
    model.functions.keep_in(FunctionStore(key))


class FunctionStore:
    """The functions of the stored model ``key`` made after it was stored, one entry each
    (``<key>-fn-<name>.model``: the CasADi serialisation), the store a
    :class:`~ncgen.model.function_set.FunctionSet` reads a function from before making it and
    writes it to once made (:meth:`~ncgen.model.function_set.FunctionSet.keep_in`)."""

    def __init__(self, key: str):
        self.key = key

    def read(self, name: str):
        """The function ``name`` stored beside the model, or None."""
        import casadi

        if not enabled():
            return None
        return _read(_path(self.key, f"fn-{name}"), self.key, lambda payload: casadi.Function.deserialize(
            payload.decode()))

    def write(self, name: str, f) -> None:
        """Store ``f`` (unless it cannot be read back, or the store is off or cannot be written)."""
        if not enabled():
            return
        text = f.serialize()
        try:
            _read_back(f, text)
        except Exception:                  # noqa: BLE001 — not stored: made again next time
            return
        _write(_path(self.key, f"fn-{name}"), self.key, text.encode())


def derived_function(model, what: str, build: Callable[[], object]):
    """The CasADi function ``build()`` derives from ``model`` (named ``what``, a file-name
    word), stored beside the model when the model came through the store (its
    ``data.store_key``), so that a later process reads it instead of deriving it again."""
    import casadi

    key = model.data.store_key
    if key is None or not enabled():
        return build()
    path = _path(key, what)
    f = _read(path, key, lambda payload: casadi.Function.deserialize(payload.decode()))
    if f is None:
        f = build()
        _write(path, key, f.serialize().encode())
    return f


def derived_data(model, what: str, build: Callable[[], object]):
    """As :func:`derived_function` for an object of plain data (numbers, strings, NumPy
    arrays) that pickles: ``build()``, stored beside a stored model and read back later."""
    key = model.data.store_key
    if key is None or not enabled():
        return build()
    path = _path(key, what)
    obj = _read(path, key, pickle.loads)
    if obj is None:
        obj = build()
        _write(path, key, pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL))
    return obj


def stored_function(model, what: str):
    """The function :func:`derived_function` stored beside ``model`` under ``what``, or None
    (the model did not come through the store, or nothing was stored): nothing is derived."""
    import casadi

    key = model.data.store_key
    path = None if key is None or not enabled() else _path(key, what)
    if path is None or not path.is_file():
        return None
    return _read(path, key, lambda payload: casadi.Function.deserialize(payload.decode()))


def _header(key: str) -> dict:
    return {"format": FORMAT, "ncgen": __version__, "key": key}


def _read(path: Path, key: str, decode: Callable[[bytes], object]):
    """``decode(payload)`` of the entry at ``path``, or None: absent, or damaged (the header's
    format, version, key, size or sha256 not matching, or ``decode`` failing), then removed."""
    return read_entry(path, _header(key), decode, "model entry")


def _write(path: Path, key: str, payload: bytes) -> bool:
    """Write an entry (header line, then ``payload``) atomically; False if it cannot be written."""
    if not write_entry(path, _header(key), payload):
        return False
    _prune(path.parent, keep=path)
    return True


def _prune(directory: Path, keep: Path) -> None:
    """Remove the least recently used entries of ``directory`` (never ``keep``) until they
    total at most :data:`MAX_BYTES`."""
    found = []
    for entry in directory.glob(f"*{SUFFIX}"):
        try:
            info = entry.stat()
        except OSError:
            continue
        found.append((info.st_mtime, info.st_size, entry))
    total = sum(size for _, size, _ in found)
    for _, size, entry in sorted(found, key=lambda x: x[0]):
        if total <= MAX_BYTES:
            break
        if entry != keep:
            entry.unlink(missing_ok=True)
            total -= size


def _mapping_proxy(items: dict) -> types.MappingProxyType:
    return types.MappingProxyType(items)


#: A C-ordered float64 array of at least this many entries, at most a quarter of them nonzero,
#: is pickled by its nonzeros (:func:`_scattered`): a chain of 1000 bars' dense ``M`` is 72 MB,
#: of which 0.2 MB nonzero.
SPARSE_MIN_SIZE = 1 << 16


def _nonzero_bits(a) -> "tuple | None":
    """``(flat indices, values)`` of the entries of ``a`` whose bits are not all zero (a
    ``-0.0`` is kept), when ``a`` is a large, mostly zero, C-ordered float64 array; else None."""
    if not (a.dtype == np.float64 and a.size >= SPARSE_MIN_SIZE and a.flags.c_contiguous):
        return None
    index = np.flatnonzero(a.reshape(-1).view(np.uint64))
    return (index, a.reshape(-1)[index]) if 4 * index.size <= a.size else None


def _scattered(shape: tuple, index, values):
    """The float64 array of ``shape`` holding ``values`` at the flat ``index``, zero elsewhere."""
    out = np.zeros(shape)
    out.reshape(-1)[index] = values
    return out


class _Pickler(pickle.Pickler):
    """Pickles a model's state as it is: read-only views by their contents, large mostly zero
    arrays (a dense ``M``) by their nonzeros, a
    :class:`~ncgen.model.system.System` by its attributes (its own pickling goes by description,
    which would rebuild it through SymPy when read), and the function set of ``made``,
    ``(functions, {name: text})``, with the serialisations of its made functions (a function
    serialised for the read-back check is not serialised again)."""

    def __init__(self, file, made: tuple | None, **kw):
        super().__init__(file, **kw)
        self.made = made

    def reducer_override(self, obj):
        from ncgen.model.model import ReadOnlyList

        kind = type(obj)
        if kind is np.ndarray:
            nonzero = _nonzero_bits(obj)
            return (_scattered, (obj.shape, *nonzero)) if nonzero is not None else NotImplemented
        if self.made is not None and obj is self.made[0]:
            return obj.reduced(self.made[1])
        if kind is types.MappingProxyType:
            return _mapping_proxy, (dict(obj),)
        if kind is ReadOnlyList:
            return ReadOnlyList, (list(obj),)
        if _is_system_type(kind):
            return object.__new__, (kind,), dict(vars(obj))
        return NotImplemented


def _is_system(obj) -> bool:
    """Whether ``obj`` is a :class:`~ncgen.model.system.System`."""
    return _is_system_type(type(obj))


@lru_cache(maxsize=None)
def _is_system_type(kind: type) -> bool:
    """Whether ``kind`` is :class:`~ncgen.model.system.System` or a subclass (by its classes'
    names: ``System.build`` imports this module, which must not import it back)."""
    return any(c.__name__ == "System" and c.__module__ == "ncgen.model.system" for c in kind.__mro__)


def _pickle(stored: dict, made: tuple | None = None) -> bytes:
    """``stored`` pickled (:class:`_Pickler`; ``made``: a function set and its serialisations)."""
    import casadi

    buffer = io.BytesIO()
    with casadi.global_pickle_context():
        _Pickler(buffer, made, protocol=5).dump(stored)
    return buffer.getvalue()


def _unpickle(payload: bytes) -> dict:
    import casadi

    with casadi.global_unpickle_context():
        stored = pickle.loads(payload)
    if not (isinstance(stored, dict) and isinstance(stored.get("state"), dict)
            and isinstance(stored.get("warnings"), list)):
        raise TypeError(f"expected a model's attributes and warnings, found {type(stored).__name__}")
    return stored

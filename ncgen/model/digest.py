"""A content digest of a :class:`~ncgen.model.system.System`: sha256 of everything it holds.

The digest walks the system's object graph — every member (its coordinate type, mass,
inertia, frame, pose, twist, markers, shape, shared points), joint, force, contact, input,
parameter (name and value), frame, visual, controller and initial state — attribute by
attribute, in order, and hashes a canonical form of each value: numbers exactly (floats by
their bits), strings, arrays by dtype, shape and bytes, CasADi expressions by their
serialisation, objects of ncgen's own classes by class name and attributes (a reference to
an object met before by its index, so shared members and cycles are exact).  Two systems
have the same digest only if they hold the same values in the same structure.

What cannot be keyed reliably makes the digest ``None`` (:class:`Unkeyable` says what and
where): a Python callable (a force given as a function), a SymPy expression, an object of a
class defined outside ncgen (its code is not part of the key).  Values a class caches from
its other attributes (its ``functools.cached_property`` values, :data:`CACHES`) are left out.
"""
from __future__ import annotations

import enum
import functools
import hashlib
import types
from pathlib import PurePath

import numpy as np

#: Attributes that hold caches of values derived from the others (skipped by the walk).
CACHES = frozenset({"_fn_memo"})


class Unkeyable(TypeError):
    """A value the digest cannot key reliably; the message names it and where it is."""


def system_digest(system, extra=None) -> str | None:
    """sha256 (hex) of ``system`` and ``extra`` (e.g. the build options), or None when the
    system holds something that cannot be keyed (see the module docstring)."""
    try:
        return digest_or_raise(system, extra)
    except Unkeyable:
        return None


def digest_or_raise(system, extra=None) -> str:
    """:func:`system_digest`, raising :class:`Unkeyable` (naming the value and its path)
    instead of returning None."""
    h = hashlib.sha256()
    _Walk(h).visit((system, extra), "system")
    return h.hexdigest()


class _Walk:
    def __init__(self, h):
        self.h = h
        self.seen: dict[int, int] = {}
        self.keep: list = []              # objects met, alive until the walk ends (ids stay unique)

    def put(self, *tokens) -> None:
        for token in tokens:
            data = token if isinstance(token, bytes) else str(token).encode()
            self.h.update(len(data).to_bytes(8, "little"))
            self.h.update(data)

    def visit(self, obj, path: str) -> None:
        if obj is None or isinstance(obj, (bool, int, str, bytes)):
            self.put(type(obj).__name__, obj)
        elif isinstance(obj, float):
            self.put("float", obj.hex())
        elif isinstance(obj, complex):
            self.put("complex", obj.real.hex(), obj.imag.hex())
        elif isinstance(obj, np.generic):
            self.visit(obj.item(), path)
        elif isinstance(obj, np.ndarray):
            self._array(obj, path)
        elif isinstance(obj, PurePath):
            self.put("path", str(obj))
        elif _is_casadi(obj):
            self._casadi(obj, path)
        elif isinstance(obj, (list, tuple)):
            self.put(type(obj).__name__, len(obj))
            for k, item in enumerate(obj):
                self.visit(item, f"{path}[{k}]")
        elif isinstance(obj, (set, frozenset)):
            self.put("set", len(obj))
            for token in sorted(_sub_digest(item, f"{path}{{}}") for item in obj):
                self.put(token)
        elif isinstance(obj, (dict, types.MappingProxyType)):
            self.put("dict", len(obj))
            for key, value in obj.items():
                self.visit(key, f"{path} key")
                self.visit(value, f"{path}[{key!r}]")
        elif isinstance(obj, enum.Enum):
            self._ncgen_type(type(obj), path)
            self.put("enum", obj.name)
        elif isinstance(obj, type):
            self._ncgen_type(obj, path)
        else:
            self._object(obj, path)

    def _array(self, a: np.ndarray, path: str) -> None:
        if a.dtype == object:
            self.put("object array", a.shape)
            for k, item in enumerate(a.reshape(-1)):
                self.visit(item, f"{path}.flat[{k}]")
            return
        self.put("array", a.dtype.str, a.shape, np.ascontiguousarray(a).tobytes())

    def _casadi(self, obj, path: str) -> None:
        import casadi as ca
        if isinstance(obj, ca.DM):
            self.put("DM", obj.sparsity().serialize())
            self._array(np.array(obj.nonzeros(), dtype=float), path)
        elif isinstance(obj, (ca.SX, ca.MX)):
            self.put(type(obj).__name__, obj.serialize())
        elif isinstance(obj, ca.Function):
            self.put("Function", obj.serialize())
        else:
            raise Unkeyable(f"{path}: a CasADi {type(obj).__name__} cannot be keyed")

    def _ncgen_type(self, cls: type, path: str) -> None:
        if not _is_ncgen(cls):
            raise Unkeyable(f"{path}: the class {cls.__module__}.{cls.__qualname__} is not ncgen's")
        self.put("type", f"{cls.__module__}.{cls.__qualname__}")

    def _object(self, obj, path: str) -> None:
        if callable(obj) and not hasattr(obj, "__dict__") or isinstance(
                obj, (types.FunctionType, types.MethodType, types.BuiltinFunctionType, functools.partial)):
            raise Unkeyable(f"{path}: a Python callable ({obj!r}) cannot be keyed")
        cls = type(obj)
        if cls.__module__.split(".")[0] == "sympy":
            raise Unkeyable(f"{path}: a SymPy expression ({obj}) cannot be keyed")
        self._ncgen_type(cls, path)
        index = self.seen.get(id(obj))
        if index is not None:
            self.put("ref", index)
            return
        self.seen[id(obj)] = len(self.seen)
        self.keep.append(obj)
        if cls.__module__ == "ncgen.symbolic.coordinates" and cls.__name__ == "CoordinateType":
            self.put(obj.name, obj.dim)             # immutable, made by (name, dim)
            return
        state = dict(vars(obj)) if hasattr(obj, "__dict__") else {}
        for slot in _slots(cls):
            if hasattr(obj, slot):
                state[slot] = getattr(obj, slot)
        cached = _cached_names(cls)
        state = {k: v for k, v in state.items() if k not in CACHES and k not in cached}
        self.put("object", len(state))
        for key, value in state.items():
            self.put(key)
            self.visit(value, f"{path}.{key}")


def _sub_digest(obj, path: str) -> str:
    h = hashlib.sha256()
    _Walk(h).visit(obj, path)
    return h.hexdigest()


def _is_casadi(obj) -> bool:
    return type(obj).__module__.split(".")[0] == "casadi"


def _is_ncgen(cls: type) -> bool:
    return cls.__module__ == "ncgen" or cls.__module__.startswith("ncgen.")


@functools.lru_cache(maxsize=None)
def _cached_names(cls: type) -> frozenset:
    """The names of ``cls``'s ``functools.cached_property`` attributes (their values are caches)."""
    return frozenset(k for c in cls.__mro__ for k, v in vars(c).items() if isinstance(v, functools.cached_property))


@functools.lru_cache(maxsize=None)
def _slots(cls: type) -> tuple:
    names = []
    for c in cls.__mro__:
        s = vars(c).get("__slots__", ())
        names.extend([s] if isinstance(s, str) else s)
    return tuple(n for n in names if n not in ("__dict__", "__weakref__"))

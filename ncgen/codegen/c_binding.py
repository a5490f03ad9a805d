"""Binding compiled C with ctypes, one way for every loader.

A C signature is written once, as C spells it (:class:`Signature`: the return type and
``(type, name)`` per argument); :func:`bind` gives ctypes the matching types.  Pointers bind
either typed (``POINTER(c_double)``: NumPy arrays pass through ``_ptr``) or as addresses
(``c_void_p``: plain integers pass without conversion objects, for loops called per run).
``casadi_real`` is ``double`` and ``casadi_int`` ``long long`` (the generated packages'
defaults).  The tables: :mod:`ncgen.codegen.stepper_abi` (a model's stepper),
:mod:`ncgen.codegen.casadi_abi` (a function CasADi generates), ``SIGNATURES`` of
:mod:`ncgen.runtime.table_library`, :mod:`ncgen.runtime.tree_library` and
:mod:`ncgen.control.contact_active`, ``JOINT_RUN`` of :mod:`ncgen.codegen.joint_loop` and
``SIGNATURE`` of :mod:`ncgen.runtime.table_step`; ``tests/test_c_binding.py`` checks each
against the header or template that defines it.
"""
from __future__ import annotations

import ctypes
import re
import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ncgen.errors import CodegenError

#: C scalar types of the generated interfaces and their ctypes.
SCALARS = {"casadi_real": ctypes.c_double, "double": ctypes.c_double, "int": ctypes.c_int,
           "long": ctypes.c_long, "long long": ctypes.c_longlong, "size_t": ctypes.c_size_t,
           "casadi_int": ctypes.c_longlong}


@dataclass(frozen=True)
class Signature:
    """``returns symbol(args)``: ``args`` are ``(C type, name)`` pairs as the header writes
    them (``{name}`` in a type stands for the model's name, e.g. ``{name}_step_options``)."""

    returns: str
    args: tuple[tuple[str, str], ...]

    def types(self, name: str) -> list[str]:
        """The argument types spelled for model ``name``, whitespace normalised."""
        return [c_type(t.format(name=name)) for t, _ in self.args]


def c_type(text: str) -> str:
    """``text`` with single spaces and its ``*`` run attached to its type: ``const double *``,
    ``const casadi_real **``."""
    return re.sub(r"(?<!\*)\*", " *", re.sub(r"\s*\*\s*", "*", " ".join(text.split()))).strip()


def ctypes_of(spelling: str, structs: dict[str, type], addresses: bool):
    """The ctypes type of the C type ``spelling`` (a scalar of :data:`SCALARS`, a pointer to
    one, to a struct of ``structs`` or ``void``; ``const char *`` as ``c_char_p``, a string; a
    type of ``structs`` by value); pointers as ``c_void_p`` if ``addresses``."""
    base = c_type(spelling).replace("const ", "").replace("volatile ", "")
    if base.endswith("*"):
        if addresses:
            return ctypes.c_void_p
        target = base[:-1].strip()
        if target == "void":
            return ctypes.c_void_p
        if target == "char":
            return ctypes.c_char_p
        if target in structs:
            return ctypes.POINTER(structs[target])
        if target in SCALARS:
            return ctypes.POINTER(SCALARS[target])
    elif base in SCALARS:
        return SCALARS[base]
    elif base in structs:
        return structs[base]
    raise CodegenError(f"C type {spelling!r}: expected one of {sorted(SCALARS)}, a pointer to one, "
                       f"to void or to {sorted(structs) or 'no struct'}")


_BYTE = ctypes.c_char


def address(a) -> int | None:
    """The address of the data of the C-contiguous NumPy array ``a`` for an argument bound
    as an address (``c_void_p``), None for an empty one (NULL): through a ``c_char`` over its
    buffer where ``a`` is writable (0.5 µs, a third of ``a.ctypes.data``), else
    ``a.ctypes.data``."""
    if a.size == 0:
        return None
    try:
        return ctypes.addressof(_BYTE.from_buffer(a))
    except TypeError:                       # read-only
        return a.ctypes.data


class ThreadWork(threading.local):
    """A C loop's work array for the calling thread: ``array`` (``size`` doubles, zeroed) and
    its ``address``, made at the thread's first use and kept (``threading.local`` runs
    ``__init__`` again, with the same ``size``, in every other thread that uses the object):
    runs in one thread follow each other, runs in other threads have their own.  For loops that
    read no value of their work before writing it (never zeroed again)."""

    def __init__(self, size: int):
        self.array = np.zeros(int(size))
        self.address = self.array.ctypes.data


def open_library(path: str | Path) -> ctypes.CDLL:
    """The shared library at ``path``, or a :class:`CodegenError` naming it."""
    try:
        return ctypes.CDLL(str(path))
    except OSError as e:
        raise CodegenError(f"cannot load the compiled library {path}: {e}; delete it to have it rebuilt") from None


def bind(lib: ctypes.CDLL, symbol: str, signature: Signature, *, name: str = "",
         structs: dict[str, type] | None = None, addresses: bool = False):
    """``lib``'s function ``symbol`` with ctypes types set from ``signature`` (``name``: the
    model's name in struct types; ``structs``: ctypes structures by C name)."""
    try:
        fn = getattr(lib, symbol)
    except AttributeError:
        raise CodegenError(f"{lib._name}: no function {symbol!r}; the library is not of the expected "
                           f"kind or older than this ncgen (delete it to have it rebuilt)") from None
    structs = structs or {}
    returns = signature.returns.format(name=name)
    fn.restype = None if returns == "void" else ctypes_of(returns, structs, False)
    fn.argtypes = [ctypes_of(t, structs, addresses) for t in signature.types(name)]
    return fn


def structure(fields: tuple[tuple[str, str], ...], name: str = "") -> list[tuple[str, type]]:
    """ctypes ``_fields_`` of a C struct written as ``(C type, field)`` pairs."""
    return [(field, ctypes_of(t.format(name=name), {}, False)) for t, field in fields]

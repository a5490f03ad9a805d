"""The C interface of a function CasADi generates (``casadi.CodeGenerator``), written once:
the entry points ncgen calls, by suffix of the function's C name (``""``: the function
itself), as the generated header declares them; ``tests/test_c_binding.py`` checks them
against a committed package's header.

``<fn>(arg, res, iw, w, mem)`` evaluates with the pointer tables ``arg``/``res`` (one pointer
per input and output, their nonzeros column-major), integer and real work arrays sized by
``<fn>_work(&sz_arg, &sz_res, &sz_iw, &sz_w)``; ``<fn>_checkout()`` gives a memory slot
(``-1`` when all ``CASADI_MAX_NUM_THREADS`` are taken), ``<fn>_release(mem)`` gives it back,
``<fn>_incref()`` initialises (optional: CasADi writes them only when needed).  ``<fn>_decref()``
is not bound: a loaded function's memory stays for the process's life, its slots reused.
"""
from __future__ import annotations

import ctypes
from types import SimpleNamespace

import numpy as np

from ncgen.codegen.c_binding import Signature, bind
from ncgen.errors import CodegenError

#: ``<fn><suffix>`` of a generated function, by suffix.
FUNCTIONS = {
    "": Signature("int", (("const casadi_real **", "arg"), ("casadi_real **", "res"), ("casadi_int *", "iw"),
                          ("casadi_real *", "w"), ("int", "mem"))),
    "_work": Signature("int", (("casadi_int *", "sz_arg"), ("casadi_int *", "sz_res"), ("casadi_int *", "sz_iw"),
                               ("casadi_int *", "sz_w"))),
    "_checkout": Signature("int", ()),
    "_release": Signature("void", (("int", "mem"),)),
    "_incref": Signature("void", ()),
}
#: Entry points CasADi writes only when the function needs them.
OPTIONAL = ("_checkout", "_release", "_incref")


def bind_casadi(lib: ctypes.CDLL, c_name: str):
    """The entry points of the generated function ``c_name`` in ``lib`` as a namespace
    (``eval``, ``work``, ``checkout``, ``release``, ``incref``; the optional ones None when absent), the
    evaluation's pointers bound as addresses."""
    bound = {}
    for suffix, sig in FUNCTIONS.items():
        if suffix in OPTIONAL and not hasattr(lib, c_name + suffix):
            bound[suffix] = None
        else:
            bound[suffix] = bind(lib, c_name + suffix, sig, addresses=suffix == "")
    return SimpleNamespace(eval=bound[""], work=bound["_work"], checkout=bound["_checkout"],
                           release=bound["_release"], incref=bound["_incref"])


def work_sizes(fn, c_name: str) -> tuple[int, int, int, int]:
    """``(sz_arg, sz_res, sz_iw, sz_w)`` of ``fn`` (:func:`bind_casadi`), each at least 1."""
    sizes = [ctypes.c_longlong() for _ in range(4)]
    if fn.work(*(ctypes.byref(s) for s in sizes)):
        raise CodegenError(f"{c_name}_work failed")
    return tuple(max(1, int(s.value)) for s in sizes)


def work_arrays(fn, c_name: str) -> tuple[np.ndarray, np.ndarray]:
    """Integer and real work arrays of ``fn`` (:func:`bind_casadi`), sized by ``<fn>_work``."""
    _, _, sz_iw, sz_w = work_sizes(fn, c_name)
    return np.zeros(sz_iw, np.int64), np.zeros(sz_w)

"""The compiled stepper loaded with ctypes: ``<model>_simulate`` of the model's compiled
package (its C: :mod:`ncgen.codegen.stepper_package`) called on NumPy arrays."""
from __future__ import annotations

import ctypes
import weakref

import numpy as np

from ncgen.runtime.library import compiled_model

_loaded: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


class CompiledStepper:
    """``<model>_simulate`` of a compiled stepper library, called on NumPy arrays."""

    def __init__(self, library: str, name: str, nq: int, nc: int, nu: int, npar: int):
        self.library = library
        self.nq, self.nc, self.nu, self.np = nq, nc, nu, npar
        self._lib = ctypes.CDLL(library)
        dp, lp = ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_long)
        f = getattr(self._lib, f"{name}_simulate")
        f.restype = ctypes.c_int
        f.argtypes = [dp, dp, ctypes.c_double, ctypes.c_double, ctypes.c_long, ctypes.c_long, dp, ctypes.c_long,
                      dp, dp, dp, dp, lp, ctypes.POINTER(_Options), lp, lp]
        self._simulate = f

    def simulate(self, q0, v0, t0: float, h: float, n_steps: int, every: int, U: np.ndarray | None,
                 p: np.ndarray, tol: float, max_iter: int, max_halvings: int):
        """``(Q, V, LAM, ITER, status, steps_done, splits)``: states after every ``every``-th of
        ``n_steps`` steps (see ``<model>_simulate`` in ``<model>_stepper.h``).  ``U``: inputs
        per step, shape ``(n_steps, nu)``, or None for zeros."""
        rows = n_steps // every
        Q, V = np.zeros((rows, self.nq)), np.zeros((rows, self.nq))
        LAM, ITER = np.zeros((rows, self.nc)), np.zeros(rows, dtype=np.dtype(ctypes.c_long))
        q0, v0 = np.ascontiguousarray(q0, float), np.ascontiguousarray(v0, float)
        p = np.ascontiguousarray(p, float)
        U = None if U is None or self.nu == 0 else np.ascontiguousarray(U, float)
        done, splits = ctypes.c_long(0), ctypes.c_long(0)
        status = self._simulate(_ptr(q0), _ptr(v0), float(t0), float(h), int(n_steps), int(every),
                                _ptr(U), self.nu if U is not None else 0, _ptr(p), _ptr(Q), _ptr(V), _ptr(LAM),
                                ITER.ctypes.data_as(ctypes.POINTER(ctypes.c_long)),
                                ctypes.byref(_Options(float(tol), int(max_iter), int(max_halvings))),
                                ctypes.byref(done), ctypes.byref(splits))
        return Q, V, LAM, ITER, int(status), int(done.value), int(splits.value)


class _Options(ctypes.Structure):
    """``<model>_step_options``."""

    _fields_ = [("tol", ctypes.c_double), ("max_iter", ctypes.c_int), ("max_halvings", ctypes.c_int)]


def _ptr(a: np.ndarray | None):
    if a is None or a.size == 0:
        return None
    return a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))


def load_stepper(model, cflags=None) -> CompiledStepper:
    """The compiled stepper of ``model``, bound from its compiled package
    (:func:`ncgen.runtime.library.compiled_model`, shared with IDAS and the kernels)."""
    key = tuple(cflags) if isinstance(cflags, (list, tuple)) else cflags
    cache = _loaded.setdefault(model, {})
    if key not in cache:
        library = compiled_model(model, cflags).library
        cache[key] = CompiledStepper(str(library), model.name, model.nq, model.nc, model.nu, model.np)
    return cache[key]

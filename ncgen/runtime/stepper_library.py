"""The compiled stepper loaded with ctypes: the loops of the model's compiled package (its C:
:mod:`ncgen.codegen.stepper_package`) called on NumPy arrays.

Ctrl-C: a loop is called by :func:`~ncgen.interrupts.call_interruptibly`; SIGINT sets the
loop's stop flag (``options->stop``), the loop ends before its next step with status
:data:`~ncgen.codegen.stepper_package.STEP_INTERRUPTED` and the rows done so far."""
from __future__ import annotations

import ctypes

import numpy as np

from ncgen.codegen.c_binding import open_library
from ncgen.codegen.stepper_abi import RunOptions, StepOptions, bind_stepper
from ncgen.codegen.stepper_package import STEP_INTERRUPTED, n_impulses, n_outputs, n_stats
from ncgen.interrupts import call_interruptibly
from ncgen.model.data import model_data
from ncgen.runtime.library import compiled_model


class CompiledStepper:
    """The loops of a compiled stepper library (``<model>_simulate``, ``_simulate_stats``,
    ``_simulate_adaptive``, ``_outputs``), called on NumPy arrays."""

    #: Which kernels it runs: the model's own package (``"flat"``) or the element tables'.
    kernels = "flat"

    def __init__(self, library: str, name: str, nq: int, nc: int, nu: int, npar: int, nout: int, nd: int = 0):
        self.library = library
        self.nq, self.nc, self.nu, self.np, self.nout = nq, nc, nu, npar, nout
        self.nd = nd   # contact impulse components per step (nonsmooth contact stepper), else 0
        self._lib = open_library(library)
        self.name = name
        loops = bind_stepper(self._lib, name, bool(nd))
        self._simulate, self._simulate_stats = loops.simulate, loops.simulate_stats
        self._simulate_adaptive, self._outputs = loops.simulate_adaptive, loops.outputs

    def simulate(self, q0, v0, t0: float, h: float, n_steps: int, every: int, U: np.ndarray | None,
                 p: np.ndarray, tol: float, max_iter: int, max_halvings: int, impulse_out=None, scheme: int = 0):
        """``(Q, V, LAM, ITER, status, steps_done, splits)``: states after every ``every``-th of
        ``n_steps`` steps (see ``<model>_simulate`` in ``<model>_stepper.h``).  ``U``: inputs
        per step, shape ``(n_steps, nu)``, or None for zeros.  ``impulse_out`` (nonsmooth
        contact stepper): an array of shape ``(n_steps // every, nd)`` that receives the
        contact impulses summed over those steps (N·s), or None.  ``scheme``: 0 RATTLE, 1 its
        triple jump (``<MODEL>_STEP_RATTLE4``)."""
        rows = n_steps // every
        Q, V = np.zeros((rows, self.nq)), np.zeros((rows, self.nq))
        LAM, ITER = np.zeros((rows, self.nc)), np.zeros(rows, dtype=np.dtype(ctypes.c_long))
        q0, v0 = np.ascontiguousarray(q0, float), np.ascontiguousarray(v0, float)
        p = np.ascontiguousarray(p, float)
        U = None if U is None or self.nu == 0 else np.ascontiguousarray(U, float)
        done, splits = ctypes.c_long(0), ctypes.c_long(0)
        status = _interruptible(self._simulate, _ptr(q0), _ptr(v0), float(t0), float(h), int(n_steps), int(every),
                                _ptr(U), self.nu if U is not None else 0, _ptr(p), _ptr(Q), _ptr(V), _ptr(LAM),
                                ITER.ctypes.data_as(ctypes.POINTER(ctypes.c_long)),
                                step_options(tol, max_iter, max_halvings, scheme),
                                ctypes.byref(done), ctypes.byref(splits), *self._impulses(impulse_out, rows))
        return Q, V, LAM, ITER, int(status), int(done.value), int(splits.value)

    def _impulses(self, impulse_out, rows) -> list:
        """The trailing ``impulse_out`` argument of the contact stepper's loops (none without contacts)."""
        if impulse_out is not None and (impulse_out.shape != (rows, self.nd) or impulse_out.dtype != float
                                        or not impulse_out.flags.c_contiguous):
            raise ValueError(f"impulse_out: expected a C-contiguous float array of shape {(rows, self.nd)}")
        return [_ptr(impulse_out)] if self.nd else []

    def _buffers(self, rows):
        return (np.zeros((rows, self.nq)), np.zeros((rows, self.nq)), np.zeros((rows, self.nc)),
                np.zeros((rows, n_stats(self.nd))))

    def simulate_stats(self, q0, v0, lam0, t0: float, h: float, n_steps: int, every: int, U: np.ndarray | None,
                       p: np.ndarray, step: "StepSettings", run: RunOptions, impulse_out=None):
        """``(Q, V, LAM, STATS, status, steps_done, splits)``: fixed steps with per-row
        statistics (columns :data:`~ncgen.codegen.stepper_package.STATS`, then for the
        nonsmooth contact stepper :data:`~ncgen.codegen.stepper_package.CONTACT_STATS`; see
        ``<model>_simulate_stats``).  ``U``: inputs per step, shape ``(n_steps, nu)``, or None
        for zeros; ``step``: the steps' options (:func:`step_options`); ``run``: the run's
        (``<model>_run_options``; fixed steps read ``estimate``: 0 none, 1 the local estimate, 2
        the shadow run, ``ESTIMATE_*`` of ncgen_fixed.h, and ``track_work``)."""
        Q, V, LAM, S = self._buffers(n_steps // every)
        U = None if U is None or self.nu == 0 else np.ascontiguousarray(U, float)
        done, splits = ctypes.c_long(0), ctypes.c_long(0)
        status = _interruptible(self._simulate_stats, _ptr(_vec(q0)), _ptr(_vec(v0)), _ptr(_vec(lam0)), float(t0), float(h),
                                      int(n_steps), int(every), _ptr(U), self.nu if U is not None else 0,
                                      _ptr(_vec(p)), _ptr(Q), _ptr(V), _ptr(LAM), _ptr(S), step,
                                      ctypes.byref(run), ctypes.byref(done),
                                      ctypes.byref(splits), *self._impulses(impulse_out, n_steps // every))
        return Q, V, LAM, S, int(status), int(done.value), int(splits.value)

    def simulate_adaptive(self, q0, v0, lam0, t0: float, dt: float, n_out: int, U: np.ndarray | None,
                          p: np.ndarray, run: RunOptions, step: "StepSettings"):
        """``(Q, V, LAM, STATS, status, rows_done, h_next)``: error-controlled steps (see
        ``<model>_simulate_adaptive``) with the run's options ``run`` (``<model>_run_options``:
        tolerances, first step, extrapolation, step attempts, input hold, work tracking) and the
        steps' ``step`` (:func:`step_options`: Newton tolerance and iterations, the scheme: 0
        RATTLE, 1 its fourth-order composition).  ``U``: input samples at the output times,
        ``(n_out + 1, nu)``, or None for zeros."""
        Q, V, LAM, S = self._buffers(n_out)
        U = None if U is None or self.nu == 0 else np.ascontiguousarray(U, float)
        rows, h_next = ctypes.c_long(0), ctypes.c_double(0.0)
        status = _interruptible(self._simulate_adaptive, _ptr(_vec(q0)), _ptr(_vec(v0)), _ptr(_vec(lam0)), float(t0), float(dt),
                                int(n_out), _ptr(U), self.nu if U is not None else 0, _ptr(_vec(p)),
                                ctypes.byref(run), _ptr(Q), _ptr(V), _ptr(LAM), _ptr(S), step, ctypes.byref(rows),
                                ctypes.byref(h_next))
        return Q, V, LAM, S, int(status), int(rows.value), float(h_next.value)

    def outputs(self, t, Q, V, LAM, U, p) -> np.ndarray:
        """Rows ``[T, V, |Φ|∞, |A v + Φ_t|∞, P, markers...]`` of the samples (see
        ``<model>_outputs``)."""
        n = len(t)
        Y = np.zeros((n, self.nout))
        t, Q, V, LAM = (np.ascontiguousarray(a, float) for a in (t, Q, V, LAM))
        U = None if U is None or self.nu == 0 else np.ascontiguousarray(U, float)
        status = self._outputs(n, _ptr(t), _ptr(Q), _ptr(V), _ptr(LAM), _ptr(U), self.nu if U is not None else 0,
                               _ptr(_vec(p)), _ptr(Y))
        if status != 0:
            raise RuntimeError(f"{self.library}: outputs failed with status {status}")
        return Y


def _vec(a):
    return None if a is None else np.ascontiguousarray(a, float)


class StepSettings(StepOptions):
    """``<model>_step_options`` of one loop call, its stop flag pointing at ``self.flag``."""

    def __init__(self, tol: float, max_iter: int, max_halvings: int, scheme: int = 0):
        self.flag = ctypes.c_int(0)
        super().__init__(tol, max_iter, max_halvings, int(scheme), ctypes.pointer(self.flag))


def step_options(tol: float, max_iter: int, max_halvings: int, scheme: int = 0) -> StepSettings:
    """The steps' options of a loop: Newton tolerance and iterations, halvings of a failed
    step, the scheme (0 RATTLE, 1 its fourth-order composition), a cleared stop flag."""
    return StepSettings(float(tol), int(max_iter), int(max_halvings), int(scheme))


def _interruptible(fn, *args) -> int:
    """The status of ``fn(*args)``, a compiled loop whose arguments include one
    :class:`StepSettings`, by :func:`~ncgen.interrupts.call_interruptibly` on its stop flag:
    :data:`~ncgen.codegen.stepper_package.STEP_INTERRUPTED` after Ctrl-C."""
    options = next(a for a in args if isinstance(a, StepSettings))
    status, interrupted = call_interruptibly(fn, *(ctypes.byref(a) if a is options else a for a in args),
                                             stop=options.flag)
    return STEP_INTERRUPTED if interrupted else status


def _ptr(a: np.ndarray | None):
    if a is None or a.size == 0:
        return None
    return a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))


def load_stepper(model, cflags=None) -> CompiledStepper:
    """The compiled stepper of ``model``, bound from its compiled package
    (:func:`ncgen.runtime.library.compiled_model`, shared with IDAS and the kernels)."""
    key = tuple(cflags) if isinstance(cflags, (list, tuple)) else cflags
    cache = model_data(model).steppers
    if key not in cache:
        library = compiled_model(model, cflags).library
        cache[key] = CompiledStepper(str(library), model.name, model.nq, model.nc, model.nu, model.np,
                                     n_outputs(model), n_impulses(model))
    return cache[key]

"""The compiled stepper as C: its package section, and the library loaded with ctypes.

:func:`stepper_section` adds to a model package (``nc.generate``) the kernels of
:mod:`ncgen.runtime.stepper_kernels`, the Newton loop ``<model>_stepper.c`` with the API
declared in ``<model>_stepper.h`` (``<model>_step``, ``<model>_simulate``; templates
``stepper.c.j2``, ``stepper.h.j2``) and the example program ``<model>_simulate``
(``simulate_main.c.j2``), which simulates from the model's initial state without Python.

:func:`load_stepper` writes a package holding only that section (named after the model, so
the C symbols are the same as in the full package), compiles it (cached by content, see
:func:`ncgen.codegen.compile_package`) and binds ``<model>_simulate`` with ctypes; the
result is kept per model for the life of the process.
"""
from __future__ import annotations

import ctypes
import tempfile
import weakref

import numpy as np

from ncgen.codegen import PackageDoc, compile_package, write_package
from ncgen.codegen.cnames import c_real
from ncgen.codegen.package import ExtraSource
from ncgen.codegen.looped import reroll_limit
from ncgen.codegen.reroll import REROLL_INSTRUCTIONS
from ncgen.runtime.stepper_kernels import CONTACT_DOCS, DOCS, mass_scale, nonsmooth, stepper_functions

#: Status codes of ``<model>_step`` (``templates/c/stepper.h.j2``) and what they mean.
STATUS = {
    0: "converged",
    1: "Newton's method did not converge within max_iter iterations, on the whole step nor on "
       "its halves (try a smaller step dt or more max_halvings; or the motion is singular there)",
    2: "a residual or Newton update was not finite: the KKT matrix is singular (a singular "
       "configuration or redundant constraints) or the forces are not finite",
    3: "the velocity constraints are violated after the second half-step: the KKT matrix is "
       "nearly singular (a singular configuration or redundant constraints)",
    4: "a generated kernel returned an error",
    5: "bad input (non-positive step, non-finite time) or out of memory",
}
#: Default Newton tolerance: |Φ|∞ ≤ tol (m²), momentum residual ≤ tol·max|M|·(1 + |w|∞),
#: |A v + Φ_t|∞ ≤ tol·(1 + |v|∞) (see ``<model>_stepper.h``).
TOL = 1e-10
#: Default Newton iterations allowed per step.
MAX_ITER = 12
#: Default number of times a failing step may be split in halves, and the most the C
#: workspace allows (``<MODEL>_STEP_MAX_HALVINGS``).
MAX_HALVINGS, HALVINGS_LIMIT = 4, 10
#: Nonsmooth contact stepper: projected Gauss–Seidel sweeps allowed per step, and its
#: convergence test: no sweep changes a contact velocity by more than PGS_TOL (1 + max |U|)
#: (m/s; a test on the impulses would never pass where contacts are redundant, as under a
#: box or a chain lying flat, whose impulses are not unique).
PGS_MAX_ITER, PGS_TOL = 2000, 1e-12
#: Nonsmooth contact stepper: a contact whose gap is below −PENETRATION_TOL (m) at the end of
#: a step is put back on its surface (``push_out`` in ``stepper.c.j2``).  The push-out is
#: linearised and followed by the projection back onto Φ = 0, which moves the gaps again at
#: second order (~1e-8 m when the falling chain of benchmarks/contact.py lands), so a smaller
#: tolerance would only repeat push-outs.
PENETRATION_TOL = 1e-8
#: Nonsmooth contact stepper: a step with closed contacts is retaken with corrected impulses
#: (at most CONTACT_REFINE_MAX times) until its end-of-step contact velocities match the
#: linearised prediction to CONTACT_REFINE_TOL (relative to 1 m/s or the largest of them).
CONTACT_REFINE_MAX, CONTACT_REFINE_TOL = 10, 1e-8
#: The demo program's defaults: simulated time and step (s).
DEMO_T_END, DEMO_H = 1.0, 1e-3

_loaded: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def stepper_section(model, reroll_instructions: int | None = REROLL_INSTRUCTIONS):
    """The stepper's part of ``model``'s C package (a
    :class:`~ncgen.codegen.model_package.Section`)."""
    from ncgen.codegen.model_package import Section

    functions = stepper_functions(model, reroll_instructions)
    names = {f.name() for f in functions}
    docs = {k: v for k, v in {**DOCS, **CONTACT_DOCS}.items() if k in names} if nonsmooth(model) else DOCS
    return Section(functions=functions, docs=docs, extra_sources=extra_sources(model, functions))


def extra_sources(model, functions) -> list[ExtraSource]:
    """The Newton loop, its header and the example program, rendered for ``model``."""
    name = model.name
    context = {"nq": model.nq, "nc": model.nc, "nu": model.nu, "np": model.np,
               "nnz_k": int(functions[0].sparsity_out("K").nnz()),
               "mass_scale": c_real(mass_scale(model)), "tol": c_real(TOL), "max_iter": MAX_ITER,
               "max_halvings": MAX_HALVINGS, "halvings_limit": HALVINGS_LIMIT,
               "kernels": [f"{name}_{f.name()}" for f in functions]}
    if nonsmooth(model):
        factor = next((f for f in functions if f.name() == "step_factor"), None)
        if factor is not None:
            context.update(nnz_v=int(factor.sparsity_out(0).nnz()), nnz_r=int(factor.sparsity_out(1).nnz()),
                           n_beta=int(factor.sparsity_out(2).nnz()))
        context.update(factored=factor is not None, nk=model.nk, dim=model.dim, pgs_max_iter=PGS_MAX_ITER,
                       pgs_tol=c_real(PGS_TOL), penetration_tol=c_real(PENETRATION_TOL),
                       refine_max=CONTACT_REFINE_MAX, refine_tol=c_real(CONTACT_REFINE_TOL),
                       gravity_norm=c_real(float(np.linalg.norm(model.gravity))),
                       mu=[c_real(c["mu"]) for c in model.contacts],
                       restitution=[c_real(c["restitution"]) for c in model.contacts],
                       any_restitution=any(c["restitution"] > 0 for c in model.contacts))
    demo = {**context, "program": f"{name}_simulate", "t0": c_real(model.t0), "t_end": c_real(DEMO_T_END),
            "h": c_real(DEMO_H), "q0": [c_real(x) for x in model.q0], "v0": [c_real(x) for x in model.v0],
            "p0": [c_real(x) for x in model.p0]}
    return [ExtraSource("stepper.c.j2", f"{name}_stepper.c", context),
            ExtraSource("stepper.h.j2", f"{name}_stepper.h", context),
            ExtraSource("simulate_main.c.j2", f"{name}_simulate.c", demo, program=True)]


def write_stepper_package(model, out_dir):
    """A package holding only the stepper of ``model`` (kernels, loop, example program)."""
    limit = reroll_limit(model)
    section = stepper_section(model, limit)
    scheme = "RATTLE with nonsmooth contacts" if nonsmooth(model) else "RATTLE"
    doc = PackageDoc(summary=f"Compiled stepper ({scheme}) of model {model.name!r}", functions=section.docs)
    return write_package(model.name, section.functions, out_dir, doc=doc, extra_sources=section.extra_sources,
                         reroll_instructions=limit)


class CompiledStepper:
    """``<model>_simulate`` of a compiled stepper library, called on NumPy arrays."""

    def __init__(self, library: str, name: str, nq: int, nc: int, nu: int, npar: int, nd: int = 0):
        self.library = library
        self.nq, self.nc, self.nu, self.np = nq, nc, nu, npar
        self.nd = nd   # contact impulse components per step (nonsmooth contact stepper), else 0
        self._lib = ctypes.CDLL(library)
        dp, lp = ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_long)
        f = getattr(self._lib, f"{name}_simulate")
        f.restype = ctypes.c_int
        f.argtypes = [dp, dp, ctypes.c_double, ctypes.c_double, ctypes.c_long, ctypes.c_long, dp, ctypes.c_long,
                      dp, dp, dp, dp, lp, ctypes.POINTER(_Options), lp, lp] + ([dp] if nd else [])
        self._simulate = f

    def simulate(self, q0, v0, t0: float, h: float, n_steps: int, every: int, U: np.ndarray | None,
                 p: np.ndarray, tol: float, max_iter: int, max_halvings: int, impulse_out=None):
        """``(Q, V, LAM, ITER, status, steps_done, splits)``: states after every ``every``-th of
        ``n_steps`` steps (see ``<model>_simulate`` in ``<model>_stepper.h``).  ``U``: inputs
        per step, shape ``(n_steps, nu)``, or None for zeros.  ``impulse_out`` (nonsmooth
        contact stepper): an array of shape ``(n_steps // every, nd)`` that receives the
        contact impulses summed over those steps (N·s), or None."""
        rows = n_steps // every
        Q, V = np.zeros((rows, self.nq)), np.zeros((rows, self.nq))
        LAM, ITER = np.zeros((rows, self.nc)), np.zeros(rows, dtype=np.dtype(ctypes.c_long))
        q0, v0 = np.ascontiguousarray(q0, float), np.ascontiguousarray(v0, float)
        p = np.ascontiguousarray(p, float)
        U = None if U is None or self.nu == 0 else np.ascontiguousarray(U, float)
        done, splits = ctypes.c_long(0), ctypes.c_long(0)
        if impulse_out is not None and (impulse_out.shape != (rows, self.nd) or impulse_out.dtype != float
                                        or not impulse_out.flags.c_contiguous):
            raise ValueError(f"impulse_out: expected a C-contiguous float array of shape {(rows, self.nd)}")
        extra = [_ptr(impulse_out)] if self.nd else []
        status = self._simulate(_ptr(q0), _ptr(v0), float(t0), float(h), int(n_steps), int(every),
                                _ptr(U), self.nu if U is not None else 0, _ptr(p), _ptr(Q), _ptr(V), _ptr(LAM),
                                ITER.ctypes.data_as(ctypes.POINTER(ctypes.c_long)),
                                ctypes.byref(_Options(float(tol), int(max_iter), int(max_halvings))),
                                ctypes.byref(done), ctypes.byref(splits), *extra)
        return Q, V, LAM, ITER, int(status), int(done.value), int(splits.value)


class _Options(ctypes.Structure):
    """``<model>_step_options``."""

    _fields_ = [("tol", ctypes.c_double), ("max_iter", ctypes.c_int), ("max_halvings", ctypes.c_int)]


def _ptr(a: np.ndarray | None):
    if a is None or a.size == 0:
        return None
    return a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))


def load_stepper(model, cflags=None) -> CompiledStepper:
    """The compiled stepper of ``model`` (generated, compiled and cached on first use)."""
    key = tuple(cflags) if isinstance(cflags, (list, tuple)) else cflags
    cache = _loaded.setdefault(model, {})
    if key not in cache:
        with tempfile.TemporaryDirectory(prefix="ncgen-stepper-") as tmp:
            pkg = write_stepper_package(model, f"{tmp}/pkg")
            built = compile_package(pkg, cflags=cflags)
        nd = model.nk * model.dim if nonsmooth(model) else 0
        cache[key] = CompiledStepper(str(built.path), model.name, model.nq, model.nc, model.nu, model.np, nd)
    return cache[key]

"""The C interface of a compiled stepper (``<model>_stepper.h``, template
``templates/c/stepper.h.j2``) written once: every loader binds from these tables
(:func:`bind_stepper`), and ``tests/test_c_binding.py`` checks them against the prototypes
and the options struct of generated headers, with and without contacts.

Types are spelled as in the header; ``{name}`` is the model's name.  Arguments listed in
:data:`CONTACT_ONLY` are the trailing ones that only a nonsmooth contact stepper has.
"""
from __future__ import annotations

import ctypes
from types import SimpleNamespace

from ncgen.codegen.c_binding import Signature, bind, structure

REAL, CREAL = "casadi_real", "const casadi_real *"
OUT, LONG_OUT = "casadi_real *", "long *"
OPTIONS = "const {name}_step_options *"
RUN = "const {name}_run_options *"

#: ``{name}_step_options``: fields as ``(C type, name)``.
STEP_OPTIONS = (("casadi_real", "tol"), ("int", "max_iter"), ("int", "max_halvings"), ("int", "scheme"),
                ("volatile int *", "stop"))

#: ``{name}_run_options``, the options of a run (error control: all but ``estimate``; fixed steps:
#: ``track_work`` and ``estimate``): fields as ``(C type, name)``.
RUN_OPTIONS = (("casadi_real", "rtol"), ("casadi_real", "atol"), ("casadi_real", "h0"), ("int", "extrapolate"),
               ("long", "max_steps"), ("int", "hold_linear"), ("int", "track_work"), ("int", "estimate"))

#: ``{name}_<function>`` of the header, by function suffix.
FUNCTIONS = {
    "step_default_options": Signature("{name}_step_options", ()),
    "step_work_bytes": Signature("size_t", ()),
    "step": Signature("int", (
        (CREAL, "q"), (CREAL, "v"), (REAL, "t"), (CREAL, "u"), (CREAL, "p"), (REAL, "h"), (OUT, "q_next"),
        (OUT, "v_next"), (OUT, "lam"), ("int *", "iterations"), (OPTIONS, "options"), ("void *", "work"),
        (OUT, "impulse"))),
    "simulate": Signature("int", (
        (CREAL, "q0"), (CREAL, "v0"), (REAL, "t0"), (REAL, "h"), ("long", "n_steps"), ("long", "every"),
        (CREAL, "u"), ("long", "u_stride"), (CREAL, "p"), (OUT, "q_out"), (OUT, "v_out"), (OUT, "lam_out"),
        (LONG_OUT, "iter_out"), (OPTIONS, "options"), (LONG_OUT, "steps_done"), (LONG_OUT, "splits"),
        (OUT, "impulse_out"))),
    "simulate_stats": Signature("int", (
        (CREAL, "q0"), (CREAL, "v0"), (CREAL, "lam0"), (REAL, "t0"), (REAL, "h"), ("long", "n_steps"),
        ("long", "every"), (CREAL, "u"), ("long", "u_stride"), (CREAL, "p"), (OUT, "q_out"), (OUT, "v_out"),
        (OUT, "lam_out"), (OUT, "stats_out"), (OPTIONS, "options"), (RUN, "run"),
        (LONG_OUT, "steps_done"), (LONG_OUT, "splits"), (OUT, "impulse_out"))),
    "simulate_adaptive": Signature("int", (
        (CREAL, "q0"), (CREAL, "v0"), (CREAL, "lam0"), (REAL, "t0"), (REAL, "dt"), ("long", "n_out"),
        (CREAL, "u"), ("long", "u_stride"), (CREAL, "p"), (RUN, "run"), (OUT, "q_out"), (OUT, "v_out"),
        (OUT, "lam_out"), (OUT, "stats_out"), (OPTIONS, "options"), (LONG_OUT, "rows_done"), (OUT, "h_next"))),
    "outputs": Signature("int", (
        ("long", "n"), (CREAL, "t"), (CREAL, "q"), (CREAL, "v"), (CREAL, "lam"), (CREAL, "u"),
        ("long", "u_stride"), (CREAL, "p"), (OUT, "y"))),
}

#: Trailing arguments present only in a nonsmooth contact stepper, by function suffix.
CONTACT_ONLY = {"step": ("impulse",), "simulate": ("impulse_out",), "simulate_stats": ("impulse_out",)}

#: The loops a loader binds (Python never calls a single step).
LOOPS = ("simulate", "simulate_stats", "simulate_adaptive", "outputs")


def signature(function: str, contacts: bool) -> Signature:
    """The signature of ``{name}_<function>`` in a stepper with or without contacts."""
    sig = FUNCTIONS[function]
    drop = () if contacts else CONTACT_ONLY.get(function, ())
    return Signature(sig.returns, tuple(a for a in sig.args if a[1] not in drop))


class StepOptions(ctypes.Structure):
    """``{name}_step_options`` (:data:`STEP_OPTIONS`)."""

    _fields_ = structure(STEP_OPTIONS)


class RunOptions(ctypes.Structure):
    """``{name}_run_options`` (:data:`RUN_OPTIONS`)."""

    _fields_ = structure(RUN_OPTIONS)


def structs(name: str) -> dict:
    """The ctypes structures of model ``name``'s stepper interface, by C type name."""
    return {f"{name}_step_options": StepOptions, f"{name}_run_options": RunOptions}


def bind_stepper(lib: ctypes.CDLL, name: str, contacts: bool, functions=LOOPS, *, addresses: bool = False):
    """``functions`` (suffixes of :data:`FUNCTIONS`) of model ``name``'s stepper in ``lib``,
    as attributes of a namespace (pointers as addresses if ``addresses``, see
    :func:`~ncgen.codegen.c_binding.bind`)."""
    return SimpleNamespace(**{f: bind(lib, f"{name}_{f}", signature(f, contacts), name=name, structs=structs(name),
                                      addresses=addresses) for f in functions})

"""The model's DAE for a backend: ``dae(t, x, z, u, p) -> (ode, alg)``, ``x = [q; v]``,
``z = [a; λ]`` (:mod:`ncgen.assembly.functions`).

Backends: ``"vm"`` is the model's SX function (CasADi's virtual machine); ``"compiled"``
loads ``dae`` with ``casadi.external`` from the model's compiled package
(:func:`ncgen.runtime.library.compiled_model`, the one the stepper uses too), which also
finds its Jacobian kernel ``jac_<model>_dae`` and so gives IDAS exact derivatives; ``"auto"``
compiles when a C compiler is available and otherwise falls back to the VM with a warning.
Loaded functions are kept per model for the life of the process.
"""
from __future__ import annotations

import weakref

import casadi as ca

from ncgen.codegen.load import warn_no_compiler
from ncgen.errors import CompilerNotFound, NcgenError
from ncgen.runtime.library import compiled_functions

BACKENDS = ("vm", "compiled", "auto")

_loaded: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def load_dae(model, backend: str) -> tuple[ca.Function, str]:
    """``(dae, backend used)``: the DAE function of ``model`` for ``backend`` (see module
    docstring); the backend used is ``"vm"`` or ``"compiled"``."""
    if backend not in BACKENDS:
        raise NcgenError(f"backend: expected one of {', '.join(BACKENDS)}, got {backend!r}")
    if backend == "vm":
        return model.functions["dae"], "vm"
    cache = _loaded.setdefault(model, {})
    if "compiled" not in cache:
        try:
            cache["compiled"] = compiled_functions(model, ["dae"])["dae"]
        except CompilerNotFound as e:
            if backend == "compiled":
                raise
            warn_no_compiler(e)
            return model.functions["dae"], "vm"
    return cache["compiled"], "compiled"

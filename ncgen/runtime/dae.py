"""The model's DAE for a backend: ``dae(t, x, z, u, p) -> (ode, alg)``, ``x = [q; v]``,
``z = [a; λ]`` (:mod:`ncgen.assembly.functions`).

Backends: ``"vm"`` is the model's SX function (CasADi's virtual machine); ``"compiled"``
generates the model's C package (:func:`ncgen.generate`, into a temporary directory: the
files depend only on the model, so the library built from them is found in the compile
cache when the same model was generated or simulated before) and loads ``dae`` from it with
``casadi.external``, which also finds its Jacobian kernel ``jac_<model>_dae`` and so gives
IDAS exact derivatives; ``"auto"`` compiles when a C compiler is available and otherwise
falls back to the VM with a warning.  Loaded functions are kept per model for the life of
the process.
"""
from __future__ import annotations

import tempfile
import weakref

import casadi as ca

from ncgen.codegen import load_functions
from ncgen.codegen.model_package import generate
from ncgen.errors import NcgenError

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
        with tempfile.TemporaryDirectory(prefix="ncgen-dae-") as tmp:
            pkg = generate(model, f"{tmp}/{model.name}")
            f = load_functions(pkg, ["dae"], backend=backend)["dae"]
        if not f.is_a("External"):
            return f, "vm"
        cache["compiled"] = f
    return cache["compiled"], "compiled"

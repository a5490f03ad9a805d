"""The model's DAE for a backend: ``dae(t, x, z, u, p) -> (ode, alg)``, ``x = [q; v]``,
``z = [a; λ]`` (:mod:`ncgen.assembly.functions`).

Backends: ``"vm"`` is the model's SX function (CasADi's virtual machine); ``"compiled"``
loads ``dae`` with ``casadi.external`` from the model's compiled package
(:func:`ncgen.runtime.library.compiled_model`, the one the stepper uses too), which also
finds its Jacobian kernel ``jac_<model>_dae`` and so gives IDAS exact derivatives; ``"auto"``
compiles when a C compiler is available and otherwise falls back to the VM with a warning.
The loaded function is kept in the model's data (``model.data.dae``).
"""
from __future__ import annotations

import casadi as ca

from ncgen.codegen.load import warn_no_compiler
from ncgen.errors import CompilerNotFound, NcgenError
from ncgen.model.data import model_data
from ncgen.runtime.library import compiled_functions

BACKENDS = ("vm", "compiled", "auto")


def load_dae(model, backend: str) -> tuple[ca.Function, str]:
    """``(dae, backend used)``: the DAE function of ``model`` for ``backend`` (see module
    docstring); the backend used is ``"vm"`` or ``"compiled"``."""
    if backend not in BACKENDS:
        raise NcgenError(f"backend: expected one of {', '.join(BACKENDS)}, got {backend!r}")
    if backend == "vm":
        return model.functions["dae"], "vm"
    data = model_data(model)
    if data.dae is None:
        try:
            data.dae = compiled_functions(model, ["dae"])["dae"]
        except CompilerNotFound as e:
            if backend == "compiled":
                raise
            warn_no_compiler(e)
            return model.functions["dae"], "vm"
    return data.dae, "compiled"

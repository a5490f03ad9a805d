"""The system functions of a very large model in the form its C package is generated from.

Flat, ``ode``, ``alg`` and ``energy`` are single expressions over the whole model (``M⁻¹``
and the energy sums couple every coordinate), so rerolling (:mod:`ncgen.codegen.reroll`)
finds nothing that repeats in them.  When one of them is longer than
:data:`~ncgen.codegen.reroll.REROLL_INSTRUCTIONS`, they are rebuilt from the same
definitions (:func:`ncgen.assembly.functions.composite_functions`) as MX functions calling
the rerolled primitives, ``M⁻¹ b`` as two triangular solves with the constant factor of
``M`` and ``V`` as the sum of its rerolled terms.  ``accel`` calls the rerolled primitives
too, and the package exports the rerolled primitives themselves, so each is generated
once.  The other functions stay as they are: :func:`ncgen.codegen.package.write_package`
rerolls each of them (and the DAE's Jacobian) by itself.
"""
from __future__ import annotations

import casadi as ca

from ncgen.assembly.functions import composite_functions
from ncgen.assembly.mass import sparse_dm
from ncgen.codegen.reroll import REROLL_INSTRUCTIONS, reroll
from ncgen.model.data import model_data

#: Functions rebuilt from calls when the model is large (``dae`` stays flat: CasADi differentiates
#: its SX exactly and the package rerolls it and its Jacobian).
REBUILT = ("ode", "alg", "energy", "accel")
#: The functions the composites call.
PRIMITIVES = ("phi", "A", "phi_t", "gamma", "F")

#: A model whose flat system functions total more than this many SX instructions (a chain
#: of ~90 bars) has its package's functions rerolled from LARGE_MODEL_REROLL instructions
#: on: its straight-line code would take a minute or more to compile at -O2 (0.5 ms per
#: instruction), and next to the loops the short straight-line functions would take most
#: of the compile time.  Smaller models keep straight-line code, the fastest at run time.
LARGE_MODEL_INSTRUCTIONS = 40_000
LARGE_MODEL_REROLL = 1_000


def reroll_limit(model, reroll_instructions: int | None = REROLL_INSTRUCTIONS) -> int | None:
    """The reroll threshold of ``model``'s package: ``reroll_instructions``, lowered to
    :data:`LARGE_MODEL_REROLL` for a model larger than :data:`LARGE_MODEL_INSTRUCTIONS`."""
    if reroll_instructions is None:
        return None
    total = sum(f.n_instructions() for f in model.functions.values())
    return min(reroll_instructions, LARGE_MODEL_REROLL) if total > LARGE_MODEL_INSTRUCTIONS else reroll_instructions


def is_large(model, reroll_instructions: int | None = REROLL_INSTRUCTIONS) -> bool:
    """Whether a flat composite of ``model`` is longer than ``reroll_instructions``
    (``None``: never)."""
    return reroll_instructions is not None and any(
        model.functions[n].n_instructions() > reroll_instructions for n in REBUILT if n != "accel")


def primitives(model) -> dict[str, ca.Function]:
    """The rerolled primitives of ``model``, ``Minv`` as triangular solves and ``V`` (the
    rerolled terms of the potential energy); computed once per model."""
    data = model_data(model)
    if data.rerolled is None:
        f = {n: reroll(model.functions[n]) for n in PRIMITIVES}
        b = ca.MX.sym("b", model.nq)
        x = model.mass_factor.solve(b) if model.mass_factor.regular else model.mass_factor.pseudo_solve(b)
        f["Minv"] = ca.Function("Minv", [b], [x], ["b"], ["x"])
        f["V"] = reroll(model.potential_terms)
        data.rerolled = f
    return data.rerolled


def package_functions(model, reroll_instructions: int | None = REROLL_INSTRUCTIONS) -> dict[str, ca.Function]:
    """``model.functions`` with, if the model is large, the primitives rerolled and the
    composites rebuilt from calls to them (each rerolled function is generated once)."""
    f = dict(model.functions)
    if not is_large(model, reroll_instructions):
        return f
    prim = primitives(model)
    alpha, beta = model.baumgarte
    f.update(composite_functions(prim, prim["V"], sparse_dm(model.M), alpha, beta, ca.MX, REBUILT,
                                 regular=model.mass_factor.regular))
    f.update({n: prim[n] for n in (*PRIMITIVES, "Minv")})
    return f

"""What the step functions share (:mod:`ncgen.control.step` for smooth models,
:mod:`ncgen.control.contact_step` for nonsmooth contacts) and the MPC uses: the error of a step
that did not converge, the checked state vectors, and the compile of a step's CasADi functions
into a loaded C package."""
from __future__ import annotations

import os

import numpy as np

from ncgen.errors import NcgenError
from ncgen.validation import as_numbers

#: How a step function's package is written: not rerolled (the exported MPC package is
#: written the same way, so that Python and C run the same arithmetic in the same order), one
#: function per file, so that the solve and the two sensitivities compile in parallel.
PACKAGE_OPTIONS = {"reroll_instructions": None, "max_file_instructions": 0}


class StepDidNotConverge(NcgenError):
    """The Newton iterations of a step ended with a residual above
    :data:`ncgen.control.step.RESIDUAL_TOL` or with NaN or inf in the state."""


def state_vector(a, n: int, name: str, what: str) -> np.ndarray:
    """``a`` as ``n`` finite floats; raw bytes, text, complex numbers and ragged nestings
    are refused by ``name`` (:func:`~ncgen.validation.as_numbers`)."""
    a = as_numbers(a, name, f"{n} finite number(s) ({what})").reshape(-1) if a is not None else np.zeros(0)
    if a.size == 1 and n > 1 and name == "u":
        a = np.full(n, a[0])
    if a.size != n or not np.all(np.isfinite(a)):
        raise NcgenError(f"{name}: expected {n} finite number(s) ({what}), got {a.size} value(s)"
                         + ("" if np.all(np.isfinite(a)) else " with NaN or inf"))
    return a


def compile_flags() -> tuple[str, ...] | None:
    """The flags of a step function's package: ``$NCGEN_CFLAGS`` if set, else ``-O1``
    (:data:`ncgen.codegen.compile_cache.LARGE_CFLAGS`: its files are long straight-line
    functions, which gcc compiles about 1.5x faster at -O1 than at -O2, and which run no
    slower)."""
    from ncgen.codegen.compile_cache import LARGE_CFLAGS
    return None if os.environ.get("NCGEN_CFLAGS") is not None else LARGE_CFLAGS


def compile_functions(name: str, functions: list, **options) -> dict:
    """``functions`` as the C package ``name`` with the step packages' options
    (:data:`PACKAGE_OPTIONS`, updated by ``options``) and flags (:func:`compile_flags`),
    compiled and loaded by :func:`ncgen.codegen.direct.compile_functions`:
    ``{function name: DirectFunction}``."""
    from ncgen.codegen import direct

    return direct.compile_functions(name, functions, compile_flags(), **{**PACKAGE_OPTIONS, **options})

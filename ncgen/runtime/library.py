"""The compiled C package of a model: generated once, compiled once (cached by content, see
:func:`ncgen.codegen.compile_package`) and shared by every compiled path of a process —
IDAS's ``dae`` (:mod:`ncgen.runtime.dae`), the stepper (:mod:`ncgen.runtime.stepper_library`)
and any kernel loaded with :func:`compiled_functions`.

The model is constant; what a run needs beyond it (the compiled library, loaded functions)
lives in its data (:class:`ncgen.model.data.ModelData`), so a model can be shared between runs.
"""
from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

import casadi as ca

from ncgen.codegen import compile_package
from ncgen.codegen.load import external_functions
from ncgen.codegen.model_package import generate
from ncgen.model.data import model_data


@dataclass(frozen=True)
class CompiledModel:
    """``library``: the shared library of the model's package; ``manifest``: its manifest
    (function names and C symbols)."""

    library: Path
    manifest: dict

    def functions(self, names) -> dict[str, ca.Function]:
        """Functions ``names`` of the package, backed by the library (``casadi.external``)."""
        return external_functions(self.library, names, self.manifest)


def compiled_model(model, cflags=None) -> CompiledModel:
    """The compiled package of ``model`` (``cflags`` as in
    :func:`~ncgen.codegen.compile_package`), built on first use and kept for the process."""
    key = tuple(cflags) if isinstance(cflags, (list, tuple)) else cflags
    cache = model_data(model).libraries
    if key not in cache:
        with tempfile.TemporaryDirectory(prefix="ncgen-") as tmp:
            pkg = generate(model, f"{tmp}/{model.name}")
            built = compile_package(pkg, cflags=cflags)
            cache[key] = CompiledModel(Path(built.path), pkg.manifest)
    return cache[key]


def is_loaded(model) -> bool:
    """Whether this process has already compiled (or found in the cache) ``model``'s package."""
    return bool(model_data(model).libraries)


def compiled_functions(model, names, cflags=None) -> dict[str, ca.Function]:
    """Functions ``names`` of ``model``'s compiled package (see :func:`compiled_model`)."""
    return compiled_model(model, cflags).functions(names)

"""The C package of a model: ``generate(model, out_dir)``.

The package (see :mod:`ncgen.codegen.package` for its files) holds the model's system
functions (:mod:`ncgen.assembly.functions`: Φ, A, Φ_t, γ, F, M (``mass``, sparse), M⁻¹ b, the
DAE as ``ode``/``alg``
and in IDAS's stacked form ``dae`` with its sparse Jacobian ``jac_<model>_dae``, the KKT
solve ``accel``, energies, markers, poses), each documented in ``<model>.h`` from
:data:`ncgen.assembly.functions.DOCS`, and the model as metadata: dimensions, the names of
coordinates, constraints, inputs, parameters, members and markers, the consistent initial
state (``t0``, ``q0``, ``v0``, ``lam0``, ``x0``, ``z0``, ``p0``),
gravity, the Baumgarte coefficients and ``model_hash``.  The initial state and
``model_hash`` are the package's data (``<model>_data.c``, :data:`DATA`): the compiled
library does not depend on them, so the same system at another initial state reuses it.  ``main.c`` evaluates ``accel`` (or
any other function) at the initial state without Python.  The compiled stepper
(``<model>_step``, ``<model>_simulate`` in ``<model>_stepper.h``) and its example program
``<model>_simulate`` complete it.

A package is made of *sections*: :data:`SECTIONS` lists functions ``model -> Section``
whose functions, documentation, metadata and extra C sources are merged in order.  A
feature that adds C to every model package (a compiled stepper, say) appends its own.
"""
from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Callable, Mapping

import casadi as ca
import numpy as np

from ncgen.assembly.functions import DOCS, IN
from ncgen.codegen import fsutil
from ncgen.codegen.compile_cache import compile_package
from ncgen.codegen.doc import PackageDoc
from ncgen.codegen.linearization_package import linearization_section
from ncgen.codegen.looped import package_functions, reroll_limit
from ncgen.codegen.manifest import canonical_json
from ncgen.codegen.package import Package, check_replaceable, publish, write_package
from ncgen.codegen.reroll import REROLL_INSTRUCTIONS
from ncgen.codegen.section import Section
from ncgen.codegen.stepper_package import stepper_section
from ncgen.model.model import component_names
from ncgen.model.rolling import refuse_rolling

#: The system functions in the package, in this order.
SYSTEM_FUNCTIONS = ("phi", "A", "phi_t", "gamma", "F", "mass", "Minv", "ode", "alg", "dae", "accel",
                    "energy", "markers", "poses")
#: Functions generated with their Jacobian (IDAS differentiates ``dae``).
SYSTEM_JACOBIANS = ("dae",)
#: Function evaluated by ``main.c`` when called without arguments.
MAIN_FUNCTION = "accel"
#: Input name -> metadata key of its default value (used by ``main.c`` and documented).
DEFAULTS = {"t": "t0", "q": "q0", "v": "v0", "lam": "lam0", "x": "x0", "z": "z0", "p": "p0"}
#: Metadata that is the model's data, not its code (:attr:`ncgen.codegen.doc.PackageDoc.data`):
#: the initial state, its default parameters and the hash that covers them.  Kept out of the
#: compiled library's sources, so a model rebuilt at a new initial state compiles nothing.
DATA = (*DEFAULTS.values(), "model_hash")


def generate(model, out_dir: str | os.PathLike, *, cflags=None, compile: bool = False,
             reroll_instructions: int | None = REROLL_INSTRUCTIONS, linearization: bool = False) -> Package:
    """Write the C package of ``model`` (a :class:`~ncgen.model.model.Model`) to ``out_dir``.

    The package is named after the model; its files depend only on the model (same model,
    same bytes).  ``out_dir`` is replaced atomically if it holds an ncgen package (and
    refused otherwise).  With ``compile=True`` the shared library is built now (with
    ``cflags``, see :func:`~ncgen.codegen.compile_cache.compile_package`; cached by content) and the
    package is moved into place only if that succeeds; otherwise the library is built when
    first loaded.  Load the functions back with
    ``ncgen.codegen.load_functions(pkg, backend="compiled")``.

    ``reroll_instructions``: functions longer than this many SX instructions are generated
    as loops over short kernels (:mod:`ncgen.codegen.reroll`, :mod:`ncgen.codegen.looped`):
    C that compiles in seconds whatever the size of the model, at about 2–4× the run time
    of straight-line code compiled with -O2 (``benchmarks/kernel.py --looped``); the limit
    is lowered for a large model (:func:`ncgen.codegen.looped.reroll_limit`).  ``None`` generates straight-line code only:
    the fastest kernels for a large model, if its compile time (minutes to hours at -O2 for
    thousands of members) is acceptable.

    ``linearization=True`` adds the kernel ``linearize`` (minimal-state ``A``, ``B``, ``C``
    about any consistent state, :mod:`ncgen.codegen.linearization_package`).
    """
    refuse_rolling(model, "generate", "the package's stepper and DAE are the model's without the rolling "
                   "rows; simulate it with nc.simulate (method 'rolling', 'idas' or 'stepper')")
    reroll_instructions = reroll_limit(model, reroll_instructions)
    makers = SECTIONS + ([linearization_section] if linearization else [])
    sections = [make(model, reroll_instructions) for make in makers]
    functions = [f for s in sections for f in s.functions]
    metadata = {k: v for s in sections for k, v in s.metadata.items()}
    doc = PackageDoc(
        summary=_summary(model),
        functions={k: v for s in sections for k, v in s.docs.items()},
        metadata=metadata,
        metadata_doc={k: v for s in sections for k, v in s.metadata_doc.items()},
        defaults={arg: key for arg, key in DEFAULTS.items() if key in metadata},
        main_function=MAIN_FUNCTION, data=tuple(key for key in DATA if key in metadata))
    options = dict(doc=doc, jacobians=[j for s in sections for j in s.jacobians],
                   reroll_instructions=reroll_instructions,
                   extra_sources=[e for s in sections for e in s.extra_sources])
    out_dir = Path(out_dir)
    if not compile:
        return write_package(model.name, functions, out_dir, **options)
    fsutil.check_target(out_dir, check_replaceable)
    with fsutil.temporary_sibling(out_dir) as tmp:
        pkg = write_package(model.name, functions, tmp / out_dir.name, **options)
        compile_package(pkg, cflags=cflags)
        publish(pkg.path, out_dir)
    return dataclasses.replace(pkg, path=out_dir)


def system_section(model, reroll_instructions: int | None = REROLL_INSTRUCTIONS) -> Section:
    """The system functions of ``model`` (:func:`ncgen.codegen.looped.package_functions`)
    and its metadata."""
    package = package_functions(model, reroll_instructions)
    functions = [package[name] for name in SYSTEM_FUNCTIONS]
    docs = {f.name(): function_doc(f) for f in functions}
    metadata, metadata_doc = model_metadata(model)
    return Section(functions=functions, docs=docs, jacobians=SYSTEM_JACOBIANS,
                   metadata=metadata, metadata_doc=metadata_doc)


#: Makers of the sections of every model package, in order: ``make(model,
#: reroll_instructions) -> Section``.
SECTIONS: list[Callable[[object, int | None], Section]] = [system_section, stepper_section]


def function_doc(f: ca.Function) -> dict:
    """Documentation of system function ``f`` from :data:`~ncgen.assembly.functions.DOCS`
    (purpose and outputs) and :data:`~ncgen.assembly.functions.IN` (inputs)."""
    purpose, outputs = DOCS[f.name()]
    return {"purpose": purpose, "inputs": {a: IN[a] for a in f.name_in()},
            "outputs": {a: outputs[a] for a in f.name_out()}}


def model_metadata(model) -> tuple[dict, dict]:
    """``(metadata, metadata_doc)`` of ``model`` for :class:`~ncgen.codegen.doc.PackageDoc`."""
    d = model.dim
    entries = [
        ("dim", d, "spatial dimension: 3, or 2 for a planar model"),
        ("nq", model.nq, "number of natural coordinates q"),
        ("nc", model.nc, "number of constraints Φ (and multipliers λ)"),
        ("dof", model.dof, "degrees of freedom, nq - rank A(q0)"),
        ("nu", model.nu, "number of input values u"),
        ("np", model.np, "number of parameter values p"),
        ("n_members", len(model.member_names), "number of members (bodies, bars, points)"),
        ("n_markers", len(model.marker_names), "number of named markers"),
        ("coordinate_names", model.coordinate_names, "name of each coordinate q[i]"),
        ("constraint_names", model.constraint_names, "name of each constraint Phi[i]"),
        ("input_names", component_names(model.input_names, model.input_sizes), "name of each input u[i]"),
        ("parameter_names", component_names(model.parameter_names, model.parameter_sizes),
         "name of each parameter p[i]"),
        ("member_names", model.member_names, "members, in the order of the blocks of poses"),
        ("marker_names", model.marker_names, "markers (member.marker), in the order of the columns of markers"),
        ("t0", [model.t0], "initial time (s), one value"),
        ("q0", model.q0, "consistent initial coordinates (m)"),
        ("v0", model.v0, "consistent initial coordinate rates (m/s)"),
        ("lam0", model.lam0, "initial Lagrange multipliers, consistent with q0, v0, p0 and zero inputs"),
        ("x0", np.concatenate([model.q0, model.v0]), "initial DAE state [q0; v0]"),
        ("z0", np.concatenate([model.a0, model.lam0]), "initial algebraic state of dae, [a0; lam0]"),
        ("p0", model.p0, "default parameter values"),
        ("gravity", model.gravity, "gravity vector (m/s^2)"),
        ("baumgarte_alpha", float(model.baumgarte[0]), "Baumgarte coefficient alpha of alg and accel (1/s)"),
        ("baumgarte_beta", float(model.baumgarte[1]), "Baumgarte coefficient beta of alg and accel (1/s)"),
    ]
    metadata = {k: v for k, v, _ in entries}
    metadata_doc = {k: doc for k, _, doc in entries}
    metadata["model_hash"] = _hash(model, metadata)
    metadata_doc["model_hash"] = ("sha256 of the model's system functions and the metadata above: "
                                  "equal hashes, same model")
    return metadata, metadata_doc


def model_hash(model) -> str:
    """sha256 identifying ``model``: equal hashes mean the same system functions, names,
    dimensions, initial state and mass matrix (the ``model_hash`` of its package)."""
    return model_metadata(model)[0]["model_hash"]


def _hash(model, metadata: Mapping) -> str:
    """sha256 of ``model``'s serialised system functions and ``metadata``."""
    plain = PackageDoc(metadata=metadata).metadata
    data = {"functions": [[name, model.functions[name].serialize()] for name in SYSTEM_FUNCTIONS],
            "metadata": plain}
    return fsutil.sha256_bytes(canonical_json(data).encode())


def _summary(model) -> str:
    return (f"Model {model.name!r} ({model.dim}D): nq = {model.nq} natural coordinates, "
            f"nc = {model.nc} constraints, {model.dof} degrees of freedom, nu = {model.nu} inputs, "
            f"np = {model.np} parameters; members: {', '.join(model.member_names)}. "
            f"Generated by ncgen.generate from the model's CasADi functions.")

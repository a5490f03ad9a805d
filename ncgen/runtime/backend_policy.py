"""Where a run's equations are evaluated: the one rule that ``nc.simulate`` and every
``ncgen`` subcommand apply to ``backend="auto"`` (the default of both).

A run starts where it is ready now and compiles only when compiling pays:

* the model's compiled library is used when this process already loaded it;
* otherwise IDAS runs on CasADi's virtual machine (ready at once) unless the estimated
  saving of compiled code over the whole run exceeds the estimated compile time::

      saving  = outputs × EVALS_PER_OUTPUT × 3 n_dae × VM_EXTRA_SECONDS
      compile = COMPILE_FIXED_SECONDS + PACKAGE_FACTOR n_model × COMPILE_SECONDS / cores

  with ``n_dae`` the SX instructions of the model's DAE residual (its Jacobian counted as
  twice that) and ``n_model`` those of all the model's functions.  Measured on this
  project's examples (benchmarks/first_run.py): IDAS on the VM runs within 20 % of IDAS on
  compiled C for every shipped example over seconds of motion, while compiling their
  packages costs 3–30 s of CPU, so short runs stay on the VM and long runs of large models
  compile;
* the compiled stepper (``method="stepper"``) is generated C: it always compiles (once; the
  library is cached by content, see :func:`ncgen.codegen.compile_package`).

Without a C compiler every path that would compile runs on the VM instead, saying so in
one line (:func:`ncgen.codegen.load.warn_no_compiler`); the stepper has no VM form and
says which option to use instead.

The joint-space loop of a tree (``method="joint"``, ``kernels="auto"``,
:func:`choose_joint_kernels`) runs on the tree tables (the tree library: units compiled once
per ncgen version, nothing compiled per model) unless the model's own flat loop is ready
(loaded in this process, or compiled earlier and found in the compile cache) or the run is
long enough for the flat loop's faster evaluations to win back deriving and compiling it
beyond what compiling the library units the tables still lack costs (the forward unit,
``TREE_UNIT_COMPILE_SECONDS``, and a kernel unit per joint kind the loops do not write out,
``TREE_KERNEL_UNIT_COMPILE_SECONDS``; nothing once they are in the cache)::

      saving  = outputs × JOINT_EVALS_PER_OUTPUT × n_v × TABLES_EXTRA_SECONDS
      compile = JOINT_COMPILE_FIXED_SECONDS + n_v × JOINT_COMPILE_SECONDS_PER_RATE
      flat when saving > compile − units

with ``n_v`` the joint rates.  Measured on the Panda (9 rates, AMD EPYC, load 5–6): 5.2 µs
per ODE evaluation on the tables, 4.0 µs flat; 26 evaluations per output interval of 0.01 s
(Dormand–Prince at the default tolerances); deriving the ODE and compiling its loop 2.7 s of
CPU — the flat loop pays only after about 800 s of simulated motion.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from functools import lru_cache

from ncgen.errors import NcgenError

BACKENDS = ("auto", "vm", "compiled")
#: IDAS residual evaluations per output interval, typical of the examples (chain: 55).
EVALS_PER_OUTPUT = 50
#: Extra seconds per SX instruction of CasADi's VM over compiled C (a generous bound).
VM_EXTRA_SECONDS = 5e-9
#: CPU seconds of gcc per SX instruction of a package (-O2, -O1 for long functions).
COMPILE_SECONDS = 3e-4
#: Instructions of a model's package (DAE Jacobian, stepper) per instruction of its functions.
PACKAGE_FACTOR = 3.0
#: Seconds of a compile beyond its instructions (gcc start-up, linking, loading).
COMPILE_FIXED_SECONDS = 1.0


#: Joint-space ODE evaluations per output interval (Dormand–Prince, default tolerances; Panda: 26).
JOINT_EVALS_PER_OUTPUT = 30
#: Extra seconds per ODE evaluation and joint rate of the tree tables' loop over the flat one.
TABLES_EXTRA_SECONDS = 0.15e-6
#: CPU seconds to derive and compile a tree's flat joint loop: fixed, and per joint rate.
JOINT_COMPILE_FIXED_SECONDS, JOINT_COMPILE_SECONDS_PER_RATE = 1.0, 0.2
#: CPU seconds to compile the tree library's forward unit (its loops and rate kernels, -O1) once
#: per ncgen version, and one of its kernel units (ncgen/runtime/tree_library.py).
TREE_UNIT_COMPILE_SECONDS, TREE_KERNEL_UNIT_COMPILE_SECONDS = 1.5, 0.6


@dataclass(frozen=True)
class Choice:
    """``backend``: ``"vm"`` or ``"compiled"`` (for the joint loop's kernels ``"tables"`` or
    ``"flat"``); ``reason``: one line saying why."""

    backend: str
    reason: str


def estimated_compile_seconds(model) -> float:
    """Wall time to compile ``model``'s package (see module docstring)."""
    n_model = sum(f.n_instructions() for f in model.functions.values())
    return COMPILE_FIXED_SECONDS + PACKAGE_FACTOR * n_model * COMPILE_SECONDS / (os.cpu_count() or 1)


def estimated_saving_seconds(model, outputs: int) -> float:
    """Seconds compiled C saves over the VM on an IDAS run of ``outputs`` output intervals."""
    return outputs * EVALS_PER_OUTPUT * 3 * model.functions["dae"].n_instructions() * VM_EXTRA_SECONDS


def choose_backend(model, outputs: int, backend: str = "auto", method: str = "idas") -> Choice:
    """The backend of a run of ``model`` over ``outputs`` output intervals (see module
    docstring); ``backend`` other than ``"auto"`` is the user's choice and is kept."""
    if backend not in BACKENDS:
        raise NcgenError(f"backend: expected one of {', '.join(BACKENDS)}, got {backend!r}")
    if method == "stepper":
        return Choice("compiled", "the stepper is generated C")
    if backend != "auto":
        return Choice(backend, "chosen")
    from ncgen.runtime.library import is_loaded

    if is_loaded(model):
        return Choice("compiled", "already compiled in this process")
    saving, cost = estimated_saving_seconds(model, outputs), estimated_compile_seconds(model)
    if saving > cost:
        return Choice("compiled", f"compiling (~{cost:.0f} s) saves ~{saving:.0f} s on this run")
    return Choice("vm", f"compiling (~{cost:.0f} s) would save ~{saving:.1f} s on this run")


@lru_cache(maxsize=256)
def choose_joint_kernels(nv: int, outputs: int, flat_ready: str | None, missing: tuple[str, ...] = ()) -> Choice:
    """The kernels (``"tables"`` or ``"flat"``) of a joint-space run of a tree with ``nv``
    joint rates over ``outputs`` output intervals that the tree tables cover and a compiler
    could build (module docstring); ``flat_ready``: why its flat loop is ready, or None;
    ``missing``: the units of the tree library the tables' run needs that are not compiled
    yet (``"forward"``, kernel units)."""
    if flat_ready is not None:
        return Choice("flat", f"the model's own loop is ready ({flat_ready})")
    cost = JOINT_COMPILE_FIXED_SECONDS + nv * JOINT_COMPILE_SECONDS_PER_RATE
    units = sum(TREE_UNIT_COMPILE_SECONDS if u == "forward" else TREE_KERNEL_UNIT_COMPILE_SECONDS for u in missing)
    saving = outputs * JOINT_EVALS_PER_OUTPUT * nv * TABLES_EXTRA_SECONDS
    if saving > cost:
        return Choice("flat", f"compiling the model's own loop (~{cost:.0f} s) saves ~{saving:.0f} s on this run")
    if saving > cost - units:
        return Choice("flat", f"the tree library's {', '.join(missing)} not compiled yet (~{units:.1f} s once per "
                              f"ncgen version, more than the model's own loop: ~{cost:.1f} s)")
    first = "nothing to compile" if not missing else \
        f"compiling the tree library's {', '.join(missing)} (~{units:.1f} s, once per ncgen version)"
    return Choice("tables", f"{first}; the model's own loop (~{cost:.0f} s to compile) would save "
                            f"~{saving:.2g} s on this run")


#: The rule as users read it (``--help``, docs/python-guide.md).
RULE = ("auto (default): IDAS starts at once on CasADi's virtual machine and compiles the "
        "model's C only when the run is long enough for compiled code to win back the compile "
        "time (estimated from the model's size and the number of output steps); a library "
        "compiled earlier in the process is reused; the stepper always compiles (cached by "
        "content, so only the first run pays); without a C compiler everything runs on the VM")

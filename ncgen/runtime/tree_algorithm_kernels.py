"""Compiled rigid-body algorithms of trees, called from Python with about 1 µs overhead: RNEA,
CRBA, ABA and the derivatives of RNEA and ABA (SX functions of
:mod:`ncgen.assembly.tree_algorithms`, one small C library each, compiled on first use and
cached on disk by content, called through :class:`~ncgen.codegen.direct.DirectFunction`).

* :func:`rnea` — ``τ(qj, vj, aj)``;  :func:`crba` — ``M(qj)``;  :func:`aba` — ``aj(qj, vj, τ)``;
* :func:`rnea_derivatives` — ``(τ, ∂τ/∂q, ∂τ/∂v, ∂τ/∂a)``;
* :func:`aba_derivatives` — ``(aj, ∂a/∂q, ∂a/∂v, ∂a/∂τ)``;
* every one takes ``out=``: an array (a tuple of arrays for the derivatives) of the outputs'
  shapes, float64 and C-contiguous, written in place and returned (no allocation); a call with
  the last call's time and parameters is one C call (:class:`Door`: 0.5–1.5 µs beside the
  kernel alone on a loaded 2-core machine, benchmarks/door_overhead.py);
* :func:`algorithm_kernel` — the compiled kernel itself (:class:`AlgorithmKernel`), for loops
  (``nc.linearize(model, qj, vj, u, space="joint")`` uses the ABA derivatives:
  :mod:`ncgen.analysis.joint_linearization`).

Kernels (``kernels=``, as the stepper's ``SimulationOptions(kernels=...)``): ``"tables"`` —
the tree library's loops over the model's data tables (:mod:`ncgen.runtime.tree_library`,
compiled once per ncgen version: no compiler call for a new robot), ``"flat"`` — the model's
own SX functions compiled per model, ``"auto"`` (default) — the tables for RNEA wherever they
cover a model without parameters (:data:`TABLES_FIRST`: one call or a batch, they cost
0.55–0.9× the flat RNEA on the Panda, xArm7, Solo12 and Talos, about as much, 0.8–1.2×, on
the UR5 and UR10), and for the ABA of trees of more than :data:`TABLES_ABA_RATES` rates
(Talos: about 0.7× the flat ABA from Python), for the other
algorithms flat wherever a C compiler is present or the flat kernel is already built in this
process with optimisation (never one compiled at -O0 for another ``$NCGEN_CFLAGS``; the tables cost 1.4–2.1× the flat ABA and 1.2–1.9× the flat CRBA:
:mod:`ncgen.runtime.tree_library`, benchmarks/tree_tables.py), else the tables when they
cover the model (:func:`~ncgen.codegen.tree_tables.tree_tables`: a uniform gravity the only
passive force).  :func:`algorithm_kernels` says which one a call uses, :func:`kernels_reason` why.

Conventions are Pinocchio's (``pinocchio.rnea``, ``crba``, ``aba``,
``computeRNEADerivatives``, ``computeABADerivatives``): joint positions ``qj`` and rates
``vj``, ``aj`` in ``model.joint_names`` order (a free joint: ``[x, y, z, qx, qy, qz, qw]`` and
``[v, ω]`` in its frame), efforts ``τ`` and every derivative per independent joint rate
(mimic followers left out), position derivatives in the tangent space, gravity and the
model's other passive forces included at inputs ``u = 0``.  Models: trees of joints with
coordinates, mimic joints allowed (:func:`~ncgen.codegen.tree_check.check_tree`), 3D.
"""
from __future__ import annotations

import ctypes
import math
import os

import numpy as np

from ncgen.codegen.compile_cache import optimised
from ncgen.codegen.compiler import compiler_present
from ncgen.codegen.fast_call import fast_caller
from ncgen.errors import CompilerNotFound, ModelError, NcgenError, ShapeError
from ncgen.model.data import cached, model_data
from ncgen.environment import key_reader
from ncgen.codegen.tree_check import (ALGORITHMS, PIVOT_TOL, check_tree, compile_tree_function, quaternion_offsets,
                                      unit_quaternions)
from ncgen.runtime.kernel_time_parameters import TimeAndParameters
from ncgen.validation import MAX_MAGNITUDE, as_numbers, as_vector, write_out

class AlgorithmKernel(TimeAndParameters):
    """``k(*args) -> outputs``: one compiled algorithm of a tree (:data:`ALGORITHMS`: ``args``
    are its inputs, ``qj`` with unit quaternions).  Time and parameters are ``model.t0``,
    ``model.p0`` until :meth:`set`.  Returns the output buffers (one array, or a tuple;
    overwritten by the next call: copy them to keep them; matrices are column-major views,
    shape ``(n, n)``).  Each argument must be ``n`` finite real numbers of magnitude at most
    :data:`~ncgen.validation.MAX_MAGNITUDE` (checked in C while copying; the
    :class:`~ncgen.errors.ShapeError` names the argument).  ABA and its derivatives raise
    :class:`ModelError` for a singular mass matrix or a non-finite result.  Not thread-safe:
    one kernel per thread (:meth:`copy`)."""

    def __init__(self, model, name: str, direct):
        self.model, self.name, self.direct = model, name, direct
        self.input_names, out_names = ALGORITHMS[name]
        self._inputs = direct.inputs[1:1 + len(self.input_names)]
        self._p = direct.inputs[-1]
        self._sizes = [b.size for b in self._inputs]
        outs = []
        for o, f_out, out_name in zip(direct.outputs, range(len(out_names)), out_names):
            shape = direct.function.size_out(f_out)
            outs.append(o if out_name in ("tau", "aj") else o.reshape(shape[::-1]).T)   # matrices even 1 x 1
        self._outputs = outs[0] if len(outs) == 1 else tuple(outs)
        self._check = None
        if direct.function.n_out() > len(out_names):
            check = direct.outputs[-1]
            self._check = (ctypes.c_double * 2).from_address(check.ctypes.data)
        self._fn, self._args = direct._fn, direct._args
        #: Whether the library was compiled with optimisation (its cache record: no -O0).
        self.optimised = optimised(direct.library)
        js = model.joint_space
        self._quaternions = js.dim == 3 and any(n in (4, 7) for n in js.nq_joint.values())
        self._fast = fast_caller(direct, len(self._inputs), first=1, result=self._outputs,
                                 check=None if self._check is None else direct.outputs[-1], tol=PIVOT_TOL,
                                 bound=MAX_MAGNITUDE)
        self.set(t=model.t0, p=model.p0)

    def door_caller(self, quaternions):
        """The fast caller returning fresh outputs or writing ``out``
        (:func:`~ncgen.codegen.fast_call.fast_caller`'s ``outputs``), the quaternions at
        ``quaternions`` in ``qj`` normalised in C; None without the extension."""
        d, names = self.direct, ALGORITHMS[self.name][1]
        outs = []
        for j, name in enumerate(names):
            rows, cols = d.function.size_out(j)
            outs.append((d.outputs[j], rows, 0 if name in ("tau", "aj") else cols))
        return fast_caller(d, len(self._inputs), first=1, check=None if self._check is None else d.outputs[-1],
                           tol=PIVOT_TOL, bound=MAX_MAGNITUDE, outputs=outs, quaternions=quaternions)

    def copy(self) -> "AlgorithmKernel":
        """The same compiled kernel with buffers (and time, parameters) of its own."""
        k = AlgorithmKernel(self.model, self.name, self.direct.copy())
        k.set(t=float(self.direct.inputs[0][0]), p=self._p)
        return k

    def __call__(self, *args):
        fast = self._fast
        if fast is not None:
            try:
                out = fast(*args)
            except (TypeError, ValueError, OverflowError):
                out = fast(*self._checked(args))
            if out is None:
                self._singular()
            return out
        for buf, x in zip(self._inputs, self._checked(args)):
            buf[...] = x
        if self._fn(*self._args):
            raise ModelError(f"{self.name}: the compiled kernel returned an error")
        check = self._check
        if check is not None and not (check[0] > PIVOT_TOL and check[1] - check[1] == 0.0):
            self._singular()
        return self._outputs

    def _checked(self, args) -> list:
        """``args`` as finite float vectors of the kernel's sizes, or the error naming the first bad one."""
        if len(args) != len(self._inputs):
            self._wrong_sizes(args)
        numbers = [as_numbers(x, f"{self.name}: {name}", "a sequence of numbers")
                   for name, x in zip(self.input_names, args)]
        if [x.size for x in numbers] != self._sizes:
            self._wrong_sizes(args)
        return [as_vector(x.reshape(-1), n, f"{self.name}: {name}")
                for name, x, n in zip(self.input_names, numbers, self._sizes)]

    def _wrong_sizes(self, args):
        raise ModelError(f"{self.name}: expected {len(self._inputs)} arguments ({', '.join(self.input_names)}) "
                         f"of {', '.join(map(str, self._sizes))} values, got {len(args)} of "
                         f"{', '.join(str(np.size(x)) for x in args)}")

    def _singular(self):
        check = self._check
        if np.isfinite(check[0]) and not check[0] > PIVOT_TOL:
            raise ModelError(f"{self.name}: the joint-space mass matrix is singular at this state "
                             f"(smallest relative Cholesky pivot {check[0]:.3g})")
        raise ModelError(f"{self.name}: the result is not finite (non-finite qj, vj or tau?)")


def algorithm_kernel(model, name: str, *, cflags=None) -> AlgorithmKernel:
    """The compiled algorithm ``name`` (a key of :data:`ALGORITHMS`) of the tree ``model``,
    built once per model and flags (``cflags``, else ``$NCGEN_CFLAGS``, else ncgen's defaults;
    the library is cached by content).  Raises :class:`ModelError` for a
    model that is not a tree (:func:`~ncgen.codegen.tree_check.check_tree`) or not 3D."""
    from ncgen.assembly import tree_algorithms

    if name not in ALGORITHMS:
        raise ModelError(f"algorithm_kernel: name: expected one of {', '.join(ALGORITHMS)}, got {name!r}")

    def build() -> AlgorithmKernel:
        check_tree(model)
        if model.joint_space.dim != 3:
            raise ModelError(f"{name}: compiled rigid-body algorithms take 3D models only")
        f = getattr(tree_algorithms, f"{name}_function")(model)
        return AlgorithmKernel(model, name, compile_tree_function(model, f, cflags, name))

    return cached(model_data(model).algorithm_kernels, (name, _flags(cflags)), build)


def _flags(cflags: str | None) -> str | None:
    """The flags a kernel asked for with ``cflags`` is compiled with: ``cflags``, else
    ``$NCGEN_CFLAGS``, else None (ncgen's defaults)."""
    return os.environ.get("NCGEN_CFLAGS") if cflags is None else cflags


def rnea_applies(model) -> list[int] | None:
    """The indices (in ``v_j``) of the independent joint rates of ``model`` when the compiled
    algorithms take it (a 3D tree, mimic joints allowed), else None (checked once per model)."""
    from ncgen.assembly.tree_dynamics import MimicMap

    data = model_data(model)
    if data.algorithm_rates is None:
        try:
            check_tree(model)
            data.algorithm_rates = (MimicMap(model).independent if model.joint_space.dim == 3 else None,)
        except ModelError:
            data.algorithm_rates = (None,)
    return data.algorithm_rates[0]


#: What each input is, for messages.
_WHAT = {"qj": "qj (joint positions, joint_names order)", "vj": "vj (joint rates, joint_names order)",
         "aj": "aj (joint accelerations, joint_names order)",
         "tau": "tau (efforts of the independent joint rates, joint_names order)"}


#: The algorithms' kernels (``kernels=``): chosen, from the tree tables, or the model's own.
KERNELS = ("auto", "tables", "flat")


#: The algorithms whose tree-table kernels ``kernels="auto"`` takes wherever they cover a model
#: without parameters: per state they measure faster than the flat ones (RNEA: 0.55–0.9× the flat
#: kernel on the Panda, xArm7, Solo12 and Talos, 0.8–1.2× on the UR5 and UR10, one call or 1000
#: states in one call, AMD EPYC at load 2–15; the flat CRBA, ABA and derivatives are the faster
#: ones: benchmarks/call_overhead.py ``--kernels``).
TABLES_FIRST = frozenset({"rnea"})

#: Trees of more independent rates than this (the tables' dense-Cholesky limit,
#: ``NCGEN_TREE_DENSE_NV``) run ``aba`` on the tables' articulated-body loops under
#: ``kernels="auto"``: the flat ABA of a large tree is long straight-line code (Talos: 25 k CasADi
#: instructions, compiled at -O1 in 9–36 s of gcc) that the caches of a shared machine do not
#: hold; from Python Talos's tables' ABA took 0.53–0.58 / 0.62–0.65 (min / median) of
#: ``pinocchio.aba``'s time against the flat kernel's 0.75–0.81 / 0.88–1.06, while on the xArm7
#: (0.78 / 0.81 against 0.80 / 0.85) and the UR10 (0.69 / 0.76 against 0.59 / 0.62) the flat ABA
#: holds (AMD EPYC, load 6–8, 9 interleaved rounds).
TABLES_ABA_RATES = 12


def _tables_first(model, name: str) -> bool:
    """Whether ``kernels="auto"`` tries the tables first for the algorithm ``name`` of ``model``
    (:data:`TABLES_FIRST`, :data:`TABLES_ABA_RATES`; models without parameters)."""
    if model.np:
        return False
    return name in TABLES_FIRST or (name == "aba" and len(rnea_applies(model) or ()) > TABLES_ABA_RATES)


def algorithm_kernels(model, name: str, kernels: str = "auto") -> str:
    """``"tables"`` or ``"flat"``: the kernels the algorithm ``name`` of ``model`` uses for the
    option ``kernels`` (module docstring; why: :func:`kernels_reason`).  ``"tables"`` on a
    model the tables do not cover raises :class:`~ncgen.codegen.tree_tables.UnsupportedTree`
    naming why."""
    return _choice(model, name, kernels)[0]


def kernels_reason(model, name: str, kernels: str = "auto") -> str:
    """Why the algorithm ``name`` of ``model`` runs on the kernels :func:`algorithm_kernels` says."""
    return _choice(model, name, kernels)[1]


def _choice(model, name: str, kernels: str) -> tuple[str, str]:
    from ncgen.codegen.tree_tables import UnsupportedTree
    from ncgen.runtime.tree_library import table_algorithm

    if kernels not in KERNELS:
        raise NcgenError(f"kernels: expected one of {', '.join(map(repr, KERNELS))} (the tree algorithms' "
                         f"kernels: from the tree tables or the model's own), got {kernels!r}")
    if kernels != "auto":
        if kernels == "tables":
            table_algorithm(model, name)
        return kernels, "chosen (kernels=)"
    if _tables_first(model, name):
        try:
            table_algorithm(model, name)
            return "tables", f"the tables' {name} measures faster than the flat kernel"
        except (UnsupportedTree, CompilerNotFound):
            pass
    built = model_data(model).algorithm_kernels.get((name, _flags(None)))
    if isinstance(built, AlgorithmKernel) and built.optimised:
        return "flat", "the flat kernel is built (faster than the tables')"
    if compiler_present():
        return "flat", "a C compiler builds the flat kernel (faster than the tables')"
    try:
        table_algorithm(model, name)
    except (UnsupportedTree, CompilerNotFound) as e:
        return "flat", f"the tables do not cover the model ({e})"
    return "tables", "no C compiler"


def kernel_of(model, name: str, kernels: str):
    """The kernel of :func:`algorithm_kernels`' choice: a :class:`AlgorithmKernel` or a
    :class:`~ncgen.runtime.tree_library.TableAlgorithm`."""
    from ncgen.runtime.tree_library import table_algorithm

    if algorithm_kernels(model, name, kernels) == "tables":
        return table_algorithm(model, name)
    return algorithm_kernel(model, name)


class Door:
    """``door(args, p, t, out)``: the algorithm of one model as ``nc.rnea`` and its siblings
    call it.  With the time and parameters of the last call (``p`` None) the arguments go
    straight to the kernel's door caller (:func:`~ncgen.codegen.fast_call.fast_caller` with
    ``outputs``), which checks their lengths, kinds and magnitudes, normalises the quaternions,
    runs the kernel, checks its pivot and returns fresh outputs or writes them into ``out``, all
    in C.  Whatever it refuses, other times or parameters, and
    rows of states take the checked path (:func:`call`, :func:`batch`), whose error names the
    argument.  ``flags``: the ``$NCGEN_CFLAGS`` it was bound under (None: ncgen's defaults).
    ``free``: the door caller itself where any time and the default parameters go to it (the
    tables' algorithms, and flat kernels whose outputs depend on neither ``t`` nor ``p``: the
    ABA of a model without time-dependent forces or parameters; else None), for callers that
    skip this object's frame (:func:`rnea`, :func:`aba`).  ``environment``: ``$NCGEN_CFLAGS``
    as the environment held it when the door was last found good (:func:`door`)."""

    __slots__ = ("model", "kernel", "fast", "tables", "flags", "free", "environment")

    def __init__(self, model, name: str, kernels: str):
        self.flags, self.environment = _flags(None), _cflags_key()
        k = self.kernel = kernel_of(model, name, kernels)
        self.model, self.tables = model, not isinstance(k, AlgorithmKernel)
        self.fast = k.door_caller(quaternion_offsets(model.joint_space))
        self.free = self.fast if self.tables or not _depends_on_time_or_parameters(k) else None

    def __call__(self, args: tuple, p, t: float, out):
        k, fast = self.kernel, self.fast
        if fast is not None and p is None and (self.tables or (t == k._t and k._default_p)):
            try:
                result = fast(*args, out)
            except (TypeError, ValueError, OverflowError, RuntimeError):
                result = False              # the checked path names what is wrong, or runs a fallback
            if result is None:
                k.singular() if self.tables else k._singular()
            if result is not False:
                return result
        return self.checked(args, p, t, out)

    def checked(self, args: tuple, p, t: float, out):
        """The call with every argument checked in Python (one state or rows of states)."""
        model, k = self.model, self.kernel
        result = batch(model, k, args, p, t, self.fast) if np.ndim(args[0]) == 2 else call(model, k, args, p, t)
        return result if out is None else write_out(out, result, k.name)


def _depends_on_time_or_parameters(k: AlgorithmKernel) -> bool:
    """Whether an output of the flat kernel ``k`` depends on its time or parameter input (CasADi's
    structural dependency: true also for a term that happens to vanish)."""
    f = k.direct.function
    return any(any(f.which_depends(f.name_in(i), f.name_out(), 1, True)) for i in (0, f.n_in() - 1))


def door(model, name: str, kernels: str = "auto") -> Door:
    """The :class:`Door` of the algorithm ``name`` of ``model`` with the kernels ``kernels``
    (:func:`algorithm_kernels`), bound once per model and found in one dictionary lookup a
    call (the model's ``data.doors``).  A door bound under ``$NCGEN_CFLAGS`` (-O0 in the test suite's
    fast tier) is looked at again once they change and bound again if they differ from its
    own (:func:`_bind`), so that its kernel is never kept for a run at ncgen's default flags."""
    try:
        d = model._data.doors.get((name, kernels))
    except AttributeError:                  # not a model: model_data names what it is
        d = model_data(model).doors.get((name, kernels))
    if d is None or (d.flags is not None and d.environment is not _cflags_key()):
        d = _bind(model, name, kernels)
    return d


#: ``$NCGEN_CFLAGS`` as the environment holds it: the same object until the variable changes
#: (:func:`ncgen.environment.key_reader`), so a door's check is one identity test.
_cflags_key = key_reader("NCGEN_CFLAGS")


def _bind(model, name: str, kernels: str) -> Door:
    """The door of :func:`door`: kept when it was bound under ncgen's default flags or under
    the present ``$NCGEN_CFLAGS``, else bound anew; marked with the environment's value."""
    doors, key = model_data(model).doors, (name, kernels)
    d = doors.get(key)
    if d is None or (d.flags is not None and d.flags != _flags(None)):
        d = doors[key] = Door(model, name, kernels)
    d.environment = _cflags_key()
    return d


def batch(model, k, args: tuple, p, t: float, fast=None):
    """The algorithm of ``k`` (an :class:`AlgorithmKernel` or a tables' algorithm) at ``n``
    states at once: each argument ``(n, size)``, outputs with a first axis of ``n`` (vectors
    ``(n, size)``, matrices ``(n, rows, columns)``), in one C loop through ``fast``, the door's
    caller (:func:`~ncgen.codegen.fast_call.fast_caller`'s ``batch``: bounds checked and
    quaternions normalised in C, row by row; the tables' RNEA does both in its own loop,
    :meth:`~ncgen.runtime.tree_library.TableAlgorithm.rows`), else checked and normalised in NumPy (a Python
    loop without the extension).  A bad row is named in the error."""
    js = model.joint_space
    sizes = {"qj": js.nq, "vj": js.nv, "aj": js.nv, "tau": k._sizes[-1]}
    if len(args) != len(k.input_names):
        k._wrong_sizes(args)
    arrays = [np.ascontiguousarray(as_numbers(x, f"{k.name}: {a}", "an array of one row per state"), dtype=float)
              for a, x in zip(k.input_names, args)]
    n = len(arrays[0])
    for a, x in zip(k.input_names, arrays):
        if x.shape != (n, sizes[a]):
            raise ShapeError(f"{k.name}: {_WHAT[a]}: expected {n} rows (the rows of qj) of {sizes[a]} values, "
                             f"got shape {x.shape}")
    tables = not isinstance(k, AlgorithmKernel)
    if tables:
        if p is not None:                   # the tables' algorithms do not depend on p: check it only
            as_vector(p, model.np, "p")
        shapes = [k._shape(o) for o in k.output_names]
    else:
        k._at(t, p)
        shapes = [np.shape(o) for o in (k._outputs if type(k._outputs) is tuple else (k._outputs,))]
    outs = [np.empty((n, math.prod(s))) for s in shapes]
    if tables and k.name == "rnea":
        if k.rows(arrays, outs[0], js) is not None:
            _name_bad_rows(js, k, arrays)
            raise NcgenError(f"{k.name}: the C check of the rows refused a row that NumPy's check accepts")
        return outs[0]
    bad = None
    try:
        if fast is None:
            return _batch_checked(js, k, arrays, outs, shapes)
        bad = fast.batch(n, outs, *arrays)
    except ValueError:                      # a value out of bound or a zero quaternion: name the first one
        _name_bad_rows(js, k, arrays)
        raise
    except RuntimeError:                    # a kernel failed, or the tables' fallback is wanted: the NumPy path
        return _batch_checked(js, k, arrays, outs, shapes)
    if bad is not None:
        try:
            k.singular() if tables else k._singular()
        except ModelError as e:
            raise ModelError(f"{e} (row {bad})") from None
    return _rows(outs, shapes)


def _rows(outs: list, shapes: list):
    """The outputs of :func:`batch` from the rows ``outs`` (matrices stored column-major)."""
    n = len(outs[0])
    result = [o if len(s) == 1 else o.reshape(n, s[1], s[0]).transpose(0, 2, 1) for o, s in zip(outs, shapes)]
    return tuple(result) if len(result) > 1 else result[0]


def _name_bad_rows(js, k, arrays: list) -> None:
    """Raise the error naming the first zero quaternion (in ``qj``) or value out of bound of
    ``arrays`` (rows of states), if any."""
    if k.input_names[0] == "qj":
        unit_quaternions(js, arrays[0])
    for a, x in zip(k.input_names, arrays):
        if not np.all(np.abs(x) <= MAX_MAGNITUDE):
            row = int(np.argmin(np.all(np.abs(x) <= MAX_MAGNITUDE, axis=1)))
            raise ShapeError(f"{k.name}: {_WHAT[a]}: row {row}: expected finite numbers of "
                             f"magnitude at most {MAX_MAGNITUDE:g}")


def _batch_checked(js, k, arrays: list, outs: list, shapes: list):
    """:func:`batch` without the extension's loop: the rows checked and normalised in NumPy,
    then the tables' own loop or the kernel row by row (into ``outs``, outputs of ``shapes``)."""
    _name_bad_rows(js, k, arrays)
    if k.input_names[0] == "qj":
        arrays = [unit_quaternions(js, arrays[0]), *arrays[1:]]
    if not isinstance(k, AlgorithmKernel):
        return k.batch(*arrays)
    for i in range(len(arrays[0])):
        try:
            out = k(*(x[i] for x in arrays))
        except ModelError as e:
            raise ModelError(f"{e} (row {i})") from None
        for o, r in zip(outs, out if type(out) is tuple else (out,)):
            o[i] = np.asarray(r).reshape(-1, order="F")
    return _rows(outs, shapes)


def call(model, k: AlgorithmKernel, args: tuple, p, t: float):
    """The outputs (copies) of the kernel ``k`` of ``model`` at one state ``args`` (in
    :data:`ALGORITHMS` order): those of :func:`buffers`, copied."""
    out = buffers(model, k, args, p, t)
    return tuple(o.copy() for o in out) if type(out) is tuple else out.copy()


def buffers(model, k: AlgorithmKernel, args: tuple, p, t: float):
    """The outputs of the kernel ``k`` of ``model`` at one state ``args`` (in
    :data:`ALGORITHMS` order) in the kernel's own buffers, overwritten by its next call
    (matrices may be column-major views): for a caller that reads them at once.  Without
    quaternion joints the arguments go straight to the kernel's caller, which checks their
    lengths, kinds and magnitudes in C (:func:`~ncgen.codegen.fast_call.fast_caller`'s
    ``bound``); the detailed message is built only when that fails (:func:`_checked`)."""
    if not isinstance(k, AlgorithmKernel):
        if p is not None:                   # the tables' algorithms do not depend on p: check it only
            as_vector(p, model.np, "p")
        fast = k._fast
        if fast is None:
            plain = k.plain(args)
            return k(*(plain if plain is not None else _checked(model, k, args)))
        if k._quaternions:
            out = fast(*_checked(model, k, args))
        else:
            try:
                out = fast(*args)
            except (TypeError, ValueError, OverflowError):
                out = fast(*_checked(model, k, args))
        if out is None:
            k.singular()
        return out
    k._at(t, p)
    fast = k._fast
    if fast is not None and not k._quaternions:
        try:
            out = fast(*args)
        except (TypeError, ValueError, OverflowError):
            out = k(*_checked(model, k, args))
        if out is None:
            k._singular()
    else:
        out = k(*_checked(model, k, args))
    return out


def _checked(model, k: AlgorithmKernel, args: tuple) -> list:
    """``args`` as finite vectors of the kernel's sizes (quaternions normalised), or the
    :class:`~ncgen.errors.ShapeError` naming the first bad one."""
    js = model.joint_space
    sizes = {"qj": js.nq, "vj": js.nv, "aj": js.nv, "tau": k._sizes[-1]}
    values = [as_vector(x, sizes[a], _WHAT[a]) for a, x in zip(k.input_names, args)]
    for a, x in zip(k.input_names, values):
        if not np.all(np.abs(x) <= MAX_MAGNITUDE):
            raise ShapeError(f"{k.name}: {_WHAT[a]}: expected finite numbers of magnitude at most {MAX_MAGNITUDE:g}")
    if k.input_names[0] == "qj":
        values[0] = unit_quaternions(js, values[0])
    return values


def rnea(model, qj, vj, aj, *, p=None, t: float = 0.0, kernels: str = "auto", out=None) -> np.ndarray:
    """``τ``: the efforts of the independent joint rates giving accelerations ``aj`` at
    ``(qj, vj)`` (module docstring; Pinocchio's ``rnea``)."""
    return through(model, "rnea", kernels, qj, vj, aj, p, t, out)


def through(model, name: str, kernels: str, x, y, z, p, t: float, out):
    """``door(model, name, kernels)((x, y, z), p, t, out)``, the door found as :func:`door`
    finds it (inline: one Python frame less) and its C caller called straight when it takes
    any time (``Door.free``) and ``p`` is None; whatever that refuses, and a singular or
    non-finite result, takes the door (whose checked path names the argument, or raises the
    kernel's :class:`ModelError`)."""
    try:
        d = model._data.doors.get((name, kernels))
    except AttributeError:                  # not a model: model_data names what it is
        d = model_data(model).doors.get((name, kernels))
    if d is None or (d.flags is not None and d.environment is not _cflags_key()):
        d = _bind(model, name, kernels)
    free = d.free
    if free is not None and p is None:
        try:
            result = free(x, y, z, out)
            if result is not None:
                return result
        except (TypeError, ValueError, OverflowError, RuntimeError):
            pass
    return d((x, y, z), p, t, out)


def crba(model, qj, *, p=None, t: float = 0.0, kernels: str = "auto", out=None) -> np.ndarray:
    """``M``: the joint-space mass matrix of the independent rates (Pinocchio's ``crba``, both triangles)."""
    d = door(model, "crba", kernels)
    free = d.free
    if free is not None and p is None:      # as through does (one argument)
        try:
            result = free(qj, out)
            if result is not None:
                return result
        except (TypeError, ValueError, OverflowError, RuntimeError):
            pass
    return d((qj,), p, t, out)


def aba(model, qj, vj, tau, *, p=None, t: float = 0.0, kernels: str = "auto", out=None) -> np.ndarray:
    """``aj``: joint accelerations under the efforts ``tau`` of the independent rates (Pinocchio's ``aba``)."""
    return through(model, "aba", kernels, qj, vj, tau, p, t, out)


def rnea_derivatives(model, qj, vj, aj, *, p=None, t: float = 0.0, kernels: str = "auto",
                     out=None) -> tuple[np.ndarray, ...]:
    """``(τ, ∂τ/∂q, ∂τ/∂v, ∂τ/∂a)`` (Pinocchio's ``computeRNEADerivatives``; ∂τ/∂a = M)."""
    return through(model, "rnea_derivatives", kernels, qj, vj, aj, p, t, out)


def aba_derivatives(model, qj, vj, tau, *, p=None, t: float = 0.0, kernels: str = "auto",
                    out=None) -> tuple[np.ndarray, ...]:
    """``(aj, ∂a/∂q, ∂a/∂v, ∂a/∂τ)`` (Pinocchio's ``computeABADerivatives``; ∂a/∂τ = M⁻¹;
    rows per independent rate)."""
    return through(model, "aba_derivatives", kernels, qj, vj, tau, p, t, out)

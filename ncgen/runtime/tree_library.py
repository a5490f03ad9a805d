"""The tree library: the joint-space algorithms of any tree over its data tables (RNEA, CRBA,
forward dynamics and their derivatives, ``templates/c/runtime/ncgen_tree_tables.h``), compiled
once per ncgen version and compiler and shared by every model — in units, each compiled at the
first run that needs it and found through an index file of the compile cache like the element
library (:func:`~ncgen.runtime.table_library.cached_library`, index
``tree-tables-<unit>-<sources key>-<compiler key>.json``): a tree of the shipped joint kinds
whose units are compiled reaches compiled RNEA/ABA with no call of the C compiler.  ``pip
install .`` compiles every unit into the package (:mod:`ncgen.runtime.installed_libraries`).

Units (:mod:`ncgen.codegen.tree_kernels`): the algorithm units ``forward`` (ABA, the joint
loop), ``inverse`` (RNEA, CRBA) and ``derivatives``, each with the rate kernels of the spherical
and free joints (the other kinds have q̇ = w), loops at :data:`UNIT_CFLAGS` (-O1, the inverse unit -O3); the kernel units
``local_<kind>``, ``edge_<kind>`` and ``body``, whose kernels :class:`TreeLibrary` sets in an
algorithm unit (``set_kernel``) for the kinds of the trees it serves.  One library of
everything took 30 s of CPU to compile (18 s of it the kernels
of every kind and their derivatives at -O2, one translation unit, 2.4 s the loops); the Panda's
joint run needs the forward unit alone (about 1.2–1.9 s of CPU at -O1, load 12–18, 1.5 s at -O2,
load 5–8; -O1 costs +7–9 % instructions per ABA against -O2 by callgrind, -Og +39 %), and without forward dynamics'
Cholesky fallback (the inverse unit's, set when a tree first needs it: :meth:`TreeLibrary.set_fallback`):
the whole forward unit's gcc 1.41 → 1.19 s of CPU (median of 5 interleaved, load 18).  ``ncgen simulate`` of a
URDF robot starts that compile in a background thread before it reads the robot (:func:`compile_ahead`), so
that gcc runs while Python reads, builds and stores the model.

:class:`TableAlgorithm` is one algorithm of :data:`~ncgen.codegen.tree_check.ALGORITHMS`
bound to one model's :class:`~ncgen.codegen.tree_tables.TreeTables`, with the interface the
callers of :class:`~ncgen.runtime.tree_algorithm_kernels.AlgorithmKernel` use (``k(*args)``,
:meth:`TableAlgorithm.batch`).  Time and parameters do not enter: the tables cover only
trees whose passive force is a uniform gravity.  :class:`TableJointLoop` is the joint-space
simulation loop (``ncgen_joint_loop.h`` in the library) on the same tables.

Speed against the flat per-robot kernel (whose numbers are folded into the code), tables / flat.
Instructions per state (callgrind, batches of 200 states in one C call, robust to the load):
RNEA 8 755 / 6 825 (Panda), 5 995 / 4 132 (UR5), 5 995 / 4 023 (UR10), 36 701 / 32 581 (Talos);
ABA 23 155 / 8 935, 12 669 / 5 090, 12 673 / 5 070, 81 948 / 53 856; CRBA 13 742 / 5 436,
7 885 / 2 976, 7 885 / 2 933, 71 447 / 29 477.  CPU time per state (benchmarks/tree_tables.py,
batches of 500, best of 7 interleaved rounds, AMD EPYC, 2 shared cores at load 17–18: the
spread is the machine's): RNEA 0.97 (Panda), 1.17 (UR5); ABA 1.44, 1.71; CRBA 1.35, 1.77; in a
C harness (best of 60 rounds, same load) RNEA 0.85, 1.17–1.44 (UR5), 1.17 (UR10), 0.72 (Talos);
ABA 2.05, 1.82, 1.91, 0.96; CRBA 1.73, 1.68, 1.87, 1.18.  The flat kernels fold the
placements' 0/±1 and the inertias' zeros; the tables pay dense spatial products in the ground
frame (CRBA, ABA: each body's pose and inertia turned into the ground's axes, 6 × 6
articulated inertias).  CRBA and ABA run in the ground's axes (``ncgen_tree_tables.h``); in
local frames they were 2.9–3.5× (ABA) and 2.7–4.5× (CRBA).
A single call goes through the fast caller as the flat kernels' do.  The tables are the default for their
first-call cost (no compile) where no compiler is present, the flat kernel otherwise (the
Panda's, UR5's and UR10's ABA and CRBA miss 1.2× the flat kernels).
"""
from __future__ import annotations

import ctypes
import hashlib
import os
import platform
import sys
import threading
from functools import lru_cache, partial
from pathlib import Path

import casadi as ca
import numpy as np

from ncgen.codegen import c_binding
from ncgen.codegen.compile_cache import BUILD_SCHEME
from ncgen.codegen.joint_loop import INTERRUPTED, JointOptions
from ncgen.codegen.render import shipped_templates_dir
from ncgen.codegen.tree_kernels import (ALGORITHM_UNITS, JOINT_KINDS, PACKAGE, SOURCES, kernel_units, kind_names,
                                        units_of, write_tree_unit)
from ncgen.codegen.tree_tables import TreeTables
from ncgen.environment import getenv
from ncgen.errors import CodegenError, ModelError
from ncgen.interrupts import call_interruptibly
from ncgen.runtime.table_library import cached_library, compiler_path, library_ready
from ncgen.codegen.tree_check import ALGORITHMS, PIVOT_TOL, quaternion_offsets
from ncgen.validation import MAX_MAGNITUDE
from ncgen.version import __version__

INDEX_PREFIX = "tree-tables"
#: Positions of each joint kind, in table order.
JOINT_KINDS_NQ = tuple(k.nq for k in JOINT_KINDS)
#: Fields of ``ncgen_tree``, in order.
TREE_FIELDS = (("int", "nb"), ("int", "nq"), ("int", "nv"), ("int", "ni"),
               *(("const int *", f) for f in ("parent", "kind", "q_at", "v_at", "num_ptr")),
               *(("const double *", f) for f in ("num", "body", "gravity")),
               *(("const int *", f) for f in ("rate_src", "rate_col")), ("const double *", "rate_coef"),
               ("const int *", "q_src"), *(("const double *", f) for f in ("q_coef", "q_off", "xin", "inertia")))
_T, _D = "const ncgen_tree *", "const double *"
#: The library's entry points (``PACKAGE`` prefix) as tree_tables.c.j2 spells them.
SIGNATURES = {
    "kind_names": c_binding.Signature("const char *", ()),
    "set_kernel": c_binding.Signature("int", (("int", "kind"), ("int", "slot"), ("ncgen_tree_kernel", "f"))),
    "set_fallback": c_binding.Signature("int", (("ncgen_tree_fallback_fn", "f"),)),
    "work_size": c_binding.Signature("long", ((_T, "T"),)),
    "check": c_binding.Signature("int", ((_T, "T"),)),
    "rnea": c_binding.Signature("int", ((_T, "T"), ("int", "n"), (_D, "q"), (_D, "v"), (_D, "a"),
                                        ("double *", "tau"), ("double *", "w"))),
    "crba": c_binding.Signature("int", ((_T, "T"), ("int", "n"), (_D, "q"), ("double *", "M"), ("double *", "w"))),
    "rnea_rows": c_binding.Signature("int", ((_T, "T"), ("int", "n"), (_D, "q"), (_D, "v"), (_D, "a"),
                                             ("double *", "tau"), ("double *", "w"), ("double", "bound"),
                                             ("int", "nquat"), ("const int *", "quat"), ("double *", "qn"),
                                             ("int *", "bad"))),
    "aba": c_binding.Signature("int", ((_T, "T"), ("int", "n"), (_D, "q"), (_D, "v"), (_D, "tau"),
                                       ("double *", "a"), ("double *", "check"), ("double *", "w"))),
    "rnea_derivatives": c_binding.Signature("int", ((_T, "T"), ("int", "n"), (_D, "q"), (_D, "v"), (_D, "a"),
                                                    *(("double *", x) for x in ("tau", "dq", "dv", "M", "w")))),
    "aba_derivatives": c_binding.Signature("int", ((_T, "T"), ("int", "n"), (_D, "q"), (_D, "v"), (_D, "tau"),
                                                   *(("double *", x) for x in ("a", "dq", "dv", "Minv", "check",
                                                                               "w")))),
    "start_state": c_binding.Signature("int", (("const ncgen_tree_start *", "S"),)),
    "joint_run": c_binding.Signature("int", (
        (_T, "T"), (_D, "E"), ("int", "nu"), ("const ncgen_joint_options *", "options"), ("int", "n_out"),
        (_D, "t_out"), ("double *", "X"), (_D, "W"), (_D, "S"), ("int", "nquat"), ("const int *", "quat"),
        ("double *", "stats"), ("int *", "k_done"), ("double *", "work"))),
}


class _Tree(ctypes.Structure):
    _fields_ = [(name, ctypes.c_void_p if "*" in t else ctypes.c_int) for t, name in TREE_FIELDS]


def sources_key() -> str:
    """sha256 of what the library is made of: ncgen's and CasADi's versions, its templates,
    the kernel generator and the formulas it reads.  The files are read again only when one of
    them changed on disk (size or modification time): a run's kernel choice asks for the key on
    every call."""
    import ncgen.assembly.joint_space as js
    import ncgen.assembly.joint_tree as jt
    import ncgen.assembly.tree_dynamics as td
    import ncgen.codegen.tree_kernels as tk
    import ncgen.rigid_motion.casadi_forms as crm

    files = _source_files(shipped_templates_dir(), (tk, js, jt, td, crm))
    return _hash_of(tuple((f, *_stamp(os.stat(f))) for f in files))


@lru_cache(maxsize=4)
def _source_files(templates: Path, modules: tuple) -> tuple[str, ...]:
    """The paths :func:`sources_key` hashes: the library's templates under ``templates`` and the
    files of ``modules``."""
    return tuple(str(templates / rel) for rel in SOURCES) + tuple(m.__file__ for m in modules)


def _stamp(st: os.stat_result) -> tuple[int, int]:
    """A file's size (bytes) and modification time (ns): what tells an edited source."""
    return st.st_size, st.st_mtime_ns


@lru_cache(maxsize=4)
def _hash_of(stamped: tuple[tuple[str, int, int], ...]) -> str:
    """:func:`sources_key` of files given with their sizes and modification times (the cache key)."""
    h = hashlib.sha256(f"{__version__}\n{ca.__version__}\n{BUILD_SCHEME}\n{sys.platform}\n"
                       f"{platform.machine()}\n".encode())
    for f, _, _ in stamped:
        h.update(Path(f).name.encode() + b"\0" + Path(f).read_bytes() + b"\0")
    return h.hexdigest()


#: The algorithm unit of each entry point.
UNIT_OF = {fn: unit for unit, fns in ALGORITHM_UNITS.items() for fn in fns}
#: What the forward unit's ``aba`` (and ``aba_one``) and ``joint_run`` return while forward dynamics of a tree
#: with mimic joints needs the Cholesky fallback (M or C Y not positive definite) and it is not set
#: (``templates/c/tree_tables.c.j2``): the caller sets it (:meth:`TreeLibrary.set_fallback`) and calls again.
NO_FALLBACK, RUN_NO_FALLBACK = 4, 6
#: What ``rnea_rows`` returns for a row out of bound or with a zero quaternion (``templates/c/tree_tables.c.j2``).
ROW = 5
#: Flags of the algorithm units' loops (``-O1``: …; the inverse unit's RNEA and CRBA at ``-O3``: the
#: batched and single-state RNEA run 20–25 % faster than at -O1 — Talos 4.9 → 3.8 µs, UR10 0.79 → 0.56
#: µs a state, a C harness, 5 interleaved rounds, AMD EPYC at load 16 — for 0.7 s more of gcc, once;
#: the forward unit stays at ``-O1``: at -O2 its ABA takes 7 % fewer instructions a state (callgrind,
#: benchmarks/tree_tables_callgrind.py: xArm7 12.8 k → 11.9 k, Talos 73.1 k → 68.2 k) but its gcc
#: takes 2.0–2.2 s of CPU against 1.2–1.4 s (quiet machine), paid by the first ``ncgen simulate`` of
#: a robot from a checkout (issue 34's ≤ 3 s), and the ABA's door is within Pinocchio's time at -O1;
#: bit-identical results: no flag reorders floating-point arithmetic); the kernel units take the
#: compile cache's defaults.
UNIT_CFLAGS = {"forward": "-O1", "inverse": "-O3", "derivatives": "-O1"}


def index_prefix(unit: str) -> str:
    return f"{INDEX_PREFIX}-{unit}"


def unit_ready(unit: str) -> bool:
    """Whether the unit ``unit`` of the tree library is compiled (installed, or in the compile cache)."""
    return library_ready(index_prefix(unit), sources_key(), unit_cflags(unit))


def missing_units(kinds, unit: str = "forward") -> list[str]:
    """The units the algorithm unit ``unit`` needs for the joint kinds ``kinds`` (names,
    :func:`~ncgen.codegen.tree_kernels.units_of`) that are not compiled yet, or were not
    when this process started compiling them ahead (:func:`compile_ahead`: a run's choice does
    not depend on how far that compile got, until the unit is first used)."""
    key = sources_key()
    return [u for u in units_of(unit, kinds)
            if (u, None) in _AHEAD or not library_ready(index_prefix(u), key, unit_cflags(u))]


def tree_library_ready() -> bool:
    """Whether every unit of the tree library is compiled (in the compile cache)."""
    return not [u for u in (*ALGORITHM_UNITS, *kernel_units()) if not unit_ready(u)]


#: The units this process started compiling ahead of their first use (:func:`compile_ahead`):
#: ``(unit, cflags) -> the thread compiling it``.
_AHEAD: dict[tuple[str, str | None], threading.Thread] = {}


def compile_ahead(units) -> list[str]:
    """Start compiling those of the units ``units`` (default flags) that are not compiled yet,
    in a background thread, so that gcc runs while the caller goes on (reading and building a
    model); the unit's first use waits for that compile (:func:`unit_library`), and a compile
    that failed there is done again, and fails, at that use.  Returns the units started
    (none without a compiler).  The process waits for the thread before it exits."""
    if compiler_path() is None:
        return []
    key = sources_key()
    started = [u for u in units if (u, None) not in _AHEAD and not library_ready(index_prefix(u), key, unit_cflags(u))]
    if started:
        thread = threading.Thread(target=_compile_units, args=(started,), name="ncgen-compile-ahead")
        _AHEAD.update({(u, None): thread for u in started})
        thread.start()
    return started


def _compile_units(units) -> None:
    for unit in units:
        try:
            unit_library(unit)
        except Exception:       # noqa: BLE001 — compiled again at the unit's use, which raises it
            return


def unit_library(unit: str, cflags: str | None = None) -> tuple[Path, bool]:
    """``(path of the unit's library, whether it was compiled now)``: compiled at first use
    (algorithm units with :data:`UNIT_CFLAGS` unless ``cflags`` or ``$NCGEN_CFLAGS`` is given),
    after the compile started ahead of it (:func:`compile_ahead`) has ended."""
    ahead = _AHEAD.get((unit, cflags))
    if ahead is not None and ahead is not threading.current_thread():
        ahead.join()
        del _AHEAD[(unit, cflags)]          # used: ready from now on, as after a compile of its own
    return cached_library(index_prefix(unit), sources_key(), partial(write_tree_unit, unit), f"{PACKAGE}_{unit}",
                          unit_cflags(unit, cflags))


def unit_cflags(unit: str, cflags: str | None = None) -> str | None:
    """``cflags``, else the unit's :data:`UNIT_CFLAGS` for an algorithm unit when ``$NCGEN_CFLAGS`` is not set."""
    if cflags is None and unit in ALGORITHM_UNITS and "NCGEN_CFLAGS" not in os.environ:
        return UNIT_CFLAGS[unit]
    return cflags


def build_tree_library(cflags: str | None = None) -> dict[str, Path]:
    """Every unit of the tree library, compiled now where not in the cache (e.g. ahead of
    a machine's first runs): ``{unit: path}``."""
    return {u: unit_library(u, cflags)[0] for u in (*ALGORITHM_UNITS, *kernel_units())}


class AlgorithmUnit:
    """One loaded algorithm unit: its entry points bound (:data:`SIGNATURES`), the kernels
    of the kernel units set in it as trees need them."""

    def __init__(self, unit: str, path: Path):
        self.unit, self.path, self.prefix = unit, path, f"{PACKAGE}_{unit}"
        self._lib = c_binding.open_library(path)
        names = {"kind_names", "set_kernel", "work_size", "check", *ALGORITHM_UNITS[unit],
                 *(("set_fallback",) if unit == "forward" else ())}
        structs = {"ncgen_tree": _Tree, "ncgen_tree_kernel": ctypes.c_void_p, "ncgen_tree_fallback_fn": ctypes.c_void_p}
        self.fn = {k: c_binding.bind(self._lib, f"{self.prefix}_{k}", s, structs=structs, addresses=True)
                   for k, s in SIGNATURES.items() if k in names}
        kinds = self.fn["kind_names"]().decode()
        if kinds != kind_names():
            raise CodegenError(f"{path}: tree library of other joint kinds ({kinds!r}, expected "
                               f"{kind_names()!r}); delete it to have it rebuilt")
        self._set = self.fn["set_kernel"]
        self.kernel_units: set[str] = set()

    def set_kernels(self, unit: str, lib: ctypes.CDLL) -> None:
        """Set the kernels of the kernel unit ``unit`` (loaded as ``lib``) in this unit: slots
        0, 1 (``tk_<k>``, ``tk_<k>_fwd``; the body's ``tk_body``, ``tk_body_fwd``: kind −1)
        and 3 (``tl_<k>``) of ``set_kernel`` (templates/c/tree_tables.c.j2)."""
        what, _, kind = unit.partition("_")
        if unit == "body":
            slots, at = {0: "tk_body", 1: "tk_body_fwd"}, -1
        else:
            slots = {3: f"tl_{kind}"} if what == "local" else {0: f"tk_{kind}", 1: f"tk_{kind}_fwd"}
            at = [k.name for k in JOINT_KINDS].index(kind)
        for slot, name in slots.items():
            address = ctypes.cast(lib[f"{PACKAGE}_{unit}_{name}"], ctypes.c_void_p).value
            if self._set(at, slot, address):
                raise CodegenError(f"{self.path}: could not set the kernel {name} (kind {at}, slot {slot})")
        self.kernel_units.add(unit)


class TreeLibrary:
    """The tree library: its units (:data:`~ncgen.codegen.tree_kernels.ALGORITHM_UNITS` and the
    kernel units), each compiled once per ncgen version at first need and loaded once per process.
    The forward unit's Cholesky fallback (forward dynamics with mimic joints where M or C Y is not
    positive definite) is the inverse unit's ``factored_aba``, set in it only when a tree first
    needs it (:meth:`set_fallback`): a first run of a robot compiles the forward unit alone."""

    def __init__(self, cflags: str | None = None):
        self.cflags = cflags
        self._units: dict[str, AlgorithmUnit] = {}
        self._kernels: dict[str, ctypes.CDLL] = {}
        self._lock = threading.Lock()
        self.fallback = False

    def unit(self, unit: str, kinds) -> AlgorithmUnit:
        """The algorithm unit ``unit`` with the kernels of the joint kinds ``kinds`` (names) set
        (each unit compiled here if not in the cache)."""
        with self._lock:
            alg = self._unit(unit, kinds)
            if unit == "forward" and self.fallback:      # the fallback serves the forward unit's kinds
                self._unit("inverse", kinds)
            return alg

    def _unit(self, unit: str, kinds) -> AlgorithmUnit:
        alg = self._units.get(unit)
        if alg is None:
            alg = self._units[unit] = AlgorithmUnit(unit, unit_library(unit, self.cflags)[0])
        for need in units_of(unit, kinds)[1:]:
            if need in alg.kernel_units:
                continue
            lib = self._kernels.get(need)
            if lib is None:
                lib = self._kernels[need] = c_binding.open_library(unit_library(need, self.cflags)[0])
            alg.set_kernels(need, lib)
        return alg

    def set_fallback(self) -> bool:
        """Set the inverse unit's ``factored_aba`` (compiled now if not in the cache, with the
        kernels of every kind the forward unit serves) as the forward unit's fallback; False
        when it was set already."""
        with self._lock:
            if self.fallback:
                return False
            forward = self._units["forward"]
            kinds = [u.partition("_")[2] for u in forward.kernel_units if u.startswith("local_")]
            inverse = self._unit("inverse", kinds)
            address = ctypes.cast(inverse._lib[f"{inverse.prefix}_factored_aba"], ctypes.c_void_p).value
            forward.fn["set_fallback"](address)
            self.fallback = True
            return True


#: The loaded tree libraries of this process by :func:`library_key`.
_LOADED: dict[tuple[str | None, str | None], TreeLibrary] = {}


def library_key(cflags: str | None = None) -> tuple[str | None, str | None]:
    """``(cflags, $NCGEN_CFLAGS)``: what the units a :class:`TreeLibrary` loads are compiled with
    (:func:`unit_cflags`), so that a unit built under other flags is never reused."""
    return cflags, getenv("NCGEN_CFLAGS")


def load_tree_library(cflags: str | None = None) -> TreeLibrary:
    """The tree library of this process for ``cflags`` and the environment's ``$NCGEN_CFLAGS``
    (its units compiled and loaded as trees need them)."""
    key = library_key(cflags)
    if key not in _LOADED:
        _LOADED[key] = TreeLibrary(cflags)
    return _LOADED[key]


class BoundTree:
    """One model's :class:`TreeTables` as the library's ``ncgen_tree`` with a work array; the
    algorithm units it is used with are checked against it once (:meth:`unit`)."""

    def __init__(self, tables: TreeTables, library: TreeLibrary | None = None):
        self.tables, self.library = tables, library or load_tree_library()
        self._arrays = {f: np.ascontiguousarray(tables.arrays[f], dtype=np.int32 if "int" in t else np.float64)
                        for t, f in TREE_FIELDS if "*" in t}
        self._struct = _Tree(nb=tables.nb, nq=tables.nq, nv=tables.nv, ni=tables.ni,
                             **{k: v.ctypes.data for k, v in self._arrays.items()})
        self.ref = ctypes.addressof(self._struct)
        self.kinds = sorted({JOINT_KINDS[int(k)].name for k in self._arrays["kind"] if 0 <= k < len(JOINT_KINDS)})
        self.work: np.ndarray | None = None
        self._checked: dict[str, AlgorithmUnit] = {}
        self._lock = threading.Lock()

    def unit(self, unit: str) -> AlgorithmUnit:
        """The algorithm unit ``unit`` for these tables (compiled if needed; checked once).  The
        work array is sized by the first unit: every unit lays out the same work."""
        alg = self._checked.get(unit)
        if alg is not None:
            return alg
        with self._lock:            # the work array is made once: fast callers keep its address
            alg = self._checked.get(unit)
            if alg is not None:
                return alg
            alg = self.library.unit(unit, self.kinds)
            status = alg.fn["check"](self.ref)
            if status:
                raise CodegenError(f"model {self.tables.name!r}: its tree tables are inconsistent (ncgen_tree_check, "
                                   f"status {status})")
            size = max(1, int(alg.fn["work_size"](self.ref)))
            if self.work is None:
                self.work = np.zeros(size)
            elif size > len(self.work):
                raise CodegenError(f"{alg.path}: the {unit} unit needs {size} doubles of work, the tables' work "
                                   f"has {len(self.work)}; delete the tree library's units to have them rebuilt")
            self._checked[unit] = alg
            return alg


class _Direct:
    """What :func:`~ncgen.codegen.fast_call.fast_caller` reads of a kernel: its input buffers,
    entry point and argument addresses (``keep``: what the addresses point into)."""

    def __init__(self, inputs, fn, args, keep):
        self.inputs, self._fn, self._args, self.keep = inputs, fn, args, keep


class TableAlgorithm:
    """``k(*args) -> outputs``: the algorithm ``name`` (a key of
    :data:`~ncgen.codegen.tree_check.ALGORITHMS`) of one tree from its tables; the
    arguments as :class:`~ncgen.runtime.tree_algorithm_kernels.AlgorithmKernel` takes them (``qj``
    with unit quaternions), checked by the caller.  Outputs are fresh arrays (matrices
    ``(ni, ni)``).  Raises :class:`ModelError` for a singular mass matrix or a non-finite
    result.  Not thread-safe (one work array)."""

    kernels = "tables"

    def __init__(self, tree: BoundTree, name: str):
        self.tree, self.name = tree, name
        self.input_names, self.output_names = ALGORITHMS[name]
        T = tree.tables
        self._in_sizes = {"qj": T.nq, "vj": T.nv, "aj": T.nv, "tau": T.ni}
        self._sizes = [self._in_sizes[a] for a in self.input_names]
        self._out_sizes = {"tau": (T.ni,), "aj": (T.nv,), "M": (T.ni, T.ni)}
        self.unit = tree.unit(UNIT_OF[name])
        self._fn = self.unit.fn[name]
        self._single = self._rows = None
        self._quaternions = bool(np.any(np.isin(np.asarray(JOINT_KINDS_NQ)[T.arrays["kind"]], (4, 7))))
        self._fast = self._fast_caller()

    def _fast_caller(self):
        """The library's ``<name>_one`` through :func:`~ncgen.codegen.fast_call.fast_caller`
        (inputs checked in C against :data:`~ncgen.validation.MAX_MAGNITUDE`; returns the
        output buffers, matrices as ``(ni, ni)`` views of column-major storage, or None when
        the pivot check fails), or None without the extension."""
        from ncgen.codegen.fast_call import fast_caller

        one = getattr(self.unit._lib, f"{self.unit.prefix}_{self.name}_one", None)
        if one is None:
            return None
        ins = [np.zeros(n) for n in self._sizes]
        outs = [np.zeros(int(np.prod(self._shape(o)))) for o in self.output_names]
        check = self._fast_check = np.zeros(2) if self.name.startswith("aba") else None
        arg = (ctypes.c_void_p * (1 + len(ins)))(self.tree.ref, *(x.ctypes.data for x in ins))
        res = (ctypes.c_void_p * (len(outs) + 1))(*(o.ctypes.data for o in outs),
                                                   None if check is None else check.ctypes.data)
        shim = self._shim = _Direct([None, *ins], one, (ctypes.addressof(arg), ctypes.addressof(res), 0,
                                                        self.tree.work.ctypes.data, 0), (arg, res, outs, self.tree))
        self._out_buffers = outs
        views = [o if len(self._shape(n)) == 1 else o.reshape(self._shape(n)).T for o, n in zip(outs, self.output_names)]
        return fast_caller(shim, len(ins), first=1, check=check, tol=PIVOT_TOL, bound=MAX_MAGNITUDE,
                           result=views[0] if len(views) == 1 else tuple(views))

    def door_caller(self, quaternions):
        """The fast caller returning fresh outputs or writing ``out``
        (:func:`~ncgen.codegen.fast_call.fast_caller`'s ``outputs``), the quaternions at
        ``quaternions`` in ``qj`` normalised in C; None without the extension."""
        from ncgen.codegen.fast_call import fast_caller

        if self._fast is None:
            return None
        shapes = [self._shape(n) for n in self.output_names]
        return fast_caller(self._shim, len(self._sizes), first=1, check=self._fast_check, tol=PIVOT_TOL,
                           bound=MAX_MAGNITUDE, quaternions=quaternions,
                           outputs=[(o, s[0], s[1] if len(s) == 2 else 0) for o, s in zip(self._out_buffers, shapes)])

    def singular(self):
        """Raise the :class:`ModelError` of the failed check of the last fast call."""
        self._checked(self._fast_check[None, :], 1)
        raise ModelError(f"{self.name}: the check of the result failed")

    def plain(self, args) -> tuple | None:
        """``args`` when each is already a C-contiguous float64 vector of its size with finite
        entries of magnitude at most :data:`~ncgen.validation.MAX_MAGNITUDE` and the model has no
        quaternions to normalise, else None (the caller checks and converts them)."""
        if self._quaternions or len(args) != len(self._sizes):
            return None
        for x, n in zip(args, self._sizes):
            if type(x) is not np.ndarray or x.dtype != np.float64 or x.shape != (n,) or \
                    not x.flags.c_contiguous or not np.abs(x).max(initial=0.0) <= MAX_MAGNITUDE:
                return None
        return args

    def _shape(self, out: str) -> tuple:
        return self._out_sizes.get(out, (self.tree.tables.ni, self.tree.tables.ni))

    def __call__(self, *args):
        """The algorithm at one state (each argument a float vector of its size), through
        buffers and addresses kept between calls (the fast caller's when it is built)."""
        fast = self._fast
        if fast is not None:
            try:
                out = fast(*args)
            except RuntimeError:                    # a kernel failed, or the fallback is wanted
                if not (self.name == "aba" and self.tree.library.set_fallback()):
                    raise
                out = fast(*args)
            if out is None:
                self.singular()
            return tuple(o.copy() for o in out) if type(out) is tuple else out.copy()
        if self._single is None:
            self._in = [np.empty(n) for n in self._sizes]
            self._single = [np.empty((1, *self._shape(o))) for o in self.output_names]
            self._check = np.empty(2) if self.name.startswith("aba") else None
            tail = [o.ctypes.data for o in self._single] + ([] if self._check is None else [self._check.ctypes.data])
            self._addresses = (self.tree.ref, 1, *(x.ctypes.data for x in self._in), *tail,
                               self.tree.work.ctypes.data)
        for buf, x in zip(self._in, args):
            buf[...] = x
        status = self._fn(*self._addresses)
        if status == NO_FALLBACK:
            self.tree.library.set_fallback()
            status = self._fn(*self._addresses)
        if status:
            raise ModelError(f"{self.name}: a kernel of the tree library failed")
        if self._check is not None:
            self._checked(self._check[None, :], 1)
        single = self._single
        if len(single) == 1:
            o = single[0]
            return o[0].copy() if o.ndim == 2 else o[0].T.copy()
        return tuple(o[0].copy() if o.ndim == 2 else o[0].T.copy() for o in single)

    def _checked(self, check: np.ndarray, n: int) -> None:
        ok = (check[:, 0] > PIVOT_TOL) & np.isfinite(check[:, 1])
        if not ok.all():
            row = int(np.argmin(ok))
            where = f" (row {row})" if n > 1 else ""
            if np.isfinite(check[row, 0]) and not check[row, 0] > PIVOT_TOL:
                raise ModelError(f"{self.name}: the joint-space mass matrix is singular at this state "
                                 f"(smallest relative Cholesky pivot {check[row, 0]:.3g}){where}")
            raise ModelError(f"{self.name}: the result is not finite (non-finite qj, vj or tau?){where}")

    def rows(self, arrays: list, out: np.ndarray, js) -> tuple[int, int] | None:
        """RNEA at the ``n`` states of ``arrays`` (``qj``, ``vj``, ``aj``: C-contiguous float64, one
        row per state) into ``out`` (``(n, ni)``) through the library's ``rnea_rows``: each row
        checked against :data:`~ncgen.validation.MAX_MAGNITUDE` and its quaternions (those of
        the joint space ``js``, :func:`~ncgen.codegen.tree_check.quaternion_offsets`)
        normalised in the algorithm's own loop.  Returns None, or
        ``(row, what)`` for the first bad row (``what``: 0, 1, 2 a value of ``qj``, ``vj``,
        ``aj``; 3 a zero quaternion), the caller naming it."""
        if self._rows is None:
            T = self.tree.tables
            self._rows = (self.unit.fn["rnea_rows"], np.array(quaternion_offsets(js), dtype=np.int32), np.empty(T.nq),
                          np.zeros(2, dtype=np.int32))
        fn, quat, qn, bad = self._rows
        q, v, a = arrays
        status = fn(self.tree.ref, len(q), q.ctypes.data, v.ctypes.data, a.ctypes.data, out.ctypes.data,
                    self.tree.work.ctypes.data, MAX_MAGNITUDE, len(quat), quat.ctypes.data, qn.ctypes.data,
                    bad.ctypes.data)
        if status == ROW:
            return int(bad[0]), int(bad[1])
        if status:
            raise ModelError(f"{self.name}: a kernel of the tree library failed")
        return None

    def batch(self, *args):
        """The algorithm at ``n`` states: each argument ``(n, size)`` (C-contiguous floats);
        outputs with a first axis of ``n``."""
        n = len(args[0])
        arrays = [np.ascontiguousarray(x, dtype=float) for x in args]
        outs = [np.empty((n, *self._shape(o))) for o in self.output_names]
        check = np.empty((n, 2)) if self.name.startswith("aba") else None
        ptrs = [a.ctypes.data for a in arrays] + [o.ctypes.data for o in outs]
        if check is not None:
            ptrs.append(check.ctypes.data)
        status = self._fn(self.tree.ref, n, *ptrs, self.tree.work.ctypes.data)
        if status == NO_FALLBACK:
            self.tree.library.set_fallback()
            status = self._fn(self.tree.ref, n, *ptrs, self.tree.work.ctypes.data)
        if status:
            raise ModelError(f"{self.name}: a kernel of the tree library failed")
        if check is not None:
            self._checked(check, n)
        # matrices come column-major: transpose each (n, ni, ni) block
        outs = [o if o.ndim == 2 else o.transpose(0, 2, 1) for o in outs]
        return tuple(outs) if len(outs) > 1 else outs[0]


def table_algorithm(model, name: str) -> TableAlgorithm:
    """The algorithm ``name`` of ``model`` from its tree tables, bound once per model (raises
    :class:`~ncgen.codegen.tree_tables.UnsupportedTree`, or
    :class:`~ncgen.errors.CompilerNotFound` with no compiler and no library in the cache)."""
    from ncgen.model.data import model_data

    data, key = model_data(model), (name, library_key())
    k = data.table_algorithms.get(key)
    if k is None:
        k = data.table_algorithms[key] = TableAlgorithm(bound_tree(model), name)
    return k


def bound_tree(model) -> BoundTree:
    """``model``'s tree tables bound once per model and :func:`library_key` (raises
    :class:`~ncgen.codegen.tree_tables.UnsupportedTree`)."""
    from ncgen.codegen.tree_tables import tree_tables
    from ncgen.model.data import model_data

    data, key = model_data(model), (None, library_key())
    tree = data.table_algorithms.get(key)
    if tree is None:
        tree = data.table_algorithms[key] = BoundTree(tree_tables(model))
    return tree


def input_efforts(model) -> np.ndarray:
    """``E`` (ni × nu): the efforts of the independent rates from the inputs, ``τ_i = E u``
    (:func:`~ncgen.assembly.tree_algorithms.efforts_function`); raises
    :class:`~ncgen.codegen.tree_tables.UnsupportedTree` when they are not a constant linear map."""
    from ncgen.assembly.tree_algorithms import efforts_function
    from ncgen.codegen.tree_tables import UnsupportedTree

    f = efforts_function(model)
    ins = f.sx_in()
    tau, E = f(*ins)
    if ca.depends_on(ca.vertcat(ca.vec(E), ca.substitute(tau, ins[2], ca.DM.zeros(model.nu))),
                     ca.vertcat(*[ca.vec(x) for x in ins])) or np.any(np.array(ca.evalf(ca.substitute(
                         tau, ins[2], ca.DM.zeros(model.nu))))):
        raise UnsupportedTree(model.name, ["joint efforts that are not a constant linear map of the inputs"])
    ni = tau.numel()
    return np.asfortranarray(np.array(ca.evalf(ca.densify(E)), float).reshape(ni, model.nu))


class TableJointLoop:
    """The joint-space loop of :mod:`ncgen.runtime.joint_simulation` (the interface of its
    ``JointLoop``: ``run``, ``mapped``) on the tree library: ``ẋ = [q̇_j; a_j(q_j, v_j, E w)]``
    with no controller and no joint dynamics, nothing compiled for the model."""

    kernels = "tables"

    def __init__(self, model):
        from ncgen.assembly.joint_ode import quaternion_offsets
        from ncgen.codegen.tree_check import tree_function

        self.model = model
        self.tree_bound = bound_tree(model)         # no fast caller: the loop runs in C
        self._fn = self.tree_bound.unit("forward").fn["joint_run"]
        self.E = input_efforts(model)
        self.quat = np.array(quaternion_offsets(model.joint_space), dtype=np.int32)
        ptr = (lambda a: None if a.size == 0 else a.ctypes.data)
        self._constants = (ptr(self.E), model.nu, ptr(self.quat))        # addresses taken once (µs each)
        self.tree = tree_function(model)
        self._maps: dict = {}
        #: The calling thread's work array and its address (the library's ``work_size`` doubles).
        self.work = c_binding.ThreadWork(self.tree_bound.work.size)

    def mapped(self, what: str, n: int):
        """``what`` (``"tree"``, ``"accel"``: CasADi functions mapped over ``n`` points;
        ``"ode"``: the applied inputs, which are the samples ``w`` themselves)."""
        if what == "ode":
            return lambda t, X, W, P: (None, None, W)
        key = (what, n)
        if key not in self._maps:
            self._maps[key] = {"tree": self.tree, "accel": self.model.functions["accel"]}[what].map(n)
        return self._maps[key]

    def run(self, options: JointOptions, t: np.ndarray, X: np.ndarray, W: np.ndarray, S, p: np.ndarray,
            stats: np.ndarray) -> tuple[int, int]:
        """As ``JointLoop.run`` (``p`` does not enter: the tables' dynamics take none)."""
        done = ctypes.c_int(0)
        start = (X[0].copy(), stats.copy())           # X's other rows are outputs
        E, nu, quat = self._constants
        address = c_binding.address
        args = (self._fn, self.tree_bound.ref, E, nu, ctypes.addressof(options), len(t) - 1, address(t), address(X),
                address(W), None if S is None else address(S), len(self.quat), quat, address(stats),
                ctypes.addressof(done), self.work.address)
        status, interrupted = call_interruptibly(*args, stop=options.stop.contents)
        if not interrupted and status == RUN_NO_FALLBACK:
            self.tree_bound.library.set_fallback()
            X[0], stats[...] = start                    # the same run again from its start, with the fallback
            status, interrupted = call_interruptibly(*args, stop=options.stop.contents)
        return INTERRUPTED if interrupted else int(status), int(done.value)


class _Start(ctypes.Structure):
    """``ncgen_tree_start``: the arguments of ``start_state``."""

    _fields_ = [*((f, ctypes.c_void_p) for f in ("T", "idx", "how", "nz_ptr", "nz", "num")), ("n", ctypes.c_int),
                *((f, ctypes.c_void_p) for f in ("q", "v", "qj", "vj", "check", "w"))]


#: Largest share of the start check's position tolerance (``TREE_Q_TOL``) its distance may take at
#: the model's own initial state (consistent to round-off) for the check to be used: where reading
#: the joints off the natural coordinates amplifies their round-off beyond it (members whose
#: coordinates are points close together: Talos of example-robot-data, 0.69 of it at its initial
#: state and 1.5–10× at others; the Panda 0.035, Solo12 0.0002), starts made by
#: ``from_joint_space`` would go on to CasADi's check after the C's, so the C is not called.
START_ROUNDOFF_SHARE = 0.25


class TreeStart:
    """``start(q, v) -> (check, qj, vj)``: the tree library's start check of one model
    (``ncgen_tree_start.h``: ``check = [max |q − q(q_j)|, max |v − v(q_j, v_j)|, |q|∞, |v|∞, s]``,
    ``s`` finite only if every value is) on its tables and members' coordinate maps
    (:func:`~ncgen.codegen.tree_start.start_tables`); the forward unit's, so a model whose
    joint run is on the tables has it loaded.  Calls from threads take turns (one work array).
    Raises :class:`~ncgen.codegen.tree_tables.UnsupportedTree` for a model the check does not
    take, and for one whose initial state it finds more than :data:`START_ROUNDOFF_SHARE` of its
    tolerance off the tree (round-off of its coordinates, read off joint by joint)."""

    def __init__(self, model):
        from ncgen.assembly.joint_space import TREE_Q_TOL
        from ncgen.codegen.tree_start import start_tables
        from ncgen.codegen.tree_tables import UnsupportedTree

        self._tables = start_tables(model)
        self.tree = bound_tree(model)
        self._fn = self.tree.unit("forward").fn["start_state"]
        nq, nv, n = self.tree.tables.nq, self.tree.tables.nv, model.nq
        self._in, self._out = np.empty(2 * n), np.empty(5 + nq + nv)      # [q; v], [check; qj; vj]: addresses taken once
        self._w = np.empty(24 * self.tree.tables.nb + self.tree.work.size)   # (NCGEN_TREE_START_WORK_SIZE or more)
        a, x = self._out.ctypes.data, self._in.ctypes.data
        self._struct = _Start(self.tree.ref, *(t.ctypes.data for t in self._tables), n, x, x + 8 * n, a + 40,
                              a + 8 * (5 + nq), a, self._w.ctypes.data)
        self._ref = ctypes.addressof(self._struct)
        self._n, self._cut = n, 5 + nq
        self._lock = threading.Lock()
        check = self(model.q0, model.v0)[0]
        share = check[0] / (TREE_Q_TOL * max(1.0, check[2]))
        if not share <= START_ROUNDOFF_SHARE:
            raise UnsupportedTree(model.name, [
                f"the start check finds its initial state {share:.3g} of its tolerance off the tree (more than "
                f"{START_ROUNDOFF_SHARE}: round-off of its natural coordinates read off joint by joint; CasADi's "
                "check decides its starts)"])

    def __call__(self, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(check, qj, vj)`` (new arrays) at ``q``, ``v`` (``nq`` floats each)."""
        n = self._n
        with self._lock:
            self._in[:n], self._in[n:] = q, v
            if self._fn(self._ref):
                raise CodegenError("start_state: the tree has a joint the start check does not take")
            out = self._out.copy()
        return out[:5], out[5:self._cut], out[self._cut:]


def loaded_tree_start(model) -> TreeStart | None:
    """``model``'s :class:`TreeStart` where its tables' forward unit is loaded already (a joint
    run on the tables loaded it: nothing is compiled here), else None (also for a tree the
    check does not cover, remembered per model)."""
    from ncgen.codegen.tree_tables import UnsupportedTree
    from ncgen.model.data import model_data

    data, key = model_data(model), library_key()
    k = data.table_algorithms.get(("start", key), False)
    if k is not False:
        return k
    tree = data.table_algorithms.get((None, key))
    if tree is None or "forward" not in tree._checked:
        return None
    try:
        return tree_start(model)
    except UnsupportedTree:
        data.table_algorithms[("start", key)] = None
        return None


def tree_start(model) -> TreeStart:
    """``model``'s :class:`TreeStart`, bound once per model and :func:`library_key` (raises
    :class:`~ncgen.codegen.tree_tables.UnsupportedTree`, or
    :class:`~ncgen.errors.CompilerNotFound` with no compiler and no forward unit in the cache)."""
    from ncgen.model.data import model_data

    data, key = model_data(model), ("start", library_key())
    k = data.table_algorithms.get(key)
    if k is None:
        k = data.table_algorithms[key] = TreeStart(model)
    return k

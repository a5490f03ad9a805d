"""The compiled stepper driven by element tables: the element library's RATTLE stepper
(``templates/c/runtime/ncgen_table_stepper.h``, compiled once per ncgen version,
:func:`~ncgen.runtime.table_library.load_element_library`) run on one model's
:class:`~ncgen.codegen.stepper_tables.StepperTables`: a model of the shipped kinds reaches
its first compiled step with no call of the C compiler.

:class:`TableStepper` has the interface of
:class:`~ncgen.runtime.stepper_library.CompiledStepper` (the stepper's driver,
:mod:`ncgen.runtime.stepper`, does not tell them apart).  :func:`stepper_kernels` is the
choice between the two (``SimulationOptions(kernels=...)``): ``"tables"``, ``"flat"`` (the
model's own package, compiled per model) or ``"auto"``: the tables when every element of the
model is covered (:func:`~ncgen.codegen.stepper_tables.uncovered_elements` and
:mod:`~ncgen.codegen.model_tables`), else flat — except that a small model (``nq + nc`` below
:data:`AUTO_FLAT_BELOW`) whose flat package this process has already compiled or loaded runs
flat: there the flat step is faster (benchmarks/table_stepper.py, CPU seconds per step of the
tables over the flat package's: 2.2–2.9 for a 10-bar chain, nq + nc = 40; 1.2 at 40 bars,
nq + nc = 160; 1.0 at 160 bars) and costs no compile.
"auto" never compiles a covered model: the first compiled step of a new model of the shipped
kinds needs no C compiler.
"""
from __future__ import annotations

import ctypes
import threading
import warnings
from functools import partial
from types import SimpleNamespace

import numpy as np

from ncgen.codegen import c_binding
from ncgen.codegen.element_kernels import PACKAGE
from ncgen.codegen.model_tables import UnsupportedElements
from ncgen.codegen.stepper_abi import LOOPS, StepOptions, signature
from ncgen.codegen.stepper_tables import StepperTables, stepper_tables
from ncgen.errors import CodegenError, NcgenError
from ncgen.model.data import model_data
from ncgen.runtime.options import KERNELS
from ncgen.runtime.stepper_library import CompiledStepper, load_stepper
from ncgen.runtime.table_library import TABLE_FIELDS, ElementLibrary, TableFunctions, _Tables, load_element_library


_QR_FIELDS = (("int", "n"), *(("const int *", f) for f in ("k_colind", "k_row", "v_colind", "v_row", "r_colind",
                                                             "r_row", "prinv", "pc")))


#: Size ``nq + nc`` below which "auto" runs a covered model flat when its package is loaded.
AUTO_FLAT_BELOW = 160
#: Size ``nq + nc`` up to which :meth:`TableStepper.multipliers` solves the KKT system dense.
DENSE_KKT = 400


class _QrPattern(ctypes.Structure):
    _fields_ = [(f, ctypes.c_void_p if "*" in t else ctypes.c_int) for t, f in _QR_FIELDS]


#: Fields of ``ncgen_stepper_tables``, in order (the struct ``qr`` last).
STEPPER_FIELDS = (
    ("const ncgen_tables *", "T"), ("int", "nu"), ("int", "np"), ("int", "n_markers"), ("int", "n_spring"),
    ("double", "mass_scale"),
    *(("const int *", f) for f in ("a_colind", "a_row", "m_colind", "m_row")),
    ("const double *", "m_val"), ("const double *", "f_gravity"), ("double", "v_gravity"),
    ("const int *", "spr_feat"), ("const double *", "spr_par"), ("const int *", "spr_kpos_ptr"),
    ("const int *", "spr_kpos"), ("const int *", "marker_feat"),
    ("int", "nnz_k"), ("int", "nnz_v"), ("int", "nnz_r"),
    *(("const int *", f) for f in ("k_mpos", "k_apos", "k_atpos")),
    ("const int *", "bu_colind"), ("const int *", "bu_row"), ("const double *", "bu_val"),
    ("int", "n_act"), *(("const int *", f) for f in ("act_kind", "act_ptr", "act_col", "act_form_ptr")),
    ("const double *", "act_form"), ("const double *", "act_tau"),
    ("const double *", "f_const"), ("int", "n_ff"),
    *(("const int *", f) for f in ("ff_kind", "ff_feat_ptr", "ff_feat", "ff_par_ptr")),
    ("const double *", "ff_par"), ("const int *", "ff_kpos_ptr"), ("const int *", "ff_kpos"),
    ("int", "n_torque"), ("const int *", "tq_member"), ("const int *", "tq_c_ptr"),
    ("const double *", "tq_c"), ("const double *", "tq_val"),
)


class _StepperTables(ctypes.Structure):
    _fields_ = [(f, ctypes.c_void_p if "*" in t else ctypes.c_double if t == "double" else ctypes.c_int)
                for t, f in STEPPER_FIELDS] + [("qr", _QrPattern)]


def _array(values, t: str) -> np.ndarray:
    return np.ascontiguousarray(values, dtype=np.int32 if "int" in t else np.float64)


class TableStepper(CompiledStepper):
    """The element library's stepper bound to one model's tables (the interface of
    :class:`~ncgen.runtime.stepper_library.CompiledStepper`).  Loops may run in several
    threads at once (the C keeps the tables of a run per thread)."""

    kernels = "tables"

    def __init__(self, st: StepperTables, library: ElementLibrary | None = None):
        lib = library or load_element_library()
        self.library_object = lib
        T = st.tables
        self.library, self.name = str(lib.path), st.name
        self.nq, self.nc, self.nu, self.np = T.nq, T.nc, st.nu, st.np
        self.nout, self.nd = 5 + T.dim * st.n_markers, 0
        self.tables = st
        self._keep = {f: _array(T.arrays[f], t) for t, f in TABLE_FIELDS if "*" in t}
        sizes = {"nq": T.nq, "nc": T.nc, "dim": T.dim, "a_nnz": T.a_nnz, "m_nnz": T.m_nnz,
                 "nf": len(self._keep["feat_ptr"]) - 1, "ne": len(self._keep["el_kind"]),
                 "nm": len(self._keep["mem_kind"])}
        self._T = _Tables(**sizes, **{k: v.ctypes.data for k, v in self._keep.items()})
        fields = {f: t for t, f in STEPPER_FIELDS} | {f: t for t, f in _QR_FIELDS}
        for f, t in fields.items():
            if "*" in t and f != "T":
                self._keep[f"s.{f}"] = _array(st.arrays[f], t)
        ptr = {f: self._keep[f"s.{f}"].ctypes.data for f in fields if f"s.{f}" in self._keep}
        qr = _QrPattern(n=T.nq + T.nc, **{f: ptr[f] for _, f in _QR_FIELDS[1:]})
        self._S = _StepperTables(T=ctypes.addressof(self._T), nu=st.nu, np=st.np, n_markers=st.n_markers,
                                 n_act=len(self._keep["s.act_kind"]),
                                 n_spring=st.n_spring, mass_scale=st.mass_scale, v_gravity=st.v_gravity,
                                 nnz_k=st.nnz_k, nnz_v=st.nnz_v, nnz_r=st.nnz_r, n_ff=st.n_ff,
                                 n_torque=st.n_torque,
                                 **{f: ptr[f] for t, f in STEPPER_FIELDS if "*" in t and f != "T"}, qr=qr)
        self._lib = lib._lib
        check = c_binding.bind(self._lib, f"{PACKAGE}_stepper_check",
                               c_binding.Signature("int", (("const void *", "S"),)))
        if check(ctypes.byref(self._S)):
            raise CodegenError(f"model {st.name!r}: its stepper tables are inconsistent (ncgen_elements_stepper_check)")
        structs = {f"{PACKAGE}_step_options": StepOptions}
        for loop in LOOPS:
            sig = signature(loop, False)
            sig = c_binding.Signature(sig.returns, (("const void *", "S"), *sig.args))
            fn = c_binding.bind(self._lib, f"{PACKAGE}_{loop}", sig, name=PACKAGE, structs=structs)
            setattr(self, f"_{loop}", partial(fn, ctypes.byref(self._S)))
        forces = c_binding.Signature("int", (("const void *", "S"), ("const double *", "q"),
                                              ("const double *", "v"), ("const double *", "u"),
                                              ("double *", "F")))
        self._forces = c_binding.bind(self._lib, f"{PACKAGE}_forces", forces, addresses=True)
        self._local = threading.local()          # TableFunctions per thread (one work array each)
        self._raw = None

    def raw_loops(self) -> SimpleNamespace:
        """``simulate`` and ``simulate_stats`` of the element library bound to these tables with
        address arguments (as :func:`ncgen.runtime.batch._raw_loops` binds a model's own)."""
        if self._raw is None:
            structs = {f"{PACKAGE}_step_options": StepOptions}
            loops = {}
            for loop in ("simulate", "simulate_stats"):
                sig = signature(loop, False)
                sig = c_binding.Signature(sig.returns, (("const void *", "S"), *sig.args))
                fn = c_binding.bind(self._lib, f"{PACKAGE}_{loop}", sig, name=PACKAGE, structs=structs,
                                    addresses=True)
                loops[loop] = partial(fn, ctypes.addressof(self._S))
            self._raw = SimpleNamespace(**loops, lib=self._lib)
        return self._raw

    def forces(self, q, v, u=None) -> np.ndarray:
        """The applied generalised force ``F(q, v, u)`` (nq; N or N·m per coordinate's unit) of
        the stepper's forces, input forces and efforts included (``u`` None: zero inputs), from
        the tables."""
        q, v = (np.ascontiguousarray(x, dtype=float).reshape(self.nq) for x in (q, v))
        u = np.zeros(self.nu) if u is None else np.ascontiguousarray(u, dtype=float).reshape(self.nu)
        out = np.zeros(self.nq)
        status = self._forces(ctypes.byref(self._S), q.ctypes.data, v.ctypes.data, u.ctypes.data, out.ctypes.data)
        if status:
            raise CodegenError(f"model {self.name!r}: the element library's forces failed (status {status})")
        return out

    def multipliers(self, q, v, u=None) -> np.ndarray:
        """``λ`` of the KKT system ``[[M, Aᵀ], [A, 0]] [q̈; λ] = [F; γ]`` at ``(q, v, u)`` from the
        tables (one state, or one per row of ``q``, ``v`` and ``u``; ``u`` None: zero inputs); NaN
        where it is singular.  Dense LU up to :data:`DENSE_KKT` unknowns, sparse LU above."""
        q, v = np.asarray(q, float), np.asarray(v, float)
        if q.ndim == 2:
            U = [None] * len(q) if u is None or not self.nu else np.asarray(u, float).reshape(len(q), self.nu)
            return np.array([self.multipliers(qk, vk, uk) for qk, vk, uk in zip(q, v, U)]).reshape(len(q), self.nc)
        if not self.nc:
            return np.zeros(0)
        fn = getattr(self._local, "functions", None)
        if fn is None:
            fn = self._local.functions = TableFunctions(self.tables.tables, self.library_object)
        T, a = self.tables.tables, self.tables.arrays
        rhs = np.concatenate([self.forces(q, v, u), fn.gamma(q, v)])
        n = self.nq + self.nc
        if n <= DENSE_KKT:
            K = np.zeros((n, n))
            K[:self.nq, :self.nq] = T.dense_M(a["m_val"])
            A = T.dense_A(fn.A(q))
            K[self.nq:, :self.nq], K[:self.nq, self.nq:] = A, A.T
            try:
                return np.linalg.solve(K, rhs)[self.nq:]
            except np.linalg.LinAlgError:
                return np.full(self.nc, np.nan)
        import scipy.sparse as sp
        from scipy.sparse.linalg import MatrixRankWarning, spsolve

        A = sp.csc_matrix((fn.A(q), T.a_indices, T.a_indptr), shape=(self.nc, self.nq))
        M = sp.csc_matrix((a["m_val"], a["m_row"], a["m_colind"]), shape=(self.nq, self.nq))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", MatrixRankWarning)
            x = spsolve(sp.bmat([[M, A.T], [A, None]], format="csc"), rhs)
        return np.asarray(x, float)[self.nq:]


def table_stepper(model, library: ElementLibrary | None = None) -> TableStepper:
    """The table-driven stepper of ``model`` (raises
    :class:`~ncgen.codegen.model_tables.UnsupportedElements` naming the elements not covered).
    Whether the model is conservative is recorded in its data from the tables (the stepper's
    checks then need no flat function)."""
    st = stepper_tables(model)
    data = model_data(model)
    if data.conservative_idle is None:
        data.conservative_idle = st.conservative
    if data.conservative is None and not model.nu:
        data.conservative = st.conservative
    return TableStepper(st, library)


def stepper_kernels(model, kernels: str, cflags=None) -> str:
    """``"tables"`` or ``"flat"``: the stepper kernels a run of ``model`` uses for the option
    ``kernels`` (module docstring; ``cflags``: those of the flat package).  ``"tables"`` on a
    model that is not covered raises :class:`~ncgen.codegen.model_tables.UnsupportedElements`
    naming its elements."""
    if kernels not in KERNELS:
        raise NcgenError(f"kernels: expected one of {', '.join(map(repr, KERNELS))}, got {kernels!r}")
    if kernels == "flat":
        return "flat"
    key = tuple(cflags) if isinstance(cflags, (list, tuple)) else cflags
    if kernels == "auto" and model.nq + model.nc < AUTO_FLAT_BELOW and key in model_data(model).libraries:
        return "flat"
    cache = model_data(model).steppers
    if ("tables", None) not in cache:
        try:
            cache[("tables", None)] = table_stepper(model)
        except UnsupportedElements as e:
            if kernels == "tables":
                raise UnsupportedElements(model.name, e.kinds) from None
            cache[("tables", None)] = e
    hit = cache[("tables", None)]
    if isinstance(hit, UnsupportedElements):
        if kernels == "tables":
            raise UnsupportedElements(model.name, hit.kinds)
        return "flat"
    return "tables"


def load_any_stepper(model, cflags=None, kernels: str = "auto") -> CompiledStepper:
    """The stepper of ``model`` with the kernels :func:`stepper_kernels` chooses: the tables'
    (no compiler; ``cflags`` do not apply) or the model's compiled package
    (:func:`~ncgen.runtime.stepper_library.load_stepper`)."""
    if stepper_kernels(model, kernels, cflags) == "tables":
        return model_data(model).steppers[("tables", None)]
    return load_stepper(model, cflags)

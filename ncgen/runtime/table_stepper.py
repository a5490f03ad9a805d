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
flat: it costs no compile, and there the flat step can still be the faster
(benchmarks/table_stepper.py, CPU seconds per step of the tables over the flat package's, with
the tables' sparse LU: 0.84–0.95 for a 10-bar chain, nq + nc = 40, but 0.96–1.28 (min) and
1.0–1.23 (median) for that chain with a cable, a spring-damper, a point force and a torque per
bar, measured at load 8–14; 0.5–0.7 at 40 bars).
"auto" never compiles a covered model: the first compiled step of a new model of the shipped
kinds needs no C compiler.
"""
from __future__ import annotations

import ctypes
from functools import partial
from types import SimpleNamespace

import numpy as np

from ncgen.codegen import c_binding
from ncgen.codegen.contact_tables import INT_ARRAYS, REAL_ARRAYS, SIZES
from ncgen.codegen.model_tables import UnsupportedElements
from ncgen.codegen.stepper_abi import LOOPS, signature, structs as stepper_structs
from ncgen.codegen.stepper_tables import StepperTables, stepper_tables
from ncgen.errors import CodegenError, NcgenError
from ncgen.model.data import model_data
from ncgen.runtime.options import KERNELS
from ncgen.runtime.stepper_checks import dissipative_contacts
from ncgen.runtime.stepper_library import CompiledStepper, load_stepper
from ncgen.runtime.table_library import (TABLE_FIELDS, ElementLibrary, _Tables, load_contact_library,
                                         load_element_library)


_QR_FIELDS = (("int", "n"), *(("const int *", f) for f in ("k_colind", "k_row", "v_colind", "v_row", "r_colind",
                                                             "r_row", "prinv", "pc")))


#: Size ``nq + nc`` below which "auto" runs a covered model flat when its package is loaded.
AUTO_FLAT_BELOW = 160


class _QrPattern(ctypes.Structure):
    _fields_ = [(f, ctypes.c_void_p if "*" in t else ctypes.c_int) for t, f in _QR_FIELDS]


#: Fields of ``ncgen_lu_pattern`` (``ncgen_sparse_lu.h``) and the stepper tables' arrays they point to.
_LU_FIELDS = (("int", "n", None), ("int", "nnz_l", None), ("const int *", "k_colind", "k_colind"),
              ("const int *", "k_prow", "lu_k_prow"), ("const int *", "p", "lu_p"), ("const int *", "pinv", "lu_pinv"),
              *(("const int *", f, f) for f in ("l_colind", "l_row", "u_colind", "u_row", "u_lpos")))


class _LuPattern(ctypes.Structure):
    _fields_ = [(f, ctypes.c_void_p if "*" in t else ctypes.c_int) for t, f, _ in _LU_FIELDS]


#: Fields of ``ncgen_stepper_tables``, in order (then the structs ``qr`` and ``lu``).
STEPPER_FIELDS = (
    ("const ncgen_tables *", "T"), ("int", "nu"), ("int", "np"), ("int", "n_markers"), ("int", "n_spring"),
    ("double", "mass_scale"), ("int", "m_nnz"),
    *(("const int *", f) for f in ("a_colind", "a_row", "m_colind", "m_row")),
    ("const double *", "m_val"), ("const double *", "f_gravity"), ("double", "v_gravity"),
    ("const int *", "spr_feat"), ("const double *", "spr_par"), ("const int *", "spr_kpos_ptr"),
    ("const int *", "spr_kpos"), ("const double *", "spr_kcoef"), ("const int *", "spr_kj"),
    ("const int *", "marker_feat"),
    ("int", "nnz_k"), ("int", "nnz_v"), ("int", "nnz_r"),
    *(("const int *", f) for f in ("k_mpos", "k_apos", "k_atpos")),
    ("const int *", "bu_colind"), ("const int *", "bu_row"), ("const double *", "bu_val"),
    ("int", "n_act"), *(("const int *", f) for f in ("act_kind", "act_ptr", "act_col", "act_form_ptr")),
    ("const double *", "act_form"), ("const double *", "act_tau"),
    ("const double *", "f_const"), ("int", "n_ff"),
    *(("const int *", f) for f in ("ff_kind", "ff_feat_ptr", "ff_feat", "ff_par_ptr")),
    ("const double *", "ff_par"), ("const int *", "ff_kpos_ptr"), ("const int *", "ff_kpos"),
    ("const double *", "ff_kcoef"), ("const int *", "ff_kj"),
    ("int", "n_torque"), ("const int *", "tq_member"), ("const int *", "tq_c_ptr"),
    ("const double *", "tq_c"), ("const double *", "tq_val"),
)


_S = ("const ncgen_stepper_tables *", "S")


def _after_tables(sig: c_binding.Signature) -> c_binding.Signature:
    """``sig`` with the stepper tables ``S`` as its first argument."""
    return c_binding.Signature(sig.returns, (_S, *sig.args))


#: The element library's stepper entry points (prefixed by ``ElementLibrary.package``) as
#: element_tables.c.j2 spells them: a model stepper's loops (:data:`~ncgen.codegen.stepper_abi.LOOPS`, without
#: contacts) after the tables ``S``, and its own.
SIGNATURES = {
    "stepper_check": c_binding.Signature("int", (_S,)),
    **{loop: _after_tables(signature(loop, False)) for loop in LOOPS},
    "forces": c_binding.Signature("int", (_S, ("const casadi_real *", "q"), ("const casadi_real *", "v"),
                                          ("const casadi_real *", "u"), ("casadi_real *", "F"))),
    "multipliers": c_binding.Signature("int", (_S, ("long", "n"), ("const casadi_real *", "q"),
                                               ("const casadi_real *", "v"), ("const casadi_real *", "u"),
                                               ("long", "u_stride"), ("casadi_real *", "lam"))),
}


def _signatures(contacts: bool) -> dict:
    """:data:`SIGNATURES` of the element library, or of the contact library (``contacts``: the
    loops' trailing impulse arguments)."""
    if not contacts:
        return SIGNATURES
    return {**SIGNATURES, **{loop: _after_tables(signature(loop, True)) for loop in LOOPS}}


class _StepperTables(ctypes.Structure):
    _fields_ = [(f, ctypes.c_void_p if "*" in t else ctypes.c_double if t == "double" else ctypes.c_int)
                for t, f in STEPPER_FIELDS] + [("qr", _QrPattern), ("lu", _LuPattern), ("ct", ctypes.c_void_p)]


class _ContactTables(ctypes.Structure):
    """``struct ncgen_contact_tables`` (``ncgen_table_stepper.h``)."""

    _fields_ = [(f, ctypes.c_int) for f in SIZES] + [("gravity_norm", ctypes.c_double)] + \
        [(f, ctypes.c_void_p) for f in INT_ARRAYS + REAL_ARRAYS]


def _array(values, t: str) -> np.ndarray:
    return np.ascontiguousarray(values, dtype=np.int32 if "int" in t else np.float64)


class TableStepper(CompiledStepper):
    """The element library's stepper bound to one model's tables (the interface of
    :class:`~ncgen.runtime.stepper_library.CompiledStepper`).  Loops may run in several
    threads at once (the C keeps the tables of a run per thread)."""

    kernels = "tables"

    def __init__(self, st: StepperTables, library: ElementLibrary | None = None):
        lib = library or (load_contact_library() if st.contacts else load_element_library())
        package = lib.package       # the element library's or the contact library's prefix
        self.library_object = lib
        T = st.tables
        self.library, self.name = str(lib.path), st.name
        self.nq, self.nc, self.nu, self.np = T.nq, T.nc, st.nu, st.np
        self.nout, self.nd = 5 + T.dim * st.n_markers, st.contacts["nk"] * T.dim if st.contacts else 0
        self.tables = st
        self._keep = {f: _array(T.arrays[f], t) for t, f in TABLE_FIELDS if "*" in t}
        sizes = {"nq": T.nq, "nc": T.nc, "dim": T.dim, "a_nnz": T.a_nnz, "m_nnz": T.m_nnz,
                 "nf": len(self._keep["feat_ptr"]) - 1, "ne": len(self._keep["el_kind"]),
                 "nm": len(self._keep["mem_kind"])}
        self._T = _Tables(**sizes, **{k: v.ctypes.data for k, v in self._keep.items()})
        fields = {f: t for t, f in STEPPER_FIELDS} | {f: t for t, f in _QR_FIELDS} \
            | {a: t for t, _, a in _LU_FIELDS if a is not None}
        for f, t in fields.items():
            if "*" in t and f != "T":
                self._keep[f"s.{f}"] = _array(st.arrays[f], t)
        ptr = {f: self._keep[f"s.{f}"].ctypes.data for f in fields if f"s.{f}" in self._keep}
        qr = _QrPattern(n=T.nq + T.nc, **{f: ptr[f] for _, f in _QR_FIELDS[1:]})
        lu = _LuPattern(n=T.nq + T.nc if st.use_lu else 0, nnz_l=st.nnz_l, **{f: ptr[a] for _, f, a in _LU_FIELDS if a is not None})
        self._S = _StepperTables(T=ctypes.addressof(self._T), nu=st.nu, np=st.np, n_markers=st.n_markers,
                                 n_act=len(self._keep["s.act_kind"]),
                                 n_spring=st.n_spring, mass_scale=st.mass_scale, m_nnz=st.m_nnz,
                                 v_gravity=st.v_gravity,
                                 nnz_k=st.nnz_k, nnz_v=st.nnz_v, nnz_r=st.nnz_r, n_ff=st.n_ff,
                                 n_torque=st.n_torque,
                                 **{f: ptr[f] for t, f in STEPPER_FIELDS if "*" in t and f != "T"}, qr=qr, lu=lu,
                                 ct=self._contact_tables(st.contacts))
        self._lib = lib._lib
        structs = {**stepper_structs(package), "ncgen_stepper_tables": _StepperTables}
        check = c_binding.bind(self._lib, f"{package}_stepper_check", SIGNATURES["stepper_check"], structs=structs)
        if check(ctypes.byref(self._S)):
            raise CodegenError(f"model {st.name!r}: its stepper tables are inconsistent ({package}_stepper_check)")
        self._signatures = _signatures(bool(self.nd))
        for loop in LOOPS:
            fn = c_binding.bind(self._lib, f"{package}_{loop}", self._signatures[loop], name=package, structs=structs)
            setattr(self, f"_{loop}", partial(fn, ctypes.byref(self._S)))
        self._forces = c_binding.bind(self._lib, f"{package}_forces", SIGNATURES["forces"], addresses=True)
        self._multipliers = c_binding.bind(self._lib, f"{package}_multipliers", SIGNATURES["multipliers"],
                                           addresses=True)
        self._raw = None

    def _contact_tables(self, contacts: dict | None):
        """The address of the ``ncgen_contact_tables`` of ``contacts`` (None without), kept alive."""
        if not contacts:
            return None
        for f in INT_ARRAYS + REAL_ARRAYS:
            self._keep[f"c.{f}"] = contacts["arrays"][f]
        self._C = _ContactTables(**{f: contacts[f] for f in SIZES}, gravity_norm=contacts["gravity_norm"],
                                 **{f: self._keep[f"c.{f}"].ctypes.data for f in INT_ARRAYS + REAL_ARRAYS})
        return ctypes.addressof(self._C)

    def raw_loops(self) -> SimpleNamespace:
        """``simulate`` and ``simulate_stats`` of the element library bound to these tables with
        address arguments (as :func:`ncgen.runtime.batch._raw_loops` binds a model's own)."""
        if self._raw is None:
            loops = {}
            package = self.library_object.package
            for loop in ("simulate", "simulate_stats"):
                fn = c_binding.bind(self._lib, f"{package}_{loop}", self._signatures[loop], name=package,
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
        tables (one state, or one per row of ``q``, ``v`` and ``u``; ``u`` None: zero inputs), by
        the stepper's sparse QR in one compiled call (``ncgen_elements_multipliers``, the GIL
        released); NaN where the system is singular."""
        q, v = np.asarray(q, float), np.asarray(v, float)
        one = q.ndim == 1
        Q = np.ascontiguousarray(q.reshape(-1, self.nq))
        V = np.ascontiguousarray(v.reshape(-1, self.nq))
        n = len(Q)
        if V.shape != Q.shape:
            raise ValueError(f"multipliers: q and v disagree in shape ({q.shape}, {v.shape})")
        U = None if u is None or not self.nu else np.ascontiguousarray(np.broadcast_to(
            np.asarray(u, float).reshape(-1, self.nu), (n, self.nu)))
        lam = np.zeros((n, self.nc))
        status = self._multipliers(ctypes.byref(self._S), n, Q.ctypes.data, V.ctypes.data,
                                   None if U is None else U.ctypes.data, self.nu, lam.ctypes.data)
        if status:
            raise CodegenError(f"model {self.name!r}: the element library's multipliers failed (status {status})")
        return lam[0] if one else lam


def table_stepper(model, library: ElementLibrary | None = None) -> TableStepper:
    """The table-driven stepper of ``model`` (raises
    :class:`~ncgen.codegen.model_tables.UnsupportedElements` naming the elements not covered).
    Whether the model is conservative is recorded in its data from the tables and its contacts'
    parameters (the stepper's checks then need no flat function)."""
    st = stepper_tables(model)
    data = model_data(model)
    conservative = st.conservative and not dissipative_contacts(model)
    if data.conservative_idle is None:
        data.conservative_idle = conservative
    if data.conservative is None and not model.nu:
        data.conservative = conservative
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

"""Tree kernels: one small CasADi function per *kind* of joint of a tree, and one for a rigid
body, the model's numbers as arguments — the pieces the joint-space algorithms over data
tables call (RNEA, CRBA, forward dynamics and their derivatives:
``templates/c/runtime/ncgen_tree_tables.h``; docs/architecture.md, "Element tables").

Notation as :mod:`ncgen.assembly.tree_dynamics` (arboris): poses ``H_gm = [[R, p], [0, 1]]``
of member frames in the ground frame g, twists ``[ω; v]`` and wrenches ``[τ; f]`` expressed
in g, every formula from :mod:`ncgen.rigid_motion.casadi_forms` and the joints' relative
poses from :func:`ncgen.assembly.joint_tree.relative_pose` with symbolic axes.

* joint kind ``k`` (:data:`JOINT_KINDS`: ``nq`` positions, ``nv`` rates, ``n_axes`` axes):
  kernel ``tk_<k>``: input ``x = [R_p (3×3, column-major); p_p; T_p; q; w; a1; b1; a2; b2;
  axes]`` (the parent's pose and twist, the joint's positions and rates, the placements
  ``H_pc = [a1, b1] T(q) [a2, b2]`` of :func:`~ncgen.assembly.joint_tree.edge_placements`),
  output ``y = [R_c; p_c; S_g (6×nv); c_g]``: the child's pose, the joint's motion subspace in
  g (``T_c = T_p + S_g w``) and ``c_g = Ṡ_g w`` (``dT_c = dT_p + c_g + S_g ẇ``); kernel
  ``tk_<k>_fwd``: input ``[x; dR_p; dp_p; dT_p; δ; dw]``, output ``dy``, the derivative of
  ``y`` along those tangents with ``q`` moved in the tangent space (``dq = q̇(q, δ)``:
  quaternions turn by ``δω`` in their own axes, a free joint's position moves by ``R δv``);
* ``tk_body``: input ``[R; p; T; dT; m; c; I_c]`` (pose, twist, acceleration, mass (kg),
  centre of mass (member axes, m), inertia about it (member axes, kg·m², column-major)),
  output ``[M_g (6×6); W]``: the mass matrix at g and the wrench ``M_g dT − ad(T)ᵀ M_g T``
  (N·m, N) the body needs; ``tk_body_fwd``: input ``[x; dR; dp; dT; ddT]``, output ``d[M_g; W]``;
* ``tk_<k>_qdot``: ``[q; w] -> q̇`` (position rates: quaternions' ``½ q ⊗ [ω; 0]``, a free
  joint's ``R v``) for the joint-space ODE, of the kinds whose rates are not their positions'
  derivatives (:func:`rate_kernel_kinds`; for the others the loops copy ``q̇ = w``);
* ``tl_<k>`` (the local recursion of RNEA, CRBA and ABA, kinds other than ``fixed``,
  ``revolute`` and ``prismatic``, which the loops write out about the z axis:
  :data:`LOCAL_MODES`): input ``[q; w; numbers]``, output ``[R_J; p_J; S (6×nv); c_J]``: the
  joint's own motion ``T(q) = [[R_J, p_J], [0, 1]]`` (:func:`~ncgen.assembly.joint_tree.relative_pose`),
  its motion subspace in the frame it moves (``vee(T⁻¹ Ṫ) = S w``) and ``c_J = Ṡ w``.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import casadi as ca
import numpy as np

from ncgen.assembly.joint_space import joint_position_rates
from ncgen.assembly.joint_tree import Edge, relative_pose
from ncgen.assembly.tree_dynamics import _mass_matrix_g
from ncgen.errors import CodegenError
from ncgen.rigid_motion import casadi_forms as crm


@dataclass(frozen=True)
class TreeJointKind:
    """A joint kind of a tree: the ``joint_tree`` kind, positions, rates and axes."""

    name: str
    kind: str
    nq: int
    nv: int
    n_axes: int

    @property
    def n_num(self) -> int:
        """Numbers of a joint of this kind: placements ``a1, b1, a2, b2`` (24) and its axes."""
        return 24 + 3 * self.n_axes


#: The joint kinds, in table order.
JOINT_KINDS: tuple[TreeJointKind, ...] = (
    TreeJointKind("fixed", "Fixed", 0, 0, 0), TreeJointKind("revolute", "Revolute", 1, 1, 1),
    TreeJointKind("prismatic", "Prismatic", 1, 1, 1), TreeJointKind("cylindrical", "Cylindrical", 2, 2, 1),
    TreeJointKind("universal", "Universal", 2, 2, 2), TreeJointKind("planar", "Planar", 3, 3, 3),
    TreeJointKind("spherical", "Spherical", 4, 3, 0), TreeJointKind("free", "Free", 7, 6, 0))
#: How the local recursion moves each kind (``ncgen_tree_tables.h``): 0 by its kernel ``tl_<k>``,
#: 1 a rotation about z, 2 a translation along z (revolute and prismatic joints, their axis
#: turned onto z by the tables), 3 not at all (fixed).
LOCAL_MODES = {"fixed": 3, "revolute": 1, "prismatic": 2}
#: Inputs of ``tk_body``: pose (12), twist (6), acceleration (6), mass, centre of mass (3), inertia (9).
BODY_INPUTS = 37
#: The body numbers of a member in the tables: ``[m; c; I_c]``.
BODY_NUMBERS = 13


def _homogeneous(R, p):
    return crm.homogeneous(R, p)


@lru_cache(maxsize=None)
def joint_kernels(name: str) -> tuple[ca.Function, ca.Function]:
    """``(tk_<name>, tk_<name>_fwd)`` (module docstring)."""
    k = next(j for j in JOINT_KINDS if j.name == name)
    Rp, pp, Tp = ca.SX.sym("Rp", 3, 3), ca.SX.sym("pp", 3), ca.SX.sym("Tp", 6)
    q, w = ca.SX.sym("q", k.nq), ca.SX.sym("w", k.nv)
    a1, b1, a2, b2 = ca.SX.sym("a1", 3, 3), ca.SX.sym("b1", 3), ca.SX.sym("a2", 3, 3), ca.SX.sym("b2", 3)
    axes = ca.SX.sym("axes", 3 * k.n_axes)
    edge = Edge("", k.kind, "p", "c", (None, None), (None, None),
                tuple(axes[3 * i:3 * i + 3] for i in range(k.n_axes)))
    R_t, p_t = relative_pose(edge, q, 3, sym=True)
    H_pc = ca.mtimes([_homogeneous(a1, b1), _homogeneous(R_t, p_t), _homogeneous(a2, b2)])
    H_gp = _homogeneous(Rp, pp)
    H_gc = ca.mtimes(H_gp, H_pc)
    x = ca.vertcat(ca.vec(Rp), pp, Tp, q, w, ca.vec(a1), b1, ca.vec(a2), b2, axes)
    if k.nv:
        qd = joint_position_rates(k.kind, 3, k.nq, q, w)
        H_pc_dot = ca.reshape(ca.jtimes(ca.vec(H_pc), q, qd), 4, 4)
        S_p = ca.jacobian(crm.se3_vee(ca.mtimes(H_pc_dot, crm.inverse(H_pc))), w)
        Ad_gp = crm.Ad(H_gp)
        S_g = ca.mtimes(Ad_gp, S_p)
        c_g = ca.mtimes(crm.ad(Tp), ca.mtimes(S_g, w)) + ca.mtimes(Ad_gp, ca.jtimes(ca.mtimes(S_p, w), q, qd))
    else:
        S_g, c_g = ca.SX(6, 0), ca.SX.zeros(6)
    y = ca.densify(ca.vertcat(ca.vec(H_gc[:3, :3]), H_gc[:3, 3], ca.vec(S_g), c_g))
    f = ca.Function(f"tk_{name}", [x], [ca.cse(y)], ["x"], ["y"])
    dRp, dpp, dTp = ca.SX.sym("dRp", 9), ca.SX.sym("dpp", 3), ca.SX.sym("dTp", 6)
    delta, dw = ca.SX.sym("delta", k.nv), ca.SX.sym("dw", k.nv)
    dq = joint_position_rates(k.kind, 3, k.nq, q, delta) if k.nv else ca.SX(0, 1)
    dx = ca.vertcat(dRp, dpp, dTp, dq, dw, ca.SX.zeros(k.n_num))
    dy = ca.densify(ca.jtimes(y, x, dx))
    fwd = ca.Function(f"tk_{name}_fwd", [ca.vertcat(x, dRp, dpp, dTp, delta, dw)], [ca.cse(dy)], ["x"], ["dy"])
    return f, fwd


@lru_cache(maxsize=None)
def local_kernel(name: str) -> ca.Function:
    """``tl_<name>`` (module docstring)."""
    k = next(j for j in JOINT_KINDS if j.name == name)
    q, w, num = ca.SX.sym("q", k.nq), ca.SX.sym("w", k.nv), ca.SX.sym("num", k.n_num)
    edge = Edge("", k.kind, "p", "c", (None, None), (None, None),
                tuple(num[24 + 3 * i:24 + 3 * i + 3] for i in range(k.n_axes)))
    R_J, p_J = relative_pose(edge, q, 3, sym=True)
    H = _homogeneous(R_J, p_J)
    qd = joint_position_rates(k.kind, 3, k.nq, q, w)
    S = ca.jacobian(crm.se3_vee(ca.mtimes(crm.inverse(H), ca.reshape(ca.jtimes(ca.vec(H), q, qd), 4, 4))), w)
    c_J = ca.jtimes(ca.mtimes(S, w), q, qd)
    y = ca.densify(ca.vertcat(ca.vec(R_J), p_J, ca.vec(S), c_J))
    return ca.Function(f"tl_{name}", [ca.vertcat(q, w, num)], [ca.cse(y)], ["x"], ["y"])


@lru_cache(maxsize=None)
def rate_kernel(name: str) -> ca.Function:
    """``tk_<name>_qdot``: ``[q; w] -> q̇`` (the joint's position rates; a quaternion
    normalised first, as the joint-space ODE sees it)."""
    k = next(j for j in JOINT_KINDS if j.name == name)
    q, w = ca.SX.sym("q", k.nq), ca.SX.sym("w", k.nv)
    qn = q
    if k.nq in (4, 7):
        quat = q[k.nq - 4:]
        qn = ca.vertcat(q[:k.nq - 4], quat / ca.norm_2(quat))
    qd = joint_position_rates(k.kind, 3, k.nq, qn, w) if k.nv else ca.SX(0, 1)
    return ca.Function(f"tk_{name}_qdot", [ca.vertcat(q, w)], [ca.densify(qd)], ["x"], ["qdot"])


@lru_cache(maxsize=None)
def rate_kernel_kinds() -> tuple[str, ...]:
    """The joint kinds whose position rates need a kernel: all but those with ``q̇ = w``
    exactly (no position, or the rate kernel's output is its rate input, read off the
    formula); the loops copy ``w`` for the others (``qdot`` unset in the tables' kinds)."""
    need = []
    for k in JOINT_KINDS:
        if not k.nq:
            continue
        f = rate_kernel(k.name)
        x = f.sx_in(0)
        y, w = f(x), x[k.nq:]
        if k.nq != k.nv or ca.depends_on(y - w, x) or np.any(np.array(ca.evalf(y - w))):
            need.append(k.name)
    return tuple(need)


@lru_cache(maxsize=None)
def body_kernels() -> tuple[ca.Function, ca.Function]:
    """``(tk_body, tk_body_fwd)`` (module docstring)."""
    R, p, T, dT = ca.SX.sym("R", 3, 3), ca.SX.sym("p", 3), ca.SX.sym("T", 6), ca.SX.sym("dT", 6)
    m, c, I_c = ca.SX.sym("m"), ca.SX.sym("c", 3), ca.SX.sym("I_c", 3, 3)
    M_g = _mass_matrix_g(m, p + ca.mtimes(R, c), R, I_c)
    W = ca.mtimes(M_g, dT) - ca.mtimes(crm.ad(T).T, ca.mtimes(M_g, T))
    x = ca.vertcat(ca.vec(R), p, T, dT, m, c, ca.vec(I_c))
    y = ca.densify(ca.vertcat(ca.vec(M_g), W))
    f = ca.Function("tk_body", [x], [ca.cse(y)], ["x"], ["y"])
    dx = ca.SX.sym("dx", 24)
    dy = ca.densify(ca.jtimes(y, x, ca.vertcat(dx, ca.SX.zeros(BODY_NUMBERS))))
    return f, ca.Function("tk_body_fwd", [ca.vertcat(x, dx)], [ca.cse(dy)], ["x"], ["dy"])


def kernels() -> list[ca.Function]:
    """Every tree kernel, in the library's order: each joint kind's ``tk_<k>``, ``tk_<k>_fwd``,
    ``tk_<k>_qdot`` (:func:`rate_kernel_kinds`) and ``tl_<k>`` (not :data:`LOCAL_MODES`), then the body's."""
    rates = rate_kernel_kinds()
    return [f for k in JOINT_KINDS for f in (*joint_kernels(k.name),
                                             *((rate_kernel(k.name),) if k.name in rates else ()),
                                             *(() if k.name in LOCAL_MODES else (local_kernel(k.name),)))] + \
        list(body_kernels())


def kind_names() -> str:
    """The joint kinds in table order, comma-separated (the library's ``kind_names()``)."""
    return ",".join(k.name for k in JOINT_KINDS)


def joint_numbers(a1, b1, a2, b2, axes) -> np.ndarray:
    """A joint's numbers in the order its kernel reads them (matrices column-major)."""
    return np.concatenate([np.asarray(a1, float).reshape(-1, order="F"), np.asarray(b1, float).reshape(-1),
                           np.asarray(a2, float).reshape(-1, order="F"), np.asarray(b2, float).reshape(-1),
                           *(np.asarray(a, float).reshape(-1) for a in axes)])


#: Name of the package (and prefix of every C symbol) of the tree library.
PACKAGE = "ncgen_trees"
#: The template files the library is made of besides this module (its cache key hashes them).
SOURCES = ("runtime/ncgen_tree_tables.h", "runtime/ncgen_spatial.h", "tree_tables.c.j2", "runtime/ncgen_joint_loop.h",
           "runtime/ncgen_tree_start.h")
#: The algorithm units of the tree library and their entry points (besides ``work_size``,
#: ``check``, ``kind_names``, ``set_kernel``); each unit also holds the rate kernels
#: (:func:`rate_kernel_kinds`).
ALGORITHM_UNITS = {"inverse": ("rnea", "crba", "rnea_rows"), "forward": ("aba", "joint_run", "start_state"),
                   "derivatives": ("rnea_derivatives", "aba_derivatives")}
#: Doubles of work each kernel may take in the units (the kernels are checked against it).
KERNEL_WORK = 1024


def kernel_units() -> tuple[str, ...]:
    """The kernel units: ``local_<k>`` (``tl_<k>``) of each kind the loops do not write out,
    ``edge_<k>`` (``tk_<k>``, ``tk_<k>_fwd``) of every kind, ``body`` (``tk_body``, ``tk_body_fwd``)."""
    return tuple(f"local_{k.name}" for k in JOINT_KINDS if k.name not in LOCAL_MODES) + \
        tuple(f"edge_{k.name}" for k in JOINT_KINDS) + ("body",)


def units_of(unit: str, kinds) -> tuple[str, ...]:
    """The units the algorithm unit ``unit`` needs for a tree of the joint kinds ``kinds``
    (names): itself, the local kernels of its kinds the loops do not write out, and for the
    derivatives every kind's edge kernels and the body's."""
    kinds = sorted(set(kinds), key=[k.name for k in JOINT_KINDS].index)
    need = [unit] + [f"local_{k}" for k in kinds if k not in LOCAL_MODES]
    if unit == "derivatives":
        need += [f"edge_{k}" for k in kinds] + ["body"]
    return tuple(need)


def unit_kernels(unit: str) -> list[ca.Function]:
    """The CasADi kernels of the unit ``unit`` (an algorithm unit: the rate kernels)."""
    if unit in ALGORITHM_UNITS:
        return [rate_kernel(k) for k in rate_kernel_kinds()]
    if unit == "body":
        return list(body_kernels())
    what, _, kind = unit.partition("_")
    if what == "local" and kind in {k.name for k in JOINT_KINDS} - set(LOCAL_MODES):
        return [local_kernel(kind)]
    if what == "edge" and kind in {k.name for k in JOINT_KINDS}:
        return list(joint_kernels(kind))
    raise CodegenError(f"tree library: no unit {unit!r} (expected one of {', '.join(ALGORITHM_UNITS)}, "
                       f"{', '.join(kernel_units())})")


def _context(units, linked: bool, fns) -> dict:
    from ncgen.codegen.tree_check import PIVOT_TOL

    if any(f.sz_iw() for f in fns) or any(f.sz_arg() > 1 or f.sz_res() > 1 for f in fns):
        raise CodegenError("tree kernels: the loops expect kernels with no integer work, one argument and one result")
    return {"pivot_tol": repr(float(PIVOT_TOL)),
            "kinds": [{"name": k.name, "nq": k.nq, "nv": k.nv, "n_num": k.n_num,
                       "rate": k.name in rate_kernel_kinds(), "mode": LOCAL_MODES.get(k.name, 0)} for k in JOINT_KINDS],
            "max_w": max(f.sz_w() for f in fns) if linked else KERNEL_WORK, "kind_names": kind_names(),
            "units": list(units), "linked": linked}


def _write(name: str, fns, out_dir, context: dict | None, summary: str):
    from ncgen.codegen.package import ExtraSource, PackageDoc, write_package

    extra = [] if context is None else [
        ExtraSource("runtime/ncgen_tree_tables.h", "ncgen_tree_tables.h", included=True),
        ExtraSource("runtime/ncgen_spatial.h", "ncgen_spatial.h", included=True),
        ExtraSource("runtime/ncgen_joint_loop.h", "ncgen_joint_loop.h", included=True),
        ExtraSource("runtime/ncgen_tree_start.h", "ncgen_tree_start.h", included=True),
        ExtraSource("tree_tables.c.j2", "tree_tables.c", context)]
    return write_package(name, fns, out_dir, doc=PackageDoc(summary=summary), max_file_instructions=None,
                         reroll_instructions=None, extra_sources=extra)


def write_tree_package(out_dir):
    """The C package of every tree kernel and every loop (``PACKAGE``, all units in one
    library) in ``out_dir``; its functions are documented in ``templates/c/tree_tables.c.j2``."""
    fns = kernels()
    return _write(PACKAGE, fns, out_dir, _context(ALGORITHM_UNITS, True, fns),
                  "Tree kernels of the shipped joint kinds and the table-driven joint-space algorithms "
                  "(RNEA, CRBA, forward dynamics and their derivatives) of any tree")


def write_tree_unit(unit: str, out_dir):
    """The C package ``ncgen_trees_<unit>`` of one unit of the tree library in ``out_dir``: an
    algorithm unit (:data:`ALGORITHM_UNITS`: its loops and the rate kernels) or a kernel
    unit (:func:`kernel_units`), each compiled on its own when a tree first needs it."""
    fns = unit_kernels(unit)
    if unit not in ALGORITHM_UNITS:
        too_big = [f.name() for f in fns if f.sz_w() > KERNEL_WORK]
        if too_big:
            raise CodegenError(f"tree kernels {', '.join(too_big)} need more than KERNEL_WORK = {KERNEL_WORK} "
                               "doubles of work: raise it in ncgen/codegen/tree_kernels.py")
        return _write(f"{PACKAGE}_{unit}", fns, out_dir, None, f"Tree kernels of the unit {unit} (tree library)")
    return _write(f"{PACKAGE}_{unit}", fns, out_dir, _context((unit,), False, fns),
                  f"The tree library's {unit} unit: {', '.join(ALGORITHM_UNITS[unit])} of any tree over its tables")

"""A built model as data: the index and number tables the table-driven library loops over
(``templates/c/runtime/ncgen_element_tables.h``; docs/architecture.md, "Element tables").

:func:`model_tables` packs a :class:`~ncgen.model.model.Model` element by element, mirroring
:func:`ncgen.assembly.build.constraint_rows`:

* every member is a *member element* of kind ``(dim, coordinate type)``
  (:data:`~ncgen.codegen.element_kernels.MEMBER_KINDS`): its local coordinates
  ``q_I = S_I q + b_I`` (a column of ``q`` per coordinate, or -1 and the ground point's value),
  its constants (:func:`~ncgen.codegen.element_kernels.member_constant_names`) and the rows of
  ``Φ`` its intrinsic constraints ``<member>.rigid.<uv>`` are;
* every joint equation is an output of a *joint element*: a joint primitive of
  :mod:`ncgen.symbolic.joint_primitives` applied to points and directions of members (*features*,
  affine in q: ``f = G q + g``, recorded as the joint writes its equations through the
  :class:`~ncgen.model.context.Context`) and constant scalars.

Rows follow ``model.constraint_names`` (equations that coordinate sharing or
``redundant="drop"`` left out are outputs without a row).  An element the tables cannot
express (a drive, a mimic joint of a Revolute, a coordinate driver, geometry depending on t or on
parameters) is refused by :class:`UnsupportedElements`, which names every such element: the
tables never describe another model than the flat functions do.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from types import SimpleNamespace

import casadi as ca
import numpy as np

from ncgen.codegen.element_kernels import (
    JOINT_KINDS, MEMBER_KINDS, joint_kind_name, member_constant_names, member_kind_name,
)
from ncgen.errors import CodegenError
from ncgen.model.context import Context
from ncgen.symbolic.joint_primitives import primitive_rows

#: Joint classes whose equations (without a drive) are joint primitives of constant scalars.
COVERED_JOINTS = ("Spherical", "Revolute", "Prismatic", "Cylindrical", "Universal", "Planar", "Fixed",
                  "Distance", "PointOnLine", "PointOnPlane", "Free", "JointSequence", "Mimic")
#: Names of the intrinsic constraints' base vectors (``<member>.rigid.uv``).
VECTOR_NAMES = "uvw"


#: Why the tables refuse a kind, by the kind name's first word (added to the refusal).
WHY = {"driven": "a driven joint's rows depend on time through its drive, an expression of t and the model's "
                 "parameters (e.g. 'omega*t'), which enters Φ, Φ_t and γ; the tables hold numbers only, and the "
                 "element library, compiled once for every model, cannot evaluate a model's own expressions "
                 "(that needs the model's flat code, compiled for it)"}


class UnsupportedElements(CodegenError):
    """The model has elements of kinds the tables do not cover; ``kinds`` maps each kind to
    the elements of it."""

    def __init__(self, model_name: str, kinds: dict[str, list[str]]):
        self.kinds = kinds
        listed = "; ".join(f"{k} ({', '.join(v)})" for k, v in sorted(kinds.items()))
        why = "".join(f" ({WHY[w]})" for w in sorted({k.split()[0] for k in kinds} & set(WHY)))
        super().__init__(f"model {model_name!r}: the element tables do not cover these element kinds: {listed}{why}; "
                         "use the model's flat functions (model.functions) for it")


@dataclass
class ModelTables:
    """The tables of one model (fields named as ``ncgen_tables`` in
    ``ncgen_element_tables.h``; integer arrays int32, real arrays float64).

    ``a_indptr``, ``a_indices``: the CSC pattern of ``A`` (nc × nq) whose nonzeros the
    library computes; ``m_indptr``, ``m_indices`` that of ``M`` (nq × nq)."""

    name: str
    dim: int
    nq: int
    nc: int
    arrays: dict[str, np.ndarray]
    a_indptr: np.ndarray
    a_indices: np.ndarray
    m_indptr: np.ndarray
    m_indices: np.ndarray
    kinds: dict[str, int] = field(default_factory=dict)
    #: The feature of each point given to :func:`model_tables` (``points``), in their order.
    point_features: list[int] = field(default_factory=list)

    @property
    def a_nnz(self) -> int:
        return int(self.a_indices.size)

    @property
    def m_nnz(self) -> int:
        return int(self.m_indices.size)

    def dense_A(self, values: np.ndarray) -> np.ndarray:
        """``A`` (nc × nq) from its nonzeros."""
        return _dense(self.nc, self.nq, self.a_indptr, self.a_indices, values)

    def dense_M(self, values: np.ndarray) -> np.ndarray:
        """``M`` (nq × nq) from its nonzeros."""
        return _dense(self.nq, self.nq, self.m_indptr, self.m_indices, values)


def _dense(rows: int, cols: int, indptr, indices, values) -> np.ndarray:
    out = np.zeros((rows, cols))
    for j in range(cols):
        out[indices[indptr[j]:indptr[j + 1]], j] = values[indptr[j]:indptr[j + 1]]
    return out


class _Recorder(Context):
    """A context that records every joint primitive it instantiates: ``(name, args, out)``.

    The output of a covered primitive is a fresh symbol per row, not the primitive's formula
    (whose SymPy-to-CasADi translation cost most of the packing): the tables only need to
    know which output each equation of a joint is (the same node), and the element kernels
    compute its value."""

    def __init__(self, system, layout):
        super().__init__(system, layout)
        self.calls: list[tuple[str, tuple, ca.SX]] = []

    def apply(self, name: str, *args):
        if (name, self.dim) in JOINT_KINDS:
            out = ca.SX.sym(f"{name}{len(self.calls)}", primitive_rows(name, self.dim))
        else:
            out = super().apply(name, *args)
        self.calls.append((name, args, out))
        return out


@dataclass
class _Joint:
    """A joint element before its features are resolved."""

    kind: int
    vectors: list          # SX/DM dim-vectors
    scalars: list[float]
    labels: list[str]
    where: str


def model_tables(model, points=()) -> ModelTables:
    """The tables of ``model`` (see module docstring); raises :class:`UnsupportedElements`.
    ``points``: ``(member, local point)`` pairs (a ground point in world coordinates) made
    features too (``point_features``: the stepper's spring ends and markers), or callables
    ``ctx -> vector`` giving any point or direction affine in q (a gauge's directions)."""
    unsupported: dict[str, list[str]] = {}
    view = SimpleNamespace(members=model.members, inputs={}, parameters={}, dim=model.dim, name=model.name)
    # its symbols cost O(nq): only for joints and points
    ctx = _Recorder(view, model.layout) if model.joints or points else None
    joints = []
    for j in model.joints:
        kind = _uncovered_kind(j)
        if kind is not None:
            unsupported.setdefault(kind, []).append(f"joint {j.name!r}")
            continue
        joints += _joint_elements(ctx, j, unsupported)
    if unsupported:
        raise UnsupportedElements(model.name, unsupported)
    rows = {label: i for i, label in enumerate(model.constraint_names)}
    members = [_member_element(model, m, rows) for m in model.members.values()]
    produced = {label for j in joints for label in j.labels} | {
        label for m in members for label in m["labels"]}
    missing = [label for label in model.constraint_names if label not in produced]
    if missing:
        raise UnsupportedElements(model.name, {"constraint rows of no element kind": missing})
    extra = [_Joint(-1, [p(ctx) if callable(p) else _point(ctx, *p)], [], [], "point") for p in points]
    return _pack(model, ctx, members, joints, rows, extra)


def _point(ctx: _Recorder, member, at):
    """The world position of the local point ``at`` of ``member`` (affine in q)."""
    at = np.asarray(at, float)
    return ca.DM(at) if member.is_ground else ctx.local_point(member, at)[0]


def _uncovered_kind(joint) -> str | None:
    """The name of the uncovered kind of ``joint``, or None when the tables cover it."""
    if joint.kind not in COVERED_JOINTS or type(joint).__module__ != "ncgen.model.joints":
        return joint.kind
    if joint.drive is not None:
        return f"driven {joint.kind}"
    if joint.kind == "Mimic" and not all(type(joint.options[r]).__name__ == "Prismatic" for r in ("leader", "follower")):
        return "Mimic of a Revolute joint (its angle, an atan2, is not a quadratic form of q)"
    return None


def _joint_elements(ctx: _Recorder, joint, unsupported) -> list[_Joint]:
    """The joint elements of ``joint``'s equations: each equation is an output of one
    recorded primitive (the same CasADi node); scalars must be constants."""
    start = len(ctx.calls)
    equations = joint.equations(ctx)
    calls = ctx.calls[start:]
    outputs = {}
    symbols = {out[k].name(): (c, k) for c, (_, _, out) in enumerate(calls) if out.is_valid_input()
               for k in range(out.numel())}          # the covered primitives' outputs (fresh symbols)
    for label, e in equations:
        hit = symbols.get(e.name()) if isinstance(e, ca.SX) and e.is_symbolic() else None
        if hit is None or not ca.is_equal(e, calls[hit[0]][2][hit[1]], 0):
            hit = next(((c, k) for c, (_, _, out) in enumerate(calls) for k in range(out.numel())
                        if ca.is_equal(e, out[k], 0)), None)
        if hit is None:
            unsupported.setdefault(f"{joint.kind} equation not a joint primitive", []).append(label)
            continue
        outputs.setdefault(hit[0], {})[hit[1]] = label
    elements = []
    for c, labels in sorted(outputs.items()):
        name, args, out = calls[c]
        if (name, ctx.dim) not in JOINT_KINDS:
            unsupported.setdefault(f"{joint.kind} through the {name} primitive", []).append(f"joint {joint.name!r}")
            continue
        vectors = [a for a in args if _is_vector(a, ctx.dim)]
        scalars = [a for a in args if not _is_vector(a, ctx.dim)]
        values = []
        for s in scalars:
            value = _constant(s, ctx)
            if value is None:
                unsupported.setdefault(f"{joint.kind} with a scalar of t or parameters", []).append(joint.name)
                break
            values.append(value)
        else:
            kind = JOINT_KINDS.index((name, ctx.dim))
            elements.append(_Joint(kind, vectors, values, [labels.get(k) for k in range(out.numel())],
                                   f"joint {joint.name!r}"))
    return elements


def _is_vector(a, dim: int) -> bool:
    return isinstance(a, (ca.SX, ca.DM, ca.MX)) and a.shape == (dim, 1) or isinstance(a, np.ndarray) and a.size == dim


def _constant(s, ctx) -> float | None:
    """``s`` as a float, or None when it depends on a symbol."""
    if isinstance(s, (int, float, np.floating, np.integer)):
        return float(s)
    s = ca.SX(s)
    if s.numel() != 1 or not s.is_constant():
        return None
    return float(ca.evalf(s))


def _member_element(model, m, rows: dict[str, int]) -> dict:
    ct = m.ctype
    kind = MEMBER_KINDS.index((model.dim, ct.name))
    values = m.rigid.constant_values
    labels = [f"{m.name}.rigid.{VECTOR_NAMES[s]}{VECTOR_NAMES[t]}" for s, t in ct.pairs]
    cols = [-1 if i is None else i for i in model.layout.member_indices(m.name)]
    return {"kind": kind, "cols": cols, "const": model.layout.member_constant(m.name),
            "c": [float(values[n]) for n in member_constant_names(model.dim, ct.name)],
            "labels": labels, "rows": [rows.get(label, -1) for label in labels]}


def _features(ctx: _Recorder, joints: list[_Joint]):
    """Resolve every vector argument to a feature id; returns ``(ids per joint, features)``
    with features as ``(entries [(component, column, coefficient)], constant)``, deduplicated."""
    args = [ca.SX(v) for j in joints for v in j.vectors]
    dim = ctx.dim
    if not args:
        return [[] for _ in joints], []
    X = ca.vertcat(*args)
    for sym, what in ((ctx.t, "time"), (ctx.p, "parameters")):
        if sym.numel() and ca.depends_on(X, sym):
            raise CodegenError(f"element tables: a joint's point or direction depends on {what}")
    J = ca.jacobian(X, ctx.q)
    if ca.depends_on(J, ctx.q):
        raise CodegenError("element tables: a joint's point or direction is not affine in q")
    values = ca.Function("affine", [ctx.q], [X, J])
    X0, J0 = values(np.zeros(ctx.layout.nq))
    rows, cols = J0.sparsity().get_triplet()
    coef = np.array(J0.nonzeros())
    g = np.array(X0).reshape(-1)
    per_row: list[list[tuple[int, float]]] = [[] for _ in range(X.numel())]
    for r, c, v in zip(rows, cols, coef):
        if v != 0.0:
            per_row[r].append((c, v))
    ids, features, seen = [], [], {}
    k = 0
    for j in joints:
        mine = []
        for _ in j.vectors:
            entries = tuple((a, c, v) for a in range(dim) for c, v in sorted(per_row[k + a]))
            const = tuple(g[k:k + dim])
            key = (entries, const)
            if key not in seen:
                seen[key] = len(features)
                features.append(key)
            mine.append(seen[key])
            k += dim
        ids.append(mine)
    return ids, features


def _csc(n_rows: int, n_cols: int, rows: np.ndarray, cols: np.ndarray):
    """``(indptr, indices, positions)``: the CSC pattern of the entries ``(rows, cols)`` and
    the nonzero each entry is."""
    keys = cols.astype(np.int64) * max(n_rows, 1) + rows.astype(np.int64)
    unique = np.unique(keys)
    positions = np.searchsorted(unique, keys).astype(np.int32)
    counts = np.bincount((unique // max(n_rows, 1)).astype(np.int64), minlength=n_cols)
    indptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int32)
    return indptr, (unique % max(n_rows, 1)).astype(np.int32), positions


def _ptr(lengths) -> np.ndarray:
    return np.concatenate([[0], np.cumsum(np.asarray(lengths, dtype=np.int64))]).astype(np.int32)


def _ints(values) -> np.ndarray:
    return np.asarray(values, dtype=np.int32).reshape(-1)


def _reals(values) -> np.ndarray:
    return np.asarray(values, dtype=np.float64).reshape(-1)


def _pack(model, ctx: _Recorder | None, members: list[dict], joints: list[_Joint], rows: dict[str, int],
          extra: list[_Joint]) -> ModelTables:
    dim, nq, nc = model.dim, model.layout.nq, len(model.constraint_names)
    ids, features = _features(ctx, joints + extra) if joints or extra else ([], [])
    ids, point_ids = ids[:len(joints)], ids[len(joints):]
    a_rows, a_cols, m_rows, m_cols = _member_entries(members)
    n_member_a = len(a_rows)
    el_rows = [[rows.get(label, -1) if label is not None else -1 for label in j.labels] for j in joints]
    for mine, rr in zip(ids, el_rows):
        rows_j, cols_j = _joint_entries(rr, mine, features)
        a_rows += rows_j
        a_cols += cols_j
    a_indptr, a_indices, a_pos = _csc(nc, nq, _ints(a_rows), _ints(a_cols))
    m_indptr, m_indices, m_pos = _csc(nq, nq, _ints(m_rows), _ints(m_cols))
    member_a = [sum(1 for r in m["rows"] if r >= 0) * sum(1 for c in m["cols"] if c >= 0) for m in members]
    member_m = [sum(1 for c in m["cols"] if c >= 0) ** 2 for m in members]
    joint_a = [sum(1 for r in rr if r >= 0) * sum(len(features[f][0]) for f in mine)
               for rr, mine in zip(el_rows, ids)]
    arrays = {
        "feat_ptr": _ptr([len(f[0]) for f in features]),
        "feat_row": _ints([a for f in features for a, _, _ in f[0]]),
        "feat_col": _ints([c for f in features for _, c, _ in f[0]]),
        "feat_coef": _reals([v for f in features for _, _, v in f[0]]),
        "feat_const": _reals([x for f in features for x in f[1]]),
        "el_kind": _ints([j.kind for j in joints]),
        "el_arg_ptr": _ptr([len(i) for i in ids]), "el_arg": _ints([f for i in ids for f in i]),
        "el_sc_ptr": _ptr([len(j.scalars) for j in joints]), "el_sc": _reals([s for j in joints for s in j.scalars]),
        "el_row_ptr": _ptr([len(r) for r in el_rows]), "el_row": _ints([r for rr in el_rows for r in rr]),
        "el_apos_ptr": _ptr(joint_a), "el_apos": a_pos[n_member_a:],
        "mem_kind": _ints([m["kind"] for m in members]),
        "mem_q_ptr": _ptr([len(m["cols"]) for m in members]), "mem_q_col": _ints([c for m in members for c in m["cols"]]),
        "mem_q_const": _reals([x for m in members for x in m["const"]]),
        "mem_c_ptr": _ptr([len(m["c"]) for m in members]), "mem_c": _reals([x for m in members for x in m["c"]]),
        "mem_row_ptr": _ptr([len(m["rows"]) for m in members]), "mem_row": _ints([r for m in members for r in m["rows"]]),
        "mem_apos_ptr": _ptr(member_a), "mem_apos": a_pos[:n_member_a],
        "mem_mpos_ptr": _ptr(member_m), "mem_mpos": m_pos,
    }
    return ModelTables(model.name, dim, nq, nc, arrays, a_indptr, a_indices, m_indptr, m_indices,
                       _kinds_used(joints, members), [i[0] for i in point_ids])


def _member_entries(members: list[dict]) -> tuple[list, list, list, list]:
    """``(rows, columns)`` of the entries of A and then of M that the members add, in the loop
    order of ``ncgen_tables_jacobian`` / ``_mass``: each of a member's constraint rows against
    its free coordinates, each free coordinate against the others."""
    a_rows, a_cols, m_rows, m_cols = [], [], [], []
    for m in members:
        free = [c for c in m["cols"] if c >= 0]
        for r in m["rows"]:
            if r >= 0:
                a_rows += [r] * len(free)
                a_cols += free
        for c in free:
            m_rows += free
            m_cols += [c] * len(free)
    return a_rows, a_cols, m_rows, m_cols


def _joint_entries(rows: list[int], feature_ids, features) -> tuple[list, list]:
    """``(rows, columns)`` of the entries of A a joint element adds: each of its constraint
    ``rows`` (-1: dropped) against the coordinates of each of its features, in the loops' order."""
    a_rows, a_cols = [], []
    for r in rows:
        if r < 0:
            continue
        for f in feature_ids:
            entries = features[f][0]
            a_rows += [r] * len(entries)
            a_cols += [c for _, c, _ in entries]
    return a_rows, a_cols


def _kinds_used(joints: list[_Joint], members: list[dict]) -> dict[str, int]:
    """How many joint elements and members of each kind (the kernels' names) the tables hold."""
    used: dict[str, int] = {}
    for name in [joint_kind_name(*JOINT_KINDS[j.kind]) for j in joints] + \
            [member_kind_name(*MEMBER_KINDS[m["kind"]]) for m in members]:
        used[name] = used.get(name, 0) + 1
    return used

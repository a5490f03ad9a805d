"""Kinematics on the constraint manifold: assembly, velocity projection, DOF, driven motion.

* :func:`assemble` — Newton–Raphson onto ``Φ(t, q) = 0`` from an approximate ``q``, keeping
  chosen coordinates fixed.  Each step is the minimum-norm correction of the free
  coordinates, ``Δq_f = −A_f⁺ Φ`` (least squares: redundant constraints and spare degrees of
  freedom are fine).
* :func:`project_velocity` — the velocity closest to a given one in the kinetic-energy
  metric that satisfies ``A v = −Φ_t``, again keeping chosen components fixed:
  ``v_f = v̄_f + M_ff⁻¹ A_fᵀ μ`` with ``(A_f M_ff⁻¹ A_fᵀ) μ = −Φ_t − A v̄``.
* :func:`dof_report` — rank of ``A``, degrees of freedom ``nq − rank A`` and the names of
  the constraints that depend on earlier ones (:func:`~ncgen.assembly.rank.dependent_rows`).

A model with rolling elements (``model.rolling``, :mod:`ncgen.assembly.nonholonomic`) has
more rows: the elements' heights join ``Φ`` (assembly, the velocity projection and the
rank of ``dof_report``), and their nonholonomic rows ``B(q) v = c(q, t)`` join ``A v = −Φ_t``
in the velocity projection and the velocity degrees of freedom ``nq − rank Â``,
``Â = [Φ̂_q; B]`` (assembly, a position-level problem, has no use for them).
* :func:`solve_kinematics` — position, velocity and acceleration of a driven (0-DOF)
  mechanism over a time grid: ``Φ(t, q) = 0``, ``A v = −Φ_t``, ``A a = γ``.

Coordinates to keep fixed (``fix=``) are named like ``"crank.r_j.x"`` (one coordinate),
``"crank.r_j"`` (a basic point or base vector), ``"crank"`` (every coordinate of a member)
or given by index in q.  Driven joints need no fixing: their drives are constraints.
Coordinates to set (``values={name: value}``) may also be coordinates as written that
coordinate sharing re-based (``model.coordinate(name)``: ``s · q + c``); those become the
extra equations ``s · q + c = value`` of the Newton step (all coordinates free).
Units: q in m, v in m/s, a in m/s², t in s.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ncgen.assembly.manifold import NEWTON_ITER as MAX_ITER, NEWTON_TOL as TOL, newton, numerical_rank, project,\
    system_size
from ncgen.assembly.rank import dependent_rows
from ncgen.errors import ModelError
from ncgen.model.expressions import did_you_mean

# ------------------------------------------------------------ coordinate names
def resolve_fix(layout, members: dict, fix) -> list[int]:
    """Indices in q of the coordinates named in ``fix`` (see the module docstring)."""
    if isinstance(fix, (str, int, np.integer)):
        fix = [fix]
    out: set[int] = set()
    d = layout.dim
    for item in fix:
        if isinstance(item, (int, np.integer)) and not isinstance(item, bool):
            if not 0 <= item < layout.nq:
                raise ModelError(f"fix: coordinate index {item} out of range (nq = {layout.nq})")
            out.add(int(item))
            continue
        if not isinstance(item, str):
            raise ModelError(f"fix: expected coordinate names or indices, got {item!r}")
        parts = item.split(".")
        m = members.get(parts[0])
        if m is None or len(parts) > 3:
            known = list(members) + layout.coordinate_names
            raise ModelError(f"fix: no coordinate, slot or member named {item!r}{did_you_mean(item, known)}")
        idx = layout.member_indices(m.name)
        slots = m.ctype.slots
        if len(parts) == 1:
            chosen = range(len(idx))
        else:
            if parts[1] not in slots:
                raise ModelError(f"fix: {m.name} ({m.ctype.name}) has slots {', '.join(slots)}, "
                                 f"got {parts[1]!r}{did_you_mean(parts[1], slots)}")
            s = slots.index(parts[1])
            axes = "xyz"[:d]
            if len(parts) == 3 and parts[2] not in axes:
                raise ModelError(f"fix: axis of {item!r}: expected one of {', '.join(axes)}")
            chosen = [s * d + axes.index(parts[2])] if len(parts) == 3 else range(s * d, s * d + d)
        out.update(idx[k] for k in chosen if idx[k] is not None)
    return sorted(out)


# ------------------------------------------------------------------ model API
def _numeric(model, t, p):
    t = model.t0 if t is None else float(t)
    p = model.p0 if p is None else np.asarray(p, float)
    f = model.functions

    def phi(x):
        return np.asarray(f["phi"](t, x, p), dtype=float).reshape(-1)

    def jac(x):
        return np.asarray(f["A"](t, x, p), dtype=float)

    return t, p, phi, jac


def _element_rows(model, t: float) -> tuple[list[str], int, Callable, Callable, Callable]:
    """The rows that ``model``'s rolling elements add (none without them), from its
    :func:`~ncgen.assembly.nonholonomic.rolling_system`: ``(names, n_heights, height(q),
    rows(q), rate(q))`` — the names of the heights then of the nonholonomic rows, the heights'
    residuals (m), the Jacobian rows of the heights then ``B(q)``, and their right-hand sides
    ``ĉ`` (zeros for the heights; the plane's rates at ``t`` for the rolling rows, m/s)."""
    if not getattr(model, "rolling", ()):
        empty = np.zeros((0, model.nq))
        return [], 0, lambda x: np.zeros(0), lambda x: empty, lambda x: np.zeros(0)
    from ncgen.assembly.nonholonomic import rolling_system
    system, nc = rolling_system(model), model.nc
    n_heights = system.n_holonomic - nc
    return (system.row_names[nc:], n_heights,
            lambda x: np.asarray(system.phi_at(x, t), float).reshape(-1)[nc:],
            lambda x: np.asarray(system.A_at(x, t), float)[nc:],
            lambda x: np.asarray(system.rate(x, t), float).reshape(-1)[nc:])


def _free(model, fix) -> np.ndarray:
    fixed = set(resolve_fix(model.layout, model.members, fix))
    return np.array([i for i in range(model.nq) if i not in fixed], dtype=int)


def _values(model, values: dict | None, what: str) -> tuple[dict, np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """``values`` split into ``{index: value}`` for the model's own coordinates and, for the
    coordinates as written (``written``), the rows ``S q + c = x`` of ``model.coordinate``."""
    from ncgen.validation import as_scalar
    if values is not None and not isinstance(values, dict):
        raise ModelError(f"{what}: expected {{coordinate name: value}}, got {type(values).__name__} {values!r}")
    direct, rows, offsets, given, written = {}, [], [], [], []
    for name, value in (values or {}).items():
        x = as_scalar(value, f"{what} {name!r}")
        if name in model.coordinate_names:
            direct[model.coordinate_names.index(name)] = x
            continue
        s, c = model.coordinate(name)
        rows.append(s)
        offsets.append(c)
        given.append(x)
        written.append(name)
    return direct, np.array(rows).reshape(-1, model.nq), np.array(offsets), np.array(given), written


def assemble(model, q=None, *, t=None, p=None, fix=(), values: dict | None = None, tol: float = TOL,
             max_iter: int = MAX_ITER) -> np.ndarray:
    """``q`` (default ``model.q0``) moved onto ``Φ(t, q) = 0`` by Newton, the coordinates in
    ``fix`` kept and those in ``values`` (``{name: value}``, m; names as written resolve,
    see the module docstring) set; raises :class:`ModelError` naming the worst constraint
    if it fails.  With rolling elements, their heights are among the equations."""
    q = np.array(model.q0 if q is None else q, dtype=float)
    t, p, phi, jac = _numeric(model, t, p)
    element_names, n_heights, height, rows, _ = _element_rows(model, t)
    if n_heights:
        phi_m, jac_m = phi, jac
        phi = lambda x: np.concatenate([phi_m(x), height(x)])          # noqa: E731
        jac = lambda x: np.vstack([jac_m(x), rows(x)[:n_heights]])     # noqa: E731
    direct, S, c, x_w, written = _values(model, values, "values")
    for i, value in direct.items():
        q[i] = value
    fix = [fix] if isinstance(fix, (str, int, np.integer)) else list(fix)
    free = _free(model, fix + list(direct))
    if written:
        phi0, jac0 = phi, jac
        phi = lambda x: np.concatenate([phi0(x), S @ x + c - x_w])  # noqa: E731
        jac = lambda x: np.vstack([jac0(x), S])                     # noqa: E731
    size = system_size(q)
    q_new, it, res = newton(phi, jac, q, free, tol=tol * size**2, max_iter=max_iter)
    if res > tol * size**2 or not np.isfinite(res):
        r = phi(q_new)
        worst = int(np.nanargmax(np.abs(r)))
        label = (model.constraint_names + element_names[:n_heights]
                 + [f"{n} = {x:g}" for n, x in zip(written, x_w)])[worst]
        kept = model.nq - free.size + len(written)
        hint = f" with {kept} coordinate(s) fixed" if kept else ""
        raise ModelError(f"assembly failed{hint}: after {it} Newton iterations "
                         f"{label} still has the residual {abs(r[worst]):.3g} "
                         "(check the geometry, the drives and the fixed coordinates)")
    return q_new


def project_velocity(model, q, v=None, *, t=None, p=None, fix=(), values: dict | None = None) -> np.ndarray:
    """The velocity nearest to ``v`` (default ``model.v0``) in the kinetic-energy metric that
    satisfies ``A v = −Φ_t`` at ``(t, q)``; the components in ``fix`` are kept and the
    rates in ``values`` (``{coordinate name: rate}``, m/s; names as written resolve, their
    rate ``s · v``) set.  With rolling elements the rows of their heights and their rolling
    rows ``B(q) v = c(q, t)`` are kept too (all rows ``Â v = ĉ``)."""
    q = np.asarray(q, float)
    v = np.array(model.v0 if v is None else v, dtype=float)
    t, p, _, jac = _numeric(model, t, p)
    direct, S, _, x_w, written = _values(model, values, "rates")
    for i, value in direct.items():
        v[i] = value
    fix = [fix] if isinstance(fix, (str, int, np.integer)) else list(fix)
    phi_t = np.asarray(model.functions["phi_t"](t, q, p), dtype=float).reshape(-1)
    _, _, _, rows, rate = _element_rows(model, t)
    A, b = np.vstack([jac(q), rows(q)]), np.concatenate([-phi_t, rate(q)])
    if written:                        # s · v = value
        A, b = np.vstack([A, S]), np.concatenate([b, x_w])
    return project(A, b, v, model.M, _free(model, fix + list(direct)))


@dataclass
class DofReport:
    """Constraint rank and degrees of freedom at one configuration.  With rolling elements,
    ``heights`` (their holonomic rows) are in ``rank`` (of ``Φ̂_q``: ``dof`` is then the
    configuration's) and ``rolling`` (their nonholonomic rows) in ``velocity_rank`` (of
    ``Â = [Φ̂_q; B]``): ``velocity_dof = nq − rank Â``, the velocities free at ``q``."""

    nq: int
    nc: int
    rank: int
    dependent: list[str]                    # constraints depending on earlier ones, at q
    dropped: list[str] = field(default_factory=list)   # dropped as redundant when building
    heights: list[str] = field(default_factory=list)   # rolling elements' height rows
    rolling: list[str] = field(default_factory=list)   # rolling elements' nonholonomic rows
    velocity_rank: int | None = None        # rank Â (None: no rolling rows, = rank)

    @property
    def dof(self) -> int:
        return self.nq - self.rank

    @property
    def velocity_dof(self) -> int:
        return self.nq - (self.rank if self.velocity_rank is None else self.velocity_rank)

    @property
    def redundant(self) -> list[str]:
        return self.dropped + self.dependent

    def rolling_summary(self) -> str:
        """The line on the rolling rows ("" without rolling elements)."""
        if not self.heights and not self.rolling:
            return ""
        heights = f" ({', '.join(self.heights)})" if self.heights else ""
        return (f"rolling elements: {len(self.heights)} height row(s){heights} counted in rank A and DOF, "
                f"{len(self.rolling)} nonholonomic row(s) ({', '.join(self.rolling)}): "
                f"rank Â = {self.velocity_rank}, velocity DOF = {self.velocity_dof}")

    def __str__(self) -> str:
        red = ", ".join(self.redundant) or "none"
        written = f" ({self.nc + len(self.dropped)} as written, {len(self.dropped)} dropped)" if self.dropped else ""
        rolling = self.rolling_summary()
        return (f"nq = {self.nq} coordinates, nc = {self.nc} constraints{written}, "
                f"rank A = {self.rank}, DOF = {self.dof}\n" + (rolling + "\n" if rolling else "")
                + f"redundant constraints: {red}")


def dof_report(model, q=None, *, t=None, p=None) -> DofReport:
    """Rank of ``A(t, q)`` (default the initial state) and the constraints that are linearly
    dependent there; those dropped at build time are listed as ``dropped``.  With rolling
    elements, ``rank`` counts their heights too and ``velocity_rank`` all their rows (see
    :class:`DofReport`)."""
    q = model.q0 if q is None else np.asarray(q, float)
    t, _, _, jac = _numeric(model, t, p)
    names, n_heights, _, rows, _ = _element_rows(model, t)
    extra = rows(q)
    A_hat = np.vstack([jac(q), extra])
    nh = model.nc + n_heights
    rank = numerical_rank(A_hat[:nh])
    labels = list(model.constraint_names) + names
    dep = [labels[i] for i in dependent_rows(A_hat)]
    dropped = list(model.redundant) if model.redundant_dropped else []
    if not names:
        return DofReport(model.nq, model.nc, rank, dep, dropped)
    return DofReport(model.nq, model.nc, rank, dep, dropped, heights=names[:n_heights], rolling=names[n_heights:],
                     velocity_rank=numerical_rank(A_hat))


@dataclass
class KinematicSolution:
    """Motion of a driven mechanism: rows of ``q``, ``v``, ``a`` are the times ``t``;
    ``residual`` is the largest |Φ| met (m²)."""

    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    a: np.ndarray
    residual: float


def solve_kinematics(model, times, *, q=None, p=None, tol: float = TOL) -> KinematicSolution:
    """Positions, velocities and accelerations of a mechanism whose every degree of freedom
    is driven, at each of ``times`` (s, increasing), starting from ``q`` (default
    ``model.q0``) and following the branch it is on."""
    times = np.asarray(times, dtype=float).reshape(-1)
    if times.size == 0 or np.any(np.diff(times) <= 0):
        raise ModelError("solve_kinematics: times: expected an increasing, non-empty sequence")
    p = model.p0 if p is None else np.asarray(p, float)
    q = model.q0 if q is None else np.asarray(q, float)
    f = model.functions
    report = dof_report(model, q, t=times[0], p=p)
    if report.dof > 0:
        raise ModelError(f"solve_kinematics: the mechanism has {report.dof} degree(s) of freedom at "
                         f"t = {times[0]:g} s; drive them (Revolute/Prismatic/Distance drive=..., "
                         "CoordinateDriver) or use a dynamic simulation")
    free = np.arange(model.nq)
    Q, V, Acc = (np.zeros((times.size, model.nq)) for _ in range(3))
    v = np.zeros(model.nq)
    a = np.zeros(model.nq)
    worst = 0.0
    size = system_size(q)
    for k, t in enumerate(times):
        if k:
            h = t - times[k - 1]
            q = q + h * v + 0.5 * h * h * a
        _, _, phi, jac = _numeric(model, t, p)
        q, it, res = newton(phi, jac, q, free, tol=tol * size**2)
        if res > tol * size**2 or not np.isfinite(res):
            raise ModelError(f"solve_kinematics: no configuration found at t = {t:g} s (residual "
                             f"{res:.3g} after {it} iterations): the drives may leave the reachable range")
        A = jac(q)
        rank = numerical_rank(A)
        if rank < model.nq:
            raise ModelError(f"solve_kinematics: singular configuration at t = {t:g} s "
                             f"(rank A = {rank} < nq = {model.nq})")
        phi_t = np.asarray(f["phi_t"](t, q, p), dtype=float).reshape(-1)
        v = np.linalg.lstsq(A, -phi_t, rcond=None)[0]
        gamma = np.asarray(f["gamma"](t, q, v, p), dtype=float).reshape(-1)
        a = np.linalg.lstsq(A, gamma, rcond=None)[0]
        Q[k], V[k], Acc[k] = q, v, a
        worst = max(worst, res)
    return KinematicSolution(times, Q, V, Acc, worst)

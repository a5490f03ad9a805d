"""``inverse_statics``: the member forces that hold a given shape under given loads, and the
rest lengths, stiffnesses or force densities that realise them.

Conventions as in :mod:`ncgen.analysis.self_stress` (members: cables, then struts; forces
``t`` in N, tension positive; loads ``f``: n × dim, N, at the nodes).  The forces solve

    minimise ½ |t|²   subject to   A t = f,   t_c ≥ cable_min,   t_c ≤ cable_max,   −t_s ≤ strut_max,
                                   t_a e^{−μθ} ≤ t_b ≤ t_a e^{μθ}   (friction at each pulley),

over ``t = G (τ_p + S_c α)`` (``τ_p`` a particular solution, ``S_c`` the states of
self-stress): the least-norm forces, raised by self-stress until every cable carries at
least ``cable_min`` (the *minimum cable force*).  A cluster with friction ``μ`` (``friction``,
one per cluster) keeps a tension per segment; consecutive segments ``a, b`` over a pulley
node with wrap angle ``θ`` (from the shape: ``π`` minus the angle between the segments,
plus ``2π`` per extra turn in ``turns``) obey the capstan (Euler–Eytelwein) law: the cable
sticks while ``e^{−μθ} ≤ t_b / t_a ≤ e^{μθ}`` and slips at either bound.  Frictionless
clusters share one tension.  The QP (``α`` only: the number of states of self-stress) is
solved by CasADi's active-set ``qrqp`` (DAQP where it fails) and then polished on its active
set by an exact least-squares solve, so that the forces satisfy ``A t = f`` and their bounds to round-off.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ncgen.blas_threads import one_blas_thread
from ncgen.errors import NcgenError
from ncgen.analysis.self_stress import RANK_TOL, Framework, SelfStress, analyse, framework

#: Loads are in the range of ``A`` when ``|A t − f|∞`` is below this times ``|f|∞`` (≥ 1 N).
LOAD_TOL = 1e-9
#: A bound is active (and a pulley slipping) within this times the force scale.
ACTIVE_TOL = 1e-7


def capstan_ratio(mu: float, theta: float) -> float:
    """``e^{μθ}``: the largest ratio of the tensions on the two sides of a cable wrapped by
    ``θ`` (rad) over a surface with friction coefficient ``μ`` before it slips."""
    return float(np.exp(mu * theta))


@dataclass
class Pulley:
    """Where a clustered cable turns: ``cluster``, the segments ``a`` (before) and ``b``
    (after) as cable indices, the ``node``, the wrap angle ``theta`` (rad), the friction
    coefficient ``mu`` and the tension ratio ``t_b / t_a``; ``state`` ``"stick"``, or
    ``"slip"`` when the ratio is at ``e^{±μθ}`` (frictionless clusters: ``"free"``)."""

    cluster: int
    a: int
    b: int
    node: int
    theta: float
    mu: float
    ratio: float = float("nan")
    state: str = ""


@dataclass
class InverseStatics:
    """Result of :func:`inverse_statics`: ``forces`` (N, cables then struts), the
    ``tensions`` of the cables and ``strut_forces``, ``lengths`` (m), ``force_densities``
    (N/m), ``reactions`` (n × dim, N, the supports' forces on the nodes, zero elsewhere),
    ``residual = |A t − f|∞`` (N), the ``pulleys`` and the configuration's ``analysis``
    (:class:`~ncgen.analysis.self_stress.SelfStress`)."""

    framework: Framework = field(repr=False)
    analysis: SelfStress = field(repr=False)
    forces: np.ndarray
    reactions: np.ndarray = field(repr=False)
    residual: float
    pulleys: list = field(default_factory=list)

    @property
    def lengths(self) -> np.ndarray:
        return self.framework.lengths()

    @property
    def tensions(self) -> np.ndarray:
        return self.forces[:len(self.framework.cables)]

    @property
    def strut_forces(self) -> np.ndarray:
        return self.forces[len(self.framework.cables):]

    @property
    def force_densities(self) -> np.ndarray:
        return self.forces / self.lengths

    def rest_lengths(self, stiffness=None, *, axial_stiffness=None) -> np.ndarray:
        """Per member the rest length (m) that gives it its force at its length: with a spring
        ``stiffness`` k (N/m, ``t = k (l − l₀)``) ``l₀ = l − t / k``; with an
        ``axial_stiffness`` EA (N, ``t = EA (l − l₀) / l₀``) ``l₀ = EA l / (EA + t)``.  A number or
        one per member.  Raises if a rest length would not be positive."""
        if (stiffness is None) == (axial_stiffness is None):
            raise NcgenError("rest_lengths: give exactly one of stiffness (N/m) and axial_stiffness (EA, N)")
        what = "stiffness" if axial_stiffness is None else "axial_stiffness"
        k = self._per_member(stiffness if axial_stiffness is None else axial_stiffness, what)
        t, l = self.forces, self.lengths
        l0 = l - t / k if axial_stiffness is None else k * l / (k + t)
        bad = np.flatnonzero(~(l0 > 0))
        if bad.size:
            e = int(bad[0])
            raise NcgenError(f"rest_lengths: {self._name(e)} would need a rest length {l0[e]:.3g} m <= 0 to carry "
                             f"{t[e]:.6g} N at {what} {k[e]:g}; raise the {what}")
        return l0

    def stiffnesses(self, rest_lengths) -> np.ndarray:
        """Per member the spring stiffness (N/m) ``k = t / (l − l₀)`` that gives it its force
        with these ``rest_lengths`` (m, one per member); raises where it is not positive."""
        l0 = self._per_member(rest_lengths, "rest_lengths")
        dl = self.lengths - l0
        with np.errstate(divide="ignore", invalid="ignore"):
            k = self.forces / dl
        bad = np.flatnonzero(~(k > 0) | ~np.isfinite(k))
        if bad.size:
            e = int(bad[0])
            raise NcgenError(f"stiffnesses: {self._name(e)}: force {self.forces[e]:.6g} N at stretch "
                             f"{dl[e]:.3g} m (length {self.lengths[e]:.6g} m, rest length {l0[e]:.6g} m) needs a "
                             "stiffness that is not positive; a member in tension needs l > l0, in compression l < l0")
        return k

    def _per_member(self, x, what: str) -> np.ndarray:
        m = len(self.forces)
        a = np.asarray(x, float)
        if a.ndim > 1 or a.size not in (1, m) or not np.all(np.isfinite(a)) or np.any(a <= 0):
            raise NcgenError(f"{what}: expected a positive number or {m} positive numbers (cables, then struts), "
                             f"got {x!r}")
        return np.broadcast_to(a.reshape(-1), (m,)).astype(float)

    def _name(self, e: int) -> str:
        nc = len(self.framework.cables)
        return f"cables[{e}]" if e < nc else f"struts[{e - nc}]"

    def table(self) -> str:
        fw = self.framework
        lines = [f"inverse statics: {len(fw.cables)} cables, {len(fw.struts)} struts, "
                 f"{self.analysis.n_self_stress} state(s) of self-stress, |A t - f| = {self.residual:.3g} N",
                 f"{'member':<10}{'nodes':>9}{'length (m)':>13}{'force (N)':>13}{'density (N/m)':>15}"]
        for e, ((i, j), l, t) in enumerate(zip(fw.members, self.lengths, self.forces)):
            lines.append(f"{self._name(e):<10}{f'{i}-{j}':>9}{l:>13.6g}{t:>13.6g}{t / l:>15.6g}")
        for p in self.pulleys:
            lines.append(f"pulley at node {p.node} (cluster {p.cluster}, cables[{p.a}] -> cables[{p.b}]): "
                         f"wrap {np.degrees(p.theta):.6g} deg, mu {p.mu:g}, t_b/t_a {p.ratio:.6g}, {p.state}")
        return "\n".join(lines) + "\n"


@one_blas_thread
def inverse_statics(nodes, struts, cables, loads=None, supports=None, *, cable_min: float = 0.0,
                    cable_max: float | None = None, strut_max: float | None = None, clusters=None,
                    friction=None, turns=None, bodies=None, tol: float = RANK_TOL) -> InverseStatics:
    """Member forces (N) holding ``nodes`` in equilibrium with the ``loads`` (n × dim, N;
    default none) on the ``supports`` (module docstring).  ``cable_min`` / ``cable_max``:
    bounds on every cable's tension (N); ``strut_max``: on every strut's compression (N);
    ``clusters``: lists of cable indices, each a cable running over the nodes its consecutive
    segments share; ``friction``: one coefficient μ per cluster (default 0: frictionless,
    one tension); ``turns``: per cluster, extra full turns at each of its pulleys (a list of
    integers, one per pulley; default none); ``bodies``: lists of node indices, each a rigid
    body (:mod:`ncgen.analysis.self_stress`; loads at its nodes act on the body)."""
    pr = problem(nodes, struts, cables, loads, supports, cable_min=cable_min, cable_max=cable_max,
                 strut_max=strut_max, clusters=clusters, friction=friction, turns=turns, bodies=bodies, tol=tol,
                 who="inverse_statics")
    return pr.result(least_norm(pr, "inverse_statics"))


def least_norm(pr: "Problem", who: str) -> np.ndarray:
    """The amplitudes ``α`` of the least-norm forces ``t_p + T α`` within the bounds."""
    alpha = np.linalg.solve(pr.H, -pr.g) if pr.T.shape[1] else np.zeros(0)     # unbounded least norm
    if np.any(pr.B_alpha @ alpha - pr.b_alpha > ACTIVE_TOL * pr.scale):
        if pr.T.shape[1] == 0:
            worst = int(np.argmin(pr.b_alpha))
            raise NcgenError(f"{who}: no member forces satisfy the bounds: the forces are unique (no state of "
                             f"self-stress) and violate {pr.names[worst]} by {-pr.b_alpha[worst]:.6g} N")
        alpha = _qp(pr.H, pr.g, pr.B_alpha, pr.b_alpha, pr.scale, pr.names, who)
    return alpha


@dataclass
class Problem:
    """The forces of a shape as ``t = t_p + T α`` (``T = G S_c``: the states of self-stress,
    ``α`` their amplitudes) with the bounds ``B_α α ≤ b_α`` and the least-norm objective
    ``½ αᵀ H α + gᵀ α`` (+ const); see :func:`problem`."""

    framework: Framework
    analysis: SelfStress
    f: np.ndarray
    t_p: np.ndarray
    T: np.ndarray
    B: np.ndarray
    b: np.ndarray
    names: list
    pulleys: list
    scale: float

    @property
    def H(self) -> np.ndarray:
        return self.T.T @ self.T

    @property
    def g(self) -> np.ndarray:
        return self.T.T @ self.t_p

    @property
    def B_alpha(self) -> np.ndarray:
        return self.B @ self.T

    @property
    def b_alpha(self) -> np.ndarray:
        return self.b - self.B @ self.t_p

    def forces(self, alpha) -> np.ndarray:
        return self.t_p + self.T @ np.asarray(alpha, float)

    def result(self, alpha, cls=None, **extra) -> InverseStatics:
        """The :class:`InverseStatics` (or ``cls``) of the forces ``t_p + T α``."""
        fw, f = self.framework, self.f
        n, d = fw.nodes.shape
        t = self.forces(alpha)
        full = fw.full_equilibrium_matrix() @ t
        free = fw.free
        residual = float(np.abs(fw.reduce(full - f.reshape(-1))).max(initial=0.0))
        reactions = np.zeros(n * d)
        fixed = np.setdiff1d(np.arange(n * d), free)
        reactions[fixed] = full[fixed] - f.reshape(-1)[fixed]
        for p in self.pulleys:
            p.ratio = t[p.b] / t[p.a] if t[p.a] != 0 else float("inf")
            if p.mu == 0:
                p.state = "free"
            else:
                e = capstan_ratio(p.mu, p.theta)
                near = min(abs(p.ratio - e), abs(p.ratio - 1 / e)) <= ACTIVE_TOL * max(1.0, e)
                p.state = "slip" if near else "stick"
        return (cls or InverseStatics)(framework=fw, analysis=self.analysis, forces=t,
                                       reactions=reactions.reshape(n, d), residual=residual,
                                       pulleys=self.pulleys, **extra)


def problem(nodes, struts, cables, loads=None, supports=None, *, cable_min: float = 0.0,
            cable_max: float | None = None, strut_max: float | None = None, clusters=None, friction=None,
            turns=None, bodies=None, tol: float = RANK_TOL, who: str) -> Problem:
    """The checked :class:`Problem` of :func:`inverse_statics` (same arguments)."""
    fw = framework(nodes, struts, cables, supports, clusters, who=who, bodies=bodies)
    n, d = fw.nodes.shape
    f = _loads(loads, n, d, who)
    mu = _friction(friction, len(fw.clusters), who)
    pulleys = _pulleys(fw, mu, turns, who)
    B, b, names = _inequalities(fw, pulleys, cable_min, cable_max, strut_max, who)
    # frictional clusters keep a tension per segment; frictionless ones share one
    smooth = Framework(nodes=fw.nodes, struts=fw.struts, cables=fw.cables, fixed=fw.fixed,
                       clusters=[c for c, m in zip(fw.clusters, mu) if m == 0], bodies=fw.bodies)
    an = analyse(smooth, tol)
    G = smooth.cluster_matrix()
    A_c, f_free = an.A_c, fw.reduce(f)
    scale = max(1.0, float(np.abs(f_free).max(initial=0.0)), abs(cable_min), cable_max or 0.0)
    U, sv, Vt = an.svd
    r = an.rank
    tau_p = Vt[:r].T @ ((U[:, :r].T @ f_free) / sv[:r])
    res = float(np.abs(A_c @ tau_p - f_free).max(initial=0.0))
    if res > LOAD_TOL * scale:
        raise NcgenError(f"{who}: loads: this shape cannot carry them (|A t - f| = {res:.3g} N at best: the "
                         f"loads act on an infinitesimal mechanism or a rigid motion the supports allow); "
                         f"support the structure or change its shape")
    Sc = Vt[r:].T
    return Problem(framework=fw, analysis=an, f=f, t_p=G @ tau_p, T=G @ Sc, B=B, b=b, names=names,
                   pulleys=pulleys, scale=scale)


def _loads(loads, n: int, d: int, who: str) -> np.ndarray:
    if loads is None:
        return np.zeros((n, d))
    f = np.asarray(loads, float)
    if f.shape != (n, d) or not np.all(np.isfinite(f)):
        raise NcgenError(f"{who}: loads: expected finite nodal forces of shape ({n}, {d}), got "
                         f"{'shape ' + str(f.shape) if f.shape != (n, d) else 'NaN or inf'}")
    return f


def _friction(friction, nclusters: int, who: str) -> np.ndarray:
    if friction is None:
        return np.zeros(nclusters)
    mu = np.asarray(friction, float).reshape(-1)
    if mu.size != nclusters or not np.all(np.isfinite(mu)) or np.any(mu < 0):
        raise NcgenError(f"{who}: friction: expected {nclusters} coefficient(s) >= 0 (one per cluster), "
                         f"got {friction!r}")
    return mu


def _pulleys(fw: Framework, mu: np.ndarray, turns, who: str) -> list[Pulley]:
    turns = [None] * len(fw.clusters) if turns is None else list(turns)
    if len(turns) != len(fw.clusters):
        raise NcgenError(f"{who}: turns: expected one list per cluster ({len(fw.clusters)}), got {len(turns)}")
    out = []
    for c, (cl, extra) in enumerate(zip(fw.clusters, turns)):
        extra = [0] * (len(cl) - 1) if extra is None else list(extra)
        if len(extra) != len(cl) - 1 or not all(isinstance(k, (int, np.integer)) and k >= 0 for k in extra):
            raise NcgenError(f"{who}: turns[{c}]: expected {len(cl) - 1} integer(s) >= 0 (one per pulley of "
                             f"cluster {c}), got {extra!r}")
        for (a, b), k in zip(zip(cl, cl[1:]), extra):
            node = (set(fw.cables[a]) & set(fw.cables[b])).pop()
            u = fw.nodes[sum(fw.cables[a]) - node] - fw.nodes[node]
            v = fw.nodes[sum(fw.cables[b]) - node] - fw.nodes[node]
            cos = np.clip(u @ v / np.linalg.norm(u) / np.linalg.norm(v), -1.0, 1.0)
            out.append(Pulley(cluster=c, a=a, b=b, node=node, theta=float(np.pi - np.arccos(cos) + 2 * np.pi * k),
                              mu=float(mu[c])))
    return out


def _inequalities(fw: Framework, pulleys, cable_min, cable_max, strut_max, who: str):
    """``(B, b, names)``: the bounds as ``B t ≤ b``."""
    nc, m = len(fw.cables), len(fw.members)
    rows, rhs, names = [], [], []
    eye = np.eye(m)
    for name, value in (("cable_min", cable_min), ("cable_max", cable_max), ("strut_max", strut_max)):
        if value is not None and not (np.isfinite(value) and value >= 0):
            raise NcgenError(f"{who}: {name}: expected a finite number >= 0 (N; cables only pull), got {value!r}")
    if cable_max is not None and cable_max < cable_min:
        raise NcgenError(f"{who}: cable_max: expected at least cable_min = {cable_min:g} N, got {cable_max:g}")
    for e in range(nc):
        rows.append(-eye[e]), rhs.append(-cable_min), names.append(f"cables[{e}] >= cable_min")
        if cable_max is not None:
            rows.append(eye[e]), rhs.append(cable_max), names.append(f"cables[{e}] <= cable_max")
    if strut_max is not None:
        for e in range(nc, m):
            rows.append(-eye[e]), rhs.append(strut_max), names.append(f"struts[{e - nc}] compression <= strut_max")
    for p in pulleys:
        if p.mu > 0:
            r = capstan_ratio(p.mu, p.theta)
            rows.append(eye[p.b] - r * eye[p.a]), rhs.append(0.0), names.append(f"pulley at node {p.node}")
            rows.append(eye[p.a] - r * eye[p.b]), rhs.append(0.0), names.append(f"pulley at node {p.node}")
    return np.array(rows).reshape(-1, m), np.array(rhs), names


def _qp(H, g, B, b, scale, names, who) -> np.ndarray:
    import casadi as ca

    n = H.shape[0]
    reg = 1e-14 * max(1.0, np.abs(H).max())
    pattern = {"h": ca.Sparsity.dense(n, n), "a": ca.Sparsity.dense(*B.shape)}
    # qrqp first; on a degenerate active set (several states of self-stress meeting one bound)
    # it can stop short of a feasible problem's solution: DAQP then
    for plugin, opts in (("qrqp", {"print_iter": False, "print_header": False, "print_info": False}),
                         ("daqp", {})):
        solver = ca.conic("inverse_statics", plugin, pattern, {**opts, "error_on_fail": False})
        sol = solver(h=H + reg * np.eye(n), g=g, a=B, lba=-np.inf, uba=b)
        alpha = np.array(sol["x"]).reshape(-1)
        viol = B @ alpha - b
        ok = solver.stats()["success"] and viol.max(initial=0.0) <= 1e-6 * scale
        if ok:
            break
    if not ok:
        worst = int(np.argmax(viol))
        raise NcgenError(f"{who}: no member forces satisfy the bounds (cable_min, cable_max, strut_max, "
                         f"friction); the closest violates {names[worst]} by {max(viol[worst], 0):.3g} N: loosen "
                         "the bounds, change the shape or the loads")
    active = np.flatnonzero(viol > -ACTIVE_TOL * scale)
    if active.size:
        # exact solve of the equality-constrained QP on the active set (KKT, least squares)
        Ba = B[active]
        K = np.block([[H, Ba.T], [Ba, np.zeros((active.size, active.size))]])
        z = np.linalg.lstsq(K, np.concatenate([-g, b[active]]), rcond=None)[0]
        polished = z[:n]
        if (B @ polished - b).max(initial=0.0) <= 1e-12 * scale:
            alpha = polished
    return alpha

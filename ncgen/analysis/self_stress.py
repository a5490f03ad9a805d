"""Self-stress and infinitesimal mechanisms of a pin-jointed configuration (struts and
cables between nodes), and its prestress stability.

Conventions.  ``nodes`` (n × dim, m); members are the ``cables`` then the ``struts`` (pairs
of node indices), so member ``e < len(cables)`` is cable ``e``; member forces ``t`` are in N,
tension positive (struts carry ``t < 0``); force densities ``q = t / l`` (N/m).  Supports
fix node coordinates: ``supports`` maps a node to the axes it is held along (``"xyz"``,
``"z"``, …) or is a list of nodes held along every axis.  A *clustered* cable (``clusters``:
lists of cable indices, its segments) runs frictionlessly through the nodes its segments
share: one tension ``τ`` for all its segments, ``t = G τ`` (``G``: members × tensions).

The *equilibrium matrix* ``A`` (free coordinates × members) has, in member ``e = (i, j)``'s
column, ``(x_i − x_j) / l_e`` at node i and the opposite at node j, so that ``A t = f`` is the
balance of the member forces with the external loads ``f`` at the nodes.  With
``A_c = A G`` (``= A`` without clusters) of rank ``r``, and ``k`` the rigid motions the
supports allow, Calladine's extended Maxwell rule counts

    states of self-stress      s = n_t − r           (null A_c, n_t = columns of G)
    infinitesimal mechanisms   m = n_free − k − r    (null A_cᵀ ⊖ rigid motions)

so that ``s − m = n_t − (n_free − k)``.  The *geometric stiffness* of a prestress is
``K_G = D ⊗ I_dim`` (``D = Cᵀ diag(q) C``, ``C`` the member–node incidence), the material
stiffness ``K_E = A_c diag(k_t) A_cᵀ`` (``k_t`` N/m per tension), the tangent stiffness
``K_T = K_E + K_G − A diag(q) Aᵀ`` (Guest 2006: at fixed tension a member's stiffness across
itself is ``q (I − u uᵀ)``).  On the mechanisms the terms in ``A`` vanish: the structure is *prestress-stable*
under ``t`` when ``Q = Mᵀ K_G M`` (``M`` an orthonormal basis of the mechanisms, N/m) is
positive definite.  The counterpart in natural coordinates: an ``rr`` bar's length
constraint has the gradient ``l`` × its strut's column of ``A``.

*Rigid bodies* (``bodies``: lists of node indices, each a rigid body the cables and struts
attach to at those nodes) replace their nodes' coordinates by the body's motion
``z_b = (c, θ)`` (translation of the centroid ``c`` of its nodes and rotation ``θ``: 6 in 3D,
3 in 2D): a node ``i`` of body ``b`` moves by ``δx_i = δc + δθ × ρ_i`` (``ρ_i = x_i − c``).
With ``T`` that kinematic map (all node coordinates × *free coordinates*: the free
coordinates of the nodes outside bodies, then each body's ``(c, θ)``) the equilibrium
matrix is ``A = Tᵀ A_nodes`` (a body's rows: the force and the moment about ``c`` of its
members, N and N·m) and loads reduce to ``Tᵀ f``.  Its geometric stiffness adds the
curvature of the rotation, ``Σ_i ½ (g_i ρ_iᵀ + ρ_i g_iᵀ) − (g_i · ρ_i) I`` on ``θ``
(``g = A_nodes t``, the members' pull at the body's nodes; loads on the body do not enter it:
prestress stability is that of the self-stress).  A body's nodes take no supports (hold a
body by members to supported nodes); a body of two nodes spins freely about its axis (a
mechanism no member loads).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ncgen.blas_threads import one_blas_thread
from ncgen.errors import NcgenError
from ncgen.analysis.formfinding import rigid_motions
from ncgen.analysis.stability import classify
from ncgen.assembly.manifold import RANK_TOL       # the one rank rule: singular values below it × the largest are zero
AXES = "xyz"


@dataclass
class Framework:
    """Nodes, members, supports and clusters, checked (see the module docstring)."""

    nodes: np.ndarray
    struts: list
    cables: list
    fixed: np.ndarray                     # n × dim booleans: coordinate held by a support
    clusters: list = field(default_factory=list)
    bodies: list = field(default_factory=list)     # lists of node indices, each a rigid body

    @property
    def dim(self) -> int:
        return self.nodes.shape[1]

    @property
    def members(self) -> list:
        return self.cables + self.struts

    @property
    def free(self) -> np.ndarray:
        """Indices of the free coordinates in ``nodes.reshape(-1)``."""
        return np.flatnonzero(~self.fixed.reshape(-1))

    def lengths(self) -> np.ndarray:
        return np.array([np.linalg.norm(self.nodes[j] - self.nodes[i]) for i, j in self.members])

    def incidence(self) -> np.ndarray:
        """``C`` (members × nodes): +1 at the first node of a member, −1 at its second."""
        C = np.zeros((len(self.members), len(self.nodes)))
        for e, (i, j) in enumerate(self.members):
            C[e, i], C[e, j] = 1.0, -1.0
        return C

    def full_equilibrium_matrix(self) -> np.ndarray:
        """``A`` over all node coordinates (n·dim × members)."""
        n, d = self.nodes.shape
        A = np.zeros((n * d, len(self.members)))
        for e, ((i, j), l) in enumerate(zip(self.members, self.lengths())):
            u = (self.nodes[i] - self.nodes[j]) / l
            A[i * d:(i + 1) * d, e], A[j * d:(j + 1) * d, e] = u, -u
        return A

    def equilibrium_matrix(self) -> np.ndarray:
        """``A = Tᵀ A_nodes`` on the free coordinates (free coordinates × members)."""
        return self.kinematic_map().T @ self.full_equilibrium_matrix()

    def kinematic_map(self) -> np.ndarray:
        """``T`` (node coordinates × free coordinates): the node velocities of the free
        coordinates' velocities (module docstring); without bodies the identity's free columns."""
        n, d = self.nodes.shape
        inside = {i for b in self.bodies for i in b}
        free = [k for k in self.free if k // d not in inside]
        rot = 3 if d == 3 else 1
        T = np.zeros((n * d, len(free) + len(self.bodies) * (d + rot)))
        T[free, np.arange(len(free))] = 1.0
        for b, body in enumerate(self.bodies):
            col = len(free) + b * (d + rot)
            c = self.nodes[body].mean(axis=0)
            for i in body:
                rho = self.nodes[i] - c
                T[i * d:(i + 1) * d, col:col + d] = np.eye(d)
                T[i * d:(i + 1) * d, col + d:col + d + rot] = -_skew(rho) if d == 3 else [[-rho[1]], [rho[0]]]
        return T

    def reduce(self, f) -> np.ndarray:
        """``Tᵀ f``: nodal forces ``f`` (n × dim, N) as forces on the free coordinates (a
        body's: its force and its moment about the centroid of its nodes)."""
        return self.kinematic_map().T @ np.asarray(f, float).reshape(-1)

    def cluster_matrix(self) -> np.ndarray:
        """``G`` (members × tensions): a column per clustered cable (1 on its segments), then
        one per other member, in member order."""
        m = len(self.members)
        inside = {e for c in self.clusters for e in c}
        alone = [e for e in range(m) if e not in inside]
        G = np.zeros((m, len(self.clusters) + len(alone)))
        for k, c in enumerate(self.clusters):
            G[c, k] = 1.0
        G[alone, len(self.clusters) + np.arange(len(alone))] = 1.0
        return G

    def geometric_stiffness(self, t) -> np.ndarray:
        """``K_G = Tᵀ ((Cᵀ diag(t / l) C) ⊗ I_dim) T`` on the free coordinates (N/m; with the
        rotation's curvature on the bodies' ``θ``, N·m)."""
        t = self.member_forces(t, "geometric_stiffness: t")
        C = self.incidence()
        D = C.T @ np.diag(t / self.lengths()) @ C
        T = self.kinematic_map()
        K = T.T @ np.kron(D, np.eye(self.dim)) @ T
        if self.bodies:
            n, d = self.nodes.shape
            g = (self.full_equilibrium_matrix() @ t).reshape(n, d)
            first = T.shape[1] - len(self.bodies) * (d + (3 if d == 3 else 1))
            for b, body in enumerate(self.bodies):
                rho = self.nodes[body] - self.nodes[body].mean(axis=0)
                if d == 3:
                    H = sum(0.5 * (np.outer(gi, ri) + np.outer(ri, gi)) - (gi @ ri) * np.eye(3)
                            for gi, ri in zip(g[body], rho))
                    k = first + b * 6 + 3
                    K[k:k + 3, k:k + 3] += H
                else:
                    k = first + b * 3 + 2
                    K[k, k] -= float(np.sum(g[body] * rho))
        return K

    def member_forces(self, t, what: str) -> np.ndarray:
        t = np.asarray(t, float).reshape(-1)
        if t.size != len(self.members) or not np.all(np.isfinite(t)):
            raise NcgenError(f"{what}: expected {len(self.members)} finite member forces (cables, then struts), "
                             f"got {t.size} value(s)" + ("" if np.all(np.isfinite(t)) else " with NaN or inf"))
        return t

    def internal_forces(self, rest_lengths, stiffness) -> np.ndarray:
        """``A t`` over the free coordinates with ``t = k (l − l₀)`` per member (the loads that
        hold the nodes where they are; its Jacobian is :meth:`tangent_stiffness` without
        clusters)."""
        t = np.asarray(stiffness, float) * (self.lengths() - np.asarray(rest_lengths, float))
        return self.equilibrium_matrix() @ t


def framework(nodes, struts, cables, supports=None, clusters=None, *, who: str, bodies=None) -> Framework:
    """A checked :class:`Framework`; errors name ``who`` and the argument."""
    try:
        nodes = np.array(nodes, float)
    except (TypeError, ValueError):
        raise NcgenError(f"{who}: nodes: expected an n × 2 or n × 3 array of numbers, got {nodes!r}") from None
    if nodes.ndim != 2 or nodes.shape[1] not in (2, 3) or len(nodes) < 2:
        raise NcgenError(f"{who}: nodes: expected an n × 2 or n × 3 array (n ≥ 2), got shape {nodes.shape}")
    if not np.all(np.isfinite(nodes)):
        raise NcgenError(f"{who}: nodes: expected finite coordinates, found "
                         f"{nodes[~np.isfinite(nodes)][0]} at node {int(np.argwhere(~np.isfinite(nodes))[0, 0])}")
    n, d = nodes.shape
    struts, cables = _pairs(struts, n, "struts", who), _pairs(cables, n, "cables", who)
    for e, (i, j) in enumerate(cables + struts):
        if np.linalg.norm(nodes[j] - nodes[i]) <= 1e-12 * max(1.0, np.abs(nodes).max()):
            what = f"cables[{e}]" if e < len(cables) else f"struts[{e - len(cables)}]"
            raise NcgenError(f"{who}: {what}: nodes {i} and {j} coincide; a member needs a length > 0")
    fixed = np.zeros((n, d), bool)
    items = supports.items() if isinstance(supports, dict) else ((i, AXES[:d]) for i in (supports or ()))
    for node, axes in items:
        if not isinstance(node, (int, np.integer)) or not 0 <= node < n:
            raise NcgenError(f"{who}: supports: expected node indices in 0..{n - 1}, got {node!r}")
        if not isinstance(axes, str) or not axes or any(a not in AXES[:d] for a in axes):
            raise NcgenError(f"{who}: supports[{node}]: expected axes among {AXES[:d]!r} such as "
                             f"{AXES[:d]!r}, got {axes!r}")
        for a in axes:
            fixed[node, AXES.index(a)] = True
    out = []
    seen: set = set()
    for c, cl in enumerate(clusters or ()):
        cl = list(cl)
        if len(cl) < 2 or not all(isinstance(e, (int, np.integer)) and 0 <= e < len(cables) for e in cl):
            raise NcgenError(f"{who}: clusters[{c}]: expected two or more cable indices in 0..{len(cables) - 1}, "
                             f"got {cl!r}")
        if seen & set(cl):
            raise NcgenError(f"{who}: clusters[{c}]: cable(s) {sorted(seen & set(cl))} are already in another cluster")
        for a, b in zip(cl, cl[1:]):
            if not set(cables[a]) & set(cables[b]):
                raise NcgenError(f"{who}: clusters[{c}]: consecutive segments cables[{a}] = {cables[a]} and "
                                 f"cables[{b}] = {cables[b]} share no node (a pulley)")
        seen |= set(cl)
        out.append([int(e) for e in cl])
    return Framework(nodes=nodes, struts=struts, cables=cables, fixed=fixed, clusters=out,
                     bodies=_bodies(bodies, nodes, fixed, struts, cables, who))


def _bodies(bodies, nodes, fixed, struts, cables, who: str) -> list[list[int]]:
    """The checked ``bodies``: two or more distinct nodes each, in one body only, unsupported,
    no member between two nodes of one body."""
    n, out, owner = len(nodes), [], {}
    for b, body in enumerate(bodies or ()):
        body = list(body)
        if len(body) < 2 or len(set(body)) != len(body) or \
                not all(isinstance(i, (int, np.integer)) and 0 <= i < n for i in body):
            raise NcgenError(f"{who}: bodies[{b}]: expected two or more different node indices in 0..{n - 1}, "
                             f"got {body!r}")
        for i in body:
            if i in owner:
                raise NcgenError(f"{who}: bodies[{b}]: node {i} is already in bodies[{owner[i]}]; a node belongs "
                                 "to one body (join two bodies by a strut or a cable)")
            if fixed[i].any():
                raise NcgenError(f"{who}: bodies[{b}]: node {i} is supported; a body's nodes take no supports "
                                 "(hold the body by members to supported nodes)")
            owner[i] = b
        out.append([int(i) for i in body])
    for what, pairs in (("struts", struts), ("cables", cables)):
        for e, (i, j) in enumerate(pairs):
            if i in owner and owner.get(j) == owner[i]:
                raise NcgenError(f"{who}: {what}[{e}]: nodes {i} and {j} are both in bodies[{owner[i]}]; a member "
                                 "within a rigid body carries nothing it could be designed for")
    return out


def _skew(v) -> np.ndarray:
    """``v̂`` with ``v̂ w = v × w``."""
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def _pairs(pairs, n: int, what: str, who: str) -> list[tuple[int, int]]:
    out = []
    for k, pair in enumerate(pairs):
        if len(pair) != 2 or not all(isinstance(i, (int, np.integer)) and 0 <= i < n for i in pair) \
                or pair[0] == pair[1]:
            raise NcgenError(f"{who}: {what}[{k}]: expected two different node indices in 0..{n - 1}, got {pair!r}")
        out.append((int(pair[0]), int(pair[1])))
    return out


def orthonormal_null(B: np.ndarray, tol: float = RANK_TOL) -> tuple[np.ndarray, np.ndarray, int]:
    """``(null B, singular values, rank)``: an orthonormal basis of ``{x: B x = 0}``."""
    if B.size == 0:
        return np.eye(B.shape[1]), np.zeros(0), 0
    _, sv, Vt = np.linalg.svd(B)
    r = int(np.sum(sv > tol * max(sv.max(initial=0.0), 1e-300)))
    return Vt[r:].T, sv, r


@dataclass
class SelfStress:
    """Result of :func:`self_stress` (module docstring): the ``framework``, ``A`` (free
    coordinates × members) and ``A_c = A G``, its ``singular_values`` and ``rank``;
    ``self_stresses`` (members × s, N per unit of each state, orthonormal in the tensions
    ``τ``; for one state its cables pull); ``mechanisms`` (free coordinates × m,
    orthonormal, orthogonal to the rigid motions); ``rigid`` (free coordinates × k: the rigid
    motions the supports allow)."""

    framework: Framework = field(repr=False)
    A: np.ndarray = field(repr=False)
    A_c: np.ndarray = field(repr=False)
    singular_values: np.ndarray = field(repr=False)
    rank: int
    self_stresses: np.ndarray = field(repr=False)
    mechanisms: np.ndarray = field(repr=False)
    rigid: np.ndarray = field(repr=False)
    svd: tuple = field(repr=False, default=())      # (U, σ, Vᵀ) of A_c, full

    @property
    def n_self_stress(self) -> int:
        return self.self_stresses.shape[1]

    @property
    def n_mechanisms(self) -> int:
        return self.mechanisms.shape[1]

    @property
    def n_rigid(self) -> int:
        return self.rigid.shape[1]

    @property
    def n_free(self) -> int:
        return self.A.shape[0]

    @property
    def n_tensions(self) -> int:
        return self.A_c.shape[1]

    def maxwell(self) -> str:
        """Calladine's extended Maxwell rule with this configuration's numbers."""
        s, m = self.n_self_stress, self.n_mechanisms
        return (f"s - m = n_t - (n_free - k): {s} - {m} = {self.n_tensions} - ({self.n_free} - {self.n_rigid})  "
                f"[rank {self.rank}]")

    def geometric_stiffness(self, t) -> np.ndarray:
        return self.framework.geometric_stiffness(t)

    def material_stiffness(self, k) -> np.ndarray:
        """``K_E = A_c diag(k) A_cᵀ``; ``k`` (N/m) one per tension (clusters, then the
        other members) or a number."""
        k = np.broadcast_to(np.asarray(k, float), (self.n_tensions,))
        return self.A_c @ np.diag(k) @ self.A_c.T

    def tangent_stiffness(self, t, k) -> np.ndarray:
        """``K_T = K_E + K_G − A diag(q) Aᵀ`` (N/m) under member forces ``t`` (``q = t / l``)
        with tension stiffnesses ``k``: the Jacobian of ``A t`` when each tension follows its
        stretch (:meth:`Framework.internal_forces`)."""
        t = self.framework.member_forces(t, "tangent_stiffness: t")
        q = t / self.framework.lengths()
        return self.material_stiffness(k) + self.geometric_stiffness(t) - self.A @ np.diag(q) @ self.A.T

    def prestress_stiffness(self, t) -> np.ndarray:
        """``Q = Mᵀ K_G M`` (N/m): the stiffness of the mechanisms under member forces ``t``."""
        M = self.mechanisms
        K = self.geometric_stiffness(t)
        return 0.5 * (M.T @ (K + K.T) @ M)

    def prestress_stability(self, t) -> tuple[str, np.ndarray]:
        """``(stability, eigenvalues of Q)``: ``"stable"`` (prestress-stable, or no mechanism),
        ``"neutral"`` or ``"unstable"``."""
        ev = np.linalg.eigvalsh(self.prestress_stiffness(t)) if self.n_mechanisms else np.zeros(0)
        scale = float(np.abs(self.framework.member_forces(t, "prestress_stability: t")
                             / self.framework.lengths()).max(initial=0.0))
        return classify(ev, scale)[0], ev

    def table(self) -> str:
        fw = self.framework
        lines = [f"framework: {len(fw.nodes)} nodes ({fw.dim}D), {len(fw.struts)} struts, {len(fw.cables)} cables"
                 + (f" ({len(fw.clusters)} clustered)" if fw.clusters else "")
                 + f", {int(fw.fixed.sum())} supported coordinates"
                 + (f", {len(fw.bodies)} rigid bodies" if fw.bodies else ""),
                 f"self-stress states: {self.n_self_stress}; infinitesimal mechanisms: {self.n_mechanisms}; "
                 f"rigid motions: {self.n_rigid}",
                 self.maxwell()]
        return "\n".join(lines) + "\n"


@one_blas_thread
def self_stress(nodes, struts, cables, supports=None, clusters=None, *, bodies=None,
                tol: float = RANK_TOL) -> SelfStress:
    """States of self-stress and infinitesimal mechanisms of the configuration ``nodes``
    (SVD of ``A_c``; singular values ≤ ``tol`` × the largest count as zero); see the module
    docstring for the arguments and conventions.  ``nodes`` may be a checked
    :class:`Framework` (the other arguments are then ignored)."""
    fw = nodes if isinstance(nodes, Framework) else framework(nodes, struts, cables, supports, clusters,
                                                            who="self_stress", bodies=bodies)
    return analyse(fw, tol)


def analyse(fw: Framework, tol: float = RANK_TOL) -> SelfStress:
    """:func:`self_stress` of a checked :class:`Framework`."""
    if not tol > 0:
        raise NcgenError(f"self_stress: tol: expected a number > 0, got {tol!r}")
    A = fw.equilibrium_matrix()
    G = fw.cluster_matrix()
    A_c = A @ G
    U, sv, Vt = np.linalg.svd(A_c) if A_c.size else (np.eye(A_c.shape[0]), np.zeros(0), np.eye(A_c.shape[1]))
    r = int(np.sum(sv > tol * max(sv.max(initial=0.0), 1e-300)))
    S = G @ Vt[r:].T
    if S.shape[1] == 1 and S[:len(fw.cables)].sum() < 0:
        S = -S
    R = rigid_motions(fw.nodes.reshape(-1), fw.dim)
    fixed = ~np.isin(np.arange(R.shape[0]), fw.free)
    allowed = R @ orthonormal_null(R[fixed], tol)[0] if fixed.any() else R
    W, w, _ = np.linalg.svd(np.linalg.lstsq(fw.kinematic_map(), allowed, rcond=None)[0], full_matrices=False)
    rigid = W[:, w > tol * max(w.max(initial=0.0), 1e-300)]
    left = U[:, r:]
    P = left - rigid @ (rigid.T @ left)
    W, w, _ = np.linalg.svd(P, full_matrices=False)
    mech = W[:, w > 0.5][:, :max(left.shape[1] - rigid.shape[1], 0)]
    return SelfStress(framework=fw, A=A, A_c=A_c, singular_values=sv, rank=r, self_stresses=S,
                      mechanisms=mech, rigid=rigid, svd=(U, sv, Vt))

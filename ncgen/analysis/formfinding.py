"""``form_find``: self-equilibrated configurations of class-1 tensegrity structures.

Topology: ``nodes`` (n × dim, a guess of the configuration), ``struts`` and ``cables``
(pairs of node indices; each node on at most one strut).  Struts are rigid bars (uniform,
``strut_mass``), nodes on no strut are point masses (``node_mass``), cables are
:class:`~ncgen.model.forces.Spring` elements with ``cable=True`` (they only pull), no gravity.

* **rest lengths** (``rest_lengths``, one per cable, and the cable stiffness
  ``stiffness``, N/m): the struts keep their lengths in ``nodes``; the configuration is the
  stable static equilibrium :func:`~ncgen.analysis.statics.equilibrium` reaches from
  ``nodes`` (descent Newton; rigid motions are zero-stiffness directions it leaves alone).
* **force densities** (``force_densities``: one per cable, then one per strut, N/m; cables
  positive, struts negative): the force density method.  With the incidence matrix ``C``
  (elements × nodes), equilibrium without loads is ``D X = 0``, ``D = Cᵀ diag(ρ) C``; a
  configuration in ``dim`` dimensions needs ``nullity D ≥ dim + 1`` (``D 1 = 0`` always).
  The configuration returned is the orthogonal projection of ``nodes`` onto ``null D``
  (the equilibrium configuration closest to the guess; it keeps the guess's symmetry).
  Member forces are ``ρ l``; cables of stiffness ``stiffness`` get rest lengths
  ``l − ρ l / k`` so that the built model is in equilibrium there (checked by
  :func:`equilibrium`).

Either way the result reports the prestress (cable tensions, strut forces, force
densities), slack cables, and the stability *modulo rigid motions*: the reduced tangent
stiffness on the motions the constraints allow, orthogonal to the ``dim (dim + 1) / 2``
rigid motions, positive definite = stable (prestress-stable when the structure is a
mechanism without its prestress).  ``result.modes()`` gives the vibration modes.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ncgen.blas_threads import one_blas_thread
from ncgen.errors import NcgenError
from ncgen.analysis.modes import Modes, modes
from ncgen.analysis.statics import Equilibrium, equilibrium
from ncgen.analysis.stability import classify

#: Eigenvalues of D below this times max |ρ| count as zero (force density method).
FDM_TOL = 1e-9


@dataclass
class Tensegrity:
    """Result of :func:`form_find`: ``nodes`` (n × dim, m), the built ``model`` and its
    ``equilibrium``; per cable ``tensions`` (N, ≥ 0) and ``rest_lengths`` (m); per strut
    ``strut_forces`` (N, tension positive: negative = compression); ``force_densities``
    (N/m, cables then struts); ``slack`` (indices of slack cables); ``stability`` modulo
    rigid motions, with the ``stiffness_eigenvalues`` it is judged from."""

    nodes: np.ndarray
    struts: list
    cables: list
    model: object = field(repr=False)
    equilibrium: Equilibrium = field(repr=False)
    tensions: np.ndarray
    rest_lengths: np.ndarray
    strut_forces: np.ndarray
    force_densities: np.ndarray
    slack: list
    stability: str
    stiffness_eigenvalues: np.ndarray

    def modes(self) -> Modes:
        """Vibration modes about the form-found configuration (rigid motions: zero modes)."""
        return modes(self.model, self.equilibrium)

    def lengths(self, pairs) -> np.ndarray:
        return np.array([np.linalg.norm(self.nodes[j] - self.nodes[i]) for i, j in pairs])

    def table(self) -> str:
        nc = len(self.cables)
        lines = [f"tensegrity: {len(self.nodes)} nodes, {len(self.struts)} struts, {nc} cables; "
                 f"stability (modulo rigid motions): {self.stability}; slack cables: "
                 f"{', '.join(f'c{i}' for i in self.slack) or 'none'}",
                 f"{'element':<8}{'nodes':>10}{'length (m)':>14}{'force (N)':>14}{'density (N/m)':>16}"]
        for i, (a, b) in enumerate(self.cables):
            lines.append(f"{'c' + str(i):<8}{f'{a}-{b}':>10}{self.lengths([(a, b)])[0]:>14.6g}"
                         f"{self.tensions[i]:>14.6g}{self.force_densities[i]:>16.6g}")
        for i, (a, b) in enumerate(self.struts):
            lines.append(f"{'s' + str(i):<8}{f'{a}-{b}':>10}{self.lengths([(a, b)])[0]:>14.6g}"
                         f"{self.strut_forces[i]:>14.6g}{self.force_densities[nc + i]:>16.6g}")
        return "\n".join(lines) + "\n"


def _from_force_densities(nodes, struts: list, cables: list, force_densities, k: np.ndarray):
    """``(nodes, rest lengths)``: the configuration the force densities (one per cable, then
    one per strut) hold in equilibrium, and the cables' rest lengths at stiffnesses ``k``
    that give them those tensions there."""
    rho = np.asarray(force_densities, float).reshape(-1)
    if rho.size != len(cables) + len(struts):
        raise NcgenError(f"form_find: force_densities: expected {len(cables) + len(struts)} values (cables, "
                         f"then struts), got {rho.size}")
    bad = [i for i in range(len(cables)) if rho[i] <= 0]
    if bad:
        raise NcgenError(f"form_find: force_densities: cables can only pull; cable(s) {bad} have "
                         f"non-positive force densities {rho[bad].tolist()}")
    nodes = _force_density_configuration(nodes, struts + cables, np.concatenate([rho[len(cables):],
                                                                                  rho[:len(cables)]]))
    lengths = np.array([np.linalg.norm(nodes[j] - nodes[i]) for i, j in cables])
    l0 = lengths - rho[:len(cables)] * lengths / k
    if np.any(l0 <= 0):
        i = int(np.argmin(l0))
        raise NcgenError(f"form_find: cable {i} would need a rest length {l0[i]:.3g} m <= 0 to carry "
                         f"{rho[i] * lengths[i]:.3g} N at stiffness {k[i]:g} N/m; raise the stiffness")
    return nodes, l0


@one_blas_thread
def form_find(nodes, struts, cables, *, rest_lengths=None, force_densities=None, stiffness=1000.0,
              strut_mass: float = 1.0, node_mass: float = 0.1, name: str = "tensegrity") -> Tensegrity:
    """A self-equilibrated configuration of the tensegrity ``(nodes, struts, cables)`` from
    the cables' ``rest_lengths`` or from all members' ``force_densities`` (exactly one of
    them); see the module docstring.  ``stiffness``: cable stiffness (N/m), a number or one
    per cable."""
    nodes = np.array(nodes, float)
    if nodes.ndim != 2 or nodes.shape[1] not in (2, 3):
        raise NcgenError(f"form_find: nodes: expected an n × 2 or n × 3 array, got shape {nodes.shape}")
    for what, x in (("nodes", nodes), ("stiffness", stiffness), ("rest_lengths", rest_lengths),
                    ("force_densities", force_densities), ("strut_mass", strut_mass), ("node_mass", node_mass)):
        a = None if x is None else np.asarray(x, float)
        if a is not None and not np.all(np.isfinite(a)):
            raise NcgenError(f"form_find: {what}: expected finite numbers, found {a[~np.isfinite(a)][0]} at "
                             f"index {tuple(np.argwhere(~np.isfinite(a))[0].tolist())}")
    struts, cables = _pairs(struts, len(nodes), "struts"), _pairs(cables, len(nodes), "cables")
    on = [i for s in struts for i in s]
    if len(set(on)) < len(on):
        raise NcgenError("form_find: struts: a node is on two struts; only class-1 tensegrities (each node "
                         "on at most one strut) are supported")
    k = np.broadcast_to(np.asarray(stiffness, float), (len(cables),)).copy()
    if np.any(k <= 0):
        raise NcgenError(f"form_find: stiffness: expected positive cable stiffnesses, got {stiffness!r}")
    if (rest_lengths is None) == (force_densities is None):
        raise NcgenError("form_find: give exactly one of rest_lengths (one per cable) and force_densities "
                         "(one per cable, then one per strut)")
    if force_densities is not None:
        nodes, l0 = _from_force_densities(nodes, struts, cables, force_densities, k)
    else:
        l0 = np.asarray(rest_lengths, float).reshape(-1)
        if l0.size != len(cables) or np.any(l0 <= 0):
            raise NcgenError(f"form_find: rest_lengths: expected {len(cables)} positive lengths, got {rest_lengths!r}")
    model = _build(nodes, struts, cables, l0, k, strut_mass, node_mass, name)
    eq = equilibrium(model)
    X = _node_positions(model, eq.q, nodes, struts)
    tensions = np.array([T for _, T, _, _ in eq.springs])
    strut_forces = _strut_forces(model, eq, struts, X)
    lengths_c = np.array([np.linalg.norm(X[j] - X[i]) for i, j in cables])
    lengths_s = np.array([np.linalg.norm(X[j] - X[i]) for i, j in struts])
    rho = np.concatenate([tensions / lengths_c, strut_forces / lengths_s])
    ev = _stiffness_modulo_rigid(model, eq)
    stability, _, _ = classify(ev, float(np.abs(np.diag(eq.K)).max(initial=0)))
    return Tensegrity(nodes=X, struts=struts, cables=cables, model=model, equilibrium=eq, tensions=tensions,
                      rest_lengths=l0, strut_forces=strut_forces, force_densities=rho,
                      slack=[i for i, (_, _, _, s) in enumerate(eq.springs) if s], stability=stability,
                      stiffness_eigenvalues=ev)


def _pairs(pairs, n: int, what: str) -> list[tuple[int, int]]:
    out = []
    for k, pair in enumerate(pairs):
        if len(pair) != 2 or not all(isinstance(i, (int, np.integer)) and 0 <= i < n for i in pair) \
                or pair[0] == pair[1]:
            raise NcgenError(f"form_find: {what}[{k}]: expected two different node indices in 0..{n - 1}, "
                             f"got {pair!r}")
        out.append((int(pair[0]), int(pair[1])))
    return out


def _force_density_configuration(guess: np.ndarray, members, rho: np.ndarray) -> np.ndarray:
    n, dim = guess.shape
    C = np.zeros((len(members), n))
    for e, (i, j) in enumerate(members):
        C[e, i], C[e, j] = 1.0, -1.0
    D = C.T @ np.diag(rho) @ C
    w, V = np.linalg.eigh(D)
    null = np.abs(w) <= FDM_TOL * np.abs(rho).max() * n
    if null.sum() < dim + 1:
        raise NcgenError(f"form_find: force_densities: the force density matrix has nullity {int(null.sum())}; "
                         f"a self-stressed configuration in {dim}D needs at least {dim + 1} (the densities "
                         "admit no self-stress: check their ratios)")
    P = V[:, null]
    X = P @ (P.T @ guess)
    centred = X - X.mean(axis=0)
    if np.linalg.matrix_rank(centred, tol=1e-9 * np.abs(centred).max(initial=1.0)) < dim:
        raise NcgenError(f"form_find: the equilibrium configuration nearest the guess is degenerate "
                         f"(flat in {dim}D); give a guess closer to the expected shape")
    return X


def _build(nodes, struts, cables, l0, k, strut_mass, node_mass, name):
    from ncgen.model.forces import Spring
    from ncgen.model.system import System

    dim = nodes.shape[1]
    s = System(name, gravity=tuple([0.0] * dim))
    where = {}
    for i, (a, b) in enumerate(struts):
        bar = s.add_bar(f"s{i}", mass=strut_mass, ends=[nodes[a], nodes[b]])
        half = np.linalg.norm(nodes[b] - nodes[a]) / 2
        where[a] = (bar, -half * np.eye(dim)[0])
        where[b] = (bar, half * np.eye(dim)[0])
    for j in range(len(nodes)):
        if j not in where:
            where[j] = (s.add_point(f"n{j}", mass=node_mass, position=nodes[j]), np.zeros(dim))
    for i, (a, b) in enumerate(cables):
        (ma, pa), (mb, pb) = where[a], where[b]
        s.add_force(Spring(ma, pa, mb, pb, k=float(k[i]), rest_length=float(l0[i]), cable=True, name=f"c{i}"))
    return s.build()


def _node_indices(model, nodes, struts):
    """Per node, the indices of its coordinates in q."""
    names = model.coordinate_names
    dim = nodes.shape[1]
    out = {}
    for i, (a, b) in enumerate(struts):
        out[a] = [names.index(f"s{i}.r_i.{c}") for c in "xyz"[:dim]]
        out[b] = [names.index(f"s{i}.r_j.{c}") for c in "xyz"[:dim]]
    for j in range(len(nodes)):
        if j not in out:
            out[j] = [names.index(f"n{j}.r.{c}") for c in "xyz"[:dim]]
    return out


def _node_positions(model, q, nodes, struts) -> np.ndarray:
    idx = _node_indices(model, nodes, struts)
    return np.array([q[idx[j]] for j in range(len(nodes))])


def _strut_forces(model, eq, struts, X) -> np.ndarray:
    """Axial force of each strut (tension positive) from the reaction of its length
    constraint at its second end: ``N = −f₂ · e``, ``e`` the unit vector from end 1 to 2."""
    names = model.coordinate_names
    dim = X.shape[1]
    out = []
    for i, (a, b) in enumerate(struts):
        j = [names.index(f"s{i}.r_j.{c}") for c in "xyz"[:dim]]
        e = (X[b] - X[a]) / np.linalg.norm(X[b] - X[a])
        out.append(-(eq.reaction[j] @ e))
    return np.array(out)


def rigid_motions(q: np.ndarray, dim: int) -> np.ndarray:
    """Basis (nq × dim(dim+1)/2) of the rigid motions of a q made of points only."""
    r = q.reshape(-1, dim)
    cols = []
    for a in range(dim):
        t = np.zeros_like(r)
        t[:, a] = 1.0
        cols.append(t.reshape(-1))
    if dim == 2:
        cols.append(np.column_stack([-r[:, 1], r[:, 0]]).reshape(-1))
    else:
        for w in np.eye(3):
            cols.append(np.cross(w, r).reshape(-1))
    return np.column_stack(cols)


def _stiffness_modulo_rigid(model, eq) -> np.ndarray:
    """Eigenvalues of the reduced tangent stiffness on ``null A`` ⊖ rigid motions."""
    R = rigid_motions(eq.q, model.dim)
    N = eq.N
    P = N - R @ np.linalg.lstsq(R, N, rcond=None)[0]
    U, s, _ = np.linalg.svd(P, full_matrices=False)
    B = U[:, s > 1e-8 * s.max()] if s.size else U
    Ks = 0.5 * (eq.K + eq.K.T)
    return np.linalg.eigvalsh(B.T @ Ks @ B) if B.size else np.zeros(0)

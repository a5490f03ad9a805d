"""``tensegrity_system``: a simulation model of a tensegrity of any class (nodes shared by
several struts included), to realise and check the forces of inverse statics.

Every free node is a point mass (``node_mass``, kg); a strut is a :class:`~ncgen.model.joints.Distance`
constraint between its nodes (rigid, massless; its force is the constraint's reaction); a
cable is a :class:`~ncgen.model.forces.Spring` with ``cable=True`` (stiffness ``k`` N/m, rest
length ``l₀`` m: tension ``k (l − l₀)`` while positive).  Supports as in
:mod:`ncgen.analysis.self_stress`: a node held along every axis is a point of the ground, along
one axis it slides on a plane (:class:`~ncgen.model.joints.PointOnPlane`), along two on a
line (:class:`~ncgen.model.joints.PointOnLine`).  Loads (n × dim, N) are constant
:class:`~ncgen.model.forces.PointForce` on the nodes; no gravity (put the weights in the loads).
A rigid body (``bodies``: lists of node indices, as in :mod:`ncgen.analysis.self_stress`) is a
3D (2D) body ``b<j>`` with its centre of mass at the centroid of its nodes, which are its
body-fixed points; mass ``node_mass`` per node, inertia of those point masses plus a ball's
``(2/5) m (s/10)²`` (``s`` the body's largest node distance from the centroid, so that a
two-node body is not singular).
With ``actuated=True`` every realised cable (clustered ones too) takes its rest length from
one input vector ``l0`` (m), in the order of ``model.springs.names``;
:func:`rest_length_inputs` orders per-cable rest lengths so (the work of changing them is
then not in the model's energy: ``−∫ T l̇₀ dt`` per cable).
"""
from __future__ import annotations

import numpy as np

from ncgen.errors import NcgenError
from ncgen.analysis.self_stress import AXES, framework


def tensegrity_system(nodes, struts, cables, rest_lengths, stiffness, loads=None, supports=None, *,
                      clusters=None, bodies=None, actuated: bool = False, node_mass: float = 0.1,
                      damping: float = 0.0, name: str = "tensegrity"):
    """The :class:`~ncgen.model.system.System` of the tensegrity (module docstring);
    ``rest_lengths`` and ``stiffness``: one per cable (or a number); nodes named ``n<i>``,
    struts ``s<i>``, cables ``c<i>``.  ``clusters`` (lists of cable indices, as in
    :func:`~ncgen.analysis.inverse_statics.inverse_statics`): each becomes one
    :class:`~ncgen.model.cables.ClusteredCable` ``k<j>`` over frictionless pulleys at the
    nodes its segments share, with the sum of its segments' rest lengths and their stiffness
    in series ``1 / Σ 1/k`` (so that segment values from ``InverseStatics.rest_lengths`` give
    the same tension).  Build it with ``.build()``."""
    from ncgen.model.joints import Distance
    from ncgen.model.system import System

    who = "tensegrity_system"
    fw = framework(nodes, struts, cables, supports, clusters, who=who, bodies=bodies)
    n, d = fw.nodes.shape
    l0 = _per_cable(rest_lengths, len(fw.cables), "rest_lengths", who)
    k = _per_cable(stiffness, len(fw.cables), "stiffness", who)
    f = np.zeros((n, d)) if loads is None else np.asarray(loads, float)
    if f.shape != (n, d) or not np.all(np.isfinite(f)):
        raise NcgenError(f"{who}: loads: expected finite nodal forces of shape ({n}, {d}), got shape {f.shape}")
    s = System(name, gravity=tuple([0.0] * d))
    end = _node_ends(s, fw, f, node_mass)
    for e, (a, b) in enumerate(fw.struts):
        (ma, _), (mb, _) = end[a], end[b]
        if ma.is_ground and mb.is_ground:
            raise NcgenError(f"{who}: struts[{e}]: both nodes {a} and {b} are fully supported")
        s.add_joint(Distance(ma, mb, at=[fw.nodes[a], fw.nodes[b]], name=f"s{e}"))
    _add_cables(s, fw, end, k, l0, actuated, damping)
    return s


def _node_ends(s, fw, f: np.ndarray, node_mass: float) -> dict:
    """Node index -> ``(member, local point)``: the rigid bodies' nodes, the ground's points
    (nodes held along every axis) and the point masses (supported on a plane or a line
    where held along some axes), with the loads ``f`` on them."""
    from ncgen.model.forces import PointForce
    from ncgen.model.joints import PointOnLine, PointOnPlane

    n, d = fw.nodes.shape
    end = {}
    for j, body in enumerate(fw.bodies):
        member, centre = _body(s, f"b{j}", fw.nodes[body], node_mass)
        for i in body:
            end[i] = (member, fw.nodes[i] - centre)
            if np.any(f[i] != 0):
                s.add_force(PointForce(member, fw.nodes[i] - centre, force=tuple(f[i]), name=f"load{i}"))
    for i in range(n):
        if i in end:
            continue
        held = [a for a in range(d) if fw.fixed[i, a]]
        if len(held) == d:
            end[i] = (s.ground, fw.nodes[i])
            continue
        p = s.add_point(f"n{i}", mass=node_mass, position=fw.nodes[i])
        end[i] = (p, np.zeros(d))
        if len(held) == 1 and d == 3:
            s.add_joint(PointOnPlane(s.ground, p, at=fw.nodes[i], normal=np.eye(3)[held[0]],
                                     name=f"support{i}"))
        elif held:
            axis = np.eye(d)[[a for a in range(d) if a not in held][0]]
            s.add_joint(PointOnLine(s.ground, p, at=fw.nodes[i], axis=axis, name=f"support{i}"))
        if np.any(f[i] != 0):
            s.add_force(PointForce(p, np.zeros(d), force=tuple(f[i]), name=f"load{i}"))
    return end


def _add_cables(s, fw, end: dict, k: np.ndarray, l0: np.ndarray, actuated: bool, damping: float) -> None:
    """The clustered cables ``k<j>`` (stiffness in series, summed rest lengths) and the other
    cables ``c<e>`` not between two ground points; with ``actuated``, their rest lengths the
    input ``l0`` (clusters first)."""
    from ncgen.model.cables import ClusteredCable
    from ncgen.model.forces import Spring

    clustered = {e for cl in fw.clusters for e in cl}
    alone = [e for e, (a, b) in enumerate(fw.cables)
             if not (end[a][0].is_ground and end[b][0].is_ground) and e not in clustered]
    u = s.add_input("l0", len(fw.clusters) + len(alone)) if actuated else None
    for j, cl in enumerate(fw.clusters):
        order = _path(fw.cables, cl)
        s.add_force(ClusteredCable([end[i] for i in order], k=float(1 / np.sum(1 / k[cl])),
                                   rest_length=u[j] if actuated else float(l0[cl].sum()), damping=damping,
                                   name=f"k{j}"))
    for i, e in enumerate(alone):
        (ma, pa), (mb, pb) = end[fw.cables[e][0]], end[fw.cables[e][1]]
        s.add_force(Spring(ma, pa, mb, pb, k=float(k[e]), damping=damping, cable=True, name=f"c{e}",
                           rest_length=u[len(fw.clusters) + i] if actuated else float(l0[e])))


def rest_length_inputs(model, rest_lengths, clusters=None) -> np.ndarray:
    """The input ``l0`` (m) of an ``actuated`` :func:`tensegrity_system` model from per-cable
    rest lengths (m; a cluster's is the sum of its segments'); ``clusters`` as it was built
    with.  Also the model's input trajectory from an array of them (… × cables)."""
    l0 = np.asarray(rest_lengths, float)
    clusters = list(clusters or ())
    cols = [l0[..., clusters[int(n[1:])]].sum(axis=-1) if n.startswith("k") else l0[..., int(n[1:])]
            for n in model.springs.names]
    return np.stack(cols, axis=-1)


def _body(s, name: str, x: np.ndarray, node_mass: float):
    """A body with point masses ``node_mass`` at the nodes ``x`` (module docstring); and its
    centre (the nodes' centroid)."""
    c = x.mean(axis=0)
    rho = x - c
    m = node_mass * len(x)
    ball = 0.4 * m * (0.1 * np.linalg.norm(rho, axis=1).max()) ** 2
    if x.shape[1] == 3:
        inertia = node_mass * sum(r @ r * np.eye(3) - np.outer(r, r) for r in rho) + ball * np.eye(3)
    else:
        inertia = node_mass * float(np.sum(rho**2)) + ball
    return s.add_body(name, mass=m, inertia=inertia, position=c), c


def _path(cables, cluster) -> list[int]:
    """The nodes a clustered cable passes, in order (its consecutive segments share one)."""
    first, second = cables[cluster[0]], cables[cluster[1]]
    start = first[0] if first[1] in second else first[1]
    order = [start]
    for e in cluster:
        a, b = cables[e]
        order.append(b if a == order[-1] else a)
    return order


def _per_cable(x, m: int, what: str, who: str) -> np.ndarray:
    a = np.asarray(x, float).reshape(-1)
    if a.size not in (1, m) or not np.all(np.isfinite(a)) or np.any(a <= 0):
        raise NcgenError(f"{who}: {what}: expected a positive number or {m} positive numbers (one per cable), "
                         f"got {x!r}")
    return np.broadcast_to(a, (m,)).astype(float)


def strut_forces(model, eq, nodes, struts, supports=None) -> np.ndarray:
    """Axial forces (N, tension positive) of the struts of a :func:`tensegrity_system`
    model at its equilibrium ``eq``: from the reaction ``−λ ∂Φ/∂r`` of strut ``s<e>``'s
    constraint on one of its free nodes, along the strut."""
    fw = framework(nodes, struts, [], supports, who="strut_forces")
    d = fw.dim
    A = np.asarray(model.A(eq.q, t=eq.t, p=eq.p)).reshape(model.nc, model.nq)
    names = model.coordinate_names
    X = {i: np.array([eq.coordinate(f"n{i}.r_i.{c}") for c in AXES[:d]]) for i in range(len(fw.nodes))
         if not fw.fixed[i].all()}
    out = []
    for e, (a, b) in enumerate(fw.struts):
        row = model.constraint_names.index(next(c for c in model.constraint_names if c.startswith(f"s{e}.")))
        node, other = (b, a) if b in X else (a, b)
        cols = [names.index(f"n{node}.r_i.{c}") for c in AXES[:d]]
        f_node = -eq.lam[row] * A[row, cols]
        xo = X.get(other, fw.nodes[other])
        u = (X[node] - xo) / np.linalg.norm(X[node] - xo)
        out.append(-(f_node @ u))
    return np.array(out)

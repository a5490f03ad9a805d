"""Final conditions on part of the configuration, in the user's terms.

A target such as "member ``fore`` in this pose" fixes some coordinates of a configuration
and leaves the rest to the joints.  It becomes a :class:`PartialTarget`: a consistent
reference configuration ``q_ref`` that meets it (the member's natural coordinates from the
pose, the other coordinates assembled onto ``Φ = 0`` from the initial configuration) and
the selection ``S`` of the coordinates it fixes.  The NLP imposes the rows
``Wᵀ S (q_N − q_ref) = 0`` with ``W`` an orthonormal basis of the range of ``S N`` (``N``: the
tangent basis of the constraints at ``q_ref``, :mod:`ncgen.optim.conditions`): as many rows
as the target has independent degrees of freedom once the joints hold, so they never
repeat a joint equation or a member's own constraints (LICQ), plus a box around ``S q_ref``
that selects the branch.

With coordinate sharing a member's pose may fix shared hinge axes and points, from which
natural-coordinate Newton can stall; for trees the reference is then found by inverse
kinematics in joint space (:func:`joint_space_fit`).

Joint coordinates (:class:`JointTarget`, ``final(joints=...)``) are imposed on the joint
positions directly — the states of the joint-space transcription, or
``model.joint_space.positions(q_N)`` in natural coordinates: ``x_N − x*`` for lengths,
``sin(θ_N − θ*)`` with the branch ``cos(θ_N − θ*) ≥ 0`` for angles (any winding).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ncgen.errors import NcgenError, OptimizationError
from ncgen.assembly.manifold import RANK_TOL, tangent_basis



@dataclass
class PartialTarget:
    """``q_ref``: a consistent configuration meeting the target; ``S`` (k × nq): the
    coordinates it fixes; ``label``: for messages."""

    q_ref: np.ndarray
    S: np.ndarray
    label: str

    def rows(self, model, t=None, p=None) -> np.ndarray:
        """``Wᵀ S``: the independent rows of the condition at ``q_ref`` (r × nq)."""
        B = self.S @ tangent_basis(model, self.q_ref, t=t, p=p)
        if B.size == 0:
            return np.zeros((0, model.nq))
        U, s, _ = np.linalg.svd(B, full_matrices=False)
        r = int(np.sum(s > RANK_TOL * max(s[0], 1e-300))) if s.size else 0
        if r == 0:
            raise OptimizationError(f"{self.label}: the joints already fix this; it constrains nothing")
        return U[:, :r].T @ self.S


def pose_target(model, poses: dict, reference, *, t=None, p=None) -> PartialTarget:
    """The target ``{member name: (rotation, position)}`` (rotation: 3×3 body→world, or an
    angle / 2×2 matrix in planar systems; position: the member frame's origin, m — a body's
    centre of mass as in ``add_body``, a bar's centre) from the configuration ``reference``."""
    q = np.asarray(reference, dtype=float).copy()
    moves = []
    for name, value in poses.items():
        if name not in model.member_names:
            raise OptimizationError(f"final pose: no member named {name!r}; members: {', '.join(model.member_names)}")
        try:
            R, pos = value
            qm = model.member(name).rigid.q_from_pose(R, pos)
        except (TypeError, ValueError, NcgenError) as exc:
            raise OptimizationError(f"final pose of {name!r}: expected (rotation, position) of the member's frame "
                                    f"({exc})") from None
        moves.append((model.layout.member_indices(name), qm))
    fixed = sorted({i for idx, _ in moves for i in idx if i is not None})
    label = "final pose of " + ", ".join(repr(n) for n in poses)
    for idx, qm in moves:
        for k, i in enumerate(idx):
            if i is not None:
                q[i] = qm[k]
    q_ref = _assemble_towards(model, q, [model.coordinate_names[i] for i in fixed], label, t, p)
    miss = np.max(np.abs(q_ref[fixed] - q[fixed]), initial=0.0)
    if miss > 1e-6 * max(1.0, float(np.max(np.abs(q)))):
        raise OptimizationError(f"{label}: the joints cannot reach it (the nearest configuration is {miss:.3g} m off)")
    S = np.zeros((len(fixed), model.nq))
    S[np.arange(len(fixed)), fixed] = 1.0
    return PartialTarget(q_ref, S, label)


def _assemble_towards(model, x, fix: list[str], label: str, t, p) -> np.ndarray:
    """The configuration on ``Φ = 0`` with the coordinates ``fix`` as in ``x`` (a member's
    target pose): Newton from ``x``; if that fails and the model is a tree,
    by inverse kinematics in joint space (:func:`joint_space_fit`).  Newton in natural
    coordinates can stall from far: with coordinate sharing a member's pose fixes a shared
    hinge axis and point, and from a symmetric start the other member's free vectors get no
    component towards their solution (measured on the benchmark 3D arm)."""
    from ncgen.assembly.kinematics import assemble
    from ncgen.optim.joint_radau import joint_space_reason
    try:
        return assemble(model, x, t=t, p=p, fix=fix)
    except NcgenError as exc:
        if joint_space_reason(model) is not None:
            raise OptimizationError(f"{label}: the joints cannot reach it: {exc}") from None
        first = exc
    rows = np.array([model.coordinate_names.index(n) for n in fix], dtype=int)
    fitted = joint_space_fit(model, x, rows, x[rows])
    if fitted is None:
        raise OptimizationError(f"{label}: the joints cannot reach it: {first}; inverse kinematics in joint "
                                "space did not reach it either") from None
    return fitted


def joint_space_fit(model, q_start, rows: np.ndarray, values: np.ndarray, *, max_iter: int = 200,
                    restarts: int = 8) -> np.ndarray | None:
    """A tree's configuration ``q(q_j)`` with ``q[rows] = values`` (m), by Levenberg–Marquardt
    on the joint coordinates from those of ``q_start`` (then from ``restarts`` random ones);
    None if none fits to round-off."""
    import casadi as ca
    js = model.joint_space
    tree = js.tree_function(model.layout)
    x = ca.SX.sym("qj", js.nq)
    qx = tree(x, ca.DM.zeros(js.nv))[0]
    res = qx[[int(i) for i in rows]] - ca.DM(values)
    fn = ca.Function("fit", [x], [res, ca.jacobian(res, x)])
    tol = 1e-12 * max(1.0, float(np.max(np.abs(values), initial=0.0)))
    rng = np.random.default_rng(1)
    starts = [np.array(js.positions(q_start)).reshape(-1)] + \
        [rng.uniform(-np.pi, np.pi, js.nq) for _ in range(restarts)]
    for y in starts:
        mu = 1e-3
        for _ in range(max_iter):
            r, J = (np.array(z) for z in fn(y))
            r = r.reshape(-1)
            cost = r @ r
            if np.sqrt(cost) < tol:
                return np.array(tree(y, np.zeros(js.nv))[0]).reshape(-1)
            step = np.linalg.solve(J.T @ J + mu * np.eye(js.nq), -J.T @ r)
            r_new = np.array(fn(y + step)[0]).reshape(-1)
            if r_new @ r_new < cost:
                y, mu = y + step, max(mu / 3, 1e-12)
            else:
                mu *= 10
                if mu > 1e8:
                    break
    return None


@dataclass
class JointTarget:
    """Joint coordinates to reach: ``index`` into the joint-position vector
    (``model.joint_space.position_names``), ``values`` (rad or m), ``angles`` (which are
    angles, taken modulo 2π), ``q_ref``: a consistent configuration with them (for the
    guess and the velocity conditions), ``label``: for messages."""

    index: np.ndarray
    values: np.ndarray
    angles: np.ndarray
    q_ref: np.ndarray
    label: str

    def residuals(self, qj):
        """``(equalities, branch)`` at joint positions ``qj`` (CasADi): ``x − x*`` for lengths,
        ``sin(θ − θ*)`` for angles (any winding) with the branch ``cos(θ − θ*) ≥ 0``."""
        import casadi as ca
        x = qj[[int(i) for i in self.index]]
        d = x - ca.DM(self.values)
        a = [int(k) for k in np.flatnonzero(self.angles)]
        lin = [int(k) for k in np.flatnonzero(~self.angles)]
        eq = ca.vertcat(*([d[lin]] if lin else []), *([ca.sin(d[a])] if a else []))
        return eq, (ca.cos(d[a]) if a else ca.DM.zeros(0, 1))


def joint_target(model, joints: dict, reference, *, what: str = "final joints", t=None, p=None) -> JointTarget:
    """The target ``{joint name: value}`` (rad or m; a list for a joint with several
    coordinates) from the configuration ``reference``: the other joints of a tree keep their
    coordinates there; in a closed loop the named joints must be independent and the rest
    are assembled (:meth:`~ncgen.assembly.joint_space.JointSpace.from_joint_space`)."""
    from ncgen.optim.joint_radau import QUATERNION_JOINTS, joint_space_reason
    js = model.joint_space
    if not isinstance(joints, dict) or not joints:
        raise OptimizationError(f"{what}: expected {{joint name: value}}, got {joints!r}")
    sl = js.slices()
    given, index = {}, []
    for name, value in joints.items():
        if name not in js.nq_joint:
            why = f" ({js.skipped[name]})" if name in js.skipped else ""
            raise OptimizationError(f"{what}: no joint with coordinates named {name!r}{why}; joints: "
                                    f"{', '.join(js.joint_names) or 'none'}")
        if js.joints[name].kind in QUATERNION_JOINTS:
            raise OptimizationError(f"{what}: joint {name!r} ({js.joints[name].kind}) has quaternion coordinates; "
                                    "give the pose of the member it carries instead (final(pose=...))")
        x = np.atleast_1d(np.asarray(value, dtype=float)).reshape(-1)
        n = js.nq_joint[name]
        if x.size != n or not np.all(np.isfinite(x)):
            names = js.position_names[sl[name]]
            raise OptimizationError(f"{what}[{name!r}]: expected {n} finite number(s) ({', '.join(names)}), "
                                    f"got {value!r}")
        given[name] = x
        index.extend(range(sl[name].start, sl[name].stop))
    index = np.array(index, dtype=int)
    values = np.concatenate([given[n] for n in joints])
    label = f"{what} " + ", ".join(repr(n) for n in joints)
    try:
        if joint_space_reason(model) is None:          # a tree: the others keep their coordinates
            x = np.array(js.positions(np.asarray(reference, dtype=float))).reshape(-1)
            x[index] = values
            q_ref = js.from_joint_space(model, x, t=t, p=p)[0]
        else:
            q_ref = js.from_joint_space(model, given, t=t, p=p)[0]
    except NcgenError as exc:
        raise OptimizationError(f"{label}: the joints cannot reach it: {exc}") from None
    B = np.array(js.position_jacobian(q_ref))[index] @ tangent_basis(model, q_ref, t=t, p=p)
    s = np.linalg.svd(B, compute_uv=False) if B.size else np.zeros(0)
    if s.size < index.size or s[-1] <= RANK_TOL * max(s[0], 1e-300):
        raise OptimizationError(f"{label}: these joint coordinates are not independent (in a closed loop "
                                "give only independent joints; the others follow)")
    return JointTarget(index, values, js.angles[index], q_ref, label)

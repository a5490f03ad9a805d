"""Forward dynamics of a tree in joint space, as one CasADi SX function.

For a model whose members hang from the ground through joints with coordinates (a tree;
:meth:`~ncgen.assembly.joint_space.JointSpace.tree_map`), the natural coordinates are
functions of the joint positions, ``q = q(q_j)``, and the rates are linear in the joint
rates, ``q̇ = G(q_j) v_j`` with ``G = ∂q̇/∂v_j`` (nq × nv_j).  The constraints hold
identically (``Φ(q(q_j)) ≡ 0``, so ``A G = 0``), and projecting ``M q̈ + Aᵀλ = F`` on ``G``
removes the multipliers:

    M_j a_j = h,   M_j = Gᵀ M G,   h = Gᵀ (F(t, q, q̇, u, p) − M ġ),

with ``q̈ = G a_j + ġ`` and ``ġ = (∂(G v_j)/∂q_j) q̇_j`` (``q̇_j`` the position rates:
quaternion rates for spherical and free joints).  ``M`` is the constant natural-coordinate
mass matrix (it may be singular, e.g. a thin disc: ``M_j`` is positive definite whenever the
dynamics are not singular).  ``M_j`` (nv_j × nv_j, symmetric) is factored by a Cholesky
written out as SX (straight-line C, no pivoting, no CasADi ``solve``).  Both forms return
``check = [min_k d_k / (M_j)_kk, Σ a_j]``: the smallest relative pivot (1 for a diagonal
``M_j``, ≤ 0 or tiny for a singular one) and a sum that is finite exactly when every ``a_j``
is, so that a caller refuses a singular or non-finite result with two comparisons.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ncgen.assembly.joint_tree import carry, relative_pose
from ncgen.assembly.mass import sparse_dm
from ncgen.errors import ModelError
from ncgen.model.sym2casadi import to_casadi


def cholesky_solve(K: ca.SX, b: ca.SX) -> tuple[ca.SX, ca.SX]:
    """``(x, r)``: ``x = K⁻¹ b`` for a symmetric positive definite ``K`` (only its lower
    triangle is read) by ``K = L Lᵀ``, and ``r = min_k d_k / K_kk`` over the pivots ``d_k``
    (before their square roots).  Structural zeros of ``K`` are kept as zeros."""
    n = K.size1()
    L = [[None] * n for _ in range(n)]
    ratios = []
    for k in range(n):
        d = K[k, k] - sum((L[k][j] ** 2 for j in range(k)), ca.SX(0))
        ratios.append(d / K[k, k])
        L[k][k] = ca.sqrt(d)
        for i in range(k + 1, n):
            s = K[i, k] - sum((L[i][j] * L[k][j] for j in range(k)), ca.SX(0))
            L[i][k] = s / L[k][k]
    y = [None] * n
    for i in range(n):
        y[i] = (b[i] - sum((L[i][j] * y[j] for j in range(i)), ca.SX(0))) / L[i][i]
    x = [None] * n
    for i in reversed(range(n)):
        x[i] = (y[i] - sum((L[j][i] * x[j] for j in range(i + 1, n)), ca.SX(0))) / L[i][i]
    r = ratios[0] if ratios else ca.SX(1)
    for z in ratios[1:]:
        r = ca.fmin(r, z)
    return ca.vertcat(*x) if n else ca.SX(0, 1), r


def joint_efforts(js, tau: ca.SX) -> ca.SX:
    """The actuated joints' efforts ``τ`` (``js.actuated`` order) placed at their joints'
    rates, zero for the others: ``Gᵀ B τ`` for a tree, since ``B = [J_kᵀ ...]`` and
    ``J G = I`` (the joint rates of ``q̇ = G v_j`` are ``v_j``)."""
    start, k = {}, 0
    for name in js.actuated:
        start[name] = k
        k += js.nv_joint[name]
    rows = [tau[start[n]:start[n] + js.nv_joint[n]] if n in start else ca.SX.zeros(js.nv_joint[n])
            for n in js.joint_names]
    return ca.vertcat(*rows) if rows else ca.SX(0, 1)


def _function(t, qj, vj, u, p, aj, pivot) -> ca.Function:
    """The kernel's signature: outputs ``aj`` and ``check = [pivot, Σ a_j]`` (the sum is
    finite exactly when every ``a_j`` is)."""
    return ca.Function("joint_forward_dynamics", [t, qj, vj, u, p], [aj, ca.vertcat(pivot, ca.sum1(aj))],
                       ["t", "qj", "vj", "u", "p"], ["aj", "check"])


def tree_dynamics_function(model) -> ca.Function:
    """``(t, qj, vj, u, p) -> (aj, check)``: the joint accelerations of a tree (module
    docstring) and ``check = [smallest relative Cholesky pivot, Σ a_j]``.  Raises
    :class:`~ncgen.errors.ModelError` (from ``tree_map``) for a model that is not a tree;
    whether the tree's constraints are all the model's is for the caller to check."""
    js = model.joint_space
    qj, vj, q, qj_dot = js.tree_map(model.layout)
    t, u, p = ca.SX.sym("t"), ca.SX.sym("u", model.nu), ca.SX.sym("p", model.np)
    v = ca.jtimes(q, qj, qj_dot)
    G = ca.jacobian(v, vj)
    gdot = ca.jtimes(v, qj, qj_dot)
    M = np.array(model.M, float)
    M[np.abs(M) < 1e-300] = 0.0
    Msp = sparse_dm(M)
    MG = ca.mtimes(Msp, G)
    n = js.nv
    Mj = ca.SX(n, n)
    for i in range(n):
        for k in range(i + 1):
            Mj[i, k] = ca.dot(G[:, i], MG[:, k])
    F = js.passive_force(t, q, v, u, p)
    h = ca.mtimes(G.T, F - ca.mtimes(Msp, gdot)) + joint_efforts(js, js.actuation(t, q, u, p)[1])
    aj, pivot = cholesky_solve(Mj, h)
    return _function(t, qj, vj, u, p, aj, pivot)


# --------------------------------------------------------------------------- recursive form
def _skew(w) -> ca.SX:
    return ca.vertcat(ca.horzcat(0, -w[2], w[1]), ca.horzcat(w[2], 0, -w[0]), ca.horzcat(-w[1], w[0], 0))


def _world_inertia(mass: float, cw, R, Ibar: np.ndarray) -> tuple:
    """A rigid body's spatial inertia about the world origin, world axes, as ``(m, h, J)``:
    ``h = m c`` (c the centre of mass), ``J = R Ī Rᵀ + m (|c|² 1 − c cᵀ)`` (symmetric, built
    from its lower triangle).  The matrix is ``[[J, [h]×], [−[h]×, m 1]]``."""
    RI = ca.mtimes(R, ca.DM(Ibar))
    J = ca.SX(3, 3)
    cc = ca.dot(cw, cw)
    for i in range(3):
        for j in range(i + 1):
            e = ca.dot(RI[i, :].T, R[j, :].T) - mass * cw[i] * cw[j] + (mass * cc if i == j else 0)
            J[i, j] = e
            J[j, i] = e
    return mass, mass * cw, J


def _apply(I: tuple, s) -> ca.SX:
    """``I s`` for ``I = (m, h, J)`` (:func:`_world_inertia`) and motion vectors ``s``
    (6 × k): ``[J α + h × a; m a − h × α]`` column by column."""
    m, h, J = I
    cols = []
    for k in range(s.size2()):
        w, a = s[:3, k], s[3:, k]
        cols.append(ca.vertcat(ca.mtimes(J, w) + ca.cross(h, a), m * a - ca.cross(h, w)))
    return ca.horzcat(*cols) if cols else ca.SX(6, 0)


def _cross_force(v, f) -> ca.SX:
    """``v ×* f`` for a spatial velocity ``v = [ω; v_O]`` and force ``f = [n_O; f]``."""
    return ca.vertcat(ca.cross(v[:3], f[:3]) + ca.cross(v[3:], f[3:]), ca.cross(v[:3], f[3:]))


def member_twist_map(js, name: str) -> ca.Function:
    """``Q(R, p)``: ``q̇_m = Q [ω; v_O]``, the rates of member ``name``'s natural
    coordinates moved rigidly with the world twist ``[ω; v_O]`` (``v_O``: velocity of the
    point at the world origin) at the pose ``(R, p)`` of its frame."""
    m = js.members[name]
    D = m.ctype.derivation
    R, p = ca.SX.sym("R", 3, 3), ca.SX.sym("p", 3)
    w, vO = ca.SX.sym("w", 3), ca.SX.sym("vO", 3)
    vals = dict(m.rigid.constants())
    vals.update({D.R_sym[a, b]: R[a, b] for a in range(3) for b in range(3)})
    vals.update({D.p_sym[a]: p[a] for a in range(3)})
    vp = vO + ca.cross(w, p)
    vals.update({D.omega_sym[a]: w[a] for a in range(3)})
    vals.update({D.v_sym[a]: vp[a] for a in range(3)})
    qd = to_casadi(D.qd_of_twist, vals)
    return ca.Function("twist_map", [R, p], [ca.jacobian(qd, ca.vertcat(w, vO))])


def member_inertia(js, name: str, Q: ca.Function) -> tuple[float, np.ndarray, np.ndarray]:
    """``(m, c, Ī)``: mass, centre of mass and inertia about it (member axes) from the
    member's natural-coordinate mass matrix (``Qᵀ M_m Q`` at the identity pose, the spatial
    inertia about the member's origin).  Raises :class:`ModelError` if that matrix is not a
    rigid body's."""
    M = np.asarray(js.members[name].rigid.M, float)
    Q0 = np.array(Q(np.eye(3), np.zeros(3)))
    I = Q0.T @ M @ Q0
    mass = I[3, 3]
    B = I[:3, 3:]
    c = np.array([B[2, 1], B[0, 2], B[1, 0]]) / mass if mass > 0 else np.zeros(3)
    C = np.array([[0, -c[2], c[1]], [c[2], 0, -c[0]], [-c[1], c[0], 0]])
    Ibar = I[:3, :3] + mass * C @ C
    scale = max(1.0, np.max(np.abs(I)))
    if (np.max(np.abs(I[3:, 3:] - mass * np.eye(3))) > 1e-12 * scale or np.max(np.abs(B - mass * C)) > 1e-12 * scale
            or np.max(np.abs(I - I.T)) > 1e-12 * scale):
        raise ModelError(f"member {name!r}: its mass matrix is not a rigid body's spatial inertia")
    return mass, c, Ibar


def _to_world(R, p, m) -> ca.SX:
    """Motion vectors ``m`` (6 × k, ``[ω; v]`` in a frame at ``(R, p)``, about its origin)
    in world coordinates about the world origin."""
    w = ca.mtimes(R, m[:3, :])
    return ca.vertcat(w, ca.mtimes(R, m[3:, :]) + ca.mtimes(_skew(p), w))


def _cross_motion(v, m) -> ca.SX:
    """``v ×m m`` for spatial velocities ``v``, ``m`` (``[ω; v_O]``)."""
    return ca.vertcat(ca.cross(v[:3], m[:3]), ca.cross(v[:3], m[3:]) + ca.cross(v[3:], m[:3]))


def _vee(W) -> ca.SX:
    return 0.5 * ca.vertcat(W[2, 1] - W[1, 2], W[0, 2] - W[2, 0], W[1, 0] - W[0, 1])


def _constant_or(S: ca.SX, x: ca.SX) -> ca.SX:
    """``S(x)`` as a constant when it takes the same value (to 1e-13) at a few joint
    positions (a revolute or prismatic axis: constant in the parent's frame, though its SX
    form from sines and cosines is not), else ``S`` itself."""
    f = ca.Function("S", [x], [S])
    rng = np.random.default_rng(0)
    values = [np.array(f(rng.uniform(-2.0, 2.0, x.numel()) if x.numel() else [])) for _ in range(3)]
    if all(np.max(np.abs(v - values[0]), initial=0.0) <= 1e-13 * max(1.0, np.max(np.abs(values[0]), initial=0.0))
           for v in values[1:]):
        return ca.SX(ca.sparsify(ca.DM(values[0]), 1e-15))
    return S


def _edge_function(js, e, forward: bool) -> ca.Function:
    """``(R_p, p_p, ω_p, v_p, x, w) -> (R_c, p_c, S, c)``: across joint ``e`` from the member
    on this side (pose, world twist) to the other, with joint positions ``x`` and rates ``w``:
    the other's pose, the joint's motion subspace ``S`` in world coordinates (its twist is
    ``[ω_p; v_p] + S w``) and ``c = Ṡ w`` (``w`` held).  ``S = X_p S_p(x)`` with ``S_p`` the
    relative twist per unit rate in this side's frame (AD of the joint's relative pose) and
    ``X_p`` this side's motion transform, so ``Ṡ w = v_p ×m (S w) + X_p (∂(S_p w)/∂x) ẋ``."""
    Rp, pp = ca.SX.sym("Rp", 3, 3), ca.SX.sym("pp", 3)
    wp, vp = ca.SX.sym("wp", 3), ca.SX.sym("vp", 3)
    has = e.name in js.nq_joint
    x = ca.SX.sym("x", js.nq_joint[e.name] if has else 0)
    w = ca.SX.sym("w", js.nv_joint[e.name] if has else 0)
    T = relative_pose(e, x, 3, sym=True)
    Rc, pc = carry((Rp, pp), e, T, forward, js.members, sym=True)
    if not has:
        return ca.Function("edge", [Rp, pp, wp, vp, x, w], [Rc, pc, ca.SX(6, 0), ca.SX.zeros(6)])
    Rl, pl = carry((ca.SX.eye(3), ca.SX.zeros(3)), e, T, forward, js.members, sym=True)
    xd = js.position_rates(e.name, x, w)
    wl = _vee(ca.mtimes(ca.reshape(ca.jtimes(ca.vec(Rl), x, xd), 3, 3), Rl.T))
    Sp = ca.jacobian(ca.vertcat(wl, ca.jtimes(pl, x, xd) - ca.cross(wl, pl)), w)
    Sp = _constant_or(Sp, x)
    S = _to_world(Rp, pp, Sp)
    c = _cross_motion(ca.vertcat(wp, vp), ca.mtimes(S, w))
    if not Sp.is_constant():
        c = c + _to_world(Rp, pp, ca.jtimes(ca.mtimes(Sp, w), x, xd))
    return ca.Function("edge", [Rp, pp, wp, vp, x, w], [Rc, pc, S, c])


def _owned(model, tree) -> dict[str, list[tuple[int, int]]]:
    """``{member: [(local slot, system index)]}``: each system coordinate given to the first
    member (breadth-first) that has it."""
    seen, out = set(), {}
    for _, name, _, _ in tree:
        out[name] = []
        for k, i in enumerate(model.layout.member_indices(name)):
            if i is not None and i not in seen:
                seen.add(i)
                out[name].append((k, i))
    return out


def uniform_gravity(model, owned) -> np.ndarray | None:
    """``g`` (m/s²) when the passive forces are exactly a uniform gravity field (constant,
    independent of the state, inputs and parameters): ``F_passive = Σ_m S_mᵀ M_m T_m g``,
    ``T_m`` a member's natural-coordinate rates under a unit translation, ``S_m`` the
    scatter onto the free coordinates (a member's coordinates fixed to the ground do not
    move, so this is not ``M T g``); else None."""
    js = model.joint_space
    f = js.passive_force
    ins = f.sx_in()
    if ca.depends_on(f(*ins), ca.vertcat(*[ca.vec(x) for x in ins])):
        return None
    F0 = np.array(f(*[np.zeros(x.shape) for x in ins])).reshape(-1)
    B = np.zeros((model.nq, 3))
    for name in owned:
        T = np.array(member_twist_map(js, name)(np.eye(3), np.zeros(3)))[:, 3:]
        local = np.asarray(js.members[name].rigid.M, float) @ T
        for k, i in enumerate(model.layout.member_indices(name)):
            if i is not None:
                B[i] += local[k]
    g = np.linalg.lstsq(B, F0, rcond=None)[0]
    return g if np.max(np.abs(B @ g - F0), initial=0.0) <= 1e-12 * max(1.0, np.max(np.abs(F0), initial=0.0)) else None


class _Recursion:
    """The Newton–Euler recursion shared by :func:`recursive_dynamics_function` and
    :func:`recursive_inverse_dynamics_function` (3D trees, world frame, spatial vectors
    ``[ω; v_O]`` about the world origin): poses, twists ``v_c = v_p + S w`` and accelerations
    ``a_c = a_p + Ṡ w (+ S a_j)`` outwards (a uniform gravity as the ground's ``[0; −g]``),
    then body forces ``f = I a + v ×* I v − f_ext`` (``f_ext = Qᵀ F``, the passive
    natural-coordinate forces of the member as a wrench) summed inwards into ``force``.
    ``aj=None``: without joint accelerations (the bias forces of forward dynamics)."""

    def __init__(self, model, aj: ca.SX | None = None):
        js = self.js = model.joint_space
        if js.dim != 3:
            raise ModelError("recursive joint-space dynamics: 3D models only")
        self.tree = tree = js.spanning_tree()
        self.t, self.u, self.p = t, u, p = ca.SX.sym("t"), ca.SX.sym("u", model.nu), ca.SX.sym("p", model.np)
        self.qj, self.vj = qj, vj = ca.SX.sym("qj", js.nq), ca.SX.sym("vj", js.nv)
        sq = js.slices()
        self.sv = sv = js.slices(rates=True)
        owned = _owned(model, tree)
        g = uniform_gravity(model, owned)
        pose = {"ground": (ca.SX.eye(3), ca.SX.zeros(3))}
        twist = {"ground": ca.SX.zeros(6)}
        acc = {"ground": ca.SX.zeros(6) if g is None else ca.vertcat(ca.SX.zeros(3), -ca.DM(g))}
        self.motion, self.parent = {}, {}
        for here, there, e, forward in tree:
            x = qj[sq[e.name]] if e.name in sq else ca.SX(0, 1)
            w = vj[sv[e.name]] if e.name in sv else ca.SX(0, 1)
            Rc, pc, S, c = _edge_function(js, e, forward)(*pose[here], twist[here][:3], twist[here][3:], x, w)
            pose[there] = (Rc, pc)
            twist[there] = twist[here] + ca.mtimes(S, w)
            acc[there] = acc[here] + c
            if aj is not None and e.name in sv:
                acc[there] = acc[there] + ca.mtimes(S, aj[sv[e.name]])
            self.motion[there], self.parent[there] = (e.name, S), here
        q, v, Qs = [None] * model.nq, [None] * model.nq, {}
        for _, name, _, _ in tree:
            Qs[name] = member_twist_map(js, name)(*pose[name])
            local_q = js.member_coordinates(name, *pose[name])
            local_v = ca.mtimes(Qs[name], twist[name])
            for k, i in owned[name]:
                q[i], v[i] = local_q[k], local_v[k]
        self.q = q = ca.vertcat(*[ca.SX(0) if x is None else x for x in q])
        v = ca.vertcat(*[ca.SX(0) if x is None else x for x in v])
        F = js.passive_force(t, q, v, u, p)
        self.inertia, force = {}, {}
        for _, name, _, _ in tree:
            mass, c, Ibar = member_inertia(js, name, member_twist_map(js, name))
            R, pos = pose[name]
            I = _world_inertia(mass, pos + ca.mtimes(R, ca.DM(c)), R, Ibar)
            fext = ca.SX.zeros(6)
            if owned[name] and g is None:
                ks, idx = [k for k, _ in owned[name]], [i for _, i in owned[name]]
                fext = ca.mtimes(Qs[name][ks, :].T, F[idx])
            self.inertia[name] = I
            force[name] = _apply(I, acc[name]) + _cross_force(twist[name], _apply(I, twist[name])) - fext
        for here, there, _, _ in reversed(tree):
            if here != "ground":
                force[here] = force[here] + force[there]
        self.force = force

    def efforts(self) -> ca.SX:
        """``τ`` of the actuated joints placed at their joint rates (:func:`joint_efforts`)."""
        return joint_efforts(self.js, self.js.actuation(self.t, self.q, self.u, self.p)[1])

    def projected_forces(self) -> ca.SX:
        """``Sᵀ f`` per joint rate (the summed body force beyond each joint)."""
        out = ca.SX.zeros(self.js.nv)
        for _, there, _, _ in self.tree:
            name, S = self.motion[there]
            if S.size2():
                out[self.sv[name]] = ca.mtimes(S.T, self.force[there])
        return out


def recursive_dynamics_function(model) -> ca.Function:
    """``(t, qj, vj, u, p) -> (aj, check)`` like :func:`tree_dynamics_function`, computed
    recursively over the tree (:class:`_Recursion`, without joint accelerations), giving the
    bias ``C = Sᵀ f``; ``M_j`` by composite inertias (CRBA).  ``M_j a_j = τ − C``, solved by
    the same written-out Cholesky, leaves first (no fill-in)."""
    rec = _Recursion(model)
    tree, motion, sv = rec.tree, rec.motion, rec.sv
    n = rec.js.nv
    Mj = ca.SX(n, n)
    composite = dict(rec.inertia)
    for here, there, _, _ in reversed(tree):
        if here != "ground":
            composite[here] = tuple(a + b for a, b in zip(composite[here], composite[there]))
    for _, there, e, _ in tree:
        name, S = motion[there]
        if S.size2() == 0:
            continue
        Fm = _apply(composite[there], S)
        Mj[sv[name], sv[name]] = ca.mtimes(S.T, Fm)
        node = rec.parent[there]
        while node != "ground":
            up, Su = motion[node]
            if Su.size2():
                block = ca.mtimes(Su.T, Fm)
                Mj[sv[up], sv[name]] = block
                Mj[sv[name], sv[up]] = block.T
            node = rec.parent[node]
    order = [i for _, there, _, _ in reversed(tree) if motion[there][1].size2()
             for i in range(sv[motion[there][0]].start, sv[motion[there][0]].stop)]
    rhs = rec.efforts() - rec.projected_forces()
    y, pivot = cholesky_solve(Mj[order, order], rhs[order])
    aj = ca.SX.zeros(n)
    aj[order] = y
    return _function(rec.t, rec.qj, rec.vj, rec.u, rec.p, aj, pivot)


def recursive_inverse_dynamics_function(model) -> ca.Function:
    """``(t, qj, vj, aj, u, p) -> r``: the joint-space equations of motion as a residual,
    ``r = M_j a_j + C − τ`` (N·m or N per joint rate; ``τ`` the actuated joints' efforts,
    :func:`joint_efforts`), by recursive Newton–Euler (:class:`_Recursion` with the joint
    accelerations): ``r = Sᵀ f − τ``.  The same quantities as
    :func:`recursive_dynamics_function` without ``M_j``: linear in ``a_j`` and O(number of
    members) operations, so its derivatives stay cheap (the joint-space collocation's rows,
    :mod:`ncgen.optim.joint_radau`)."""
    aj = ca.SX.sym("aj", model.joint_space.nv)
    rec = _Recursion(model, aj)
    r = rec.projected_forces() - rec.efforts()
    return ca.Function("joint_inverse_dynamics", [rec.t, rec.qj, rec.vj, aj, rec.u, rec.p], [r],
                       ["t", "qj", "vj", "aj", "u", "p"], ["r"])

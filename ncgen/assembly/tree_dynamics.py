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
from ncgen.symbolic.coordinates import component_names, matrix_names
from ncgen.rigid_motion import casadi_forms as crm


def cholesky_solve(K: ca.SX, b: ca.SX) -> tuple[ca.SX, ca.SX]:
    """``(x, r)``: ``x = K⁻¹ b`` for a symmetric positive definite ``K`` (only its lower
    triangle is read) by ``K = L Lᵀ`` (factored once for every column of ``b``), and
    ``r = min_k d_k / K_kk`` over the pivots ``d_k`` (before their square roots).  Structural
    zeros of ``K`` are kept as zeros."""
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
    cols = []
    for c in range(b.size2()):
        y = [None] * n
        for i in range(n):
            y[i] = (b[i, c] - sum((L[i][j] * y[j] for j in range(i)), ca.SX(0))) / L[i][i]
        x = [None] * n
        for i in reversed(range(n)):
            x[i] = (y[i] - sum((L[j][i] * x[j] for j in range(i + 1, n)), ca.SX(0))) / L[i][i]
        cols.append(ca.vertcat(*x) if n else ca.SX(0, 1))
    r = ratios[0] if ratios else ca.SX(1)
    for z in ratios[1:]:
        r = ca.fmin(r, z)
    return ca.horzcat(*cols) if cols else ca.SX(n, 0), r


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
    if mimic_relations(model):
        raise ModelError("joint forward dynamics: the projected form does not take mimic joints "
                         "(the recursive form does: 3D models of rigid bodies)")
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
# Arboris notation (docs/notation.md, "Rigid motion"): g the ground frame, H_gm = [[R, p], [0, 1]]
# the pose of member m's frame, twists [ω; v] and wrenches [τ; f] expressed in g (v: velocity of
# the point at g's origin, τ: moment about it), M_g a member's mass matrix at g.  Every formula
# comes from ncgen.rigid_motion.casadi_forms (crm): Ad, ad, adᵀ (newton_euler_bias), se3_vee, ...


def _rotated_inertia(R, I_c: np.ndarray) -> ca.SX:
    """``R I_c Rᵀ``, exactly symmetric (built from its lower triangle)."""
    RI = ca.mtimes(R, I_c if isinstance(I_c, ca.SX) else ca.DM(I_c))
    out = ca.SX(3, 3)
    for i in range(3):
        for j in range(i + 1):
            out[i, j] = out[j, i] = ca.dot(RI[i, :].T, R[j, :].T)
    return out


def _mass_matrix_g(mass: float, c_g, R_gm, I_c: np.ndarray) -> ca.SX:
    """``M_g = [[I_o, m ĉ], [m ĉᵀ, m 1]]``: a member's mass matrix at g (``crm.mass_matrix``)
    with centre of mass ``c_g`` and ``I_o = R I_c Rᵀ + m ĉᵀĉ`` (``crm.inertia_about_point``)."""
    return crm.mass_matrix(mass, c_g, crm.inertia_about_point(mass, c_g, _rotated_inertia(R_gm, I_c)))


def member_twist_map(js, name: str) -> ca.Function:
    """``Q(R, p)``: ``q̇_m = Q T_g``, the rates of member ``name``'s natural coordinates
    moved rigidly with the twist ``T_g = [ω; v]`` (expressed in g) at the pose ``(R, p)`` of
    its frame: the member's ``q̇(R, p, ω, v_p)`` with ``[ω; v_p] = Ad(H_pg) T_g``, p the
    frame at the member's origin with g's axes."""
    m = js.members[name]
    R, p = ca.SX.sym("R", 3, 3), ca.SX.sym("p", 3)
    T_g = ca.SX.sym("T_g", 6)
    vals = dict(m.rigid.constant_values)
    vals.update({n: R[a, b] for a, row in enumerate(matrix_names("R", 3)) for b, n in enumerate(row)})
    vals.update(zip(component_names("p", 3), (p[a] for a in range(3))))
    T_p = crm.transport_twist(crm.translation(-p), T_g)
    vals.update(zip(component_names("omega", 3), (T_p[a] for a in range(3))))
    vals.update(zip(component_names("v", 3), (T_p[3 + a] for a in range(3))))
    from ncgen.model.member_forms import FORMS   # generated; a stored model never needs it
    qd = FORMS[m.ctype.name, 3, "qd_of_twist"](vals)
    return ca.Function("twist_map", [R, p], [ca.jacobian(qd, T_g)])


def member_twist_map_at_identity(js, name: str) -> np.ndarray:
    """``Q₀ = Q(I, 0)`` of :func:`member_twist_map` (the member's frame at the ground's pose,
    where ``[ω; v_p] = T_g``): column ``i`` is the member's ``q̇`` form (linear in the twist)
    at ``T_g = e_i``, evaluated in floats — no symbols (a twentieth of the symbolic map's cost)."""
    m = js.members[name]
    vals = {k: float(v) for k, v in m.rigid.constant_values.items()}
    vals.update({n: float(a == b) for a, row in enumerate(matrix_names("R", 3)) for b, n in enumerate(row)})
    vals.update(zip(component_names("p", 3), (0.0, 0.0, 0.0)))
    from ncgen.model.member_forms import FORMS   # generated; a stored model never needs it
    form = FORMS[m.ctype.name, 3, "qd_of_twist"]
    names = (*component_names("omega", 3), *component_names("v", 3))
    columns = [np.array(form({**vals, **{n: float(i == k) for k, n in enumerate(names)}}), float).reshape(-1)
               for i in range(6)]
    return np.stack(columns, axis=1)


def member_inertia(js, name: str) -> tuple[float, np.ndarray, np.ndarray]:
    """``(m, c, I_c)``: mass, centre of mass and inertia about it (member axes) from the
    member's natural-coordinate mass matrix: ``M_m = Q₀ᵀ M Q₀`` at the identity pose
    (:func:`member_twist_map_at_identity`) is its mass matrix at its frame, split by
    ``mass_matrix_parts``.  Raises :class:`ModelError` if that matrix is not a rigid body's."""
    M = np.asarray(js.members[name].rigid.M, float)
    Q0 = member_twist_map_at_identity(js, name)
    M_m = Q0.T @ M @ Q0
    mass = M_m[3, 3]
    if mass > 0:
        _, c, I_c = (np.array(x, float).reshape(s) for x, s in zip(crm.mass_matrix_parts(ca.DM(M_m)), [(), (3,), (3, 3)]))
    else:
        c, I_c = np.zeros(3), M_m[:3, :3]
    rebuilt = np.array(crm.mass_matrix(mass, c, crm.inertia_about_point(mass, c, I_c)), float)
    if np.max(np.abs(rebuilt - M_m)) > 1e-12 * max(1.0, np.max(np.abs(M_m))):
        raise ModelError(f"member {name!r}: its mass matrix is not a rigid body's spatial inertia")
    return mass, c, I_c


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
    """``(R_p, p_p, ω_p, v_p, x, w) -> (R_c, p_c, S_g, c_g)``: across joint ``e`` from the
    member p on this side (pose ``H_gp``, twist ``T_p = [ω_p; v_p]`` in g) to the member c on
    the other, with joint positions ``x`` and rates ``w``: c's pose, the joint's motion
    subspace in g (``T_c = T_p + S_g w``) and ``c_g = Ṡ_g w`` (``w`` held).
    ``S_g = Ad(H_gp) S_p(x)``, ``S_p`` the twist of c relative to p per unit rate, in p
    (``(Ḣ_pc H_pc⁻¹)^∨``, by AD of the joint's relative pose), so
    ``Ṡ_g w = ad(T_p) S_g w + Ad(H_gp) (∂(S_p w)/∂x) ẋ``."""
    Rp, pp = ca.SX.sym("Rp", 3, 3), ca.SX.sym("pp", 3)
    wp, vp = ca.SX.sym("wp", 3), ca.SX.sym("vp", 3)
    has = e.name in js.nq_joint
    x = ca.SX.sym("x", js.nq_joint[e.name] if has else 0)
    w = ca.SX.sym("w", js.nv_joint[e.name] if has else 0)
    T = relative_pose(e, x, 3, sym=True)
    Rc, pc = carry((Rp, pp), e, T, forward, js.members, sym=True)
    if not has:
        return ca.Function("edge", [Rp, pp, wp, vp, x, w], [Rc, pc, ca.SX(6, 0), ca.SX.zeros(6)])
    H_pc = crm.homogeneous(*carry((ca.SX.eye(3), ca.SX.zeros(3)), e, T, forward, js.members, sym=True))
    xd = js.position_rates(e.name, x, w)
    H_pc_dot = ca.reshape(ca.jtimes(ca.vec(H_pc), x, xd), 4, 4)
    S_p = _constant_or(ca.jacobian(crm.se3_vee(ca.mtimes(H_pc_dot, crm.inverse(H_pc))), w), x)
    Ad_gp = crm.Ad(crm.homogeneous(Rp, pp))
    S_g = ca.mtimes(Ad_gp, S_p)
    c_g = ca.mtimes(crm.ad(ca.vertcat(wp, vp)), ca.mtimes(S_g, w))
    if not S_p.is_constant():
        c_g = c_g + ca.mtimes(Ad_gp, ca.jtimes(ca.mtimes(S_p, w), x, xd))
    return ca.Function("edge", [Rp, pp, wp, vp, x, w], [Rc, pc, S_g, c_g])


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
        T = member_twist_map_at_identity(js, name)[:, 3:]
        local = np.asarray(js.members[name].rigid.M, float) @ T
        for k, i in enumerate(model.layout.member_indices(name)):
            if i is not None:
                B[i] += local[k]
    g = np.linalg.lstsq(B, F0, rcond=None)[0]
    return g if np.max(np.abs(B @ g - F0), initial=0.0) <= 1e-12 * max(1.0, np.max(np.abs(F0), initial=0.0)) else None


def mimic_relations(model) -> list[tuple[str, str, float, float]]:
    """``(follower, leader, k, offset)`` of every :class:`~ncgen.model.joints.Mimic` joint of
    ``model`` (``θ_follower = k θ_leader + offset``), leaders resolved through chains of
    mimics.  Raises :class:`ModelError` when a joint mimics itself (a cycle) or a joint
    without exactly one coordinate."""
    js = model.joint_space
    direct = {}
    for j in model.joints:
        if j.kind == "Mimic":
            o = j.options
            f, lead = o["follower"].name, o["leader"].name
            for role, n in (("follower", f), ("leader", lead)):
                if js.nv_joint.get(n) != 1:
                    raise ModelError(f"joint {j.name!r}: the {role} {n!r} is not a joint with one coordinate")
            if f in direct:
                raise ModelError(f"joint {j.name!r}: joint {f!r} already mimics {direct[f][0]!r}")
            direct[f] = (lead, o["multiplier"], o["offset"])
    out = []
    for f, (lead, k, off) in direct.items():
        seen = {f}
        while lead in direct:
            if lead in seen:
                raise ModelError(f"mimic joints: {f!r} mimics itself through {' -> '.join(sorted(seen))}")
            seen.add(lead)
            lead2, k2, off2 = direct[lead]
            lead, k, off = lead2, k * k2, k * off2 + off
        out.append((f, lead, float(k), float(off)))
    return out


class MimicMap:
    """The joint rates of a tree with mimic joints: ``v_j = G v_i`` (``G``: nv × nv_i, an
    identity column per independent rate, ``k`` at a follower's row in its leader's column),
    ``q_j`` the same map plus the offsets.  ``independent``: the indices of the independent
    rates in ``v_j`` (``model.joint_names`` order); without mimic joints ``G = 1``."""

    def __init__(self, model):
        js = model.joint_space
        sq, sv = js.slices(), js.slices(rates=True)
        self.relations = mimic_relations(model)
        self.follows = {sv[f].start: (sv[lead].start, k) for f, lead, k, _ in self.relations}
        self.position = {sq[f].start: (sq[lead].start, k, off) for f, lead, k, off in self.relations}
        self.independent = [i for i in range(js.nv) if i not in self.follows]
        G = np.zeros((js.nv, len(self.independent)))
        col = {i: c for c, i in enumerate(self.independent)}
        for i in range(js.nv):
            lead, k = self.follows.get(i, (i, 1.0))
            G[i, col[lead]] = k
        self.G = G

    def positions(self, qj):
        """``q_j`` with every follower's position set from its leader's (SX)."""
        rows = [self.position[i][1] * qj[self.position[i][0]] + self.position[i][2] if i in self.position else qj[i]
                for i in range(qj.numel())]
        return ca.vertcat(*rows) if rows else qj

    def rates(self, vj):
        """``v_j`` with every follower's rate set from its leader's (SX): ``G v_j[independent]``."""
        rows = [self.follows[i][1] * vj[self.follows[i][0]] if i in self.follows else vj[i] for i in range(vj.numel())]
        return ca.vertcat(*rows) if rows else vj


class _Recursion:
    """The Newton–Euler recursion shared by :func:`recursive_dynamics_function` and
    :func:`recursive_inverse_dynamics_function` (3D trees; twists, accelerations and wrenches
    expressed in g): poses, twists ``T_c = T_p + S_g w`` and accelerations
    ``dT_c = dT_p + Ṡ_g w (+ S_g a_j)`` outwards (a uniform gravity as the ground's
    ``[0; −g]``), then member wrenches ``W_g = M_g dT − ad(T)ᵀ M_g T − W_ext``
    (``W_ext = Qᵀ F``, the member's passive natural-coordinate
    forces as a wrench) summed inwards into ``wrench``.  Mimic joints: the followers'
    positions, rates and accelerations are set from their leaders' (:class:`MimicMap`) before
    the recursion; the bias ``−ad(T)ᵀ (M_g T)`` is
    ``crm.newton_euler_bias`` evaluated as two products (its SymPy form is expanded).  ``aj=None``: without joint
    accelerations (the bias forces of forward dynamics)."""

    def __init__(self, model, aj: ca.SX | None = None):
        js = self.js = model.joint_space
        if js.dim != 3:
            raise ModelError("recursive joint-space dynamics: 3D models only")
        self.tree = tree = js.spanning_tree()
        self.t, self.u, self.p = t, u, p = ca.SX.sym("t"), ca.SX.sym("u", model.nu), ca.SX.sym("p", model.np)
        self.qj, self.vj = ca.SX.sym("qj", js.nq), ca.SX.sym("vj", js.nv)
        self.mimic = mimic = MimicMap(model)
        qj, vj = mimic.positions(self.qj), mimic.rates(self.vj)
        aj = None if aj is None else mimic.rates(aj)
        self.sv = js.slices(rates=True)
        owned = _owned(model, tree)
        g = uniform_gravity(model, owned)
        pose, T_g, dT_g = self._outwards(qj, vj, aj, g)
        Qs = {name: member_twist_map(js, name)(*pose[name]) for _, name, _, _ in tree}
        q, v = [None] * model.nq, [None] * model.nq
        for _, name, _, _ in tree:
            local_q = js.member_coordinates(name, *pose[name])
            local_v = ca.mtimes(Qs[name], T_g[name])
            for k, i in owned[name]:
                q[i], v[i] = local_q[k], local_v[k]
        self.q = q = ca.vertcat(*[ca.SX(0) if x is None else x for x in q])
        v = ca.vertcat(*[ca.SX(0) if x is None else x for x in v])
        F = js.passive_force(t, q, v, u, p)
        W_ext = {}                                        # the passive forces as wrenches
        for _, name, _, _ in tree:
            W_ext[name] = ca.SX.zeros(6)
            if owned[name] and g is None:
                ks, idx = [k for k, _ in owned[name]], [i for _, i in owned[name]]
                W_ext[name] = ca.mtimes(Qs[name][ks, :].T, F[idx])
        self.wrench = self._inwards(pose, T_g, dT_g, W_ext)

    def _outwards(self, qj, vj, aj, g):
        """Poses, twists ``T_c = T_p + S_g w`` and accelerations ``dT_c = dT_p + Ṡ_g w (+ S_g
        a_j)`` of every member from the ground outwards (the ground's ``[0; −g]`` with a
        uniform gravity ``g``); records each member's joint motion ``(joint, S_g)`` and parent."""
        js = self.js
        sq, sv = js.slices(), self.sv
        pose = {"ground": (ca.SX.eye(3), ca.SX.zeros(3))}
        T_g = {"ground": ca.SX.zeros(6)}
        dT_g = {"ground": ca.SX.zeros(6) if g is None else ca.vertcat(ca.SX.zeros(3), -ca.DM(g))}
        self.motion, self.parent = {}, {}
        for here, there, e, forward in self.tree:
            x = qj[sq[e.name]] if e.name in sq else ca.SX(0, 1)
            w = vj[sv[e.name]] if e.name in sv else ca.SX(0, 1)
            Rc, pc, S_g, c_g = _edge_function(js, e, forward)(*pose[here], T_g[here][:3], T_g[here][3:], x, w)
            pose[there] = (Rc, pc)
            T_g[there] = T_g[here] + ca.mtimes(S_g, w)
            dT_g[there] = dT_g[here] + c_g
            if aj is not None and e.name in sv:
                dT_g[there] = dT_g[there] + ca.mtimes(S_g, aj[sv[e.name]])
            self.motion[there], self.parent[there] = (e.name, S_g), here
        return pose, T_g, dT_g

    def _inwards(self, pose, T_g, dT_g, W_ext) -> dict:
        """Each member's wrench ``W_g = M_g dT − ad(T)ᵀ M_g T − W_ext`` (its mass matrix about
        g in ``inertia``), summed from the leaves inwards."""
        self.inertia, wrench = {}, {}
        for _, name, _, _ in self.tree:
            mass, c, I_c = member_inertia(self.js, name)
            R, pos = pose[name]
            M_g = _mass_matrix_g(mass, pos + ca.mtimes(R, ca.DM(c)), R, I_c)
            self.inertia[name] = M_g
            h_g = ca.mtimes(M_g, T_g[name])                 # momentum; −ad(T)ᵀ h is the velocity bias
            wrench[name] = ca.mtimes(M_g, dT_g[name]) - ca.mtimes(crm.ad(T_g[name]).T, h_g) - W_ext[name]
        for here, there, _, _ in reversed(self.tree):
            if here != "ground":
                wrench[here] = wrench[here] + wrench[there]
        return wrench

    def efforts(self) -> ca.SX:
        """``τ`` of the actuated joints placed at their joint rates (:func:`joint_efforts`)."""
        return joint_efforts(self.js, self.js.actuation(self.t, self.q, self.u, self.p)[1])

    def projected_forces(self) -> ca.SX:
        """``S_gᵀ W_g`` per joint rate (the summed member wrench beyond each joint)."""
        out = ca.SX.zeros(self.js.nv)
        for _, there, _, _ in self.tree:
            name, S_g = self.motion[there]
            if S_g.size2():
                out[self.sv[name]] = ca.mtimes(S_g.T, self.wrench[there])
        return out


def composite_mass_matrix(rec: _Recursion) -> ca.SX:
    """``M_j`` (nv × nv, both triangles) by composite inertias (CRBA): ``(M_j)_ik = S_iᵀ M^c_k S_k``
    for ``i`` an ancestor of (or equal to) ``k``, ``M^c_k`` the summed mass matrices of the
    subtree beyond joint ``k`` (in g)."""
    tree, motion, sv = rec.tree, rec.motion, rec.sv
    n = rec.js.nv
    Mj = ca.SX(n, n)
    composite = dict(rec.inertia)
    for here, there, _, _ in reversed(tree):
        if here != "ground":
            composite[here] = composite[here] + composite[there]
    for _, there, e, _ in tree:
        name, S = motion[there]
        if S.size2() == 0:
            continue
        Fm = ca.mtimes(composite[there], S)
        Mj[sv[name], sv[name]] = ca.mtimes(S.T, Fm)
        node = rec.parent[there]
        while node != "ground":
            up, Su = motion[node]
            if Su.size2():
                block = ca.mtimes(Su.T, Fm)
                Mj[sv[up], sv[name]] = block
                Mj[sv[name], sv[up]] = block.T
            node = rec.parent[node]
    return Mj


def leaves_first(rec: _Recursion) -> list[int]:
    """The positions in ``rec.mimic.independent`` of the independent joint rates, joints of
    the deepest members first (a Cholesky factor of ``M_j`` in this order has no fill-in)."""
    col = {i: c for c, i in enumerate(rec.mimic.independent)}
    return [col[i] for _, there, _, _ in reversed(rec.tree) if rec.motion[there][1].size2()
            for i in range(rec.sv[rec.motion[there][0]].start, rec.sv[rec.motion[there][0]].stop) if i in col]


def independent_solve(rec: _Recursion, M_i: ca.SX, b: ca.SX) -> tuple[ca.SX, ca.SX]:
    """``(M_i⁻¹ b, pivot)`` by :func:`cholesky_solve` in the :func:`leaves_first` order (``b``
    a vector or a matrix of columns)."""
    order = leaves_first(rec)
    x = ca.SX.zeros(b.size1(), b.size2())
    y, pivot = cholesky_solve(M_i[order, order], b[order, :])
    if order:
        x[order, :] = y
    return x, pivot


def recursive_dynamics_function(model) -> ca.Function:
    """``(t, qj, vj, u, p) -> (aj, check)`` like :func:`tree_dynamics_function`, computed
    recursively over the tree (:class:`_Recursion`, without joint accelerations), giving the
    bias ``C = S_gᵀ W_g``; ``M_j`` by composite inertias (:func:`composite_mass_matrix`).
    ``M_i a_i = Gᵀ (τ − C)`` with ``M_i = Gᵀ M_j G`` (:class:`MimicMap`; ``G = 1`` without
    mimic joints), solved by the written-out Cholesky, leaves first (no fill-in); ``aj = G a_i``
    (a follower's entries of ``qj``, ``vj`` are ignored: set from its leader's)."""
    rec = _Recursion(model)
    G = ca.DM(rec.mimic.G)
    M_i = ca.mtimes([G.T, composite_mass_matrix(rec), G])
    rhs = ca.mtimes(G.T, rec.efforts() - rec.projected_forces())
    a_i, pivot = independent_solve(rec, M_i, rhs)
    return _function(rec.t, rec.qj, rec.vj, rec.u, rec.p, ca.mtimes(G, a_i), pivot)


def recursive_inverse_dynamics_function(model) -> ca.Function:
    """``(t, qj, vj, aj, u, p) -> r``: the joint-space equations of motion as a residual,
    ``r = M_j a_j + C − τ`` (N·m or N per joint rate; ``τ`` the actuated joints' efforts,
    :func:`joint_efforts`), by recursive Newton–Euler (:class:`_Recursion` with the joint
    accelerations): ``r = Gᵀ (S_gᵀ W_g − τ)`` (one row per independent rate,
    :class:`MimicMap`).  The same quantities as
    :func:`recursive_dynamics_function` without ``M_j``: linear in ``a_j`` and O(number of
    members) operations, so its derivatives stay cheap (the joint-space collocation's rows,
    :mod:`ncgen.optim.joint_radau`)."""
    aj = ca.SX.sym("aj", model.joint_space.nv)
    rec = _Recursion(model, aj)
    r = ca.mtimes(ca.DM(rec.mimic.G).T, rec.projected_forces() - rec.efforts())
    return ca.Function("joint_inverse_dynamics", [rec.t, rec.qj, rec.vj, aj, rec.u, rec.p], [r],
                       ["t", "qj", "vj", "aj", "u", "p"], ["r"])

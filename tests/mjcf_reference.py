"""MuJoCo as the reference for MJCF imports: the shipped MJCF files, and the map between
MuJoCo's joint space (qpos, qvel, qacc) and ncgen's (model.joint_names order).

MuJoCo's compiled model is used only here, as the independent reference; the ncgen model
comes from the XML (ncgen.model.mjcf)."""
from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np



def package_dir(name: str) -> Path | None:
    spec = importlib.util.find_spec(name)
    return None if spec is None or spec.origin is None else Path(spec.origin).parent


def shipped_files() -> dict[str, Path]:
    """``{"gymnasium/hopper.xml": path, "dm_control/cheetah.xml": path, ...}`` of the
    installed packages (either may be missing)."""
    out = {}
    for pkg, sub in (("gymnasium", "envs/mujoco/assets"), ("dm_control", "suite")):
        d = package_dir(pkg)
        if d is not None and (d / sub).is_dir():
            for f in sorted((d / sub).glob("*.xml")):
                out[f"{pkg}/{f.name}"] = f
    return out


def quat_wxyz_to_matrix(q):
    w, x, y, z = np.asarray(q, float) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


class JointMap:
    """MuJoCo (qpos, qvel, qacc) ↔ ncgen (qj, vj, aj) for hinge, slide, free joints and joint
    sequences (several hinges or slides in one body: coordinate k is the body's k-th joint),
    joint by joint."""

    def __init__(self, model, system, mj):
        import mujoco
        self.model, self.mj = model, mj
        self.items = []
        names = model.joint_names
        js = model.joint_space
        sq, sv = js.slices(), js.slices(rates=True)
        for n in names:
            joint = js.joints[n]
            if joint.kind in ("Revolute", "Prismatic"):
                jid = mujoco.mj_name2id(mj, mujoco.mjtObj.mjOBJ_JOINT, n)
                assert jid >= 0, n
                self.items.append(("one", sq[n], sv[n], mj.jnt_qposadr[jid], mj.jnt_dofadr[jid]))
            elif joint.kind == "JointSequence":
                j0 = mj.body_jntadr[mujoco.mj_name2id(mj, mujoco.mjtObj.mjOBJ_BODY, joint.B.name)]
                assert mj.body_jntnum[mj.jnt_bodyid[j0]] == len(joint.laws), n
                for k in range(len(joint.laws)):
                    self.items.append(("one", slice(sq[n].start + k, sq[n].start + k + 1),
                                       slice(sv[n].start + k, sv[n].start + k + 1), mj.jnt_qposadr[j0 + k],
                                       mj.jnt_dofadr[j0 + k]))
            elif joint.kind == "Free":
                body = joint.B.name
                jid = mj.body_jntadr[mujoco.mj_name2id(mj, mujoco.mjtObj.mjOBJ_BODY, body)]
                self.items.append(("free", sq[n], sv[n], mj.jnt_qposadr[jid], mj.jnt_dofadr[jid]))
            else:
                raise AssertionError(f"no map for {joint.kind}")

    def to_ncgen(self, qpos, qvel):
        qj, vj = np.zeros(self.model.joint_space.nq), np.zeros(self.model.joint_space.nv)
        for kind, sq, sv, ia, da in self.items:
            if kind == "one":
                qj[sq], vj[sv] = qpos[ia:ia + 1] - self.mj.qpos0[ia], qvel[da:da + 1]   # ncgen: qpos − ref
            else:
                w, x, y, z = qpos[ia + 3:ia + 7]
                qj[sq] = np.r_[qpos[ia:ia + 3], x, y, z, w]
                R = quat_wxyz_to_matrix(qpos[ia + 3:ia + 7])
                vj[sv] = np.r_[R.T @ qvel[da:da + 3], qvel[da + 3:da + 6]]
        return qj, vj

    def acceleration_to_mujoco(self, qpos, qvel, aj):
        """ncgen's joint accelerations in MuJoCo's dof order."""
        qacc = np.zeros(self.mj.nv)
        for kind, sq, sv, ia, da in self.items:
            if kind == "one":
                qacc[da] = aj[sv][0]
            else:
                R = quat_wxyz_to_matrix(qpos[ia + 3:ia + 7])
                w = qvel[da + 3:da + 6]
                v_local = R.T @ qvel[da:da + 3]
                qacc[da:da + 3] = R @ (aj[sv][:3] + np.cross(w, v_local))
                qacc[da + 3:da + 6] = aj[sv][3:]
        return qacc


def joint_ode(model):
    """The joint-space ODE the joint simulation integrates, with the joint dynamics (damping,
    armature, friction, limits): ``(t, x, tau, p) -> xdot``."""
    from ncgen.assembly.joint_ode import armature_dynamics_function, armature_vector, joint_ode_function
    from ncgen.assembly.tree_dynamics import recursive_inverse_dynamics_function
    from ncgen.runtime.joint_simulation import dynamics_function
    arm = armature_vector(model)
    if np.any(arm):
        dyn = armature_dynamics_function(model, recursive_inverse_dynamics_function(model), arm)
    else:
        dyn = dynamics_function(model)
    return joint_ode_function(model, dyn, None, joint_dynamics=True)


def mujoco_free_dynamics(path):
    """MuJoCo's model of ``path`` with contacts, limits, equality constraints and friction
    loss off (the dynamics the import represents; controls are clamped to ``ctrlrange`` as
    the imported actuation does)."""
    import mujoco
    mj = mujoco.MjModel.from_xml_path(str(path))
    D = mujoco.mjtDisableBit
    mj.opt.disableflags |= D.mjDSBL_CONTACT | D.mjDSBL_LIMIT | D.mjDSBL_EQUALITY | D.mjDSBL_FRICTIONLOSS
    return mj


def random_state(mj, rng):
    """A random qpos (hinges and slides inside their ranges when limited, hinges within 3 rad
    of zero: an imported hinge spring is a TorsionalSpring, periodic beyond π; unit
    quaternions) and qvel."""
    import mujoco
    qpos = mj.qpos0.copy()
    for j in range(mj.njnt):
        a = mj.jnt_qposadr[j]
        t = mj.jnt_type[j]
        if t == mujoco.mjtJoint.mjJNT_FREE:
            qpos[a:a + 3] += rng.normal(0, 0.3, 3)
            q = rng.normal(size=4)
            qpos[a + 3:a + 7] = q / np.linalg.norm(q)
        elif t == mujoco.mjtJoint.mjJNT_BALL:
            q = rng.normal(size=4)
            qpos[a:a + 4] = q / np.linalg.norm(q)
        else:
            lo, hi = mj.jnt_range[j] if mj.jnt_limited[j] else (-1.0, 1.0)
            if t == mujoco.mjtJoint.mjJNT_HINGE:
                lo, hi = max(lo, -3.0), min(hi, 3.0)
            qpos[a] = rng.uniform(lo, hi)
    return qpos, rng.normal(0, 1.0, mj.nv)


def coupling_rows(mj) -> np.ndarray:
    """Rows ``J`` (one per active joint or tendon equality; nv columns) of MuJoCo's linear
    couplings ``J qvel = 0``: ``<joint>`` with ``polycoef = 0 c1 0 0 0`` (``e_1 − c1 e_2``),
    ``<tendon tendon1>`` (the fixed tendon's coefficients)."""
    import mujoco
    rows = []
    for e in range(mj.neq):
        if not mj.eq_active0[e]:
            continue
        row = np.zeros(mj.nv)
        if mj.eq_type[e] == mujoco.mjtEq.mjEQ_JOINT:
            row[mj.jnt_dofadr[mj.eq_obj1id[e]]] = 1.0
            row[mj.jnt_dofadr[mj.eq_obj2id[e]]] -= mj.eq_data[e][1]
        elif mj.eq_type[e] == mujoco.mjtEq.mjEQ_TENDON:
            t = mj.eq_obj1id[e]
            for w in range(mj.tendon_adr[t], mj.tendon_adr[t] + mj.tendon_num[t]):
                assert mj.wrap_type[w] == mujoco.mjtWrap.mjWRAP_JOINT      # a fixed tendon
                row[mj.jnt_dofadr[mj.wrap_objid[w]]] += mj.wrap_prm[w]
        else:
            continue
        rows.append(row)
    return np.array(rows).reshape(-1, mj.nv)


def on_couplings(mj, J, qpos, qvel):
    """``(qpos, qvel)`` moved onto the couplings ``J (qpos − qpos0) = 0``, ``J qvel = 0``
    (hinge and slide dofs, whose qpos and qvel entries are one to one)."""
    if len(J) == 0:
        return qpos, qvel
    P = np.eye(mj.nv) - np.linalg.pinv(J) @ J
    dof_q = np.zeros(mj.nv, int)
    for j in range(mj.njnt):
        dof_q[mj.jnt_dofadr[j]] = mj.jnt_qposadr[j]
    cols = np.flatnonzero(np.any(J != 0, axis=0))
    x = np.zeros(mj.nv)
    x[cols] = qpos[dof_q[cols]] - mj.qpos0[dof_q[cols]]
    qpos = qpos.copy()
    qpos[dof_q[cols]] = mj.qpos0[dof_q[cols]] + (P @ x)[cols]
    return qpos, P @ qvel


def constrained_qacc(mj, d, J) -> np.ndarray:
    """MuJoCo's acceleration with the linear couplings ``J qacc = 0`` held exactly, from its
    unconstrained one (``d.qacc`` with equality constraints disabled) and mass matrix:
    ``a = a₀ − M⁻¹Jᵀ (J M⁻¹ Jᵀ)⁻¹ J a₀``."""
    import mujoco
    if len(J) == 0:
        return d.qacc.copy()
    M = np.zeros((mj.nv, mj.nv))
    mujoco.mj_fullM(mj, d, M)
    MJ = np.linalg.solve(M, J.T)
    return d.qacc - MJ @ np.linalg.solve(J @ MJ, J @ d.qacc)


def mujoco_without_meshes(path):
    """MuJoCo's compiled model of ``path`` with its mesh geoms, meshes and textures taken out
    (a Menagerie model whose mesh files are not here; their inertials are explicit, so the
    dynamics do not change), contacts, limits, equality constraints and friction loss off."""
    import mujoco
    spec = mujoco.MjSpec.from_file(str(path))
    for g in list(spec.geoms):
        if g.type == mujoco.mjtGeom.mjGEOM_MESH:
            spec.delete(g)
    for item in list(spec.meshes) + list(spec.textures):
        spec.delete(item)
    for mat in spec.materials:
        mat.textures = [""] * len(mat.textures)
    mj = spec.compile()
    D = mujoco.mjtDisableBit
    mj.opt.disableflags |= D.mjDSBL_CONTACT | D.mjDSBL_LIMIT | D.mjDSBL_EQUALITY | D.mjDSBL_FRICTIONLOSS
    return mj


def to_mujoco(model, mj, qj, vj, aj):
    """MuJoCo's ``(qpos, qvel, qacc)`` of ncgen's joint positions, rates and accelerations
    (``model.to_joint_space``; a Spherical joint's rotation and rates are in world axes as
    they were at the start, carried by the members, MuJoCo's ball in its body's axes):
    hinges and slides (``qpos = ref + x``), balls and free joints by name or body; joints
    that MuJoCo does not have (an ``<equality><connect>`` imported as a Spherical joint) are
    left out, their rates following from the others."""
    import mujoco
    qpos, qvel, qacc = mj.qpos0.copy(), np.zeros(mj.nv), np.zeros(mj.nv)
    js = model.joint_space
    sq, sv = js.slices(), js.slices(rates=True)
    for n in model.joint_names:
        joint = js.joints[n]
        jid = mujoco.mj_name2id(mj, mujoco.mjtObj.mjOBJ_JOINT, n.replace("_", "-"))
        if jid < 0:
            jid = mujoco.mj_name2id(mj, mujoco.mjtObj.mjOBJ_JOINT, n)
        if joint.kind == "Free":
            jid = mj.body_jntadr[mujoco.mj_name2id(mj, mujoco.mjtObj.mjOBJ_BODY, joint.B.name.replace("_", "-"))]
        if jid < 0:
            assert joint.kind == "Spherical", n
            continue
        ia, da = mj.jnt_qposadr[jid], mj.jnt_dofadr[jid]
        x, w, a = np.asarray(qj[sq[n]]), np.asarray(vj[sv[n]]), np.asarray(aj[sv[n]])
        if joint.kind in ("Revolute", "Prismatic"):
            qpos[ia], qvel[da], qacc[da] = mj.qpos0[ia] + x[0], w[0], a[0]
        elif joint.kind == "Spherical":        # ncgen: world axes at the start, carried; MuJoCo: B's axes
            R0 = joint.B.R0
            qpos[ia:ia + 4], qvel[da:da + 3], qacc[da:da + 3] = np.r_[x[3], R0.T @ x[:3]], R0.T @ w, R0.T @ a
        elif joint.kind == "Free":             # MuJoCo: world linear velocity, local angular one
            qpos[ia:ia + 7] = np.r_[x[:3], x[6], x[3:6]]
            R = quat_wxyz_to_matrix(qpos[ia + 3:ia + 7])
            qvel[da:da + 3], qvel[da + 3:da + 6] = R @ w[:3], w[3:]
            qacc[da:da + 3], qacc[da + 3:da + 6] = R @ (a[:3] + np.cross(w[3:], w[:3])), a[3:]
        else:
            raise AssertionError(f"no map for {joint.kind}")
    return qpos, qvel, qacc


def connect_rows(mj, d):
    """``(J, J̇ qvel)`` of MuJoCo's ``<connect>`` equalities at ``d`` (after ``mj_forward``):
    the anchors' relative position ``x_1 − x_2`` has velocity ``J qvel`` and acceleration
    ``J qacc + J̇ qvel``."""
    import mujoco
    rows, bias = [], []
    for k in range(mj.neq):
        if mj.eq_type[k] != mujoco.mjtEq.mjEQ_CONNECT:
            continue
        J, Jd = np.zeros((3, mj.nv)), np.zeros((3, mj.nv))
        for body, anchor, sign in ((mj.eq_obj1id[k], mj.eq_data[k, 0:3], 1.0), (mj.eq_obj2id[k], mj.eq_data[k, 3:6], -1.0)):
            x = d.xpos[body] + d.xmat[body].reshape(3, 3) @ anchor
            jp, jpd = np.zeros((3, mj.nv)), np.zeros((3, mj.nv))
            mujoco.mj_jac(mj, d, jp, None, x, body)
            mujoco.mj_jacDot(mj, d, jpd, None, x, body)
            J += sign * jp
            Jd += sign * jpd
        rows.append(J)
        bias.append(Jd @ d.qvel)
    return np.vstack(rows), np.concatenate(bias)


def loop_qacc(mj, d):
    """MuJoCo's acceleration with its connect equalities held exactly (``J qacc + J̇ qvel =
    0``), from its unconstrained one and mass matrix: ``a = a₀ − M⁻¹Jᵀ (J M⁻¹ Jᵀ)⁺ (J a₀ +
    J̇ qvel)`` (the pseudo-inverse: a planar loop's out-of-plane rows are dependent)."""
    import mujoco
    J, Jdv = connect_rows(mj, d)
    M = np.zeros((mj.nv, mj.nv))
    mujoco.mj_fullM(mj, d, M)
    MJ = np.linalg.solve(M, J.T)
    lam = np.linalg.lstsq(J @ MJ, J @ d.qacc + Jdv, rcond=1e-12)[0]
    return d.qacc - MJ @ lam


def on_loops(model, rng, spread: float):
    """A random state on the constraints: ``q0`` moved along the tangent space, then by
    minimum-norm Newton onto ``Φ = 0``; a random velocity in the null space of ``A(q)``."""
    from ncgen.assembly.manifold import newton, null_basis
    N = null_basis(np.asarray(model.A(model.q0)), model.nq)
    q, _, residual = newton(lambda x: np.asarray(model.phi(x)).ravel(), lambda x: np.asarray(model.A(x)),
                            model.q0 + N @ rng.normal(0.0, spread, N.shape[1]), np.arange(model.nq), tol=1e-13)
    assert residual <= 1e-13
    return q, null_basis(np.asarray(model.A(q)), model.nq) @ rng.normal(0.0, 1.0, N.shape[1])


def connect_gap(mj, d) -> float:
    """The largest distance (m) between the two anchors of MuJoCo's ``<connect>``
    equalities at ``d`` (after ``mj_forward`` or ``mj_step``): their closure error."""
    import mujoco
    worst = 0.0
    for k in range(mj.neq):
        if mj.eq_type[k] == mujoco.mjtEq.mjEQ_CONNECT:
            b1, b2 = mj.eq_obj1id[k], mj.eq_obj2id[k]
            x1 = d.xpos[b1] + d.xmat[b1].reshape(3, 3) @ mj.eq_data[k, 0:3]
            x2 = d.xpos[b2] + d.xmat[b2].reshape(3, 3) @ mj.eq_data[k, 3:6]
            worst = max(worst, float(np.linalg.norm(x1 - x2)))
    return worst


def closure_run(mj, t_end: float, every: int = 0):
    """MuJoCo's run of ``mj`` from its initial state for ``t_end`` s at its own integrator and
    timestep: ``(largest connect gap (m) over every step, qpos at t = 0 and after every
    ``every`` steps (none if 0))``."""
    import mujoco
    d = mujoco.MjData(mj)
    mujoco.mj_forward(mj, d)
    gap, qpos = connect_gap(mj, d), [d.qpos.copy()]
    for k in range(int(round(t_end / mj.opt.timestep))):
        mujoco.mj_step(mj, d)
        gap = max(gap, connect_gap(mj, d))
        if every and (k + 1) % every == 0:
            qpos.append(d.qpos.copy())
    return gap, np.array(qpos)

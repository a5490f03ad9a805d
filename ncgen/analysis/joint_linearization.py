"""Joint-space linearisation of a tree (``nc.linearize(model, qj, vj, u, space="joint")``)
from the compiled ABA derivatives of :mod:`ncgen.runtime.tree_algorithm_kernels`: joint-angle
``A``, ``B`` at any state (matching Pinocchio's ``computeABADerivatives``)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ncgen.errors import ModelError
from ncgen.runtime.tree_algorithm_kernels import aba_derivatives, rnea_applies
from ncgen.codegen.tree_check import check_tree, unit_quaternions
from ncgen.validation import as_vector


@dataclass
class JointLinearModel:
    """``δẋ = A δx + B δu`` about ``(t, qj, vj, u, p)`` in joint space: ``x = [δ; v_i]``,
    ``δ`` the tangent-space position deviation of the independent joint rates (``q_j ⊕ Gδ``,
    Pinocchio's ``integrate``: angles and lengths add, a spherical joint turns by ``exp(δ̂)``
    in its own axes, a free joint moves by the SE(3) exponential in its own frame) and
    ``v_i`` the independent rates.  ``A = [[K, 1], [∂a/∂q, ∂a/∂v]]``, ``B = [[0], [∂a/∂τ ∂τ/∂u]]``;
    ``K`` is zero for angles and lengths, ``−ω̂`` for a spherical joint and ``−ad(T)`` (its
    twist ``T`` in its frame, Pinocchio's ``[v; ω]`` order) for a free joint.  ``xdot = [v_i; a_i]``:
    the state derivative at the point (not zero away from equilibria).  ``state_names``:
    ``q:<rate name>`` then ``v:<rate name>``."""

    model: object = field(repr=False)
    A: np.ndarray
    B: np.ndarray
    xdot: np.ndarray
    t: float
    qj: np.ndarray = field(repr=False)
    vj: np.ndarray = field(repr=False)
    u: np.ndarray = field(repr=False)
    p: np.ndarray = field(repr=False)
    state_names: list = field(repr=False, default_factory=list)

    @property
    def eigenvalues(self) -> np.ndarray:
        return np.linalg.eigvals(self.A)


def _efforts(model):
    """The model's :func:`~ncgen.assembly.tree_algorithms.efforts_function` (built once)."""
    from ncgen.assembly.tree_algorithms import efforts_function
    from ncgen.model.data import model_data

    data = model_data(model)
    if "joint_efforts" not in data.functions:
        data.functions["joint_efforts"] = efforts_function(model)
    return data.functions["joint_efforts"]


def joint_linearization(model, qj, vj=None, u=None, p=None, t: float | None = None) -> JointLinearModel:
    """The joint-space linear model of a 3D tree about ``(qj, vj)`` with inputs ``u``
    (:class:`JointLinearModel`), from the compiled ABA derivatives (matching Pinocchio's
    ``computeABADerivatives`` at any state)."""
    from ncgen.rigid_motion import ad, so3_hat

    js = model.joint_space
    independent = rnea_applies(model)
    if independent is None:
        check_tree(model)
        raise ModelError("linearize(space='joint'): 3D trees only")
    t = model.t0 if t is None else float(t)
    qj = unit_quaternions(js, as_vector(qj, js.nq, "qj (joint positions, joint_names order)"))
    vj = np.zeros(js.nv) if vj is None else as_vector(vj, js.nv, "vj (joint rates, joint_names order)")
    u = np.zeros(model.nu) if u is None else as_vector(u, model.nu, "u (model.input_names order)")
    p = model.p0 if p is None else as_vector(p, model.np, "p")
    q, _ = model.from_joint_space(qj, vj, t=t, p=p)
    tau, dtau_du = (np.array(x, float) for x in _efforts(model)(t, q, u, p))
    a, da_dq, da_dv, da_dtau = aba_derivatives(model, qj, vj, tau.reshape(-1), p=p, t=t)
    n = len(independent)
    col = {i: c for c, i in enumerate(independent)}
    K = np.zeros((n, n))
    sv = js.slices(rates=True)
    for name in js.joint_names:
        kind, s = js.joints[name].kind, sv[name]
        w = vj[s]
        if kind == "Spherical" and js.nq_joint[name] == 4:
            idx = [col[i] for i in range(s.start, s.stop)]
            K[np.ix_(idx, idx)] = -so3_hat(w)
        elif kind == "Free":
            idx = [col[i] for i in range(s.start, s.stop)]
            ad_T = ad(np.concatenate([w[3:], w[:3]]))              # arboris [ω; v] order
            swap = np.r_[3:6, 0:3]
            K[np.ix_(idx, idx)] = -ad_T[np.ix_(swap, swap)]
    A = np.block([[K, np.eye(n)], [da_dq, da_dv]])
    B = np.vstack([np.zeros((n, model.nu)), da_dtau @ dtau_du.reshape(n, model.nu)])
    names = [js.rate_names[i] for i in independent]
    return JointLinearModel(model=model, A=A, B=B, xdot=np.concatenate([vj[independent], a[independent]]), t=t,
                            qj=qj, vj=vj, u=u, p=p, state_names=[f"q:{x}" for x in names] + [f"v:{x}" for x in names])

"""``linearize``: a minimal-state linear model ``ẋ = A x + B u``, ``y = C x + D u`` of a
model about a consistent state, in independent coordinates.

State ``x = [z; w]`` with ``z = G (q − q*)`` and ``w = G v`` (2·dof entries).  By default
``N`` is the orthonormal basis of ``null A(q*)`` from the SVD (:mod:`ncgen.assembly.manifold`)
and ``G = Nᵀ``; ``coordinates=G`` (dof × nq) chooses other independent coordinates, for
instance rows of ``∂(joint angles)/∂q`` so that ``z`` are joint-angle deviations.  Outputs
``y = [δq; δv]`` (the natural coordinates and rates to first order), ``D = 0``.  The
formulas, valid about non-equilibrium states too, are in :mod:`ncgen.assembly.linearization_function`.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ncgen.blas_threads import one_blas_thread
from ncgen.assembly.linearization_function import linearization_function
from ncgen.errors import NcgenError
from ncgen.model.rolling import STEADY_MOTIONS, refuse_rolling
from ncgen.analysis.statics import _parameters
from ncgen.analysis.stability import cached
from ncgen.assembly.manifold import coordinate_basis, manifold_point, numerical_rank, tangent_velocity
from ncgen.validation import as_vector

#: A state is consistent when |Φ| and |A v + Φ_t| are below this times the system's size².
CONSISTENCY_TOL = 1e-8


@dataclass
class LinearModel:
    """``A`` (2dof × 2dof), ``B`` (2dof × nu), ``C`` (2nq × 2dof), ``D`` (2nq × nu) about the
    point ``(t, q, v, u, p)``; ``N`` (nq × dof) and ``G`` (dof × nq) define the coordinates
    (``A_constraint N = 0``, ``G N = I``, ``z = G (q − q*)``, ``w = G v``); ``xdot`` is the
    state derivative at the point (zero at an equilibrium: the affine term of the model
    ``ẋ ≈ xdot + A δx + B δu`` otherwise).  ``state_names``: ``z0.. , w0..``."""

    model: object = field(repr=False)
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray = field(repr=False)
    D: np.ndarray = field(repr=False)
    xdot: np.ndarray
    N: np.ndarray = field(repr=False)
    G: np.ndarray = field(repr=False)
    t: float
    q: np.ndarray = field(repr=False)
    v: np.ndarray = field(repr=False)
    u: np.ndarray = field(repr=False)
    p: np.ndarray = field(repr=False)

    @property
    def state_names(self) -> list[str]:
        dof = self.N.shape[1]
        return [f"z{i}" for i in range(dof)] + [f"w{i}" for i in range(dof)]

    @property
    def eigenvalues(self) -> np.ndarray:
        return np.linalg.eigvals(self.A)

    def state(self, dz, dw=None) -> tuple[np.ndarray, np.ndarray]:
        """The consistent ``(q, v)`` with independent coordinates ``z = dz``, ``w = G v*
        + dw`` (``Φ(q) = 0`` and ``A v + Φ_t = 0`` exactly): to start a simulation from a
        perturbed state."""
        m = self.model
        dof = self.N.shape[1]
        dz = as_vector(dz, dof, "dz")
        dw = np.zeros(dof) if dw is None else as_vector(dw, dof, "dw")
        q = manifold_point(lambda x: m.phi(x, t=self.t, p=self.p), lambda x: m.A(x, t=self.t, p=self.p),
                           self.q, self.N, self.G, dz)
        phi_t = m._call("phi_t", q=q, t=self.t, p=self.p)
        v = tangent_velocity(m.A(q, t=self.t, p=self.p), self.G, self.G @ self.v + dw, phi_t)
        return q, v

    def save(self, path) -> None:
        """NPZ with ``A``, ``B``, ``C``, ``D``, ``xdot``, ``N``, ``G`` and the point
        ``t``, ``q``, ``v``, ``u``, ``p`` (``np.load(path)`` reads it)."""
        from ncgen.files import atomic_path
        with atomic_path(path) as tmp, open(tmp, "wb") as fh:
            np.savez(fh, A=self.A, B=self.B, C=self.C, D=self.D, xdot=self.xdot, N=self.N, G=self.G,
                     t=self.t, q=self.q, v=self.v, u=self.u, p=self.p,
                     state_names=np.array(self.state_names),
                     coordinate_names=np.array(self.model.coordinate_names))

    def coordinates(self, q, v) -> np.ndarray:
        """The state ``x = [G (q − q*); G v]`` of a configuration and rates."""
        return np.concatenate([self.G @ (np.asarray(q) - self.q), self.G @ np.asarray(v)])


def linearization(model):
    """The model's ``linearize`` CasADi function (built once; see :mod:`ncgen.assembly.linearization_function`)."""
    from ncgen.assembly.mass import sparse_dm
    return cached(model, "linearize", lambda: linearization_function(model.functions, sparse_dm(model.M),
                                                                       model.dof))


@one_blas_thread
def linearize(model, q, v=None, u=None, p=None, *, t: float | None = None, coordinates=None,
              space: str = "natural"):
    """Linearise ``model`` about ``(q, v)`` (consistent: ``Φ = 0``, ``A v + Φ_t = 0``; ``v``
    default zeros) with inputs ``u`` (default zeros), parameters ``p`` (default the model's;
    array or dict by name) at time ``t`` (default ``model.t0``).  ``coordinates``: the
    matrix ``G`` (dof × nq) of independent coordinates (default ``Nᵀ``, ``N`` orthonormal).
    ``q`` may also be an :class:`~ncgen.analysis.statics.Equilibrium` (its ``q``, ``u``, ``p``, ``t``).
    See the module docstring; redundant constraints must have been dropped (the default
    of ``System.build``).  ``space="joint"`` (3D trees): ``q``, ``v`` are joint positions and
    rates and the result is the joint-space model of
    :func:`~ncgen.analysis.joint_linearization.joint_linearization` (Pinocchio's
    ``computeABADerivatives``, at any state)."""
    refuse_rolling(model, "linearize", STEADY_MOTIONS)
    if space not in ("natural", "joint"):
        raise NcgenError(f"linearize: space: expected 'natural' or 'joint', got {space!r}")
    if space == "joint":
        from ncgen.analysis.joint_linearization import joint_linearization
        if coordinates is not None:
            raise NcgenError("linearize: coordinates= is for space='natural' (space='joint' uses the joint angles)")
        return joint_linearization(model, q, v, u, p, t)
    from ncgen.analysis.statics import Equilibrium
    if isinstance(q, Equilibrium):
        eq = q
        q, u, p, t = eq.q, eq.u if u is None else u, eq.p if p is None else p, eq.t if t is None else t
    nq = model.nq
    t = model.t0 if t is None else float(t)
    q = as_vector(q, nq, "q")
    v = np.zeros(nq) if v is None else as_vector(v, nq, "v")
    u = np.zeros(model.nu) if u is None else as_vector(u, model.nu, "u")
    p = _parameters(model, p)
    A = model.A(q, t=t, p=p).reshape(-1, nq)
    size = max(1.0, float(np.abs(q).max()))
    phi = model.phi(q, t=t, p=p)
    rate = A @ v + model._call("phi_t", q=q, t=t, p=p)
    if phi.size and np.abs(phi).max() > CONSISTENCY_TOL * size**2:
        k = int(np.argmax(np.abs(phi)))
        raise NcgenError(f"linearize: q is not on the constraints: {model.constraint_names[k]} = {phi[k]:.3g}; "
                         "use nc.equilibrium or nc.assemble to get a consistent configuration")
    if rate.size and np.abs(rate).max() > CONSISTENCY_TOL * max(size, float(np.abs(v).max())) * size:
        k = int(np.argmax(np.abs(rate)))
        raise NcgenError(f"linearize: v violates the velocity constraint of {model.constraint_names[k]} "
                         f"(A v + Phi_t = {rate[k]:.3g}); use nc.project_velocity")
    if numerical_rank(A) < A.shape[0]:
        raise NcgenError("linearize: the constraint Jacobian is rank-deficient at q (redundant constraints "
                         "or a singular configuration); build the model with redundant='drop'")
    N, G = coordinate_basis(A, nq, coordinates)
    if N.shape[1] != model.dof:
        raise NcgenError(f"linearize: the constraints leave {N.shape[1]} degrees of freedom at q, "
                         f"but the model was built with {model.dof}: rebuild it near this configuration")
    A_lin, B_lin, C_lin, xdot = (np.array(x, float) for x in linearization(model)(t, q, v, u, p, N, G))
    return LinearModel(model=model, A=A_lin, B=B_lin.reshape(A_lin.shape[0], model.nu), C=C_lin,
                       D=np.zeros((2 * nq, model.nu)), xdot=xdot.reshape(-1), N=N, G=G, t=t, q=q, v=v, u=u, p=p)

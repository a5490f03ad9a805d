"""Conditions on full states in optimal control: consistent configurations and velocities
(the manifold's numerics are in :mod:`ncgen.assembly.manifold`).

The transcriptions integrate the index-1 dynamics, whose invariants are ``Φ(q) = 0`` and
``A v + Φ_t = 0``.  A full-state target ``q*`` (or ``v*``) therefore fixes only ``dof``
independent quantities; imposing all ``nq`` components would repeat the ``nc`` invariants
and make the NLP's constraint Jacobian rank-deficient.  Conditions on full states are
imposed through ``Nᵀ (q − q*) = 0`` with ``N`` (nq × dof) an orthonormal basis of the null
space of ``A`` at a reference configuration: together with the invariants they determine
the state locally, and the rows are independent of the invariants' rows.  Only locally:
a pendulum hanging down and upright has the same tangent coordinate, so a configuration
condition also keeps ``q`` in a box of half-width ``BRANCH_RADIUS ×`` :func:`length_scale`
around the target (an inequality, inactive at the solution).
"""
from __future__ import annotations

import numpy as np

from ncgen.assembly.manifold import consistent_velocity, newton, system_size
from ncgen.errors import OptimizationError

#: Half-width of the box that selects the branch of a configuration condition, as a
#: fraction of the shortest member dimension.
BRANCH_RADIUS = 0.25



def consistent_configuration(model, q, *, t=None, p=None, what: str = "q", tolerance: float = 1e-3,
                             max_iter: int = 50) -> np.ndarray:
    """``q`` moved onto ``Φ = 0`` by minimum-norm Gauss–Newton steps
    (:func:`ncgen.assembly.manifold.newton`); an
    :class:`OptimizationError` if that needs more than ``tolerance`` × the model's size (m)."""
    q_in = np.asarray(q, dtype=float).copy()
    size = system_size(q_in)
    tol = 1e-12 * size ** 2                   # round-off (Panda: |Φ| stalls at 7e-14)
    q, _, res = newton(lambda x: np.atleast_1d(model.phi(x, t=t, p=p)),
                       lambda x: np.atleast_2d(model.A(x, t=t, p=p)), q_in, np.arange(q_in.size), tol=tol,
                       max_iter=max_iter)
    if not res <= tol:
        r = np.atleast_1d(model.phi(q, t=t, p=p))
        k = int(np.argmax(np.abs(r)))
        raise OptimizationError(f"{what}: the constraints cannot be satisfied near the given configuration "
                                f"({model.constraint_names[k]} keeps a residual of {abs(r[k]):.3g})")
    dq = np.abs(q - q_in)
    if dq.size and dq.max() > tolerance * size:
        k = int(np.argmax(dq))
        r0 = np.atleast_1d(model.phi(q_in, t=t, p=p))
        worst = model.constraint_names[int(np.argmax(np.abs(r0)))]
        raise OptimizationError(
            f"{what}: the configuration violates the constraints ({worst} = {r0.max(initial=0):.3g}); "
            f"making it consistent moves {model.coordinate_names[k]} by {dq[k]:.3g} m. Give a "
            "configuration that satisfies the joints (e.g. from model.q0 or a simulation)")
    return q


def length_scale(model) -> float:
    """The shortest member dimension (m): the smallest local base-vector length of any bar
    or body (1 for unit direction vectors); 1 for a system of points."""
    lengths = [float(np.min(np.linalg.norm(m.rigid.Xbar, axis=0)))
               for m in model.members.values() if m.rigid.Xbar.size]
    return min(lengths) if lengths else 1.0


def resolve_configuration(model, spec, reference, *, t=None, p=None, what: str = "q") -> np.ndarray:
    """A consistent configuration from a condition: a full ``q`` (projected), or a dict
    ``{coordinate name: value}`` — those coordinates (names as written included, see
    ``model.coordinate``) set from ``reference`` and kept while the others are assembled
    onto ``Φ = 0`` (``ncgen.assemble``)."""
    if not isinstance(spec, dict):
        return consistent_configuration(model, spec, t=t, p=p, what=what)
    from ncgen.assembly.kinematics import assemble
    from ncgen.errors import NcgenError
    try:
        return assemble(model, reference, t=t, p=p, values=spec)
    except NcgenError as exc:
        raise OptimizationError(f"{what}: no configuration satisfies the joints with "
                                f"{', '.join(f'{k} = {v:g}' for k, v in spec.items())}: {exc}") from None


def resolve_velocity(model, spec, q, *, t=None, p=None) -> np.ndarray:
    """A velocity tangent to the constraints at ``q``: a full ``v`` (M-orthogonal
    projection), or a dict ``{coordinate name: rate}`` — those rates kept (names as written
    included), the others nearest to zero in the kinetic-energy metric (``ncgen.project_velocity``)."""
    if not isinstance(spec, dict):
        return consistent_velocity(model, q, spec, t=t, p=p)
    from ncgen.assembly.kinematics import project_velocity
    return project_velocity(model, q, np.zeros(model.nq), t=t, p=p, values=spec)

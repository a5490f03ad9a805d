"""Final conditions on part of the configuration, in the user's terms.

A target such as "member ``fore`` in this pose" fixes some coordinates of a configuration
and leaves the rest to the joints.  It becomes a :class:`PartialTarget`: a consistent
reference configuration ``q_ref`` that meets it (the member's natural coordinates from the
pose, the other coordinates assembled onto ``Φ = 0`` from the initial configuration) and
the selection ``S`` of the coordinates it fixes.  The NLP imposes the rows
``Wᵀ S (q_N − q_ref) = 0`` with ``W`` an orthonormal basis of the range of ``S N`` (``N``: the
tangent basis of the constraints at ``q_ref``, :mod:`ncgen.optim.manifold`): as many rows
as the target has independent degrees of freedom once the joints hold, so they never
repeat a joint equation or a member's own constraints (LICQ), plus a box around ``S q_ref``
that selects the branch.

Joint angles (from the joint-space layer, when it exists) fit the same mould: a resolver
returning the configuration with those angles and the coordinates they move.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ncgen.errors import NcgenError, OptimizationError
from ncgen.optim.manifold import RANK_TOL, tangent_basis


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
    from ncgen.assembly.kinematics import assemble
    q = np.asarray(reference, dtype=float).copy()
    fixed: list[int] = []
    for name, value in poses.items():
        if name not in model.member_names:
            raise OptimizationError(f"final pose: no member named {name!r}; members: {', '.join(model.member_names)}")
        try:
            R, pos = value
            qm = model.member(name).rigid.q_from_pose(R, pos)
        except (TypeError, ValueError, NcgenError) as exc:
            raise OptimizationError(f"final pose of {name!r}: expected (rotation, position) of the member's frame "
                                    f"({exc})") from None
        for k, i in enumerate(model.layout.member_indices(name)):
            if i is not None:
                q[i] = qm[k]
                fixed.append(i)
    fixed = sorted(set(fixed))
    label = "final pose of " + ", ".join(repr(n) for n in poses)
    try:
        q_ref = assemble(model, q, t=t, p=p, fix=[model.coordinate_names[i] for i in fixed])
    except NcgenError as exc:
        raise OptimizationError(f"{label}: the joints cannot reach it: {exc}") from None
    miss = np.max(np.abs(q_ref[fixed] - q[fixed]), initial=0.0)
    if miss > 1e-6 * max(1.0, float(np.max(np.abs(q)))):
        raise OptimizationError(f"{label}: the joints cannot reach it (the nearest configuration is {miss:.3g} m off)")
    S = np.zeros((len(fixed), model.nq))
    S[np.arange(len(fixed)), fixed] = 1.0
    return PartialTarget(q_ref, S, label)

"""A motion between two configurations, for initial guesses: every member turns along the
shortest arc between its initial and final orientation, and the configuration follows on
``Φ = 0`` (:func:`pose_path`).

Linear interpolation of natural coordinates themselves would shrink the members (a
pendulum swinging up would pass through its pivot, where ``A = 0``) and, from a
mirror-symmetric start, keeps the guess on the symmetry plane where Newton's method cannot
leave it; pose interpolation does neither.  A half turn is taken counter-clockwise (about
+z in a plane, about the first axis found in 3D) unless ``turns`` gives a member its
direction (:func:`turn_about`).  (Interpolating joint coordinates instead, for trees, was
measured on benchmarks/optimal_control.py: the same path up to 4e-4 rad on the acrobot, yet
it sent the N = 40 swing-up to a failure and cost the cart-pole 1.4–1.9× the iterations;
not adopted.)
"""
from __future__ import annotations

import numpy as np

from ncgen import rigid_motion as rm
from ncgen.assembly.manifold import kkt_solve


def rotation_log(R: np.ndarray) -> np.ndarray:
    """Rotation vector (rad) of a 3×3 rotation (:func:`ncgen.rigid_motion.log_so3`); the
    angle, shape (1,), of a 2×2 one."""
    if R.shape == (2, 2):
        return np.array([np.arctan2(R[1, 0], R[0, 0])])
    return rm.log_so3(R)


def rotation_exp(w: np.ndarray) -> np.ndarray:
    """Inverse of :func:`rotation_log` (:func:`ncgen.rigid_motion.exp_so3` in 3D)."""
    w = np.asarray(w, dtype=float)
    if w.size == 1:
        c, s = np.cos(w[0]), np.sin(w[0])
        return np.array([[c, -s], [s, c]])
    return rm.exp_so3(w)


def turn_about(step: np.ndarray, axis, R_a: np.ndarray, name: str) -> np.ndarray:
    """The rotation vector ``step`` (body frame of the start pose ``R_a``) of a member's turn,
    made to go the positive way about ``axis``: a world direction in 3D (the turn must be
    about it), ``+1`` (counter-clockwise) or ``−1`` (clockwise) in a plane."""
    from ncgen.errors import OptimizationError
    angle = float(np.linalg.norm(step))
    if step.size == 1:
        sign = float(np.sign(np.asarray(axis, dtype=float).reshape(-1)[0]))
        if sign == 0 or np.size(axis) != 1:
            raise OptimizationError(f"guess_turn {name!r}: expected +1 (counter-clockwise) or -1 in a planar system")
        return step + 2 * np.pi * sign if step[0] * sign < 0 else step
    a = np.asarray(axis, dtype=float).reshape(-1)
    if a.size != 3 or not np.linalg.norm(a) > 0:
        raise OptimizationError(f"guess_turn {name!r}: expected an axis (3 numbers, world frame), got {axis!r}")
    a_body = R_a.T @ a / np.linalg.norm(a)
    if angle < 1e-12:
        return step
    if np.linalg.norm(np.cross(step / angle, a_body)) > 1e-6:
        raise OptimizationError(f"guess_turn {name!r}: the member's rotation from the initial to the final pose "
                                f"is not about {a.tolist()}")
    return angle * a_body if step @ a_body > 0 else (2 * np.pi - angle) * a_body


def pose_path(model, q_a: np.ndarray, q_b: np.ndarray, s: np.ndarray, *, t=None, p=None,
              anchor: float = 1e-3, max_iter: int = 30, turns: dict | None = None) -> np.ndarray:
    """Configurations (``len(s) × nq``) at fractions ``s ∈ [0, 1]`` from ``q_a`` to ``q_b``.

    Each member's base vectors (``X = Y[dim:] q_member``, linear in q) are rotated along the
    shortest arc between their initial and final directions; ``q(s)`` is the configuration
    on ``Φ = 0`` whose base vectors are closest to those targets, with a weak pull
    (``anchor``) towards the linear interpolation of the coordinates for what rotations
    do not fix (translations).  ``turns``: ``{member name: axis}`` (:func:`turn_about`).  Solved by Gauss–Newton on the KKT system, continuing from
    the previous ``s``."""
    Ra, _ = model.poses(q_a)
    Rb, _ = model.poses(q_b)
    layout, d = model.layout, model.dim
    G_rows, c_rows, targets = [], [], []
    for j, name in enumerate(model.member_names):
        member = model.member(name)
        E = np.asarray(member.ctype.derivation.Y, dtype=float)[d:]
        if E.shape[0] == 0:
            continue
        S = np.zeros((E.shape[1], model.nq))
        for k, i in enumerate(layout.member_indices(name)):
            if i is not None:
                S[k, i] = 1.0
        G_rows.append(E @ S)
        c_rows.append(E @ layout.member_constant(name))
        step = rotation_log(Ra[j].T @ Rb[j])
        if turns and name in turns:
            step = turn_about(step, turns[name], Ra[j], name)
        targets.append((E, member.rigid, Ra[j], step))
    G = np.vstack(G_rows) if G_rows else np.zeros((0, model.nq))
    c = np.concatenate(c_rows) if c_rows else np.zeros(0)
    q_a, q_b = np.asarray(q_a, dtype=float), np.asarray(q_b, dtype=float)
    out, q = [], q_a.copy()
    for sk in np.atleast_1d(s):
        target = np.concatenate([E @ local.q_from_pose(R @ rotation_exp(sk * step), np.zeros(d))
                                 for E, local, R, step in targets]) if targets else np.zeros(0)
        q_lin = (1 - sk) * q_a + sk * q_b
        H = G.T @ G + anchor * np.eye(model.nq)
        last = np.inf
        for _ in range(max_iter):
            grad = G.T @ (G @ q + c - target) + anchor * (q - q_lin)
            A = np.atleast_2d(model.A(q, t=t, p=p)).reshape(-1, model.nq)
            phi = np.atleast_1d(model.phi(q, t=t, p=p))
            dq = kkt_solve(H, A, -np.concatenate([grad, phi]))[:model.nq]
            q = q + dq
            step = np.max(np.abs(dq), initial=0.0)
            if step < 1e-12 * max(1.0, np.max(np.abs(q))) or step >= last:   # converged, or stalled at round-off
                break
            last = step
        out.append(q.copy())
    return np.array(out)

"""Quantities derived from a simulated state history, evaluated on the whole grid at once
(CasADi ``map`` of the model's SX functions).

Arrays are stacked by time step first: ``q`` is ``(n_t, nq)``, results ``(n_t, ...)``.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ncgen.assembly.derived import residual_function
from ncgen.model.data import model_data


def _mapped(f: ca.Function, n: int, *columns):
    """``f`` on ``n`` instances; each argument has one column per instance, or is shared."""
    out = f.map(n)(*columns)
    return out if isinstance(out, tuple) else (out,)


def energies(model, t, q, v, p) -> tuple[np.ndarray, np.ndarray]:
    """Kinetic ``T = ½ vᵀ M v`` and potential ``V`` energy (J) per step."""
    T, V = _mapped(model.functions["energy"], len(t), np.asarray(t)[None, :], q.T, v.T, p)
    return np.array(T).reshape(-1), np.array(V).reshape(-1)


def residuals(model, t, q, v, p) -> tuple[np.ndarray, np.ndarray]:
    """``|Φ(t, q)|∞`` (m²) and ``|A v + Φ_t|∞`` (m²/s) per step."""
    functions = model_data(model).functions
    f = functions.get("residuals")
    if f is None:
        f = functions["residuals"] = residual_function(model)
    r, rd = _mapped(f, len(t), np.asarray(t)[None, :], q.T, v.T, p)
    return np.array(r).reshape(-1), np.array(rd).reshape(-1)


def markers(model, q, v) -> np.ndarray:
    """World positions of the model's markers, ``(n_t, n_markers, dim)``."""
    n, k = len(q), len(model.marker_names)
    if k == 0:
        return np.zeros((n, 0, model.dim))
    r, _ = _mapped(model.functions["markers"], n, q.T, v.T)
    return np.array(r).reshape(model.dim, n, k).transpose(1, 2, 0)


def poses(model, q) -> tuple[np.ndarray, np.ndarray]:
    """Rotation (local→world) and centre of mass of every member per step:
    ``R`` is ``(n_t, n_members, dim, dim)``, ``p`` is ``(n_t, n_members, dim)``."""
    n, k, d = len(q), len(model.member_names), model.dim
    R, pos = _mapped(model.functions["poses"], n, q.T)
    R = np.array(R).reshape(d, n, k, d).transpose(1, 2, 0, 3)
    return R, np.array(pos).reshape(d, n, k).transpose(1, 2, 0)


def member_coordinates(model, member: str, q: np.ndarray) -> np.ndarray:
    """``q_I = S_I q + b_I`` of ``member`` per step, ``(n_t, n_I)`` (ground-fixed points are
    constants)."""
    layout = model.layout
    idx = layout.member_indices(member)
    qI = np.tile(layout.member_constant(member), (len(q), 1))
    for k, i in enumerate(idx):
        if i is not None:
            qI[:, k] = q[:, i]
    return qI


def joint_states(model, q, v) -> tuple[np.ndarray, np.ndarray]:
    """Joint positions and rates ``(n_t, Σ n_j)`` per step (``model.joint_names`` order).
    Angles are continuous in time (unwrapped: a joint turning past ±π keeps counting, never
    jumps by 2π between samples); the first sample is in (−π, π]."""
    js = getattr(model, "joint_space", None)
    n = len(q)
    if js is None or not js.joint_names or n == 0:
        return np.zeros((n, 0)), np.zeros((n, 0))
    qj, = _mapped(js.positions, n, q.T)
    vj, = _mapped(js.rates, n, q.T, v.T)
    qj = np.array(qj).T.reshape(n, -1)
    angles = getattr(js, "angles", np.zeros(qj.shape[1], bool))
    if angles.any():
        qj[:, angles] = np.unwrap(qj[:, angles], axis=0)
    return qj, np.array(vj).T.reshape(n, -1)

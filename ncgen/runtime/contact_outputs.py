"""Contact quantities of a simulated state history (:class:`~ncgen.runtime.trajectory.Trajectory`).

Per output time and contact (order of ``model.contact_names``):

* ``gap`` (m): ``g(q)``, positive apart;
* ``contact_normal`` (N): the normal force on the contact's second element (sphere, or
  sphere ``b``), ``≥ 0``;
* ``contact_tangent`` (N), ``(n_t, nk, dim − 1)``: its tangential components along the
  contact's tangent basis (:mod:`ncgen.assembly.contact_kinematics`);
* ``contact_state``: :data:`OPEN` (no force), :data:`STICK` or :data:`SLIP`.

Smooth contacts (``contacts="smooth"``): the compliant law at each state; a contact sticks
while its slip speed is within the law's ``slip_velocity``.  Nonsmooth contacts (compiled
stepper): the mean force over the output interval ending at that time, impulse sum / dt
(zero at ``t0``); a contact sticks when its friction is inside the cone,
``|P_T| < μ P_N (1 − 1e−6)``.
"""
from __future__ import annotations

import numpy as np

from ncgen.assembly.derived import slip_function

#: Values of ``contact_state``.
OPEN, STICK, SLIP = 0, 1, 2
#: Relative margin of the friction cone below which a nonsmooth contact counts as sticking.
CONE_MARGIN = 1e-6

KEYS = ("gap", "contact_normal", "contact_tangent", "contact_state")


def gaps(model, q, p) -> np.ndarray:
    """``(n_t, nk)`` gaps (m)."""
    g = model.functions["gap"].map(len(q))(q.T, p)
    return np.array(g).reshape(model.nk, len(q)).T


def smooth_outputs(model, t, q, v, p) -> dict:
    """Contact outputs of the compliant law (see the module docstring)."""
    n, nk, nt = len(t), model.nk, model.dim - 1
    fN, fT = model.functions["contact_force"].map(n)(np.asarray(t)[None, :], q.T, v.T, p)
    fN = np.array(fN).reshape(nk, n).T
    fT = np.array(fT).reshape(nk, nt, n).transpose(2, 0, 1)
    vT = _tangent_speeds(model, q, v, p)
    slip = np.array([[c["slip_velocity"] for c in model.contacts]])
    state = np.where(fN > 0, np.where(vT <= slip, STICK, SLIP), OPEN)
    return {"gap": gaps(model, q, p), "contact_normal": fN, "contact_tangent": fT, "contact_state": state}


def _tangent_speeds(model, q, v, p) -> np.ndarray:
    """``(n_t, nk)`` slip speeds ``|W_T v|`` (m/s)."""
    nk, nt = model.nk, model.dim - 1
    out = np.array(slip_function(model).map(len(q))(q.T, v.T, p)).reshape(nk, nt, len(q))
    return np.linalg.norm(out, axis=1).T


def impulse_outputs(model, t, q, p, impulses: np.ndarray) -> dict:
    """Contact outputs from the nonsmooth stepper's impulse sums per output interval
    (``impulses``: ``(n_t − 1, nk·dim)``, N·s)."""
    n, nk, d = len(t), model.nk, model.dim
    P = np.zeros((n, nk, d))
    if n > 1:
        dt = np.diff(np.asarray(t, float))
        P[1:] = impulses[:n - 1].reshape(n - 1, nk, d) / dt[:, None, None]
    fN, fT = P[:, :, 0], P[:, :, 1:]
    mu = np.array([[c["mu"] for c in model.contacts]])
    friction = np.linalg.norm(fT, axis=2)
    state = np.where(fN > 0, np.where(friction < mu * fN * (1 - CONE_MARGIN), STICK, SLIP), OPEN)
    return {"gap": gaps(model, q, p), "contact_normal": fN, "contact_tangent": fT, "contact_state": state}

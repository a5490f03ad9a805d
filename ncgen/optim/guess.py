"""Initial guesses for the NLP: rest, pose interpolation, or a previous motion.

``"rest"`` holds the initial configuration at rest, with the inputs that hold it there
(static inverse dynamics, least squares, clipped into their bounds);
``"interpolate"`` (the default when ``final(q=...)`` is given) moves every member's pose
from the initial to the final configuration (:mod:`ncgen.optim.interpolate`) with a
timing that starts and ends at rest where the problem says so (initial ``v = 0``,
``final(v=0)``: the smoothstep ``s = 3τ² − 2τ³``), velocities tangent to the constraints,
and the inputs that best produce this motion (inverse dynamics: ``M q̈ + Aᵀ λ = F(u)`` in
least squares for ``(u, λ)``, linear in ``u`` about the rest inputs, then clipped).  So the
guess lies on the constraint manifold and the dynamics hold as far as the inputs can make
them.

A previous motion is anything with ``t`` (s), ``q``, ``v`` (``len(t) × nq``) and optionally
``lam`` and ``u`` (``len(t) × nu`` or ``(len(t) − 1) × nu``, held piecewise constant unless
its ``info["hold"]`` is ``"linear"``):
a simulation ``Trajectory`` or an :class:`~ncgen.optim.result.OptimalTrajectory`.  Its
time span is stretched onto the horizon.  Multipliers missing from a guess are computed
from the KKT system at the guessed states, and so are the accelerations.
"""
from __future__ import annotations

import numpy as np

from ncgen.errors import OptimizationError
from ncgen.optim.interpolate import pose_path
from ncgen.assembly.manifold import consistent_velocity
from ncgen.optim.conditions import consistent_configuration
from ncgen.optim.transcription import Guess


def make_guess(ocp, warm_start, q_init: np.ndarray, v_init: np.ndarray, q_final: np.ndarray | None,
               p: np.ndarray) -> tuple[Guess, np.ndarray]:
    """``(guess, p_guess)`` for ``ocp``; ``q_init``, ``v_init``: the initial state to hold
    at rest (the fixed one, or the model's); ``q_final``: the consistent final
    configuration, if one is imposed."""
    model = ocp.model
    T = guess_duration(ocp, warm_start)
    t0 = ocp.t0
    u_rest = np.clip(np.zeros(model.nu), ocp.u_bounds[0], ocp.u_bounds[1])
    bad = ~np.isfinite(u_rest)
    u_rest[bad] = 0.0
    if warm_start is None:
        warm_start = "interpolate" if q_final is not None else "rest"
    if isinstance(warm_start, str) and warm_start in ("rest", "interpolate"):
        tg = t0 + T * np.linspace(0.0, 1.0, 4 * ocp.N + 1)
        if warm_start == "rest":
            qg = np.tile(np.asarray(q_init, dtype=float), (tg.size, 1))
            vg = np.tile(np.asarray(v_init, dtype=float), (tg.size, 1))
        else:
            if q_final is None:
                raise OptimizationError('warm_start="interpolate" needs a final configuration (final(q=...))')
            at_rest = (not np.any(v_init), _final_at_rest(ocp))
            tau = (tg - t0) / T
            s_of, ds_dt = {(True, True): (3 * tau ** 2 - 2 * tau ** 3, 6 * tau * (1 - tau)),
                           (True, False): (tau ** 2, 2 * tau),
                           (False, True): (1 - (1 - tau) ** 2, 2 * (1 - tau)),
                           (False, False): (tau, np.ones_like(tau))}[at_rest]
            grid = np.linspace(0.0, 1.0, tau.size)           # the path on a uniform grid of s ...
            q_s = pose_path(model, q_init, q_final, grid, t=t0, p=p, turns=ocp.guess_turns)
            dq_ds = np.gradient(q_s, grid, axis=0, edge_order=2)
            qg = np.column_stack([np.interp(s_of, grid, q_s[:, i]) for i in range(model.nq)])
            qg = np.array([consistent_configuration(model, q, t=t0, p=p, what="guess", tolerance=1.0) for q in qg])
            vg = np.column_stack([np.interp(s_of, grid, dq_ds[:, i]) for i in range(model.nq)]) * (ds_dt / T)[:, None]
            vg = np.array([consistent_velocity(model, q, v, t=ti, p=p) for ti, q, v in zip(tg, qg, vg)])
        ag = np.gradient(vg, tg, axis=0)
        ug, lg = inverse_dynamics(model, ocp, tg, qg, vg, ag, u_rest, p)
        q_of, v_of, lam_of, u_of = _from_motion(_Samples(tg, qg, vg, lg, ug), model, t0, T, u_rest)
        a_of = _sampled(tg, ag, t0, T)
    elif isinstance(warm_start, str):
        raise OptimizationError(f'warm_start: expected "rest", "interpolate", a Trajectory or a previous '
                                f"solution, got {warm_start!r}")
    else:
        q_of, v_of, lam_of, u_of = _from_motion(warm_start, model, t0, T, u_rest)
        a_of, lam_kkt = _kkt(model, q_of, v_of, u_of, p)
        lam_of = lam_kkt if lam_of is None else lam_of
    p_guess = p.copy()
    wp = getattr(warm_start, "p", None)
    if wp is not None and np.size(wp) == p.size:
        for i in ocp.p_free:
            p_guess[i] = float(np.asarray(wp).reshape(-1)[i])
    for i, (lo, hi) in ocp.p_free.items():
        p_guess[i] = float(np.clip(p_guess[i], lo, hi))
    return Guess(T=T, q=q_of, v=v_of, a=a_of, lam=lam_of, u=u_of), p_guess


class _Samples:
    def __init__(self, t, q, v, lam=None, u=None):
        self.t, self.q, self.v, self.lam, self.u = t, q, v, lam, u
        self.info = {"hold": "linear"}


def _final_at_rest(ocp) -> bool:
    v = ocp.final_spec["v"]
    if v is None:
        return False
    if isinstance(v, dict):
        return not any(v.values())
    return not np.any(v)


def _sampled(tg, X, t0, T):
    def f(t):
        s = np.atleast_1d(np.asarray(t, dtype=float))
        return np.column_stack([np.interp(s, tg, X[:, i]) for i in range(X.shape[1])]) if X.shape[1] \
            else np.zeros((s.size, 0))
    return f


def inverse_dynamics(model, ocp, t, q, v, a, u0, p) -> tuple[np.ndarray, np.ndarray]:
    """``(u, λ)`` (``len(t) × nu``, ``len(t) × nc``) that best produce the accelerations ``a``:
    ``M a + Aᵀ λ = F(u)`` in least squares, ``F`` linearised in ``u`` about ``u0``, the inputs
    clipped into their bounds and ``λ`` recomputed for the clipped inputs."""
    import casadi as ca
    f = model.functions
    nu, nc, M = model.nu, model.nc, np.asarray(model.M)
    ts, qs, vs, us, ps = ca.SX.sym("t"), ca.SX.sym("q", model.nq), ca.SX.sym("v", model.nq), \
        ca.SX.sym("u", nu), ca.SX.sym("p", model.np)
    F = f["F"](ts, qs, vs, us, ps)
    FB = ca.Function("FB", [ts, qs, vs, us, ps], [F, ca.jacobian(F, us), f["A"](ts, qs, ps)])
    U, LAM = np.zeros((t.size, nu)), np.zeros((t.size, nc))
    lo, hi = ocp.u_bounds
    for i in range(t.size):
        F0, B, A = (np.array(x, dtype=float).reshape(s) for x, s in
                    zip(FB(t[i], q[i], v[i], u0, p), ((model.nq,), (model.nq, nu), (nc, model.nq))))
        rhs = M @ a[i] - F0
        K = np.hstack([-B, A.T])
        x = np.linalg.lstsq(K, -rhs, rcond=None)[0] if K.size else np.zeros(0)
        u = np.clip(u0 + x[:nu], lo, hi)
        U[i] = u
        if nc:
            LAM[i] = np.linalg.lstsq(A.T, -(rhs - B @ (u - u0)), rcond=None)[0]
    return U, LAM


def guess_duration(ocp, warm_start) -> float:
    """The horizon of the guess (s): the fixed one, or the warm start's clipped into the
    bounds of a free final time (their midpoint without a warm start)."""
    if ocp.t_final_bounds is None:
        return ocp.t_final
    t = getattr(warm_start, "t", None)
    T = float(t[-1] - t[0]) if t is not None and len(t) > 1 else ocp.t_final
    lo, hi = ocp.t_final_bounds
    return float(np.clip(T, lo, hi))


def _constant(x: np.ndarray):
    x = np.asarray(x, dtype=float)

    def f(t):
        return np.tile(x, (len(np.atleast_1d(t)), 1))
    return f


def _numbers(x, what: str) -> np.ndarray:
    """Real numbers (:func:`ncgen.validation.as_numbers`) or an :class:`OptimizationError`."""
    from ncgen.errors import NcgenError
    from ncgen.validation import as_numbers
    try:
        return as_numbers(x, what)
    except NcgenError as exc:
        raise OptimizationError(str(exc)) from None


def _from_motion(m, model, t0: float, T: float, u_rest: np.ndarray):
    if not all(hasattr(m, k) for k in ("t", "q", "v")):
        raise OptimizationError(f"warm_start: expected an object with t, q and v (a Trajectory or a previous "
                                f"solution), got {type(m).__name__}")
    tw, qw, vw = (_numbers(getattr(m, k), f"warm_start.{k}") for k in ("t", "q", "v"))
    tw = tw.reshape(-1)
    n = tw.size
    if n < 2 or qw.shape != (n, model.nq) or vw.shape != (n, model.nq):
        raise OptimizationError(f"warm_start: expected t (n ≥ 2), q and v of shape (n, {model.nq}); got "
                                f"t {tw.shape}, q {qw.shape}, v {vw.shape}")
    for what, X in (("t", tw), ("q", qw), ("v", vw), ("u", getattr(m, "u", None)), ("lam", getattr(m, "lam", None))):
        X = None if X is None else _numbers(X, f"warm_start.{what}")
        bad = None if X is None else np.argwhere(~np.isfinite(X))
        if bad is not None and bad.size:
            raise OptimizationError(f"warm_start.{what}: expected finite numbers, found "
                                    f"{np.asarray(X, dtype=float)[tuple(bad[0])]} at index {tuple(bad[0].tolist())} "
                                    f"({len(bad)} non-finite entries)")
    if np.any(np.diff(tw) <= 0):
        raise OptimizationError("warm_start.t: expected increasing times")

    def to_w(t):
        return tw[0] + (np.asarray(t, dtype=float) - t0) / T * (tw[-1] - tw[0])

    def sampled(X):
        def f(t):
            s = to_w(np.atleast_1d(t))
            return np.column_stack([np.interp(s, tw, X[:, i]) for i in range(X.shape[1])]) \
                if X.shape[1] else np.zeros((s.size, 0))
        return f

    lam = getattr(m, "lam", None)
    lam_of = sampled(np.asarray(lam, float)) if lam is not None and np.shape(lam) == (n, model.nc) else None
    u = getattr(m, "u", None)
    u = None if u is None else np.asarray(u, dtype=float).reshape(-1, model.nu) if model.nu else None
    linear = getattr(m, "info", {}).get("hold") == "linear"
    if u is not None and (u.shape[0] == n - 1 or (u.shape[0] == n and not linear)):
        def u_of(t):
            s = to_w(np.atleast_1d(t))
            k = np.clip(np.searchsorted(tw, s, side="right") - 1, 0, n - 2)
            return u[k]
    elif u is not None and u.shape[0] == n:
        u_of = sampled(u)
    else:
        u_of = _constant(u_rest)
    return sampled(qw), sampled(vw), lam_of, u_of


def _kkt(model, q_of, v_of, u_of, p):
    """Accelerations and multipliers of the guessed states from the KKT system."""
    accel = model.functions["accel"]

    def solve(t):
        t = np.atleast_1d(np.asarray(t, dtype=float))
        a, lam = accel.map(t.size)(t[None, :], q_of(t).T, v_of(t).T, u_of(t).T, p)
        return np.array(a).reshape(model.nq, t.size).T, np.array(lam).reshape(model.nc, t.size).T

    return (lambda t: solve(t)[0]), (lambda t: solve(t)[1])

"""Stage and terminal costs written by the user with CasADi-compatible operations, turned
into CasADi functions with their derivatives (by algorithmic differentiation).

``stage(x, u) -> scalar`` and ``terminal(x) -> scalar`` are called once with CasADi SX
symbols (``x``: nx × 1, ``u``: nu × 1); they may use ``+ − * /``, ``@``, indexing,
``casadi.sumsqr``, ``casadi.sin`` and the like, but not NumPy functions that need numbers.
The total cost of a trajectory is ``Σ_{k<N} stage(x_k, u_k) + terminal(x_N)``.
"""
from __future__ import annotations

import casadi as ca

from ncgen.errors import NcgenError


def _scalar(fn, args, what: str) -> ca.SX:
    try:
        out = fn(*args)
    except Exception as exc:      # a user function: say which one failed and how to write it
        raise NcgenError(f"{what}: calling it with CasADi symbols failed ({type(exc).__name__}: {exc}); "
                         "write it with CasADi-compatible operations (casadi.sumsqr, casadi.sin, @, ...)") from None
    try:
        out = ca.SX(out)
    except (NotImplementedError, TypeError, RuntimeError):
        raise NcgenError(f"{what}: expected a scalar CasADi expression, got {type(out).__name__}") from None
    if out.numel() != 1:
        raise NcgenError(f"{what}: expected a scalar cost, got shape {out.shape}")
    return out


def cost_functions(costs, nx: int, nu: int) -> tuple[ca.Function, ca.Function]:
    """``(stage_d, terminal_d)``: ``stage_d(x, u) -> (l, l_x, l_u, l_xx, l_uu, l_ux)`` and
    ``terminal_d(x) -> (l, l_x, l_xx)`` (dense; gradients as columns)."""
    try:
        stage, terminal = costs
    except (TypeError, ValueError):
        raise NcgenError(f"costs: expected (stage, terminal): stage(x, u) and terminal(x) returning scalars, "
                         f"got {costs!r}") from None
    if not callable(stage) or not callable(terminal):
        raise NcgenError("costs: expected (stage, terminal), two callables stage(x, u) and terminal(x)")
    x, u = ca.SX.sym("x", nx), ca.SX.sym("u", nu)
    l = _scalar(stage, (x, u), "stage cost")
    lf = _scalar(terminal, (x,), "terminal cost")
    lx, lu = ca.gradient(l, x), ca.gradient(l, u)
    stage_d = ca.Function("stage", [x, u], [ca.densify(e) for e in (l, lx, lu, ca.jacobian(lx, x),
                                                                      ca.jacobian(lu, u), ca.jacobian(lu, x))],
                          ["x", "u"], ["l", "l_x", "l_u", "l_xx", "l_uu", "l_ux"])
    lfx = ca.gradient(lf, x)
    terminal_d = ca.Function("terminal", [x], [ca.densify(e) for e in (lf, lfx, ca.jacobian(lfx, x))],
                             ["x"], ["l", "l_x", "l_xx"])
    return stage_d, terminal_d

"""The output time grid, input signals and parameter values of a simulation.

Grid: ``t_k = t0 + k·h``, ``k = 0..N``, with ``N = ⌈(t_end − t0)/dt⌉`` and ``h = (t_end − t0)/N``
(``dt`` is shortened, if needed, so that ``t_end`` lies on the grid).

Inputs (``model.nu`` values: a constant vector, ``u(t)`` or samples) are sampled on the grid,
``U[k] = u(t_k)``, and held between
samples: ``"zoh"`` (zero-order hold) applies ``U[k]`` on ``[t_k, t_{k+1})``, as piecewise
constant controls from an optimiser expect; ``"linear"`` interpolates between ``U[k]`` and
``U[k+1]`` (first-order hold), closer to a smooth ``u(t)``.  Each grid interval is
integrated separately by IDAS (it stops at every grid time), so the hold's kinks and jumps
cost no accuracy.
"""
from __future__ import annotations

import inspect
import math
from functools import lru_cache

import numpy as np

from ncgen.environment import getenv
from ncgen.errors import NcgenError, ShapeError
from ncgen.validation import allocation, as_numbers, as_scalar, as_vector

HOLDS = ("zoh", "linear")


def time_grid(t0: float, t_end: float, dt: float, bytes_per_point: float = 8.0) -> np.ndarray:
    """``t0, t0 + h, ..., t_end`` (see module docstring).  Each argument is checked on its own
    and named; a grid whose results would need more than
    :data:`~ncgen.validation.MAX_ALLOCATION` bytes (``bytes_per_point`` each) is refused
    before anything is allocated.  A fresh array each call."""
    return _checked_grid(as_scalar(t0, "t0"), as_scalar(t_end, "t_end"), as_scalar(dt, "dt"), float(bytes_per_point),
                         getenv("NCGEN_MAX_BYTES")).copy()


@lru_cache(maxsize=64)
def _checked_grid(t0: float, t_end: float, dt: float, bytes_per_point: float, limit: str | None) -> np.ndarray:
    """The grid of :func:`time_grid`, checked and computed once per arguments and allocation
    limit ``limit`` (``$NCGEN_MAX_BYTES``, which :func:`~ncgen.validation.allocation` reads);
    a refused grid is refused again every call (nothing kept)."""
    if dt <= 0:
        raise NcgenError(f"dt: expected a positive output step (s), got {dt:g}")
    if not t_end > t0:
        raise NcgenError(f"t_end: expected a time after t0 = {t0:g} s, got {t_end:g}")
    steps = (t_end - t0) / dt
    if not math.isfinite(steps) or steps > 2**53:
        raise NcgenError(f"dt: {dt:g} s is too small for the span {t_end - t0:g} s ({steps:.3g} steps)")
    n = max(1, math.ceil(steps - 1e-9))
    allocation((n + 1) * bytes_per_point, lambda: f"the output grid t0 = {t0:g} ... t_end = {t_end:g} s with "
               f"dt = {dt:g} s ({n + 1:,} points)", "use a larger dt (the output step; the integrator "
               "chooses its own internal steps) or a shorter run")
    return t0 + (t_end - t0) * np.arange(n + 1) / n


def feedback_kind(u) -> str | None:
    """How a callable ``u`` is called: ``"time"`` (``u(t)``), ``"natural"`` (``u(t, q, v)``,
    natural coordinates) or ``"joint"`` (``u(t, qj, vj)``, joint space); None for data.

    Detection: the number of positional parameters without defaults (``*args`` counts as
    one more), 1 → ``u(t)``, 3 → feedback; a feedback whose second and third parameters are
    named ``qj`` and ``vj`` gets joint space, any other names natural coordinates.  A
    callable whose signature cannot be read is taken as ``u(t)``."""
    if u is None or not callable(u):
        return None
    try:
        params = list(inspect.signature(u).parameters.values())
    except (TypeError, ValueError):
        return "time"
    positional = [x for x in params if x.kind in (x.POSITIONAL_ONLY, x.POSITIONAL_OR_KEYWORD)
                  and x.default is x.empty]
    star = any(x.kind == x.VAR_POSITIONAL for x in params)
    if len(positional) == 3 or (star and 1 < len(positional) < 3):
        names = [x.name for x in positional[1:3]]
        return "joint" if names == ["qj", "vj"] else "natural"
    if len(positional) in (0, 1):
        return "time"
    raise NcgenError(f"u: a callable must take (t), (t, q, v) or (t, qj, vj); "
                     f"{getattr(u, '__name__', 'it')} takes {len(positional)} positional argument(s)")


def input_samples(u, model, t: np.ndarray) -> np.ndarray:
    """``U``, shape ``(len(t), nu)``: ``u`` (None, a constant vector of ``nu`` values — a
    scalar when ``nu = 1`` —, a callable ``u(t)`` or samples on the grid) evaluated on the
    grid ``t``.  Feedback ``u(t, q, v)`` is the caller's (:func:`feedback_kind`): zeros here."""
    nu, n = model.nu, len(t)
    if u is None:
        return np.zeros((n, nu))
    if nu == 0:
        raise NcgenError(f"u: model {model.name!r} has no inputs, but u was given")
    names = ", ".join(f"{k}[{s}]" for k, s in zip(model.input_names, model.input_sizes))
    if feedback_kind(u) in ("natural", "joint"):
        return np.zeros((n, nu))
    shapes = f"{nu} values, a callable u(t) or samples of shape (len(t), {nu})"
    if not callable(u):
        arr = as_numbers(u, "u", shapes)
        if arr.ndim == 0 or (arr.ndim == 1 and arr.size == nu):
            u = np.broadcast_to(arr.reshape(-1), (n, nu)).copy() if arr.size == nu else None
            if u is None:
                raise ShapeError(f"u: a constant input needs {nu} values (inputs {names}); got a scalar")
    if callable(u):
        U = np.empty((n, nu))
        for k, tk in enumerate(t):
            try:
                out = u(float(tk))
            except (TypeError, ValueError) as e:
                raise NcgenError(f"u({tk:g}) failed: {e}") from None
            val = as_numbers(out, f"u({tk:g}) returned", f"{nu} numbers").reshape(-1)
            if val.size != nu:
                raise ShapeError(f"u({tk:g}) returned {val.size} value(s); expected {nu}, one per input "
                                 f"value of model {model.name!r}: {names}")
            U[k] = val
    else:
        U = as_numbers(u, "u", shapes)
        if U.ndim == 1 and nu == 1:
            U = U[:, None]
        if U.shape not in ((n, nu), (n - 1, nu)):
            raise ShapeError(f"u: expected samples of shape ({n}, {nu}) on the {n} grid times "
                             f"(inputs {names}), or ({n - 1}, {nu}) for the {n - 1} intervals; "
                             f"got shape {U.shape}")
        if len(U) == n - 1:
            U = np.vstack([U, U[-1:]])
    bad = np.argwhere(~np.isfinite(U))
    if bad.size:
        k = int(bad[0, 0])
        raise NcgenError(f"u: non-finite input {U[k].tolist()} at t = {t[k]:g} s")
    return U


def hold_columns(U: np.ndarray, t: np.ndarray, hold: str) -> np.ndarray:
    """Per grid interval k, the integrator's piecewise-constant control column:
    ``[U_k]`` (zoh) or ``[U_k; (U_{k+1} − U_k)/(t_{k+1} − t_k); t_k]`` (linear).  Shape
    ``(n_columns, N)``."""
    if hold not in HOLDS:
        raise NcgenError(f"hold: expected one of {', '.join(HOLDS)}, got {hold!r}")
    if hold == "zoh":
        return U[:-1].T.copy()
    slope = np.diff(U, axis=0) / np.diff(t)[:, None]
    return np.vstack([U[:-1].T, slope.T, t[None, :-1]])


def parameter_values(p, model) -> np.ndarray:
    """The parameter vector: ``None`` (defaults), an array of ``model.np`` values, or a dict
    by name (others keep their defaults)."""
    if p is None:
        return model.p0.copy()
    if isinstance(p, dict):
        try:
            return model.parameters(**p)
        except KeyError as e:
            raise NcgenError(str(e.args[0])) from None
    try:
        values = as_numbers(p, "p (parameter values)")
    except ShapeError:
        values = None
    if values is not None and values.shape == (model.np,):
        offsets = np.cumsum([0] + model.parameter_sizes)
        by_name = {n: values[offsets[i]:offsets[i + 1]] for i, n in enumerate(model.parameter_names)}
        return model.parameters(**by_name)       # names the parameter that is wrong
    return as_vector(p, model.np, "p (parameter values)")


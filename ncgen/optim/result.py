"""``OptimalTrajectory``: an optimised motion — a simulation ``Trajectory`` plus solver
statistics.

Arrays are sampled at the ``N + 1`` nodes ``t_k = t0 + k T / N`` with the
:class:`~ncgen.runtime.trajectory.Trajectory` conventions (``t``, ``q``, ``v``, ``lam``,
energies, residuals, markers; ``save``/``load``, ``point``, ``marker``, ``poses``).  Inputs
are piecewise constant: ``u[k]`` acts on ``[t_k, t_{k+1})`` and the last row repeats
``u[N−1]``, so ``nc.simulate(model, T, T/N, u=sol.u, hold="zoh", ...)`` replays them
exactly.  ``stats``: :class:`SolverStats`; ``nlp``: the built problem (for diagnostics).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from ncgen.runtime.trajectory import Trajectory


@dataclass
class SolverStats:
    """What IPOPT reported and what was measured at the solution.

    ``status``: IPOPT's return status; ``success``; ``iterations``; ``objective``;
    ``solve_time`` (s, wall clock of the solver call); ``build_time`` (s, building the
    NLP); ``max_defect``: largest residual of the dynamics equations (collocation or
    shooting continuity, in the units of the state); ``max_violation``: largest violation of
    any constraint; ``n_variables``, ``n_constraints``; ``method``: the transcription."""

    status: str
    success: bool
    iterations: int
    objective: float
    solve_time: float
    build_time: float
    max_defect: float
    max_violation: float
    n_variables: int
    n_constraints: int
    method: str

    def as_dict(self) -> dict:
        return asdict(self)


class OptimalTrajectory(Trajectory):
    """The result of :meth:`ncgen.OptimalControl.solve` (see the module docstring)."""

    def __init__(self, *, stats: SolverStats | None = None, nlp=None, **trajectory):
        super().__init__(**trajectory)
        self.stats = stats
        self.nlp = nlp

    @classmethod
    def from_solution(cls, model, *, t, q, v, lam, u, p, stats: SolverStats, nlp=None) -> "OptimalTrajectory":
        """``u``: ``N × nu`` piecewise-constant inputs."""
        u = np.asarray(u, dtype=float).reshape(len(t) - 1, model.nu)
        samples = np.vstack([u, u[-1:]])
        info = {"method": "optimal control", "solver": "ipopt", "transcription": stats.method,
                "hold": "zoh", "optimization": stats.as_dict(), "complete": True}
        traj = cls.from_states(model, t, q, v, lam, samples, p, info)
        traj.stats, traj.nlp = stats, nlp
        return traj

    @property
    def t_final(self) -> float:
        """Horizon length T (s)."""
        return float(self.t[-1] - self.t[0])

    @property
    def N(self) -> int:
        """Number of intervals."""
        return len(self.t) - 1

    def input(self, t) -> np.ndarray:
        """Inputs at time(s) ``t``: ``u[k]`` on ``[t_k, t_{k+1})`` (``u[N−1]`` from ``t_N`` on);
        shape ``(nu,)`` for a scalar ``t``, else ``len(t) × nu``."""
        ts = np.atleast_1d(np.asarray(t, dtype=float))
        k = np.clip(np.searchsorted(self.t, ts, side="right") - 1, 0, self.N - 1)
        out = self.u[k]
        return out[0] if np.ndim(t) == 0 else out

    def parameters(self) -> dict:
        """Parameter values by name (scalars as floats)."""
        out, i = {}, 0
        sizes = self.model.parameter_sizes if self.model is not None else [1] * len(self.parameter_names)
        for name, size in zip(self.parameter_names, sizes):
            val = self.p[i:i + size]
            out[name] = float(val[0]) if size == 1 else val.copy()
            i += size
        return out

    def summary(self) -> str:
        s = self.stats
        lines = [f"Optimal trajectory of model {self.model_name!r} ({s.method}): {s.status} after "
                 f"{s.iterations} iterations ({s.solve_time:.2f} s solve, {s.build_time:.2f} s build)",
                 f"  objective {s.objective:.6g}; T = {self.t_final:.6g} s; N = {self.N}",
                 f"  max dynamics defect {s.max_defect:.2e}; max constraint violation {s.max_violation:.2e}",
                 f"  constraint drift on the nodes: max |phi| = {np.max(self.constraint_residual):.3g}, "
                 f"max |A v + phi_t| = {np.max(self.velocity_residual):.3g}"]
        if len(self.p):
            lines.append("  parameters: " + ", ".join(f"{k} = {np.round(v, 6)}" for k, v in self.parameters().items()))
        return "\n".join(lines)

    def __repr__(self) -> str:
        return (f"<OptimalTrajectory {self.model_name!r}: {self.stats.status}, N={self.N}, "
                f"T={self.t_final:.4g} s, objective={self.stats.objective:.6g}>")

"""``modes``: natural frequencies and mode shapes about a static equilibrium.

Small motions ``q = q* + N z`` on the constraint manifold (``N`` orthonormal basis of
``null A(q*)``) obey ``M_r z̈ + K_r z = 0`` with the reduced mass ``M_r = Nᵀ M N`` and the
reduced tangent stiffness ``K_r = Nᵀ K_s N`` (:mod:`ncgen.analysis.statics`: it holds the
springs' elastic and geometric stiffness — prestressed cables stiffen a structure — and the
constraint curvature weighted by the reactions).  The generalised eigenproblem
``K_r x = ω² M_r x`` gives ``ω² ≥ 0``: frequencies ``f = ω / 2π`` (Hz); ``ω² ≈ 0``: a
zero-stiffness (mechanism or rigid-body) mode; ``ω² < 0``: the equilibrium is unstable
along that mode (frequency reported as NaN, growth rate ``√−ω²``).  Shapes ``φ = N x``
(natural coordinates, m per unit of modal amplitude), mass-normalised (``φᵀ M φ = 1``).
Damping is ignored.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg

from ncgen.blas_threads import one_blas_thread
from ncgen.analysis.statics import Equilibrium, equilibrium
from ncgen.analysis.stability import ZERO_TOL
from ncgen.assembly.manifold import manifold_point
from ncgen.model.rolling import STEADY_MOTIONS, refuse_rolling


@dataclass
class Modes:
    """Result of :func:`modes`: ``omega2`` (rad²/s², ascending), ``frequencies`` (Hz, NaN
    where ``ω² < 0``), ``shapes`` (nq × n, columns mass-normalised), ``kind`` per mode
    (``"vibration"``, ``"zero"`` or ``"unstable"``) and the ``equilibrium`` they are about."""

    equilibrium: Equilibrium = field(repr=False)
    omega2: np.ndarray
    frequencies: np.ndarray
    shapes: np.ndarray = field(repr=False)
    kind: list

    def table(self) -> str:
        """Mode number, frequency (Hz), ω (rad/s), kind and the coordinate moving most."""
        names = self.equilibrium.model.coordinate_names
        lines = [f"modes of {self.equilibrium.model.name!r} about its equilibrium "
                 f"({self.equilibrium.stability}):",
                 f"{'mode':>4}  {'f (Hz)':>12}  {'omega (rad/s)':>14}  {'kind':<10} largest motion"]
        for i, w2 in enumerate(self.omega2):
            k = int(np.argmax(np.abs(self.shapes[:, i])))
            f = self.frequencies[i]
            lines.append(f"{i + 1:>4}  {f:>12.6g}  {np.sqrt(abs(w2)):>14.6g}  {self.kind[i]:<10} {names[k]}")
        return "\n".join(lines) + "\n"

    def save(self, path) -> None:
        """CSV (mode, frequency_hz, omega2, kind) or NPZ (everything)."""
        from pathlib import Path

        from ncgen.files import atomic_path
        path = Path(path)
        with atomic_path(path) as tmp:
            if path.suffix == ".npz":
                with open(tmp, "wb") as fh:
                    np.savez(fh, omega2=self.omega2, frequencies=self.frequencies, shapes=self.shapes,
                             kind=np.array(self.kind), q=self.equilibrium.q,
                             coordinate_names=np.array(self.equilibrium.model.coordinate_names))
            else:
                rows = ["mode,frequency_hz,omega2,kind"]
                rows += [f"{i + 1},{f:.12g},{w2:.12g},{k}" for i, (f, w2, k)
                         in enumerate(zip(self.frequencies, self.omega2, self.kind))]
                tmp.write_text("\n".join(rows) + "\n")

    def trajectory(self, index: int, *, amplitude: float | None = None, cycles: int = 2,
                   frames_per_cycle: int = 40):
        """The motion of mode ``index`` as a :class:`~ncgen.runtime.trajectory.Trajectory`
        (time in periods of the mode, or in s for a zero or unstable mode)."""
        from ncgen.runtime.trajectory import Trajectory
        eq = self.equilibrium
        model = eq.model
        shape = self.shapes[:, index]
        size = max(1.0, float(np.abs(eq.q).max()))
        amp = (0.05 * size if amplitude is None else float(amplitude)) / max(np.abs(shape).max(), 1e-300)
        n = cycles * frames_per_cycle + 1
        s = np.linspace(0.0, cycles, n)
        period = 1.0 / self.frequencies[index] if self.kind[index] == "vibration" else 1.0
        N, G = eq.N, eq.N.T
        x = G @ shape
        q = np.array([manifold_point(lambda q: model.phi(q, t=eq.t, p=eq.p), lambda q: model.A(q, t=eq.t, p=eq.p),
                                     eq.q, N, G, amp * np.sin(2 * np.pi * si) * x) for si in s])
        v = np.gradient(q, s * period, axis=0)
        info = {"method": f"mode {index + 1} shape", "complete": True}
        return Trajectory.from_states(model, s * period, q, v, np.tile(eq.lam, (n, 1)),
                                      np.tile(eq.u, (n, 1)), eq.p, info)


@one_blas_thread
def modes(model, eq: Equilibrium | None = None, **equilibrium_options) -> Modes:
    """Natural frequencies and mode shapes of ``model`` about ``eq`` (default: the
    equilibrium :func:`~ncgen.analysis.statics.equilibrium` finds with
    ``equilibrium_options``); see the module docstring."""
    refuse_rolling(model, "modes", STEADY_MOTIONS)
    if eq is None:
        eq = equilibrium(model, **equilibrium_options)
    N = eq.N
    Mr = N.T @ np.asarray(model.M, float) @ N
    Kr = eq.K_reduced
    if Kr.size == 0:
        return Modes(eq, np.zeros(0), np.zeros(0), np.zeros((model.nq, 0)), [])
    w2, X = scipy.linalg.eigh(0.5 * (Kr + Kr.T), Mr)
    tol = ZERO_TOL * max(np.abs(w2).max(), 1e-300)
    kind = ["zero" if abs(x) <= tol else "unstable" if x < 0 else "vibration" for x in w2]
    freq = np.array([np.sqrt(x) / (2 * np.pi) if k == "vibration" else (0.0 if k == "zero" else np.nan)
                     for x, k in zip(w2, kind)])
    shapes = N @ X
    for j in range(shapes.shape[1]):
        i = int(np.argmax(np.abs(shapes[:, j])))
        if shapes[i, j] < 0:
            shapes[:, j] = -shapes[:, j]
    return Modes(eq, w2, freq, shapes, kind)

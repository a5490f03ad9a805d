"""The Whipple–Carvallo bicycle as a multibody model, linearised about upright straight
running (Meijaard, Papadopoulos, Ruina & Schwab 2007, Proc. R. Soc. A 463, 1955–1982).

Four bodies in natural coordinates (rear wheel, rear frame, front frame, front wheel), three
hinges (rear axle, steer axis, front axle) and two knife-edge wheels rolling without
slipping on ``z = 0`` (:class:`~ncgen.model.rolling.RollingDisc`).  Nothing of the paper's
linearised equations is typed in: the lean φ (rear frame, right-handed about the forward
axis) and the steer angle δ (front frame relative to the rear frame, right-handed about the
steer axis pointing down) are functions of the natural coordinates, and
:func:`~ncgen.analysis.steady_motion.linearize_steady` finds their equations
``M q̈ + v C1 q̇ + (g K0 + v² K2) q = f`` about the steady motion at speed ``v`` (m/s) of the
rear wheel's centre.

Parameters (:class:`WhippleParameters`) are given as the paper's Table 1 gives them, in its
axes (x forward, y right, z down, origin at the rear contact); the model's world has x
forward, y left, z up, gravity ``(0, 0, −g)``.
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import casadi as ca
import numpy as np
from scipy.optimize import brentq

from ncgen.analysis.steady_motion import SecondOrder, linearize_steady, spin_generator, translation_rate
from ncgen.assembly.nonholonomic import RollingSystem, coordinate_function
from ncgen.errors import ModelError, NcgenError
from ncgen.model.joints import Revolute
from ncgen.model.rolling import RollingDisc
from ncgen.model.system import System

#: The paper's axes (x forward, y right, z down) to the model's (x forward, y left, z up).
_FLIP = np.diag([1.0, -1.0, -1.0])
_NAMES = ("rear_wheel", "rear_frame", "front_frame", "front_wheel")


@dataclass(frozen=True)
class WhippleParameters:
    """Table 1 of Meijaard et al. (2007), SI units, the paper's axes.  ``I_B``, ``I_H``:
    3×3 inertia tensors about the centres of mass; wheels: ``(I_xx, I_yy)`` with the axle
    along y."""
    w: float
    c: float
    lam: float
    g: float
    r_R: float
    m_R: float
    I_R: tuple
    x_B: float
    z_B: float
    m_B: float
    I_B: tuple
    x_H: float
    z_H: float
    m_H: float
    I_H: tuple
    r_F: float
    m_F: float
    I_F: tuple

    def __post_init__(self):
        for f in fields(self):
            value = np.asarray(getattr(self, f.name), dtype=float)
            if not np.all(np.isfinite(value)):
                raise ModelError(f"WhippleParameters: {f.name}: expected finite numbers, found {value}")
        for name in ("r_R", "r_F", "m_R", "m_B", "m_H", "m_F", "g"):
            if getattr(self, name) <= 0:
                raise ModelError(f"WhippleParameters: {name}: expected a positive number, "
                                 f"found {getattr(self, name)}")
        for name, shape in (("I_R", (2,)), ("I_F", (2,)), ("I_B", (3, 3)), ("I_H", (3, 3))):
            if np.shape(getattr(self, name)) != shape:
                raise ModelError(f"WhippleParameters: {name}: expected shape {shape}, "
                                 f"found {np.shape(getattr(self, name))}")

    def steer_axis(self) -> np.ndarray:
        """Unit vector of the steer axis pointing down, model axes."""
        return np.array([np.sin(self.lam), 0.0, -np.cos(self.lam)])


def whipple_system(par: WhippleParameters) -> tuple[System, list[RollingDisc]]:
    """The bicycle upright at rest (bodies' axes along the world's) and its two wheels."""
    wheel = (lambda I: np.diag([I[0], I[1], I[0]]))
    s = System("whipple", gravity=(0.0, 0.0, -par.g))
    R = s.add_body(_NAMES[0], mass=par.m_R, inertia=wheel(par.I_R), position=(0.0, 0.0, par.r_R))
    B = s.add_body(_NAMES[1], mass=par.m_B, inertia=_FLIP @ np.asarray(par.I_B) @ _FLIP,
                   position=_FLIP @ [par.x_B, 0.0, par.z_B])
    H = s.add_body(_NAMES[2], mass=par.m_H, inertia=_FLIP @ np.asarray(par.I_H) @ _FLIP,
                   position=_FLIP @ [par.x_H, 0.0, par.z_H])
    F = s.add_body(_NAMES[3], mass=par.m_F, inertia=wheel(par.I_F), position=(par.w, 0.0, par.r_F))
    s.add_joint(Revolute(R, B, at=(0.0, 0.0, par.r_R), axis=(0.0, 1.0, 0.0), name="rear_axle"))
    s.add_joint(Revolute(B, H, at=(par.w + par.c, 0.0, 0.0), axis=par.steer_axis(), name="steer"))
    s.add_joint(Revolute(H, F, at=(par.w, 0.0, par.r_F), axis=(0.0, 1.0, 0.0), name="front_axle"))
    discs = [RollingDisc(R, radius=par.r_R), RollingDisc(F, radius=par.r_F)]
    return s, discs


class WhippleBicycle:
    """The benchmark bicycle of ``par`` as a multibody model with rolling wheels, and its
    linearisation about upright straight running."""

    def __init__(self, par: WhippleParameters):
        self.parameters = par
        system, self.discs = whipple_system(par)
        self.model = system.build()
        self.rolling = RollingSystem(self.model, self.discs)
        self.rolling.check_rank(self.model.q0)
        self.spins = [spin_generator(self.model, d.body, d.axle) for d in self.discs]
        self.forward = translation_rate(self.model, (1.0, 0.0, 0.0))
        self.coordinates = coordinate_function(self._lean_steer, self.model.nq)
        q0 = self.model.q0
        A = np.asarray(self.rolling.A(q0))
        # unit forward speed: the wheels' spin rates that make it roll (least squares, exact)
        W = np.column_stack([A @ (K @ q0) for K in self.spins])
        self.spin_rates = np.linalg.lstsq(W, -A @ self.forward, rcond=None)[0]
        self.rolling_residual = float(np.max(np.abs(W @ self.spin_rates + A @ self.forward)))
        if self.rolling_residual > 1e-12:
            raise NcgenError(f"WhippleBicycle: no spin rates roll both wheels without slipping "
                             f"(residual {self.rolling_residual:.3g} m/s); check the geometry")

    def _lean_steer(self, q):
        R, _ = self.model.functions["poses"](q)
        kB, kH = (self.model.member_names.index(n) for n in _NAMES[1:3])
        RB, RH = R[:, 3 * kB:3 * kB + 3], R[:, 3 * kH:3 * kH + 3]
        yB, yH = RB[:, 1], RH[:, 1]
        s = ca.mtimes(RB, ca.DM(self.parameters.steer_axis()))
        lean = ca.asin(yB[2])
        steer = ca.atan2(ca.dot(s, ca.cross(yB, yH)), ca.dot(yB, yH))
        return ca.vertcat(lean, steer)

    def reference(self, speed: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(q0, v0, K)``: upright straight running at ``speed`` (m/s), its spin generator."""
        K = speed * sum(rate * G for rate, G in zip(self.spin_rates, self.spins))
        q0 = self.model.q0
        return q0, speed * self.forward + K @ q0, K

    def linearize(self, speed: float) -> SecondOrder:
        """``M q̈ + C q̇ + K q = f`` in ``q = [φ, δ]`` at ``speed`` (m/s)."""
        return linearize_steady(self.rolling, *self.reference(speed), self.coordinates)

    def matrices(self, speed: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(M, C1, K0, K2)`` of the paper's form, from the linearisations at rest and at
        ``speed`` (m/s)."""
        if not speed > 0:
            raise NcgenError(f"WhippleBicycle.matrices: speed: expected a positive speed (m/s), found {speed!r}")
        g = self.parameters.g
        still, moving = self.linearize(0.0), self.linearize(speed)
        K0 = still.K / g
        return moving.M, moving.C / speed, K0, (moving.K - g * K0) / speed ** 2

    def eigenvalues(self, speeds) -> np.ndarray:
        """Eigenvalues (1/s) of the linearisation at each of ``speeds`` (m/s), one row each."""
        return np.array([self.linearize(float(v)).eigenvalues() for v in np.atleast_1d(speeds)])

    def weave_speed(self, bracket=(1.0, 6.0)) -> float:
        """The speed (m/s) where the weave pair's real part crosses zero (root in ``bracket``)."""
        def weave_real(v):
            lam = self.linearize(v).eigenvalues()
            pair = lam[np.abs(lam.imag) > 1e-9]
            if pair.size == 0:
                raise NcgenError(f"weave_speed: no oscillatory pair at {v} m/s; give another bracket")
            return float(pair.real.max())
        return brentq(weave_real, *bracket, xtol=1e-14, rtol=4 * np.finfo(float).eps)

    def capsize_speed(self, bracket=(5.0, 8.0)) -> float:
        """The speed (m/s) where the capsize root crosses zero: ``det K(v) = 0`` in ``bracket``."""
        return brentq(lambda v: float(np.linalg.det(self.linearize(v).K)), *bracket,
                      xtol=1e-14, rtol=4 * np.finfo(float).eps)

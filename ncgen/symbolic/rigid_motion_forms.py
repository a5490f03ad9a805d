"""Signatures of the rigid-motion functions that have NumPy, CasADi and C forms.

One table, read by :mod:`ncgen.rigid_motion` (NumPy) and :mod:`ncgen.assembly.rigid_motion`
(CasADi, hence C): for each function, placeholder arguments named after the mathematics
(``H_ab``, ``T_b``, ...), optional intermediate *stages* and the output expressions, all
built by calling :mod:`ncgen.symbolic.rigid_motion` and :mod:`ncgen.symbolic.spatial_inertia`.
Nothing is written here twice.

A stage ``(symbols, expression)`` is evaluated before the outputs and its value bound to
``symbols``; it keeps a large ``Piecewise`` (the rotation part of ``log_se3``) from being
copied into every expression that uses it.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache

import sympy as sp

from ncgen.symbolic import rigid_motion as rm
from ncgen.symbolic import spatial_inertia as si


@dataclass(frozen=True)
class Arg:
    """An argument: ``shape`` is ``()`` (scalar), ``(n,)`` (vector) or ``(r, c)`` (matrix)."""

    name: str
    shape: tuple[int, ...]

    def placeholder(self):
        """A real SymPy symbol, or a matrix of them named ``<name>_<i>[<j>]`` (row-major)."""
        if self.shape == ():
            return sp.Symbol(self.name, real=True)
        rows, cols = (self.shape[0], 1) if len(self.shape) == 1 else self.shape
        suffix = (lambda i, j: f"{i}") if len(self.shape) == 1 else (lambda i, j: f"{i}{j}")
        return sp.Matrix(rows, cols, lambda i, j: sp.Symbol(f"{self.name}_{suffix(i, j)}", real=True))


@dataclass(frozen=True)
class Output:
    name: str
    expr: object

    @property
    def shape(self) -> tuple[int, ...]:
        if not isinstance(self.expr, sp.MatrixBase):
            return ()
        rows, cols = self.expr.shape
        return (rows,) if cols == 1 else (rows, cols)


@dataclass(frozen=True)
class Form:
    """A function: arguments, their placeholders, stages and outputs."""

    name: str
    doc: str
    args: tuple[Arg, ...]
    placeholders: tuple
    stages: tuple[tuple[sp.Matrix, sp.Matrix], ...]
    outputs: tuple[Output, ...]


def _scalar(name):
    return Arg(name, ())


def _vec(name, n=3):
    return Arg(name, (n,))


def _mat(name, rows, cols=None):
    return Arg(name, (rows, cols or rows))


def _log_se3(H_ab):
    R, p = rm.rotation_of(H_ab), rm.position_of(H_ab)
    omega = sp.Matrix(3, 1, lambda i, j: sp.Symbol(f"omega_{i}", real=True))
    stage = (omega, rm.log_so3(R))
    return (stage,), (("T", sp.Matrix.vstack(omega, rm.log_se3_translation(omega, R, p))),)


_log_se3.source = rm.log_se3


def _plain(fn: Callable, *out_names: str) -> Callable:
    def build(*placeholders):
        values = fn(*placeholders)
        values = values if len(out_names) > 1 else (values,)
        return (), tuple(zip(out_names, values, strict=True))
    build.source = fn
    return build


_H = _mat("H_ab", 4)
_SPECS: dict[str, tuple[tuple[Arg, ...], Callable]] = {
    "rotx": ((_scalar("angle"),), _plain(rm.rotx, "R")),
    "roty": ((_scalar("angle"),), _plain(rm.roty, "R")),
    "rotz": ((_scalar("angle"),), _plain(rm.rotz, "R")),
    "rotzyx": ((_scalar("az"), _scalar("ay"), _scalar("ax")), _plain(rm.rotzyx, "R")),
    "zyx_angles": ((_mat("R_ab", 3),), _plain(rm.zyx_angles, "angles")),
    "homogeneous": ((_mat("R_ab", 3), _vec("p_ab")), _plain(rm.homogeneous, "H_ab")),
    "translation": ((_vec("p_ab"),), _plain(rm.translation, "H_ab")),
    "inverse": ((_H,), _plain(rm.inverse, "H_ba")),
    "transform_point": ((_H, _vec("x_b")), _plain(rm.transform_point, "x_a")),
    "transform_vector": ((_H, _vec("u_b")), _plain(rm.transform_vector, "u_a")),
    "so3_hat": ((_vec("omega"),), _plain(rm.so3_hat, "Omega")),
    "so3_vee": ((_mat("Omega", 3),), _plain(rm.so3_vee, "omega")),
    "se3_hat": ((_vec("T", 6),), _plain(rm.se3_hat, "T_hat")),
    "se3_vee": ((_mat("T_hat", 4),), _plain(rm.se3_vee, "T")),
    "Ad": ((_H,), _plain(rm.Ad, "Ad_ab")),
    "Ad_inv": ((_H,), _plain(rm.Ad_inv, "Ad_ba")),
    "ad": ((_vec("T", 6),), _plain(rm.ad, "ad_T")),
    "Ad_dot": ((_H, _vec("T_b", 6)), _plain(rm.Ad_dot, "Ad_dot_ab")),
    "transport_twist": ((_H, _vec("T_b", 6)), _plain(rm.transport_twist, "T_a")),
    "transport_wrench": ((_H, _vec("W_a", 6)), _plain(rm.transport_wrench, "W_b")),
    "power": ((_vec("W", 6), _vec("T", 6)), _plain(rm.power, "P")),
    "exp_so3": ((_vec("omega"),), _plain(rm.exp_so3, "R")),
    "log_so3": ((_mat("R_ab", 3),), _plain(rm.log_so3, "omega")),
    "exp_se3": ((_vec("T", 6),), _plain(rm.exp_se3, "H")),
    "log_se3": ((_H,), _log_se3),
    "mass_matrix": ((_scalar("m"), _vec("r"), _mat("I_o", 3)), _plain(si.mass_matrix, "M")),
    "inertia_about_point": ((_scalar("m"), _vec("r"), _mat("I_c", 3)),
                            _plain(si.inertia_about_point, "I_o")),
    "inertia_from_second_moment": ((_mat("S", 3),), _plain(si.inertia_from_second_moment, "I")),
    "mass_matrix_parts": ((_mat("M", 6),), _plain(si.mass_matrix_parts, "m", "r", "I_c")),
    "transport_mass_matrix": ((_mat("M_a", 6), _H), _plain(si.transport_mass_matrix, "M_b")),
    "box": ((_vec("half_extents"), _scalar("m")), _plain(si.box, "M")),
    "cylinder": ((_scalar("length"), _scalar("radius"), _scalar("m")), _plain(si.cylinder, "M")),
    "sphere": ((_scalar("radius"), _scalar("m")), _plain(si.sphere, "M")),
    "ellipsoid": ((_vec("semi_axes"), _scalar("m")), _plain(si.ellipsoid, "M")),
    "newton_euler_bias": ((_mat("M_b", 6), _vec("T_b", 6)), _plain(si.newton_euler_bias, "bias")),
}

NAMES: tuple[str, ...] = tuple(_SPECS)
"""Every function with numeric forms, in table order."""

@lru_cache(maxsize=None)
def form(name: str) -> Form:
    """The :class:`Form` of ``name`` (one of :data:`NAMES`), built once per process."""
    args, build = _SPECS[name]
    placeholders = tuple(a.placeholder() for a in args)
    stages, outputs = build(*placeholders)
    doc = build.source.__doc__.strip().split("\n\n")[0]
    return Form(name, doc, args, placeholders, tuple(stages),
                tuple(Output(n, e) for n, e in outputs))

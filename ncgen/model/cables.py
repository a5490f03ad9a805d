"""``ClusteredCable``: one elastic cable running through several points over frictionless
pulleys, its total length one quantity and its tension one value in every segment.

The cable passes the points ``path = [(member, at), ...]`` in order (``at`` in the member's
local frame; the ground's points are fixed pulleys or anchors in world coordinates).  With
``L = Σ_i |r_{i+1} − r_i|`` its tension is ``T = k (L − l₀) + c L̇`` (N), kept ≥ 0 (slack)
as :class:`~ncgen.model.forces.Spring` with ``cable=True`` does, and its generalised force
``Q = −T ∂L/∂q``: at each intermediate point the pull ``T`` along both segments, the sum of
the two unit vectors (a frictionless pulley).  ``k`` (N/m), ``rest_length`` (m, the whole
cable's: an input makes it an actuated cable, a parameter a design value) and ``damping``
(N·s/m) take numbers, expressions, inputs or parameters as other forces do.  Potential
``½ k (L − l₀)²`` while taut, unless ``k`` or ``l₀`` depend on inputs (then the cable's work is
not in the potential energy).
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ncgen.errors import ModelError
from ncgen.model.expressions import ExpressionError
from ncgen.model.forces import Force


class ClusteredCable(Force):
    """A frictionless clustered cable through the points of ``path`` (module docstring)."""

    kind = "ClusteredCable"

    def __init__(self, path, *, k, rest_length, damping=0.0, name: str | None = None):
        super().__init__(name)
        self.path = list(path)
        self.k, self.rest_length, self.damping = k, rest_length, damping

    def members(self):
        return [item[0] for item in self.path if isinstance(item, (tuple, list)) and len(item) == 2]

    def check(self, system):
        if len(self.path) < 2:
            raise ModelError(f"{self.label}: path: expected two or more (member, point) pairs, got {len(self.path)}")
        for i, item in enumerate(self.path):
            if not isinstance(item, (tuple, list)) or len(item) != 2:
                raise ModelError(f"{self.label}: path[{i}]: expected a (member, point) pair, got {item!r}")
            self._local_point(item[0], item[1], f"path[{i}]")
        if all(m.is_ground for m, _ in self.path):
            raise ModelError(f"{self.label}: path: every point is on the ground; the cable exerts no force")

    def nonnegative(self) -> dict:
        return {"k": self.k, "damping": self.damping, "rest_length": self.rest_length}

    def _points(self, ctx):
        out = []
        for m, at in self.path:
            at = np.asarray(at, float)
            out.append((ca.DM(at), ca.DM.zeros(ctx.dim)) if m.is_ground else ctx.local_point(m, at))
        return out

    def length(self, ctx):
        """``(L, L̇)``: the cable's length (m) and its rate (m/s)."""
        pts = self._points(ctx)
        L, rate = ca.SX(0), ca.SX(0)
        for (ra, va), (rb, vb) in zip(pts, pts[1:]):
            d = rb - ra
            seg = ca.sqrt(ca.sumsqr(d))
            L += seg
            rate += ca.dot(d, vb - va) / seg
        return L, rate

    def tension(self, ctx) -> ca.SX:
        L, rate = self.length(ctx)
        k = self._value(ctx, self.k, 1, "k")
        l0 = self._value(ctx, self.rest_length, 1, "rest_length")
        c = self._value(ctx, self.damping, 1, "damping")
        return ca.fmax(k * (L - l0) + c * rate, 0)

    def generalized(self, ctx):
        T = self.tension(ctx)
        pts = self._points(ctx)
        Q = ca.SX.zeros(ctx.layout.nq)
        pull = [ca.SX.zeros(ctx.dim) for _ in pts]          # force of the cable on each point
        for i, ((ra, _), (rb, _)) in enumerate(zip(pts, pts[1:])):
            d = rb - ra
            u = d / ca.sqrt(ca.sumsqr(d))
            pull[i] += T * u
            pull[i + 1] -= T * u
        for (m, at), f in zip(self.path, pull):
            if not m.is_ground:
                C = ca.DM(m.rigid.C(m.rigid.affine(np.asarray(at, float))))
                Q += ctx.scatter(m, ca.mtimes(C.T, f))
        return Q

    def potential(self, ctx):
        """``½ k (L − l₀)²`` while taut; 0 when ``k`` or ``l₀`` depend on inputs (an actuated
        cable does work on the system: its force is then not counted as conservative)."""
        L, _ = self.length(ctx)
        try:
            k = self._value(ctx, self.k, 1, "k (in the potential energy)", inputs=False)
            l0 = self._value(ctx, self.rest_length, 1, "rest_length (in the potential energy)", inputs=False)
        except ExpressionError:          # generalized() has accepted them with the inputs
            return ca.SX(0)
        stretch = L - l0
        return ca.if_else(stretch > 0, 0.5 * k * stretch**2, 0)

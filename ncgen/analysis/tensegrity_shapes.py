"""Topologies and shapes of standard tensegrities: the regular n-strut prism and towers of
prisms stacked ring on ring.  Each returns ``(nodes, struts, cables)`` in the conventions of
:mod:`ncgen.analysis.self_stress` (nodes in m).

The regular n-prism: a bottom ring of n nodes at radius ``r`` in ``z = 0``, a top ring at
``z = h`` turned by the twist ``φ``; strut i joins bottom i to top i, cables: the bottom ring,
the top ring, and bottom i to top i − 1.  It has a state of self-stress only at
``φ = 90° + 180°/n`` (each vertical cable turns by ``φ − 360°/n = 90° − 180°/n`` about the
axis), with force densities ring : vertical cable : strut = ``1 : 2 sin(π/n) : −2 sin(π/n)``.
"""
from __future__ import annotations

import numpy as np

from ncgen.errors import NcgenError


def prism_twist(n: int) -> float:
    """The twist ``φ = π/2 + π/n`` (rad) of the regular n-prism in equilibrium."""
    return np.pi / 2 + np.pi / n


def prism(n: int = 3, radius: float = 0.3, height: float = 0.5, twist: float | None = None):
    """The regular ``n``-strut prism (module docstring); ``twist`` (rad) defaults to the
    equilibrium twist :func:`prism_twist`.  Cables 0..n−1 bottom ring, n..2n−1 top ring,
    2n..3n−1 vertical; struts i = bottom i → top i."""
    return stacked_prisms(n, 1, radius, height, twist)


def stacked_prisms(n: int = 3, stages: int = 2, radius: float = 0.3, height: float = 0.5,
                   twist: float | None = None):
    """``stages`` regular ``n``-prisms stacked ring on ring (class 2 from two stages up: the
    nodes of an inner ring end two struts), each turned by ``twist`` against the one below.
    Nodes: ring k (k = 0..stages) is nodes ``k n .. k n + n − 1``; cables: the rings, then
    each stage's vertical cables; struts: stage by stage.  Every stage's self-stress is one of
    the tower's, so it has at least ``stages`` states."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 3:
        raise NcgenError(f"prism: n: expected an integer number of struts >= 3, got {n!r}")
    if isinstance(stages, bool) or not isinstance(stages, (int, np.integer)) or stages < 1:
        raise NcgenError(f"stacked_prisms: stages: expected an integer >= 1, got {stages!r}")
    for what, x in (("radius", radius), ("height", height)):
        if not (isinstance(x, (int, float, np.floating)) and np.isfinite(x) and x > 0):
            raise NcgenError(f"prism: {what}: expected a length > 0 (m), got {x!r}")
    phi = prism_twist(n) if twist is None else float(twist)
    th = 2 * np.pi * np.arange(n) / n
    nodes = np.vstack([np.column_stack([radius * np.cos(th + k * phi), radius * np.sin(th + k * phi),
                                        np.full(n, k * height)]) for k in range(stages + 1)])
    cables = [(k * n + i, k * n + (i + 1) % n) for k in range(stages + 1) for i in range(n)]
    cables += [(k * n + i, (k + 1) * n + (i - 1) % n) for k in range(stages) for i in range(n)]
    struts = [(k * n + i, (k + 1) * n + i) for k in range(stages) for i in range(n)]
    return nodes, struts, cables

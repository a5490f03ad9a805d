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


def tower_of_radii(radii, strut_length: float, n: int = 3):
    """A tower of ``len(radii) − 1`` regular ``n``-prisms stacked ring on ring (as
    :func:`stacked_prisms`) whose ring k has radius ``radii[k]`` (m) and whose struts all have
    the length ``strut_length`` (m): each stage's height follows from its two radii and the
    equilibrium twist ``φ`` (``h² = s² − r_a² − r_b² + 2 r_a r_b cos φ``; each stage stays in
    self-stress).  Shapes of one structure: changing the radii deploys or folds it."""
    radii = np.asarray(radii, float).reshape(-1)
    if radii.size < 2 or not np.all(np.isfinite(radii)) or np.any(radii <= 0):
        raise NcgenError(f"tower_of_radii: radii: expected two or more radii > 0 (m), got {radii.tolist()}")
    nodes, struts, cables = stacked_prisms(n, radii.size - 1, 1.0, 1.0)
    c = np.cos(prism_twist(n))
    z = 0.0
    for k, r in enumerate(radii):
        if k:
            h2 = strut_length**2 - radii[k - 1]**2 - r**2 + 2 * radii[k - 1] * r * c
            if not h2 > 0:
                raise NcgenError(f"tower_of_radii: strut_length: {strut_length!r} m cannot span rings of radii "
                                 f"{radii[k - 1]:g} and {r:g} m at the twist {np.degrees(prism_twist(n)):g} deg")
            z += np.sqrt(h2)
        nodes[k * n:(k + 1) * n, :2] *= r
        nodes[k * n:(k + 1) * n, 2] = z
    return nodes, struts, cables

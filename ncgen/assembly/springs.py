"""Spring and cable forces of a model as plain data: names, cable flags and one CasADi
function evaluating every spring's tension, so that statics, form-finding and the viewer can
report prestress and slack cables without going back to the force elements.

``springs: t, q, v, u, p -> tension, length, pull`` (one entry per
:class:`~ncgen.model.forces.Spring` and :class:`~ncgen.model.cables.ClusteredCable`, in the
order the forces were added): ``pull = k (l − l₀) + c l̇`` (N), ``tension`` the force the
element exerts (``max(pull, 0)`` for a cable, ``pull`` otherwise), ``length`` ``l`` (m; a
clustered cable's whole length ``L``, the sum of its segments).
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca


@dataclass(frozen=True)
class SpringTable:
    """The springs of a model: ``names``, ``cable`` flags (``True``: pulls only),
    ``segments`` (1 per spring, the number of segments of a clustered cable) and ``function``
    (see the module docstring)."""

    names: tuple[str, ...]
    cable: tuple[bool, ...]
    function: ca.Function
    segments: tuple[int, ...] = ()


def tension_elements(forces) -> list:
    """The forces of a model that the table describes, in order: its ``Spring`` and
    ``ClusteredCable`` elements."""
    from ncgen.model.cables import ClusteredCable
    from ncgen.model.forces import Spring

    return [f for f in forces if isinstance(f, (Spring, ClusteredCable))]


def spring_table(system, ctx) -> SpringTable:
    """The :class:`SpringTable` of ``system`` (its springs and clustered cables)."""
    from ncgen.model.cables import ClusteredCable

    elements = tension_elements(system.forces)
    pulls, lengths = [], []
    for s in elements:
        if isinstance(s, ClusteredCable):
            length, rate = s.length(ctx)
        else:
            _, _, _, length, rate = s._geometry(ctx)
        k = s._value(ctx, s.k, 1, "k")
        l0 = s._value(ctx, s.rest_length, 1, "rest_length")
        c = s._value(ctx, s.damping, 1, "damping")
        pulls.append(k * (length - l0) + c * rate)
        lengths.append(length)
    cable = tuple(isinstance(s, ClusteredCable) or s.cable for s in elements)
    pull = ca.vertcat(*pulls) if elements else ca.SX(0, 1)
    length = ca.vertcat(*lengths) if elements else ca.SX(0, 1)
    tension = ca.vertcat(*[ca.fmax(pulls[i], 0) if cable[i] else pulls[i] for i in range(len(elements))]) \
        if elements else ca.SX(0, 1)
    f = ca.Function("springs", [ctx.t, ctx.q, ctx.v, ctx.u, ctx.p], [tension, length, pull],
                    ["t", "q", "v", "u", "p"], ["tension", "length", "pull"])
    segments = tuple(len(s.path) - 1 if isinstance(s, ClusteredCable) else 1 for s in elements)
    return SpringTable(tuple(s.name for s in elements), cable, f, segments)

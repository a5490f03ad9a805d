"""Spring and cable forces of a model as plain data: names, cable flags and one CasADi
function evaluating every spring's tension, so that statics and form-finding can report
prestress and slack cables without going back to the force elements.

``springs: t, q, v, u, p -> tension, length, pull`` (one entry per :class:`~ncgen.model.forces.Spring`,
in the order the forces were added): ``pull = k (l − l₀) + c l̇`` (N), ``tension`` the force the
element exerts (``max(pull, 0)`` for a cable, ``pull`` otherwise), ``length`` ``l`` (m).
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca


@dataclass(frozen=True)
class SpringTable:
    """The springs of a model: ``names``, ``cable`` flags (``True``: pulls only) and
    ``function`` (see the module docstring)."""

    names: tuple[str, ...]
    cable: tuple[bool, ...]
    function: ca.Function


def spring_table(system, ctx) -> SpringTable:
    """The :class:`SpringTable` of ``system`` (its :class:`~ncgen.model.forces.Spring` forces)."""
    from ncgen.model.forces import Spring

    springs = [f for f in system.forces if isinstance(f, Spring)]
    pulls, lengths = [], []
    for s in springs:
        _, _, _, length, rate = s._geometry(ctx)
        k = s._value(ctx, s.k, 1, "k")
        l0 = s._value(ctx, s.rest_length, 1, "rest_length")
        c = s._value(ctx, s.damping, 1, "damping")
        pulls.append(k * (length - l0) + c * rate)
        lengths.append(length)
    pull = ca.vertcat(*pulls) if springs else ca.SX(0, 1)
    length = ca.vertcat(*lengths) if springs else ca.SX(0, 1)
    cable = tuple(s.cable for s in springs)
    tension = ca.vertcat(*[ca.fmax(pulls[i], 0) if cable[i] else pulls[i] for i in range(len(springs))]) \
        if springs else ca.SX(0, 1)
    f = ca.Function("springs", [ctx.t, ctx.q, ctx.v, ctx.u, ctx.p], [tension, length, pull],
                    ["t", "q", "v", "u", "p"], ["tension", "length", "pull"])
    return SpringTable(tuple(s.name for s in springs), cable, f)

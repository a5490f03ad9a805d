"""Spring and cable forces of a model as plain data: names, cable flags and one CasADi
function evaluating every spring's tension, so that statics, form-finding and the viewer can
report prestress and slack cables without going back to the force elements.

``springs: t, q, v, u, p -> tension, length, pull`` (one entry per
:class:`~ncgen.model.forces.Spring` and :class:`~ncgen.model.cables.ClusteredCable`, one per side of a
:class:`~ncgen.model.capstan.CapstanCable`, its sides ``<name>.a``, ``<name>.b``, … in path order, in the
order the forces were added): ``pull = k (l − l₀) + c l̇`` (N; a capstan side's
``EA (l − ρ)/ρ + c (l̇ − ρ̇)``), ``tension`` the force the element exerts (``max(pull, 0)`` for a
cable, ``pull`` otherwise), ``length`` ``l`` (m; a clustered cable's whole length ``L``, the sum
of its segments; a capstan side's length).
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
    """The forces of a model that the table describes, in order: its ``Spring``,
    ``ClusteredCable`` and ``CapstanCable`` elements."""
    from ncgen.model.cables import ClusteredCable
    from ncgen.model.capstan import CapstanCable
    from ncgen.model.forces import Spring

    return [f for f in forces if isinstance(f, (Spring, ClusteredCable, CapstanCable))]


def tension_rows(forces) -> list[tuple]:
    """The table's rows, in order: ``(element, name, path)``, ``path`` the ``(member, point)``
    pairs the row's segments join (a spring's two ends; a capstan cable's sides a, b, … in turn)."""
    from ncgen.model.capstan import CapstanCable

    rows = []
    for f in tension_elements(forces):
        if isinstance(f, CapstanCable):
            rows += [(f, name, path) for name, path in zip(f.side_names(), f.side_paths())]
        else:
            rows.append((f, f.name, f.path if hasattr(f, "path") else [(f.a, f.at_a), (f.b, f.at_b)]))
    return rows


def spring_table(system, ctx) -> SpringTable:
    """The :class:`SpringTable` of ``system`` (its springs, clustered and capstan cables)."""
    from ncgen.model.capstan import CapstanCable
    from ncgen.model.cables import ClusteredCable

    pulls, lengths = [], []
    for s in tension_elements(system.forces):
        if isinstance(s, CapstanCable):
            pulls += list(s.pulls(ctx))
            lengths += [length for length, _ in s.lengths(ctx)]
            continue
        if isinstance(s, ClusteredCable):
            length, rate = s.length(ctx)
        else:
            _, _, _, length, rate = s._geometry(ctx)
        k = s._value(ctx, s.k, 1, "k")
        l0 = s._value(ctx, s.rest_length, 1, "rest_length")
        c = s._value(ctx, s.damping, 1, "damping")
        pulls.append(k * (length - l0) + c * rate)
        lengths.append(length)
    rows = tension_rows(system.forces)
    cable = tuple(getattr(s, "cable", True) for s, _, _ in rows)
    pull = ca.vertcat(*pulls) if rows else ca.SX(0, 1)
    length = ca.vertcat(*lengths) if rows else ca.SX(0, 1)
    tension = ca.vertcat(*[ca.fmax(pulls[i], 0) if cable[i] else pulls[i] for i in range(len(rows))]) \
        if rows else ca.SX(0, 1)
    f = ca.Function("springs", [ctx.t, ctx.q, ctx.v, ctx.u, ctx.p], [tension, length, pull],
                    ["t", "q", "v", "u", "p"], ["tension", "length", "pull"])
    segments = tuple(len(path) - 1 for _, _, path in rows)
    return SpringTable(tuple(name for _, name, _ in rows), cable, f, segments)

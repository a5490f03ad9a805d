"""Models of the element kinds the table stepper covers, shared by its tests and by the
process they start with no compiler on PATH (tests/test_table_stepper.py,
tests/test_table_forces.py): a chain of bars and a model with every force kind
of the tables but gravity (spring-dampers, a cable, a torsional spring-damper, a constant
point force, constant torques on a body and a bar, a constant generalised force)."""
from __future__ import annotations

import numpy as np

import ncgen as nc
from ncgen.model.layout import make_layout


def chain_system(n: int, springs: bool = False, name: str | None = None):
    """A 3D chain of ``n`` bars sharing their ends, the first end a ground point; with
    ``springs``, a spring-damper from every joint to a ground point above it."""
    s = nc.System(name or f"tchain{n}{'s' if springs else ''}")
    start = s.ground.point((0.0, 0.0, 0.0))
    pos = np.zeros(3)
    bars = []
    for k in range(n):
        pos = pos + np.array([0.31 + 0.02 * k, 0.09 * (k % 3), -0.07])
        bars.append(s.add_bar(f"b{k}", coords="rr", mass=0.4 + 0.05 * k, ends=[start, tuple(pos)]))
        start = bars[-1].end(1)
    if springs:
        for k, b in enumerate(bars):
            s.add_force(nc.Spring(b, (0.0, 0.0, 0.0), s.ground, (0.3 * k, 0.2, 0.6), k=30.0 + 5 * k,
                                  rest_length=0.4, damping=0.8 + 0.1 * k))
    return s


def every_force(dim: int = 3, name: str | None = None):
    """A body on a spherical joint (3D; a hinge in 2D) carrying a bar on a hinge with a
    torsional spring-damper, a cable from the bar to the ground, a spring-damper, a constant
    point force and torque on the body, a torque on the bar, and a free point pushed by a
    constant generalised force: every force kind of the stepper tables in one model."""
    s = nc.System(name or f"every_force{dim}d", gravity=(0.0, 0.0, -9.81) if dim == 3 else (0.0, -9.81))
    if dim == 3:
        body = s.add_body("body", coords="ruvw", mass=1.2, inertia=np.diag([0.02, 0.03, 0.04]),
                          position=(0.3, 0.0, 0.1))
        bar = s.add_bar("bar", coords="rr", mass=0.5, ends=[(0.6, 0.0, 0.1), (0.9, 0.1, 0.0)])
        s.add_joint(nc.Spherical(s.ground, body, at=(0.0, 0.0, 0.1)))
        hinge = nc.Revolute(body, bar, at=(0.6, 0.0, 0.1), axis=(0.0, 1.0, 0.0), name="hinge")
        point = s.add_point("puck", mass=0.3, position=(0.0, 1.0, 0.0), velocity=(0.1, 0.0, 0.2))
        tau_body, tau_bar, push = (0.05, 0.1, -0.02), (0.03, -0.02, 0.04), (0.5, -0.3, 0.2)
    else:
        body = s.add_body("body", coords="ruv", mass=1.2, inertia=0.03, position=(0.3, 0.1), rotation=0.2)
        bar = s.add_bar("bar", coords="rr", mass=0.5, ends=[(0.6, 0.1), (0.9, 0.3)])
        s.add_joint(nc.Revolute(s.ground, body, at=(0.0, 0.1)))
        hinge = nc.Revolute(body, bar, at=(0.6, 0.1), name="hinge")
        point = s.add_point("puck", mass=0.3, position=(0.0, 1.0), velocity=(0.1, 0.2))
        tau_body, tau_bar, push = 0.05, -0.03, (0.5, -0.3)
    s.add_joint(hinge)
    z = (0.0,) * dim
    end = (0.15,) + (0.0,) * (dim - 1)
    s.add_force(nc.TorsionalSpring(hinge, k=3.0, damping=0.2, rest_angle=0.3, name="twist"))
    s.add_force(nc.Spring(bar, end, s.ground, (1.0, 0.3, 0.5)[:dim], k=40.0, rest_length=0.3, damping=0.5,
                          cable=True, name="cable"))
    s.add_force(nc.Spring(body, z, s.ground, (0.2, -0.4, 0.6)[:dim], k=25.0, rest_length=0.2, damping=0.3,
                          name="spring"))
    s.add_force(nc.PointForce(body, (0.1,) + (0.05,) * (dim - 1), force=push, name="push"))
    s.add_force(nc.Torque(body, tau_body, name="twist_body"))
    s.add_force(nc.Torque(bar, tau_bar, name="twist_bar"))
    layout = make_layout(dim, list(s.members.values()))
    value = np.zeros(layout.nq)
    value[list(layout.member_indices(point.name))] = (0.4, -0.2, 0.7)[:dim]
    s.add_force(nc.GeneralizedForce(value, name="shove"))
    return s

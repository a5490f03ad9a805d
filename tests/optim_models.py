"""Small models for the trajectory-optimisation tests (planar, SI units)."""
from __future__ import annotations

import casadi as ca

import ncgen as nc

G = 9.81


def cartpole(cart_mass: float = 1.0, pole_mass: float = 0.2, length: float = 0.5) -> nc.Model:
    """A point cart on a rail along x (PointOnLine) carrying a uniform pole on a shared
    pivot, hanging down; input ``force`` (N) pushes the cart; marker ``pole.tip``."""
    s = nc.System("cartpole", gravity=(0, -G))
    cart = s.add_point("cart", mass=cart_mass, position=(0, 0))
    pole = s.add_bar("pole", mass=pole_mass, ends=[cart.node(0), (0, -length)])
    pole.add_marker("tip", (length / 2, 0))
    s.add_joint(nc.PointOnLine(s.ground, cart, at=(0, 0), axis=(1, 0)))
    force = s.add_input("force")
    s.add_force(nc.PointForce(cart, (0, 0), force=ca.vertcat(force, 0)))
    return s.build()


def pendulum(length: float = 1.0, mass: float = 1.0) -> nc.Model:
    """A uniform bar pinned to the ground at the origin, hanging down, driven by the torque
    ``tau`` (N·m); marker ``bar.tip``; parameter ``k`` (N/m, default 1) of a spring of zero
    rest length from the ground point (0, length) to the tip."""
    s = nc.System("pendulum", gravity=(0, -G))
    bar = s.add_bar("bar", mass=mass, ends=[s.ground.point((0, 0)), (0, -length)])
    bar.add_marker("tip", (length / 2, 0))
    tau = s.add_input("tau")
    k = s.add_parameter("k", 1.0)
    s.add_force(nc.Torque(bar, tau))
    s.add_force(nc.Spring(s.ground, (0, length), bar, (length / 2, 0), k=k))
    return s.build()


def slider(mass: float = 2.0) -> nc.Model:
    """A point mass on a rail along x (PointOnLine), gravity across the rail, pushed by
    ``force`` (N): the double integrator m ẍ = force, with the rail carrying m g."""
    s = nc.System("slider", gravity=(0, -G))
    p = s.add_point("mass", mass=mass, position=(0, 0))
    s.add_joint(nc.PointOnLine(s.ground, p, at=(0, 0), axis=(1, 0)))
    f = s.add_input("force")
    s.add_force(nc.PointForce(p, (0, 0), force=ca.vertcat(f, 0)))
    return s.build()

"""A weight lifted and held by a rope over a fixed drum with friction (capstan law).

The weight (mass m, on a vertical line at x = −0.1) hangs from side a of a rope that runs
over a drum at (−0.1, 0, 1) (friction μ, wrap θ) and a frictionless pulley at (0.1, 0, 1) to
a hand (mass m_h, on a vertical line at x = 0.1) pulled down by a force F.  The rope starts
at the static tensions T_a = m g, T_b = F + m_h g.  Closed forms (massless, inextensible rope):
the weight stays while e^{−μθ} ≤ T_b/T_a ≤ e^{μθ}; else it accelerates at
a = (F + m_h g − e^{±μθ} m g)/(m_h + e^{±μθ} m) (+: lifted, −: lowered).

Run: python examples/capstan_lift.py
"""
import numpy as np

import ncgen as nc

G = 9.81


def capstan_lift(force, wrap, *, mu=0.3, mass=1.0, hand=0.2, ea=1e5, damping=20.0, material_mass=1e-3, slip_velocity=1e-4):
    """The system (see the module docstring); ``wrap`` θ (rad; None: from the shape, π/2 here),
    ``ea`` the rope's axial stiffness (N), ``damping`` its internal damping (N·s/m)."""
    s = nc.System("capstan_lift", gravity=(0, 0, -G))
    w = s.add_point("weight", mass=mass, position=(-0.1, 0, 0))
    h = s.add_point("hand", mass=hand, position=(0.1, 0, 0))
    for p, x in ((w, -0.1), (h, 0.1)):
        s.add_joint(nc.PointOnLine(s.ground, p, at=(x, 0, 0), axis=(0, 0, 1)))
    s.add_force(nc.PointForce(h, (0, 0, 0), force=(0, 0, -force), name="pull"))
    t_a, t_b = mass * G, force + hand * G
    nc.add_capstan_cable(s, [(w, (0, 0, 0)), (s.ground, (-0.1, 0, 1)), (s.ground, (0.1, 0, 1)), (h, (0, 0, 0))],
                         pulley=1, mu=mu, wrap=wrap, ea=ea, rest_lengths=(1.0 / (1 + t_a / ea), 1.2 / (1 + t_b / ea)),
                         damping=damping, material_mass=material_mass, slip_velocity=slip_velocity, name="rope")
    return s


def closed_form(force, wrap, *, mu=0.3, mass=1.0, hand=0.2):
    """The weight's acceleration (m/s², up positive) for a massless, inextensible rope."""
    e = np.exp(mu * wrap)
    ratio = (force + hand * G) / (mass * G)
    if ratio > e:
        return (force + hand * G - e * mass * G) / (hand + e * mass)
    if ratio < 1 / e:
        return (force + hand * G - mass * G / e) / (hand + mass / e)
    return 0.0


if __name__ == "__main__":
    for wrap, name in ((np.pi, "π"), (2 * np.pi, "2π")):
        for force in (0.0, 10.0, 30.0, 70.0):
            traj = nc.simulate(capstan_lift(force, wrap).build(), t_end=0.25, dt=0.005, backend="vm")
            z = traj.point("weight", (0, 0, 0))[:, 2]
            a = 2 * np.polyfit(traj.t, z, 2)[0]
            print(f"θ = {name:2s}  F = {force:4.1f} N: weight acceleration {a:+.4f} m/s², "
                  f"closed form {closed_form(force, wrap):+.4f}")

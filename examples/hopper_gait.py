"""A hopper that finds a hop from a standing guess (contact-implicit optimal control).

A body (a 1 kg point) and a foot (a 0.2 kg point with a sphere of radius 0.05 m against
the floor, no bounce, no friction) slide on a vertical guide (two ``PointOnLine`` joints
with the ground: the leg's prismatic joint).  A leg actuator pushes them apart with the
force ``leg`` (N, at most 40 N either way; piecewise constant over N = 30 equal steps).
From standing at rest (body 0.45 m, foot 0.05 m high) the hopper must follow a reference
that lifts body and foot 0.2 m and puts them back (``track_marker`` on both), over
T = 1 s, ending at rest where it started, with the least ``∫ leg² dt`` and tracking error.
Internal forces cannot lift the centre of mass: only the floor can, so following the
reference means pushing off, flying and landing.  The guess is the hopper standing still
(``"rest"``); the transcription (:mod:`ncgen.optim.contact_implicit`) finds where the foot
leaves and meets the floor: it pushes off at 0.23 s, flies, taps the floor once at 0.43 s,
flies again and lands at 0.63 s.  The homotopy starts at σ = 1 (:data:`CONTACTS`).

The leg force acts on the body alone apart from gravity, so the body's motion is set by the
force (the replay matches it to round-off); the floor acts on the foot.  A model with a leg
spring and stroke limits, or a robot with a hip, would make a richer gait: not done here.

Checks (tests/test_optim_contact_implicit.py): the optimum has a flight phase (foot above
the floor, no contact force) between phases of contact; in flight the foot moves with the
constant acceleration ``−leg/m_foot − g`` of each step (closed form); the cost is below
3/4 of the best motion with the foot kept down (a least-squares closed form); the
complementarity residual is below the tolerance; the optimal force replayed by the
nonsmooth stepper follows the optimum (foot within 2 mm).

Run:  python examples/hopper_gait.py      (writes hopper_gait.png and .html)
"""
import casadi as ca
import numpy as np

import ncgen as nc

G, BODY, FOOT, RADIUS, LEG = 9.81, 1.0, 0.2, 0.05, 0.4
T, N, LIFT, FORCE, EFFORT = 1.0, 30, 0.2, 40.0, 1e-2
#: The homotopy from σ = 1 (a smoother first contact law): from 0.1 the first solve stays
#: standing, a local optimum with twice the cost.
CONTACTS = {"sigma0": 1.0}


def build():
    s = nc.System("hopper", gravity=(0, -G))
    body = s.add_point("body", mass=BODY, position=(0, RADIUS + LEG))
    foot = s.add_point("foot", mass=FOOT, position=(0, RADIUS))
    body.add_marker("centre", (0, 0))
    foot.add_marker("centre", (0, 0))
    for p, y in ((body, RADIUS + LEG), (foot, RADIUS)):
        s.add_joint(nc.PointOnLine(s.ground, p, at=(0, y), axis=(0, 1), name=f"{p.name}_guide"))
    leg = s.add_input("leg")
    s.add_force(nc.PointForce(body, (0, 0), force=ca.vertcat(0, leg)))
    s.add_force(nc.PointForce(foot, (0, 0), force=ca.vertcat(0, -leg)))
    s.add_contact(nc.SpherePlane(foot, radius=RADIUS, mu=0.0, name="floor"))
    return s.build(contacts="nonsmooth")


def lift(t):
    """The reference's rise (m) at time ``t`` (s): 0 at the ends, ``LIFT`` at T/2."""
    return LIFT * np.sin(np.pi * t / T) ** 2


def problem(model, weight=1000.0, contacts=CONTACTS):
    ocp = nc.OptimalControl(model, N=N, t_final=T, contacts=contacts)
    ocp.final(q=model.q0, v=0)
    ocp.bound_input("leg", -FORCE, FORCE)
    ocp.track_marker("body.centre", lambda t: (0.0, RADIUS + LEG + lift(t)), weight=weight)
    ocp.track_marker("foot.centre", lambda t: (0.0, RADIUS + lift(t)), weight=weight)
    ocp.minimize_effort(EFFORT)
    return ocp


def phases(sol, tol=1e-6):
    """``(stance, flight)`` boolean arrays over the N intervals: a contact force acts, or
    the foot is above the floor at both ends with no force."""
    gap = sol.marker("foot.centre")[:, 1] - RADIUS
    force = sol.contact_force[:, 0] > tol
    flight = (gap[:-1] > tol) & (gap[1:] > tol) & ~force
    return force, flight


def replay(model, sol, substeps=20):
    """The optimal leg force replayed by the nonsmooth stepper (held over each step)."""
    return nc.simulate(model, T, T / N, u=sol.u, hold="zoh", method="stepper", substeps=substeps)


if __name__ == "__main__":
    model = build()
    sol = problem(model).solve("rest")
    stance, flight = phases(sol)
    print(sol.summary())
    print(f"stance in {int(stance.sum())} intervals, flight in {int(flight.sum())} of {N}; "
          f"highest foot {sol.marker('foot.centre')[:, 1].max() - RADIUS:.4f} m above the floor; "
          f"complementarity residual {sol.complementarity_residual:.2e}; {sol.stats.iterations} iterations, "
          f"{sol.stats.solve_time:.1f} s")
    sim = replay(model, sol)
    miss = max(np.abs(sim.marker(m)[-1] - sol.marker(m)[-1]).max() for m in ("body.centre", "foot.centre"))
    print(f"replayed by the nonsmooth stepper: ends {miss:.2e} m from the optimum")
    from ncgen.optim.solution_plot import plot_solution
    plot_solution(sol, "hopper_gait.png")
    sol.to_html("hopper_gait.html")
    print("wrote hopper_gait.png, hopper_gait.html")

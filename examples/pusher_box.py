"""A pusher bringing a box to a pose on the floor (contact-implicit optimal control).

A planar pusher (a 0.5 kg point on a horizontal guide at the box's mid-height, driven by the
force ``push`` in N, piecewise constant over N = 10 equal steps) carries a sphere of radius
2 cm, 1 cm left of a box's left face.  The box (a 1 kg rectangle 0.1 × 0.1 m, a rigid body free
in the plane) rests on the floor on its corners (``BoxPlane``, μ = 0.4).  The sphere meets the
box through a ``SphereBox`` contact carried by the box (frictionless): the gap and normal of
the face nearest to the sphere, the formulas of the simulator's pair kernels.  From rest, the
box must end 0.15 m to the right, upright, everything at rest, in T = 1 s, with the least
``∫ push² dt``; the guess is everything at rest.

The homotopy starts at σ₀ = 1e-3 (``CONTACTS``; from the default σ₀ = 0.1 the next solve, at
σ = 1e-3, ends "locally infeasible").  Why: σ bounds every product gap · force (m·N) and
gap · impulse (m·N·s) in absolute units, so at σ = 0.1 contacts 0.1 m apart may still push
with 1 N (or 1 N·s).  From rest the first solve moves the box by that action at a distance:
the pusher, 0.1–0.3 m behind the box, pushes it with 1.2 N, the top corners take node
impulses of 0.08 and 0.25 N·s, the box hops 6.8 mm, and it reaches the target while the pusher
goes backwards (0.42 → 0.27 m).  Nothing of this survives σ → 0, and from there, with the
pusher far behind the box, IPOPT finds no feasible point at σ = 1e-3.  From σ₀ = 1e-3 a
contact 0.1 m apart carries at most 0.01 N, and the homotopy goes through: the pusher draws
back, strikes the box (a plastic impact, 0.94 N·s) and pushes it to the target, where both
stop (cost ∫ push² dt = 15.41 N²·s, a local optimum; complementarity residual 6e-11 after the
polish; 671 IPOPT iterations).

Checked (tests/test_optim_contact_boxes.py): the complementarity residual;
the box at the target; where the box slides over an interval its momentum changes by the
push less Coulomb's sliding friction μ Σ f_N (exact for constant forces); the box never lifts
or turns; the optimal push replayed by the nonsmooth stepper ends where the optimiser said.
The Panda's NLP: ``benchmarks/contact_implicit_panda.py``.

Run:  python examples/pusher_box.py      (writes pusher_box.png and .html)
"""
import casadi as ca
import numpy as np

import ncgen as nc

G = 9.81
BOX, BOX_MASS, BOX_X = 0.1, 1.0, 0.5               # edge (m), mass (kg), initial centre x (m)
PUSHER_MASS, RADIUS, GAP, MU_FLOOR = 0.5, 0.02, 0.01, 0.4
DISTANCE, T, N = 0.15, 1.0, 10
CONTACTS = {"sigma0": 1e-3}                     # the homotopy's first σ (m·N; docstring)


def build():
    s = nc.System("pusher_box", gravity=(0, -G))
    start = (BOX_X - BOX / 2 - RADIUS - GAP, BOX / 2)
    pusher = s.add_point("pusher", mass=PUSHER_MASS, position=start)
    pusher.add_marker("centre", (0, 0))
    s.add_joint(nc.PointOnLine(s.ground, pusher, at=start, axis=(1, 0), name="guide"))
    s.add_force(nc.PointForce(pusher, (0, 0), force=ca.vertcat(s.add_input("push"), 0)))
    box = s.add_body("box", coords="ruv", mass=BOX_MASS, inertia=BOX_MASS * BOX ** 2 / 6, position=(BOX_X, BOX / 2))
    box.add_marker("centre", (0, 0))
    box.add_marker("front", (BOX / 2, 0))
    s.add_contact(nc.BoxPlane(box, size=(BOX, BOX), mu=MU_FLOOR, name="floor"))
    s.add_contact(nc.SphereBox(pusher, (0, 0), RADIUS, box=box, size=(BOX, BOX), name="push"))
    return s.build(contacts="nonsmooth")


def problem(model, contacts=CONTACTS):
    """The box moved by ``DISTANCE``, upright (two of its points), everything at rest at the end."""
    ocp = nc.OptimalControl(model, N=N, t_final=T, contacts=contacts)
    ocp.final(marker=[("box.centre", (BOX_X + DISTANCE, BOX / 2)),
                      ("box.front", (BOX_X + DISTANCE + BOX / 2, BOX / 2))], v=0)
    ocp.minimize_effort()
    return ocp


def contact_index(model, name):
    return [c["name"] for c in model.contacts].index(name)


def phases(model, sol, tol=1e-6):
    """``(pushing, moving)`` boolean arrays over the N intervals: the pusher presses on the
    box; the box's centre moves over the interval."""
    push = sol.contact_force[:, contact_index(model, "push")] > tol
    x = sol.marker("box.centre")[:, 0]
    return push, np.abs(np.diff(x)) > tol * T / N


def replay(model, sol, substeps=20):
    """The optimal push replayed by the nonsmooth stepper (held over each step)."""
    return nc.simulate(model, T, T / N, u=sol.u, hold="zoh", method="stepper", substeps=substeps)


if __name__ == "__main__":
    model = build()
    sol = problem(model).solve("rest")
    pushing, moving = phases(model, sol)
    print(sol.summary())
    print(f"pushing in {int(pushing.sum())} intervals, the box moving in {int(moving.sum())} of {N}; "
          f"complementarity residual {sol.complementarity_residual:.2e}; {sol.stats.iterations} iterations, "
          f"{sol.stats.solve_time:.1f} s")
    sim = replay(model, sol)
    miss = np.abs(sim.marker("box.centre")[-1] - sol.marker("box.centre")[-1]).max()
    print(f"replayed by the nonsmooth stepper: the box ends {miss:.2e} m from the optimum")
    from ncgen.optim.solution_plot import plot_solution
    plot_solution(sol, "pusher_box.png")
    sol.to_html("pusher_box.html")
    print("wrote pusher_box.png, pusher_box.html")

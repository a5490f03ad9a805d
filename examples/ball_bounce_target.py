"""A ball thrown to hit a target after one bounce (contact-implicit optimal control).

A ball of radius 0.1 m (a point member with a sphere against the floor, restitution 0.8,
no friction) starts at (0, 1) m; its initial velocity is free.  It must be at the target
(2, 0.8) m after 0.9 s without rising above 1.2 m, which no throw meets without touching
the floor (the throw that reaches the target in flight rises to 1.9 m).  The model is built
with ``contacts="nonsmooth"``, so ``nc.OptimalControl`` transcribes the contact
(:mod:`ncgen.optim.contact_implicit`): free step lengths put a node on the impact, where
Newton's law with restitution holds exactly.  The guess is a throw at the floor simulated by
the nonsmooth stepper.  Checked against the closed form (the vertical throw solving the
bounce's equation, :func:`closed_form`) and replayed by the nonsmooth stepper.

Run:  python examples/ball_bounce_target.py      (writes ball_bounce_target.png and .html)
"""
import numpy as np

import ncgen as nc

G, RADIUS, RESTITUTION = 9.81, 0.1, 0.8
START, TARGET, T, CEILING, N = (0.0, 1.0), (2.0, 0.8), 0.9, 1.2, 20


def build():
    s = nc.System("ball_bounce", gravity=(0, -G))
    ball = s.add_point("ball", mass=1.0, position=START)
    ball.add_marker("centre", (0, 0))
    s.add_contact(nc.SpherePlane(ball, radius=RADIUS, restitution=RESTITUTION, name="floor"))
    return s.build(contacts="nonsmooth")


def closed_form():
    """``(vx, vz, t_impact)``: the one-bounce throw.  Flight ``z = z0 + vz t − g t²/2`` to the
    floor ``z = R`` at ``t1``, rebound ``−e`` times the impact speed, then flight to the target
    height at ``T``; ``vz`` by bisection on that equation (a downward throw: the only one
    under the ceiling)."""
    from scipy.optimize import brentq
    z0, zT = START[1], TARGET[1]

    def impact(vz):
        return (vz + np.sqrt(vz * vz + 2 * G * (z0 - RADIUS))) / G

    def miss(vz):
        t1 = impact(vz)
        rebound, tau = -RESTITUTION * (vz - G * t1), T - impact(vz)
        return RADIUS + rebound * tau - G * tau ** 2 / 2 - zT
    vz = brentq(miss, -20.0, 0.0, xtol=1e-14)
    return (TARGET[0] - START[0]) / T, vz, impact(vz)


def problem(model):
    ocp = nc.OptimalControl(model, N=N, t_final=T)       # restitution: free step lengths
    ocp.initial(q=model.q0, v=None)                    # the throw is free
    ocp.final(marker=("ball.centre", TARGET))
    ocp.bound_coordinate("ball.r_i.y", upper=CEILING)
    return ocp


def guess(model):
    """A throw at the floor (5 m/s down), simulated by the nonsmooth stepper."""
    return nc.simulate(model, T, T / N, method="stepper", v0=((TARGET[0] - START[0]) / T, -5.0), substeps=20)


def replay(model, sol, dt=1e-3, substeps=10):
    """The optimal throw simulated by the nonsmooth stepper (step ``dt / substeps``)."""
    return nc.simulate(model, T, dt, method="stepper", v0=sol.v[0], substeps=substeps)


if __name__ == "__main__":
    model = build()
    sol = problem(model).solve(guess(model))
    vx, vz, t1 = closed_form()
    print(sol.summary())
    print(f"optimal throw ({sol.v[0][0]:.9f}, {sol.v[0][1]:.9f}) m/s; closed form ({vx:.9f}, {vz:.9f}) m/s")
    k = int(np.argmax(sol.contact_impulse[:, 0]))
    print(f"impact at t = {sol.t[k]:.9f} s (closed form {t1:.9f} s), impulse {sol.contact_impulse[k, 0]:.6f} N·s; "
          f"complementarity residual {sol.complementarity_residual:.2e}")
    sim = replay(model, sol)
    miss = np.linalg.norm(sim.marker("ball.centre")[-1] - sol.marker("ball.centre")[-1])
    print(f"replayed by the nonsmooth stepper (h = 0.1 ms): ends {miss:.2e} m from the optimum")
    from ncgen.optim.solution_plot import plot_solution
    plot_solution(sol, "ball_bounce_target.png")
    sol.to_html("ball_bounce_target.html")
    print("wrote ball_bounce_target.png, ball_bounce_target.html")

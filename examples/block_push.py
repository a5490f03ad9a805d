"""A block pushed to a target with Coulomb friction, with the least effort (contact-implicit
optimal control).

A 2 kg block (a point member resting on the floor through a contact of radius 0, μ = 0.5)
is pushed along the floor by a horizontal force ``push`` (N), piecewise constant over
N = 20 equal steps, from rest at x = 0 to rest at x = 0.5 m in T seconds, minimising
∫ push² dt.  The model is built with ``contacts="nonsmooth"``: the transcription
(:mod:`ncgen.optim.contact_implicit`) carries the floor's normal force and the friction
cone with complementarity, so the optimiser decides where the block slides and where it
sticks.  The guess is the block at rest.

Closed forms (:func:`closed_form`).  While the block slides forward its acceleration is
``push/m − μ g``; over n moving steps of length h (the scheme is exact for piecewise-constant
accelerations) the least ``h Σ push²`` reaching x = D at rest is an equality-constrained
least-squares problem in the accelerations.  In continuous time it is
``u = m (6D/T'² (1 − 2t/T') + μ g)`` over a motion of length T', costing
``m² (12 D²/T'³ + (μ g)² T')``: least at ``T' = sqrt(6 D / (μ g))`` (0.78 s here), so over a
longer horizon the block rests part of the time, and over a shorter one it slides
throughout.

Run:  python examples/block_push.py      (writes block_push.png and .html)
"""
import casadi as ca
import numpy as np

import ncgen as nc

G, MASS, MU, DISTANCE, N = 9.81, 2.0, 0.5, 0.5, 20


def build():
    s = nc.System("block_push", gravity=(0, -G))
    block = s.add_point("block", mass=MASS, position=(0, 0))
    block.add_marker("centre", (0, 0))
    push = s.add_input("push")
    s.add_force(nc.PointForce(block, (0, 0), force=ca.vertcat(push, 0)))
    s.add_contact(nc.SpherePlane(block, radius=0.0, mu=MU, name="floor"))
    return s.build(contacts="nonsmooth")


def problem(model, T):
    ocp = nc.OptimalControl(model, N=N, t_final=T)
    ocp.final(marker=("block.centre", (DISTANCE, 0.0)), v=0)
    ocp.minimize_effort()
    return ocp


def closed_form(T, moving=N):
    """``(push, cost)``: the least-effort push (N, one per step) that slides the block over
    ``moving`` consecutive steps of length ``T/N`` (at rest, unpushed, the others) and its
    cost ``h Σ push²`` (N²·s)."""
    h = T / N
    k = np.arange(moving)
    A = np.vstack([np.ones(moving), h * h * (moving - k - 0.5)])      # Σ a = 0 (rest), Σ h²(n−k−½) a = D
    kkt = np.block([[np.eye(moving), A.T], [A, np.zeros((2, 2))]])
    a = np.linalg.solve(kkt, np.concatenate([-MU * G * np.ones(moving), [0.0, DISTANCE]]))[:moving]
    push = MASS * (a + MU * G)
    return push, h * float(np.sum(push ** 2))


def continuous_cost(T):
    """The least ``∫ push² dt`` (N²·s) over a horizon ``T`` in continuous time."""
    Tm = min(T, np.sqrt(6 * DISTANCE / (MU * G)))
    return MASS ** 2 * (12 * DISTANCE ** 2 / Tm ** 3 + (MU * G) ** 2 * Tm)


def replay(model, sol, substeps=10):
    """The optimal push replayed by the nonsmooth stepper (held over each step), with the
    stepper's checks on: the block rests under a push of round-off size (1e-14..1e-11 N) before
    and after the motion, and creeps within the contact solves' tolerance where that push
    reverses: energies the check measures against what round-off and that tolerance can make
    (:func:`ncgen.runtime.stepper_checks.roundoff_energy`)."""
    T = sol.t[-1] - sol.t[0]
    return nc.simulate(model, T, T / N, u=sol.u, hold="zoh", method="stepper", substeps=substeps)


if __name__ == "__main__":
    model = build()
    for T in (0.6, 1.0):
        sol = problem(model, T).solve("rest")
        cost = sol.stats.objective
        best = min(closed_form(T, n)[1] for n in range(2, N + 1))
        moving = int(np.sum(np.abs(sol.v[1:, 0]) > 1e-9))
        print(f"T = {T} s: effort {cost:.9f} N²·s (closed form over the best number of moving steps "
              f"{best:.9f}; continuous time {continuous_cost(T):.6f}); moving during {moving} of {N} nodes; "
              f"complementarity residual {sol.complementarity_residual:.2e}; {sol.stats.iterations} iterations, "
              f"{sol.stats.solve_time:.1f} s")
        sim = replay(model, sol)
        print(f"  replayed by the nonsmooth stepper: ends {abs(sim.q[-1, 0] - sol.q[-1, 0]):.2e} m from the optimum")
    from ncgen.optim.solution_plot import plot_solution
    plot_solution(sol, "block_push.png")
    sol.to_html("block_push.html")
    print("wrote block_push.png, block_push.html")

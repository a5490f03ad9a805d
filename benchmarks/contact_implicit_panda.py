"""What stands between the contact-implicit transcription and a Panda pushing a box: the NLP's
size and IPOPT's CPU time per iteration, measured (issue 39, deliverable 3).

Case: example-robot-data's Panda (``nc.System.from_urdf``, joint torques as inputs; 9 bodies
in natural coordinates, nq = 69, 61 constraints) with an end effector, a sphere of radius
2 cm at 0.15 m along link 7's z, beside a 1 kg box of 0.1 m on the floor (``BoxPlane``, 8
corners, μ = 0.4; the end effector against the box ``SphereBox``, μ = 0.2): nq = 81, 67
constraints, 9 contacts.  The arm starts bent down (joints 2, 4, 6 at 0.75, −1.6, 2.35 rad),
the box must move 0.1 m in 1 s at rest, least ∫ |τ|² dt, N intervals.  Two solves from rest
stopped after ``a`` and ``b`` IPOPT iterations (the first σ of the homotopy only): the CPU
time per iteration is the difference of their solver CPU times over ``b − a`` (what both
share: IPOPT's set-up, CasADi's derivative functions, the first evaluations).

Run:  python benchmarks/contact_implicit_panda.py [--N 20] [--iterations 3 10]
"""
from __future__ import annotations

import argparse
import time

import numpy as np

import ncgen as nc
from ncgen.errors import OptimizationError

RADIUS, EDGE, REACH = 0.02, 0.1, 0.15
JOINTS = {"panda_joint2": 0.75, "panda_joint4": -1.6, "panda_joint6": 2.35}


def _arm():
    s = nc.System.from_urdf(nc.robots.urdf_path("panda"))
    s.members["panda_link7"].add_marker("tip", (0, 0, REACH))
    return s


def problem(N: int):
    """``(ocp, model)``: the push with the arm bent down and the box beside its end effector."""
    arm = _arm().build()
    qj = np.zeros(arm.joint_space.nq)
    for name, angle in JOINTS.items():
        qj[arm.joint_names.index(name)] = angle
    qa, _ = arm.from_joint_space(qj, np.zeros(arm.joint_space.nv))
    r, _ = arm.markers(qa)
    tip = r[:, arm.marker_names.index("panda_link7.tip")]
    s = _arm()
    x = tip[0] + RADIUS + EDGE / 2
    box = s.add_body("box", mass=1.0, inertia=np.eye(3) * EDGE ** 2 / 6, position=(x, tip[1], EDGE / 2))
    box.add_marker("centre", (0, 0, 0))
    s.add_contact(nc.BoxPlane(box, size=(EDGE,) * 3, mu=0.4, name="floor"))
    s.add_contact(nc.SphereBox(s.members["panda_link7"], (0, 0, REACH), RADIUS, box=box, size=(EDGE,) * 3, mu=0.2,
                               name="push"))
    model = s.build(contacts="nonsmooth")
    q0 = np.array(model.q0, float)
    q0[:arm.nq] = qa                                  # the arm's members come first
    ocp = nc.OptimalControl(model, N=N, t_final=1.0)
    ocp.initial(q=q0, v=np.zeros(model.nq))
    ocp.final(marker=("box.centre", (x + 0.1, tip[1], EDGE / 2)), v=0)
    ocp.minimize_effort()
    return ocp, model, tip


def stopped_solve(N: int, iterations: int):
    ocp, model, tip = problem(N)
    try:
        result = ocp.solve("rest", max_iter=iterations, diagnose=False)
    except OptimizationError as exc:
        result = exc.result
    return model, tip, result


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--N", type=int, default=20)
    ap.add_argument("--iterations", type=int, nargs=2, default=(3, 10))
    args = ap.parse_args(argv)
    a, b = args.iterations
    runs = {}
    for n in (a, b):
        model, tip, result = stopped_solve(args.N, n)
        runs[n] = result
        st = result.stats
        print(f"N = {args.N}, stopped after {st.iterations} iterations: {st.n_variables} variables, "
              f"{st.n_constraints} constraints, NLP built in {st.build_time:.1f} s (wall), solver CPU "
              f"{result.homotopy[0]['cpu_time']:.1f} s", flush=True)
    print(f"model: {model}; end effector at {np.round(tip, 4).tolist()} m")
    per = (runs[b].homotopy[0]["cpu_time"] - runs[a].homotopy[0]["cpu_time"]) / (b - a)
    print(f"IPOPT CPU per iteration: {per:.2f} s; set-up and first evaluations: "
          f"{runs[a].homotopy[0]['cpu_time'] - a * per:.1f} s")


if __name__ == "__main__":
    t = time.process_time()
    main()
    print(f"process CPU {time.process_time() - t:.1f} s")

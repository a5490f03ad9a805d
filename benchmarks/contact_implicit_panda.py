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

The planar variant (``--locked``): the stock URDF through ``nc.robots.locked_urdf`` with the
fingers and joints 1, 3, 5, 7 locked at 0, so that joints 2, 4, 6 (parallel axes, the world y)
move the arm in the x–z plane: three bodies, nq = 21.  The hand points down; a sphere of
radius 2 cm at its tool point (``panda_hand`` + 0.1034 m along z) is 1 cm behind a 1 kg box of
0.1 m standing on the floor (``--feet corners``, the default: ``BoxPlane``, its 8 corners; ``tripod``: three
spheres of 5 mm under it, statically determinate), μ = 0.4 on the floor, 0.2 on the box.  The
task (``--task push``): the box 0.1 m further along x, the arm in the posture that touches it
with the hand down, everything at rest, after 1 s; the URDF's joint limits; least
``weight`` ∫ |τ|² dt; σ₀ = 1e-3 and the joints' reactions guessed (``reaction_guess``); the
guess is the rest posture with the box at its start.  ``--task reach``: the same arm and
final posture with the box out of reach (2 m away), the control problem without the push.
``--pusher point``: the arm replaced by a 0.5 kg point on a guide along x carrying the same
sphere (the same box, contacts and target; run it with ``--weight 1``).  Printed: the NLP's
size, IPOPT's iterations and CPU per iteration, the status of each stage and, over the last
stage, the largest inertia regularisation and the last primal and dual infeasibilities (what
shows the push stalling where the reach and the point's push converge).

Measured (issue 39, AMD EPYC, load 14–22): from rest every variant stalled in the first σ
stage; the largest violation at the stall was the joint-limit path constraint of joint 6
(2.59 rad): its range reaches 3.75 rad and the natural coordinates measured the angle by
``atan2`` in (−π, π], so the limit jumped by 2π when the iterates passed π (fixed in
``ncgen.optim.nlp.continuous_angle``).  The active rows' Jacobian after 60 iterations from
rest, before the fix (``benchmarks/contact_implicit_panda_rank.py``, rows within 1e-6 of
their bound) has full rank (2 001 rows, 3 120 variables): no LICQ failure there.  After the
fix, from rest: still stalled (600 iterations of σ = 1e-3, 1 100 s CPU, inertia
regularisation 5e11, dual infeasibility 1e9).  After the fix, ``--guess point``: the
first stage (σ = 1e-3) solved to IPOPT's acceptable level in 188 iterations (46 s CPU), the
second (σ = 1e-5) stopped at 1 000 iterations (161 s CPU; dynamics defects 1.7e-3,
complementarity residual 5.7e-3): the push is not delivered yet.

Measured next (AMD EPYC, load 11–17; N = 10; the arm's NLP 3 120 variables, 5 607
constraints):

* ``--guess point`` under OpenBLAS's own threads: the point pusher solves in 573 iterations;
  the arm's σ = 1e-3 stage ends ``Restoration_Failed`` after 406 iterations (347 s CPU;
  inertia regularisation up to 4.4e17).  The same under ``OPENBLAS_NUM_THREADS=1``: the point
  pusher takes 619 iterations, the arm's first stage ends "acceptable" in 188 (46.9 s CPU) —
  the solves move with the BLAS's round-off.  That "acceptable" point is feasible (violation
  2.8e-13) but not stationary: its dual infeasibility is 13.0 (IPOPT's
  ``acceptable_dual_inf_tol`` is 1e10), μ 1e-8, the regularisation 1e15 over its last
  iterations.  With ``--sigma-factor 0.1`` the σ = 1e-4 stage stops at 300 iterations (52.7 s
  CPU; complementarity residual 9.2e-3, primal / dual infeasibility 1.2e-3 / 1.1e2).
* ``--feet tripod --guess path`` (the box's straight path, the arm by inverse kinematics): after
  44 iterations primal 0.13, dual 1.9e10, the adaptive barrier raised to μ = 2.5e3 (stopped).
* ``--sequence point`` (the point pusher's contact sequence imposed, a smooth NLP, from its
  guess): IPOPT converges to a point of local infeasibility (219 iterations, 40.8 s CPU,
  violation 1.5e-4); with ``--final pose`` the same (314 iterations, 71.3 s CPU; the largest
  violations Φ at node 2 1.3e-4, the positions of interval 0 6.3e-5, Φ at node 3 4.6e-5): the
  arm cannot follow the point's contact sequence over the first intervals.
* The active rows at the σ = 1e-3 stage's "acceptable" point from the point guess
  (``contact_implicit_panda_rank.py --guess point``, within 1e-6 of their bound): 2 011 rows,
  3 120 variables, **rank 2 006**; the 5 dependent rows are all at the last node: the push's
  gap at node N (the final configuration puts the tool on the box's face, so ``g(q_N) ≥ 0``
  is a function of the imposed final q and Φ at node N), three bottom corners' gaps at node N
  (a flat face's corners, and the box's pose fixed) and one final-q row.  LICQ fails there by
  the problem's statement; ``--final pose`` (the box's pose only, the arm at rest anywhere)
  leaves the push's gap free — but from the point guess with ``--final pose --sigma-factor
  0.1`` the first stage stalls the same way: feasible after 99 iterations (violation 3.6e-12)
  with dual infeasibility 3.8e8 and inertia regularisation 4e12, still so at 111 (stopped).
  Its active rows at 100 iterations: 2 003, rank 1 999, the 4 dependent ones the bottom
  corners' gaps (as on the point pusher, which solves), the next singular values 1.0e-3 and
  9.2e-4: no rank defect of the arm's own.  The multipliers diverge on those rows
  (``contact_implicit_panda_rank.py --final pose``, median |λ| 45): 1e13 on the box's final
  pose (its 6 independent rows) and on the bottom corners' ``g(q_N) ≥ 0``, 1e12 on the box's
  Φ rows at node N: with the box's pose imposed at the last node, its corners' gaps there are
  functions of the imposed rows, so an active ``g ≥ 0`` combines with the equalities to 0 —
  MFCQ fails and the multiplier set is unbounded.  Not the only cause: without the bottom
  corners' ``g(q_N) ≥ 0`` (a local experiment, not kept) the same first stage stops at 300
  iterations further from feasibility (primal 0.27, dual 1.9e8, 158 s CPU); with
  ``--final soft`` (at rest, the box's x, y and yaw in the cost, its height and tilt free: no
  final row meets a gap) the first stage is at primal 1.2, dual 1.4e10 after 180 iterations
  (stopped); with ``--final pose --lbfgs`` at primal 1.1, dual 1.2e10 after 300 (34.9 s CPU).
  ``--final soft`` after 100 iterations (rank script): primal 1.9, dual 2.2e10, the active rows
  of full rank (1 993), the largest multipliers 2e10 on a complementarity product and 1e9 on
  the box's dynamics and Φ rows and on interior nodes' floor gaps: IPOPT heads for an
  infeasible point with the multipliers growing, not a rank defect.

Run:  python benchmarks/contact_implicit_panda.py [--N 20] [--iterations 3 10]
      python benchmarks/contact_implicit_panda.py --locked [--task push|reach] [--feet corners|tripod]
             [--pusher arm|point] [--guess rest|point|path|interpolate] [--N 10] [--weight 0.01]
             [--max-iter 300] [--sigma0 S] [--sigma-final S] [--sigma-factor K] [--sequence free|point]
             [--final q|pose] [--joint-limits 0|1] [--point-cache FILE.npz] [--lbfgs] [--verbose]
"""
from __future__ import annotations

import argparse
import time

import numpy as np

import ncgen as nc
from common import impose_contact_sequence
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


LOCKED = ["panda_finger_joint1", "panda_finger_joint2", "panda_joint1", "panda_joint3", "panda_joint5",
          "panda_joint7"]
TOOL, HEIGHT, START, GAP, DISTANCE, FOOT = 0.1034, 0.05, 0.5, 0.01, 0.1, 0.005


def _planar_arm():
    """The locked Panda, the marker ``panda_link6.tool`` at the tool point."""
    s = nc.System.from_urdf(nc.robots.locked_urdf("panda", LOCKED))
    member, R, p = s.frames["panda_hand"]
    s.members[member].add_marker("tool", p + R @ np.array([0.0, 0.0, TOOL]))
    return s


def planar_posture(model, x):
    """Joints 2, 4, 6 (rad) putting the tool at ``(x, 0, HEIGHT)``, the hand pointing down
    (Newton's method on the planar inverse kinematics)."""
    def residual(qj):
        R, p = model.frame_pose("panda_hand", model.from_joint_space(qj, np.zeros(3))[0])
        tool = p + R @ np.array([0.0, 0.0, TOOL])
        return np.array([tool[0] - x, tool[2] - HEIGHT, R[0, 2]])
    qj = np.array([0.75, -1.6, 2.35])
    for _ in range(50):
        r = residual(qj)
        if np.max(np.abs(r)) < 1e-12:
            return qj
        J = np.column_stack([(residual(qj + 1e-7 * e) - r) / 1e-7 for e in np.eye(3)])
        qj = qj - np.linalg.solve(J, r)
    raise RuntimeError(f"inverse kinematics of the tool at x = {x} m did not converge ({np.max(np.abs(r)):.1e})")


def locked_problem(N: int, task: str, feet: str, weight: float, pusher: str = "arm", contacts=None,
                   final: str = "q", limits: bool = True):
    """``(ocp, model)``: the planar Panda's push or reach (module docstring); ``pusher="point"``:
    the arm replaced by a 0.5 kg point on a guide along x carrying the same sphere at the same
    place, driven by a force (N) — the same box, contacts and target."""
    import casadi as ca
    s = _planar_arm() if pusher == "arm" else nc.System("point_push", gravity=(0, 0, -9.81))
    box_x = START + RADIUS + GAP + EDGE / 2 if task == "push" else 2.0
    box = s.add_body("box", mass=1.0, inertia=np.eye(3) * EDGE ** 2 / 6, position=(box_x, 0.0, EDGE / 2))
    if feet == "tripod":
        a = EDGE / 2
        for name, at in (("foot_left", (FOOT - a, a - FOOT, FOOT - a)), ("foot_right", (FOOT - a, FOOT - a, FOOT - a)),
                         ("foot_front", (a - FOOT, 0.0, FOOT - a))):
            s.add_contact(nc.SpherePlane(box, at, FOOT, mu=0.4, name=name))
    else:
        s.add_contact(nc.BoxPlane(box, size=(EDGE,) * 3, mu=0.4, name="floor"))
    if pusher == "point":
        start = (START, 0.0, HEIGHT)
        point = s.add_point("pusher", mass=0.5, position=start)
        s.add_joint(nc.PointOnLine(s.ground, point, at=start, axis=(1, 0, 0), name="guide"))
        s.add_force(nc.PointForce(point, (0, 0, 0), force=ca.vertcat(s.add_input("push"), 0, 0)))
        s.add_contact(nc.SphereBox(point, (0, 0, 0), RADIUS, box=box, size=(EDGE,) * 3, mu=0.2, name="push"))
        model = s.build(contacts="nonsmooth")
        ocp = nc.OptimalControl(model, N=N, t_final=1.0, contacts={"sigma0": 1e-3, "reaction_guess": True})
        ocp.final(pose={"box": (np.eye(3), (box_x + (DISTANCE if task == "push" else 0.0), 0.0, EDGE / 2))}, v=0)
        ocp.minimize_effort(weight)
        return ocp, model
    arm = s.members["panda_link6"]
    s.add_contact(nc.SphereBox(arm, arm.markers["tool"], RADIUS, box=box, size=(EDGE,) * 3, mu=0.2, name="push"))
    model = s.build(contacts="nonsmooth")
    alone = _planar_arm().build()
    q0, q1 = np.array(model.q0, float), np.array(model.q0, float)
    for q, x in ((q0, START), (q1, START + GAP + DISTANCE)):
        q[:alone.nq] = alone.from_joint_space(planar_posture(alone, x), np.zeros(3))[0]   # the arm comes first
    if task == "push":
        q1[model.coordinate_names.index("box.r_i.x")] += DISTANCE
    ocp = nc.OptimalControl(model, N=N, t_final=1.0,
                            contacts={"sigma0": 1e-3, "reaction_guess": True, **(contacts or {})})
    ocp.initial(q=q0, v=np.zeros(model.nq))
    if final == "q":
        ocp.final(q=q1, v=0)
    elif final == "pose":
        box_at = q1[model.coordinate_names.index("box.r_i.x")]
        ocp.final(pose={"box": (np.eye(3), (box_at, 0.0, EDGE / 2))}, v=0)
    else:                                  # "soft": the box's x, y and yaw in the cost, its height and tilt free
        names = model.coordinate_names
        ix, iy, iu = (names.index(n) for n in ("box.r_i.x", "box.r_i.y", "box.u.y"))
        box_at = q1[ix]
        ocp.final(v=0)
        ocp.minimize_terminal(lambda q, v, p: (q[ix] - box_at) ** 2 + q[iy] ** 2 + q[iu] ** 2, weight=1e4)
    if limits:
        ocp.joint_limits()
    ocp.minimize_effort(weight)
    return ocp, model


def point_solution(N: int, feet: str, max_iter: int, cache=None):
    """``(solution, model)``: the point pusher's push (``--pusher point``, ``weight`` 1);
    ``cache``: an ``.npz`` file holding its ``t``, ``q``, ``v`` and contact sequence, read if
    it exists, else written (the solve's result moves with the BLAS's round-off)."""
    from pathlib import Path
    from types import SimpleNamespace
    ocp, point_model = locked_problem(N, "push", feet, 1.0, "point")
    if cache and Path(cache).exists():
        data = np.load(cache)
        sizes = np.cumsum(data["sizes"])[:-1]
        sol = SimpleNamespace(t=data["t"], q=data["q"], v=data["v"], sequence=np.split(data["sequence"], sizes))
        print(f"  guess: the point pusher's solution read from {cache}", flush=True)
        return sol, point_model
    try:
        sol = ocp.solve("rest", max_iter=max_iter, diagnose=False)
    except OptimizationError as exc:
        sol = exc.result
    sol.sequence = contact_sequence(sol)
    x = sol.q[:, point_model.coordinate_names.index("pusher.r_i.x")]
    print(f"  guess: the point pusher's solve, {sol.stats.status}, {sol.stats.iterations} iterations, "
          f"pusher x from {x.min():.4f} to {x.max():.4f} m", flush=True)
    if cache:
        np.savez(cache, t=sol.t, q=sol.q, v=sol.v, sequence=np.concatenate(sol.sequence),
                 sizes=[len(z) for z in sol.sequence])
    return sol, point_model


def guess_from_point(model, sol, point_model):
    """A warm start for the arm's push: the point pusher's optimum with the arm's joints put
    by :func:`planar_posture` under the point at each node (rates by finite differences) and
    the box's coordinates copied."""
    from types import SimpleNamespace
    names = list(point_model.coordinate_names)
    x = sol.q[:, names.index("pusher.r_i.x")]
    alone = _planar_arm().build()
    qj = np.array([planar_posture(alone, xk) for xk in x])
    rates = np.gradient(qj, sol.t, axis=0)
    q, v = np.zeros((sol.t.size, model.nq)), np.zeros((sol.t.size, model.nq))
    for k in range(sol.t.size):
        q[k, :alone.nq], v[k, :alone.nq] = alone.from_joint_space(qj[k], rates[k])
    for i, name in enumerate(model.coordinate_names):
        if name.startswith("box."):
            q[:, i], v[:, i] = sol.q[:, names.index(name)], sol.v[:, names.index(name)]
    return SimpleNamespace(t=sol.t, q=q, v=v)


def contact_sequence(sol):
    """``sequence[i][j]``: in the solution ``sol``, pair i's element j has its first side
    (``a``) at 0 (else its second, ``c``)."""
    from ncgen.optim.contact_implicit import pair_values
    return [a <= c for a, c in pair_values(sol.nlp.ocp.transcription.pairs, sol.nlp.value)]


def fixed_sequence_solve(ocp, guess, sequence, max_iter: int, verbose: bool, ipopt=None):
    """The NLP of ``ocp`` built from ``guess`` with ``sequence`` imposed (the zero side of every
    complementarity pair an equality) and solved once: ``(nlp, value, cpu)``."""
    from ncgen.optim.contact_implicit import FIRST_SOLVE
    from ncgen.optim.nlp import NLP
    nlp = NLP(ocp)
    nlp.build(guess)
    impose_contact_sequence(nlp, sequence)
    cpu = time.process_time()
    value = nlp.solve(max_iter=max_iter, tol=1e-8, verbose=verbose, ipopt={**FIRST_SOLVE, **(ipopt or {})})
    return nlp, value, time.process_time() - cpu


def released_solve(ocp, guess, fixed, max_iter: int, verbose: bool):
    """The NLP of ``ocp`` (no sequence imposed) started from the fixed-sequence solve ``fixed``
    (``(nlp, value)``: its variables and the multipliers of the rows both NLPs share) and
    solved by the transcription's homotopy from ``contacts.sigma0``, every solve warm started
    (``WARM_START``), then polished: the result or the exception's result."""
    from ncgen.optim.contact_implicit import WARM_START
    from ncgen.optim.nlp import NLP, extract
    nlp0, value0 = fixed
    nlp = NLP(ocp)
    nlp.build(guess)
    ng = nlp.opti.ng
    nlp.opti.set_initial(nlp.opti.x, value0(nlp0.opti.x))
    nlp.opti.set_initial(nlp.opti.lam_g, np.array(value0(nlp0.opti.lam_g)).reshape(-1)[:ng])
    tr = ocp.transcription
    value = tr.solve(nlp, lambda **extra: nlp.solve(max_iter=max_iter, tol=1e-8, verbose=verbose,
                                                     ipopt=dict(WARM_START)), 1e-8)
    result = extract(nlp, value, 0.0)
    try:
        tr.finish(value, result)
    except OptimizationError as exc:
        result = exc.result
    return result


def smoothstep(x):
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3 - 2 * x)


def guess_from_path(model, N: int, approach: float = 0.2, samples: int = 201):
    """A kinematic warm start for the arm's push: the tool closes the gap ``GAP`` over the
    first ``approach`` of the horizon (the box at rest), then tool and box move together along
    x by ``DISTANCE`` (both on smoothsteps, so at rest at both ends of each phase); the arm's
    joints by :func:`planar_posture` under the tool at each sample, rates by finite differences."""
    from types import SimpleNamespace
    t = np.linspace(0.0, 1.0, samples)
    s1, s2 = smoothstep(t / approach), smoothstep((t - approach) / (1 - approach))
    box_dx, tool_x = DISTANCE * s2, START + GAP * s1 + DISTANCE * s2
    alone = _planar_arm().build()
    qj = np.array([planar_posture(alone, x) for x in tool_x])
    rates = np.gradient(qj, t, axis=0)
    q = np.tile(np.array(model.q0, float), (t.size, 1))
    v = np.zeros_like(q)
    for k in range(t.size):
        q[k, :alone.nq], v[k, :alone.nq] = alone.from_joint_space(qj[k], rates[k])
    i = model.coordinate_names.index("box.r_i.x")
    q[:, i] += box_dx
    v[:, i] = np.gradient(box_dx, t)
    return SimpleNamespace(t=t, q=q, v=v)


def locked(args):
    settings = {k: v for k, v in (("sigma0", args.sigma0), ("sigma_final", args.sigma_final),
                                  ("sigma_factor", args.sigma_factor)) if v is not None}
    ocp, model = locked_problem(args.N, args.task, args.feet, args.weight, args.pusher, settings, args.final, bool(args.joint_limits))
    guess = "rest"
    if args.guess == "point":
        point, point_model = point_solution(args.N, args.feet, args.max_iter, args.point_cache)
        guess = guess_from_point(model, point, point_model)
        if args.sequence == "point":
            from ncgen.optim.contact_implicit import complementarity_residual
            nlp, value, cpu = fixed_sequence_solve(ocp, guess, point.sequence, args.max_iter, args.verbose,
                                                   {"hessian_approximation": "limited-memory"} if args.lbfgs else None)
            st = nlp.opti.stats()
            print(f"  the point pusher's contact sequence imposed: {st['return_status']}, {st['iter_count']} "
                  f"iterations, {cpu:.1f} s CPU, cost {float(value(nlp.opti.f)):.6g}, complementarity residual "
                  f"{complementarity_residual(ocp.transcription.pairs, value):.1e}", flush=True)
            from ncgen.optim.diagnostics import violation_of
            worst = sorted(((violation_of(value, g), g.label) for g in nlp.groups), reverse=True)[:5]
            print("  largest violations: " + "; ".join(f"{label} {v:.1e}" for v, label in worst), flush=True)
            if args.sigma0 is None:
                return
            cpu = time.process_time()
            result = released_solve(ocp, guess, (nlp, value), args.max_iter, args.verbose)
            print(f"  released from σ = {args.sigma0:g}: {result.stats.status}, cost {result.stats.objective:.6g}, "
                  f"{time.process_time() - cpu:.1f} s CPU")
            for stage in result.homotopy:
                print(f"  σ = {stage['sigma']}: {stage['status']}, {stage['iterations']} iterations, "
                      f"{stage['cpu_time']:.1f} s CPU, complementarity residual {stage['residual']:.1e}")
            return
    elif args.guess in ("path", "interpolate"):
        guess = guess_from_path(model, args.N) if args.guess == "path" else "interpolate"
    cpu = time.process_time()
    try:
        result = ocp.solve(guess, max_iter=args.max_iter, diagnose=False, verbose=args.verbose,
                           ipopt={"hessian_approximation": "limited-memory"} if args.lbfgs else None)
    except OptimizationError as exc:
        result = exc.result
    cpu = time.process_time() - cpu
    st = result.stats
    print(f"planar Panda ({args.pusher} pusher), {args.task}, box on {args.feet}, N = {args.N}: {model}; {st.n_variables} variables, "
          f"{st.n_constraints} constraints; NLP built in {st.build_time:.1f} s (wall)")
    for stage in result.homotopy:
        print(f"  σ = {stage['sigma']}: {stage['status']}, {stage['iterations']} iterations, "
              f"{stage['cpu_time']:.1f} s CPU, complementarity residual {stage['residual']:.1e}")
    it = result.nlp.opti.stats().get("iterations", {})
    reg = [x for x in it.get("regularization_size", []) if x > 0]
    print(f"  last stage: largest inertia regularisation {max(reg, default=0.0):.1e}, last primal / dual "
          f"infeasibility {it['inf_pr'][-1]:.1e} / {it['inf_du'][-1]:.1e}")
    iterations = sum(stage["iterations"] for stage in result.homotopy)
    print(f"  {st.status}; {iterations} iterations in {cpu:.1f} s CPU ({cpu / max(iterations, 1):.2f} s each, "
          f"NLP build included)")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--N", type=int, default=None, help="intervals (default 20, --locked 10)")
    ap.add_argument("--iterations", type=int, nargs=2, default=(3, 10))
    ap.add_argument("--locked", action="store_true", help="the planar 3-joint arm (module docstring)")
    ap.add_argument("--task", choices=("push", "reach"), default="push")
    ap.add_argument("--feet", choices=("corners", "tripod"), default="corners")
    ap.add_argument("--pusher", choices=("arm", "point"), default="arm", help="--locked: the arm or a point on a guide")
    ap.add_argument("--guess", choices=("rest", "point", "path", "interpolate"), default="rest",
                    help="--locked arm push: start at rest, or from the point pusher's optimum (guess_from_point)")
    ap.add_argument("--weight", type=float, default=0.01, help="weight of ∫ |τ|² dt (--locked)")
    ap.add_argument("--max-iter", type=int, default=300, help="IPOPT iterations per stage (--locked)")
    ap.add_argument("--sigma0", type=float, help="--locked arm: contacts.sigma0 (default 1e-3)")
    ap.add_argument("--sigma-final", type=float, help="--locked arm: contacts.sigma_final")
    ap.add_argument("--sigma-factor", type=float, help="--locked arm: contacts.sigma_factor")
    ap.add_argument("--sequence", choices=("free", "point"), default="free",
                    help="--guess point: solve once with the point pusher's contact sequence imposed "
                         "(with --sigma0: then released by the homotopy from that point)")
    ap.add_argument("--lbfgs", action="store_true", help="IPOPT's L-BFGS Hessian (the homotopy's solves, or --sequence point's)")
    ap.add_argument("--final", choices=("q", "pose", "soft"), default="q",
                    help="--locked arm: the final configuration, or only the box's pose (both at rest); soft: "
                         "at rest, the box's x, y and yaw in the cost (weight 1e4)")
    ap.add_argument("--point-cache", help="--guess point: an .npz file for the point pusher's solution")
    ap.add_argument("--joint-limits", type=int, default=1, help="--locked arm: 0 drops the URDF's joint limits")
    ap.add_argument("--verbose", action="store_true", help="--locked: IPOPT's iteration log")
    args = ap.parse_args(argv)
    if args.locked:
        args.N = args.N or 10
        return locked(args)
    args.N = args.N or 20
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

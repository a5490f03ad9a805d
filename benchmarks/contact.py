"""A chain falling onto the ground and a pile of spheres in a box: the ncgen nonsmooth
contact stepper beside MuJoCo.

Model: the chain of benchmarks/common.py (N uniform 'rr' bars, L = 0.3 m, m = 0.2 kg, a
staircase in x-y) with its first end free instead of fixed, lifted so that node k is at
height 0.3 + 0.02 k m, released from rest.  Every node (bar end) carries a sphere of radius
r = 0.02 m in contact with the ground plane z = 0: Coulomb friction μ = 0.5, restitution
e = 0.  The MuJoCo twin: the same bodies (free joint on the first bar, ball joints after,
explicit inertias as in common.py) with massless sphere geoms at the nodes, friction 0.5,
elliptic cones, default soft-contact parameters (solref 0.02 s, solimp default), the same
fixed step h for both.

Pile (``--pile N``, default 20): N frictionless spheres (radius 0.03 m, 0.1 kg) dropped
in a loose column (four per layer, seeded offsets of a few mm) into a square box (floor and
four walls, inner half-width 0.08 m), restitution 0, 1 s.  In ncgen each sphere is a point
member (3 coordinates: without friction its rotation never changes, so the point is the
whole sphere), with a SpherePlane contact per wall and floor and a SphereSphere contact
per pair (5 N + N (N − 1) / 2 contacts; the stepper's broad phase evaluates only the
elements whose bounding volumes are near, ncgen/assembly/pair_kernels.py).  The MuJoCo twin: free bodies with sphere geoms (solid-sphere inertia), condim 1
(frictionless), the box as five planes, default solref/solimp, the same step.

What is compared, in one run:

ncgen runs the model's own compiled package (``kernels="flat"``, the fastest per step; ``--kernels
auto`` times the contact library's tables that ``nc.simulate`` takes by default: no compile, slower
per step).

* wall time per simulated second, best of ``--repeat`` runs (ncgen: the compiled stepper,
  one C call, ``info["stepping_time"]``; MuJoCo: ``mj_step`` with ``nstep``, no Python in
  the loop; both outside compile/build time); "with sampling" adds the output every 10 ms
  (ncgen: the whole ``nc.simulate`` with the Trajectory outputs; MuJoCo: a Python loop
  reading energies and depths);
* penetration: the largest depth of a sphere in the ground, a wall or another sphere, at
  the 10 ms samples (m);
* energy gain: max over the run of E(t) − E(0) (J; ≤ 0 means the contacts never created
  energy; the fall turns potential energy into kinetic and the contacts dissipate it);
* ncgen only: the bilateral constraint drift max |Φ| (MuJoCo's joints cannot drift).

Heap (``--heap N``, default 20): N spheres with friction (radius 0.03 m, 0.2 kg, μ = 0.5
on the ground and between spheres, e = 0) dropped in the pile's loose column onto the ground
plane (no walls), 1 s.  Twice: with non-rotating spheres (ncgen point members; MuJoCo bodies
with three slide joints, an exact twin) and with rotating spheres (ncgen 'ruvw' bodies with
the solid sphere's inertia; MuJoCo free joints).  MuJoCo: condim 3, elliptic cones, default
solref/solimp.  The heap's times are taken interleaved (ncgen, MuJoCo, ncgen, ...,
``--repeat`` rounds, CPU time), and the ratio is printed as the min and the median over the rounds.

Sparse scene (``--sparse N``, default 0: none): N frictional spheres of the heap resting on the
ground on a square grid 0.2 m apart (no two touch), with a SphereSphere contact per pair as in the
heap, 1 s: the time per step with N (N − 1) / 2 far pairs, against the heap's; ncgen only (the
broad phase takes bounds only for the close pairs, but the step's loops over every contact
still grow with all pairs: benchmarks/broad_phase.py).

Pyramid (``--pyramid``: this scene alone): 10 cubes (edge 0.1 m, 1 kg, μ = 0.5 everywhere, e = 0)
in rows of 4, 3, 2, 1 in the x-z plane, 1 cm apart within a row, each above the first row
centred over the gap between the two it stands on, placed at rest touching, 2 s.  ncgen: 'ruvw'
bodies, a BoxPlane per box of the first row and a BoxBox per box and each of its two supports
(224 point contacts; neighbours in a row never touch and have no contact).  The MuJoCo twin:
free bodies with box geoms (every pair collides), condim 3, elliptic cones, default
solref/solimp, Newton solver.  Each runs at its largest resting step: no box centre moves
sideways by more than 1 mm over the run, no speed above 1e-2 m/s at the end (ncgen also: no
contact solve at the sweep cap); ncgen's from 2.5, 5, 10, 20, 30, 40 ms, MuJoCo's from 1, 2, 4, …
128 ms then 5 bisections, with the Euler and the implicitfast integrator, the faster kept; and
MuJoCo's largest step that also keeps the pyramid's shape (no box centre moved by more than a
tenth of the edge: its boxes sink into each other and the floor), timed against ncgen too.
Printed: the search, ncgen's first run in a fresh process with an empty compile cache,
penetration (deepest contact at any step, m), drift (largest displacement of a box centre, m),
solves at the cap, and the interleaved min / median ratio of the stepping CPU times.

    python benchmarks/contact.py [--sizes 5 20] [--pile 20] [--heap 20] [--sparse 100] [--t-end 2] [--h 1e-3] [--repeat 3]
    python benchmarks/contact.py --smoke
    python benchmarks/contact.py --pyramid [--repeat 7] [--smoke]
"""
from __future__ import annotations

import argparse
import os
import time

import numpy as np

from common import GRAVITY, L, MASS, AXIAL_INERTIA, best_time, ends, machine

RADIUS, MU, HEIGHT, TILT = 0.02, 0.5, 0.3, 0.02
SAMPLE = 0.01
#: ncgen's stepper kernels (``--kernels``): "flat" (default; the model's own compiled package, the
#: fastest per step for long runs) or "auto"/"tables" (the contact library's tables: no compile).
KERNELS = ["flat"]
#: The pile: sphere radius (m) and mass (kg), box inner half-width (m), simulated time (s).
BALL_R, BALL_M, BOX, PILE_T = 0.03, 0.1, 0.08, 1.0
WALLS = (((0, 0, 0), (0, 0, 1)), ((-BOX, 0, 0), (1, 0, 0)), ((BOX, 0, 0), (-1, 0, 0)),
         ((0, -BOX, 0), (0, 1, 0)), ((0, BOX, 0), (0, -1, 0)))


def nodes(n: int) -> list[np.ndarray]:
    """The n + 1 node positions at release."""
    return [p + np.array([0.0, 0.0, HEIGHT + TILT * k]) for k, p in enumerate(ends(n))]


def chain_with_contacts(n: int):
    """The ncgen model (contacts="nonsmooth")."""
    import ncgen as nc

    s = nc.System(f"fallchain{n}", gravity=GRAVITY)
    pts = nodes(n)
    start = tuple(pts[0])
    for k in range(1, n + 1):
        bar = s.add_bar(f"bar{k}", coords="rr", mass=MASS, ends=[start, tuple(pts[k])])
        half = np.linalg.norm(pts[k] - pts[k - 1]) / 2
        if k == 1:
            s.add_contact(nc.SpherePlane(bar, (-half, 0, 0), RADIUS, mu=MU, name="node0"))
        s.add_contact(nc.SpherePlane(bar, (half, 0, 0), RADIUS, mu=MU, name=f"node{k}"))
        start = bar.end(1)
    return s.build(contacts="nonsmooth")


def ball_centres(n: int) -> list[np.ndarray]:
    """Release positions of the pile: four per layer, 2.4 radii apart, seeded offsets."""
    rng = np.random.default_rng(1)
    out = []
    for k in range(n):
        layer, slot = divmod(k, 4)
        x, y = (1.2 * BALL_R * (1 if slot & 1 else -1), 1.2 * BALL_R * (1 if slot & 2 else -1))
        out.append(np.array([x, y, BALL_R * (1.5 + 2.4 * layer)]) + rng.uniform(-0.005, 0.005, 3) * (1, 1, 0))
    return out


def pile(n: int):
    """The ncgen pile (contacts="nonsmooth"), see the module docstring."""
    import ncgen as nc

    s = nc.System(f"pile{n}", gravity=GRAVITY)
    balls = [s.add_point(f"ball{k}", mass=BALL_M, position=tuple(c)) for k, c in enumerate(ball_centres(n))]
    for k, b in enumerate(balls):
        for w, (point, normal) in enumerate(WALLS):
            s.add_contact(nc.SpherePlane(b, None, BALL_R, point=point, normal=normal, name=f"wall{w}_{k}"))
    for i in range(n):
        for j in range(i + 1, n):
            s.add_contact(nc.SphereSphere(balls[i], None, BALL_R, balls[j], None, BALL_R, name=f"pair{i}_{j}"))
    return s.build(contacts="nonsmooth")


#: The heap: sphere radius (m), mass (kg), friction coefficient, simulated time (s).
HEAP_R, HEAP_M, HEAP_MU, HEAP_T = 0.03, 0.2, 0.5, 1.0


def heap(n: int, rotating: bool):
    """The ncgen heap (contacts="nonsmooth"), see the module docstring."""
    import ncgen as nc

    s = nc.System(f"heap{n}{'r' if rotating else 'p'}", gravity=GRAVITY)
    inertia = 0.4 * HEAP_M * HEAP_R**2 * np.eye(3)
    balls = [s.add_body(f"ball{k}", mass=HEAP_M, inertia=inertia, position=tuple(c)) if rotating
             else s.add_point(f"ball{k}", mass=HEAP_M, position=tuple(c)) for k, c in enumerate(ball_centres(n))]
    for k, b in enumerate(balls):
        s.add_contact(nc.SpherePlane(b, None, HEAP_R, mu=HEAP_MU, name=f"floor_{k}"))
    for i in range(n):
        for j in range(i + 1, n):
            s.add_contact(nc.SphereSphere(balls[i], None, HEAP_R, balls[j], None, HEAP_R, mu=HEAP_MU,
                                          name=f"pair{i}_{j}"))
    return s.build(contacts="nonsmooth")


def sparse(n: int):
    """The sparse scene (module docstring): the heap's spheres on a grid 0.2 m apart, at rest."""
    import ncgen as nc

    s = nc.System(f"sparse{n}", gravity=GRAVITY)
    side = int(np.ceil(np.sqrt(n)))
    balls = [s.add_point(f"ball{k}", mass=HEAP_M, position=(0.2 * (k % side), 0.2 * (k // side), HEAP_R))
             for k in range(n)]
    for k, b in enumerate(balls):
        s.add_contact(nc.SpherePlane(b, None, HEAP_R, mu=HEAP_MU, name=f"floor_{k}"))
    for i in range(n):
        for j in range(i + 1, n):
            s.add_contact(nc.SphereSphere(balls[i], None, HEAP_R, balls[j], None, HEAP_R, mu=HEAP_MU,
                                          name=f"pair{i}_{j}"))
    return s.build(contacts="nonsmooth")


#: The pyramid: cube edge (m), mass (kg), friction coefficient, gap between neighbours in a row (m),
#: boxes per row from the ground up, simulated time (s).
CUBE, CUBE_M, PYR_MU, PYR_GAP, PYR_ROWS, PYR_T = 0.1, 1.0, 0.5, 0.01, (4, 3, 2, 1), 2.0


def cube_centres() -> list[tuple[int, np.ndarray]]:
    """The pyramid's boxes at rest, (row, centre) from the ground up and in x: each box above the
    first row centred over the gap between the two it stands on (y = 0, faces touching)."""
    pitch = CUBE + PYR_GAP
    return [(row, np.array([(k - (n - 1) / 2) * pitch, 0.0, CUBE * (row + 0.5)]))
            for row, n in enumerate(PYR_ROWS) for k in range(n)]


def pyramid():
    """The ncgen pyramid (contacts="nonsmooth"), see the module docstring: a BoxPlane per box of
    the first row and a BoxBox per box and each of the two it stands on."""
    import ncgen as nc

    s = nc.System("pyramid10", gravity=GRAVITY)
    size = np.full(3, CUBE)
    inertia = CUBE_M * CUBE**2 / 6 * np.eye(3)
    boxes = [s.add_body(f"box{k}", mass=CUBE_M, inertia=inertia, position=tuple(c))
             for k, (_, c) in enumerate(cube_centres())]
    start = np.cumsum((0,) + PYR_ROWS)
    for row, n in enumerate(PYR_ROWS):
        for k in range(n):
            i = start[row] + k
            if row == 0:
                s.add_contact(nc.BoxPlane(boxes[i], size=size, mu=PYR_MU, name=f"floor_{i}"))
                continue
            for j in (start[row - 1] + k, start[row - 1] + k + 1):
                s.add_contact(nc.BoxBox(boxes[i], size, boxes[j], size, mu=PYR_MU, name=f"on{i}_{j}"))
    return s.build(contacts="nonsmooth")


def pyramid_mjcf(h: float, integrator: str = "Euler", solver: str = "Newton") -> str:
    """The MuJoCo twin of :func:`pyramid`: free bodies with box geoms (every pair collides),
    condim 3, elliptic cones, default solref/solimp."""
    inertia = CUBE_M * CUBE**2 / 6
    boxes = "".join(f'<body name="box{k}" pos="{_nums(c)}"><freejoint/>'
                    f'<inertial pos="0 0 0" mass="{CUBE_M}" diaginertia="{inertia} {inertia} {inertia}"/>'
                    f'<geom type="box" size="{_nums([CUBE / 2] * 3)}"/></body>'
                    for k, (_, c) in enumerate(cube_centres()))
    return (f'<mujoco model="pyramid10"><compiler inertiafromgeom="false"/>'
            f'<option timestep="{h!r}" gravity="{_nums(GRAVITY)}" cone="elliptic" integrator="{integrator}" '
            f'solver="{solver}"><flag energy="enable"/></option>'
            f'<default><geom condim="3" friction="{PYR_MU} 0 0" contype="1" conaffinity="1"/></default>'
            f'<worldbody><geom type="plane" size="5 5 0.1"/>{boxes}</worldbody></mujoco>')


def heap_mjcf(n: int, h: float, rotating: bool) -> str:
    """The MuJoCo twin of :func:`heap`: free joints, or three slide joints (no rotation)."""
    inertia = 0.4 * HEAP_M * HEAP_R**2
    joints = ("<freejoint/>" if rotating else
              "".join(f'<joint type="slide" axis="{a}" damping="0" armature="0"/>' for a in ("1 0 0", "0 1 0", "0 0 1")))
    balls = "".join(f'<body name="ball{k}" pos="{_nums(c)}">{joints}'
                    f'<inertial pos="0 0 0" mass="{HEAP_M}" diaginertia="{inertia} {inertia} {inertia}"/>'
                    f'<geom type="sphere" size="{HEAP_R}"/></body>' for k, c in enumerate(ball_centres(n)))
    return (f'<mujoco model="heap{n}"><compiler inertiafromgeom="false"/>'
            f'<option timestep="{h!r}" gravity="{_nums(GRAVITY)}" cone="elliptic"><flag energy="enable"/></option>'
            f'<default><geom condim="3" friction="{HEAP_MU} 0 0" contype="1" conaffinity="1"/></default>'
            f'<worldbody><geom type="plane" size="5 5 0.1"/>{balls}</worldbody></mujoco>')


def pile_mjcf(n: int, h: float) -> str:
    """The MuJoCo twin of :func:`pile`."""
    inertia = 0.4 * BALL_M * BALL_R**2
    walls = "".join(f'<geom type="plane" size="1 1 0.1" pos="{_nums(p)}" zaxis="{_nums(nrm)}"/>'
                    for p, nrm in WALLS)
    balls = "".join(f'<body name="ball{k}" pos="{_nums(c)}"><freejoint/>'
                    f'<inertial pos="0 0 0" mass="{BALL_M}" diaginertia="{inertia} {inertia} {inertia}"/>'
                    f'<geom type="sphere" size="{BALL_R}"/></body>' for k, c in enumerate(ball_centres(n)))
    return (f'<mujoco model="pile{n}"><compiler inertiafromgeom="false"/>'
            f'<option timestep="{h!r}" gravity="{_nums(GRAVITY)}"><flag energy="enable"/></option>'
            f'<default><geom condim="1" contype="1" conaffinity="1"/></default>'
            f'<worldbody>{walls}{balls}</worldbody></mujoco>')


def chain_mjcf(n: int, h: float) -> str:
    """The MuJoCo twin (see the module docstring)."""
    pts = nodes(n)
    transverse = MASS * L**2 / 12
    body, close = "", ""
    for k in range(1, n + 1):
        d = pts[k] - pts[k - 1]
        # body frame at the bar's first node, axes parallel to the world at release
        pos = pts[0] if k == 1 else pts[k - 1] - pts[k - 2]
        joint = "<freejoint/>" if k == 1 else '<joint type="ball" damping="0" armature="0"/>'
        u = d / np.linalg.norm(d)
        J = transverse * (np.eye(3) - np.outer(u, u)) + AXIAL_INERTIA * np.outer(u, u)
        full = (J[0, 0], J[1, 1], J[2, 2], J[0, 1], J[0, 2], J[1, 2])
        body += (f'<body name="bar{k}" pos="{_nums(pos)}">{joint}'
                 f'<inertial pos="{_nums(d / 2)}" mass="{MASS}" fullinertia="{_nums(full)}"/>')
        if k == 1:
            body += f'<geom type="sphere" size="{RADIUS}" pos="0 0 0" mass="0"/>'
        body += f'<geom type="sphere" size="{RADIUS}" pos="{_nums(d)}" mass="0"/>'
        close += "</body>"
    return (f'<mujoco model="fallchain{n}"><compiler inertiafromgeom="false" angle="radian"/>'
            f'<option timestep="{h!r}" gravity="{_nums(GRAVITY)}" cone="elliptic">'
            f'<flag energy="enable"/></option>'
            f'<default><geom friction="{MU} 0 0" condim="3" contype="1" conaffinity="0"/></default>'
            f'<worldbody><geom type="plane" size="20 20 0.1" contype="0" conaffinity="1"/>'
            f'{body}{close}</worldbody></mujoco>')


def _nums(x) -> str:
    return " ".join(repr(float(v)) for v in x)


def run_ncgen(model, t_end: float, h: float, repeat: int, centres: list[str] | None = None):
    import warnings

    import ncgen as nc

    substeps = int(round(SAMPLE / h))
    nc.simulate(model, SAMPLE, SAMPLE, method="stepper", substeps=substeps, kernels=KERNELS[0])        # compile outside timings
    with warnings.catch_warnings(record=True) as caught:     # unconverged contact solves: reported once below
        warnings.simplefilter("always")
        runs = [nc.simulate(model, t_end, SAMPLE, method="stepper", substeps=substeps, kernels=KERNELS[0]) for _ in range(repeat)]
        wall, _ = best_time(lambda: nc.simulate(model, t_end, SAMPLE, method="stepper", substeps=substeps, kernels=KERNELS[0]), 1)
    for w in {str(w.message) for w in caught}:
        print(f"ncgen warning: {w}")
    traj = runs[-1]
    stepper = min(r.info["stepping_time"] for r in runs)             # the C call alone
    return {"wall": wall, "stepper": stepper, "penetration": max(0.0, -float(traj.gap.min())),
            "energy_gain": float(np.max(traj.energy - traj.energy[0])), "E0": float(traj.energy[0]),
            "E_end": float(traj.energy[-1]), "drift": float(traj.constraint_residual.max()),
            "rest_height": float(np.mean([traj.point(c, (0, 0, 0))[-1, 2] for c in centres]) if centres
                                 else traj.q[-1, 2::3].mean()),
            "contacts": traj.info["contacts"]}


def run_mujoco(xml: str, t_end: float, h: float, repeat: int):
    import mujoco

    model = mujoco.MjModel.from_xml_string(xml)
    per_sample = int(round(SAMPLE / h))
    samples = int(round(t_end / SAMPLE))
    node_geoms = [g for g in range(model.ngeom) if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_SPHERE]
    radius = model.geom_size[node_geoms, 0]

    def run():
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        E = [data.energy.sum()]
        depth = 0.0
        for _ in range(samples):
            mujoco.mj_step(model, data, nstep=per_sample)
            E.append(data.energy.sum())
            dist = data.contact.dist[:data.ncon]
            depth = max(depth, float(np.max(radius - data.geom_xpos[node_geoms, 2])),
                        float(-dist.min()) if data.ncon else 0.0)
        return np.array(E), depth, data

    wall, (E, depth, data) = best_time(run, repeat)
    def pure_run():
        data2 = mujoco.MjData(model)
        start = time.perf_counter()
        mujoco.mj_step(model, data2, nstep=samples * per_sample)
        return time.perf_counter() - start

    pure = min(pure_run() for _ in range(repeat))
    return {"wall": wall, "stepper": pure, "penetration": depth, "energy_gain": float(np.max(E - E[0])),
            "E0": float(E[0]), "E_end": float(E[-1]),
            "rest_height": float(np.mean(data.geom_xpos[node_geoms, 2]))}


#: Resting: no box centre moves sideways by more than this (m) over the run, and none moves
#: faster than PYR_VMAX (m/s) at the end; keeping its shape, also: no box centre moves by more
#: than PYR_SHAPE (m, a tenth of the edge) in any direction (MuJoCo's boxes sink).
PYR_SIDEWAYS, PYR_VMAX, PYR_SHAPE = 1e-3, 1e-2, 0.1 * CUBE


def pyramid_ncgen(model, h: float, t_end: float) -> dict:
    """One ncgen run of the pyramid at step h (output every max(h, SAMPLE)): stepping time (s),
    penetration (m, deepest gap at the samples and at the end of any step), drift (m, largest
    displacement of a box centre from its start at the samples), solves at the sweep cap."""
    import warnings

    import ncgen as nc
    from ncgen.errors import SimulationError

    substeps = max(1, int(round(SAMPLE / h)))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            tr = nc.simulate(model, t_end, h * substeps, method="stepper", substeps=substeps, kernels=KERNELS[0])
        except SimulationError as err:   # the run's checks refused it (e.g. energy created): not at rest
            return {"rests": False, "refused": str(err).split(": ", 1)[-1][:120]}
    start = [c for _, c in cube_centres()]
    x = np.stack([tr.point(f"box{k}", (0, 0, 0)) for k in range(len(start))], axis=1)
    moved = np.abs(x - np.array(start))
    v_end = np.abs(tr.v[-1]).max()
    return {"stepper": tr.info["stepping_time"], "cpu": tr.info["stepping_cpu_time"], "penetration": max(0.0, -float(tr.gap.min()),
                                                                      tr.info["contacts"]["penetration"]),
            "drift": float(moved.max()), "sideways": float(moved[..., :2].max()),
            "cap": tr.info["contacts"]["pgs_unconverged"], "energy_gain": float(np.max(tr.energy - tr.energy[0])),
            "phi": float(tr.constraint_residual.max()), "v_end": float(v_end), "contacts": len(tr.contact_names),
            "rests": bool(moved[..., :2].max() <= PYR_SIDEWAYS and v_end <= PYR_VMAX
                          and tr.info["contacts"]["pgs_unconverged"] == 0)}


def pyramid_mujoco(h: float, t_end: float, integrator: str) -> dict:
    """One MuJoCo run of the twin at step h, stepped one step at a time for the figures
    (penetration: deepest contact, m; drift: largest displacement of a box centre, m); the
    time is taken separately (:func:`mujoco_time`)."""
    import mujoco

    m = mujoco.MjModel.from_xml_string(pyramid_mjcf(h, integrator))
    d = mujoco.MjData(m)
    start = np.array([c for _, c in cube_centres()])
    drift = sideways = depth = 0.0
    mujoco.mj_forward(m, d)
    E0, gain = d.energy.sum(), 0.0
    for _ in range(int(round(t_end / h))):
        mujoco.mj_step(m, d)
        moved = np.abs(d.xpos[1:] - start)
        drift, sideways = max(drift, float(moved.max())), max(sideways, float(moved[:, :2].max()))
        depth = max(depth, float(-d.contact.dist[:d.ncon].min()) if d.ncon else 0.0)
        gain = max(gain, float(d.energy.sum() - E0))
    v_end = float(np.abs(d.qvel).max())
    ok = bool(np.all(np.isfinite(d.qpos)) and sideways <= PYR_SIDEWAYS and v_end <= PYR_VMAX)
    return {"penetration": depth, "drift": drift, "sideways": sideways, "v_end": v_end, "energy_gain": gain,
            "rests": ok, "shape": ok and drift <= PYR_SHAPE}


def largest_resting_step(rests, coarse: list[float], fine: int) -> tuple[float, list[str]]:
    """The largest step h of ``coarse`` (ascending) with ``rests(h)`` true (passes) before the first that
    fails, then ``fine`` bisections between it and that failing one; and a log of the tries."""
    log, good, bad = [], None, None
    for h in coarse:
        ok = rests(h)
        log.append(f"{h * 1e3:g} ms {'passes' if ok else 'fails'}")
        if not ok:
            bad = h
            break
        good = h
    if good is None:
        raise RuntimeError(f"no step of {coarse} keeps the pyramid resting: {log}")
    for _ in range(fine if bad is not None else 0):
        mid = 0.5 * (good + bad)
        ok = rests(mid)
        log.append(f"{mid * 1e3:.4g} ms {'passes' if ok else 'fails'}")
        good, bad = (mid, bad) if ok else (good, mid)
    return good, log


def mujoco_time(xml: str, t_end: float, clock=time.perf_counter) -> float:
    """Seconds of ``mj_step`` with ``nstep`` over t_end (no Python in the loop), by ``clock``."""
    import mujoco

    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    start = clock()
    mujoco.mj_step(m, d, nstep=int(round(t_end / m.opt.timestep)))
    return clock() - start


def first_run_cold() -> float:
    """Wall seconds of a fresh Python process that builds the pyramid and takes one step with
    an empty compile cache (NCGEN_CACHE_DIR in a temporary directory)."""
    import subprocess
    import sys
    import tempfile

    here = os.path.dirname(os.path.abspath(__file__))
    code = ("import sys; sys.path.insert(0, %r); import contact, ncgen as nc; "
            "nc.simulate(contact.pyramid(), contact.SAMPLE, contact.SAMPLE, method='stepper', substeps=1, kernels=%r)" % (here, KERNELS[0]))
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        subprocess.run([sys.executable, "-c", code], check=True, env={**os.environ, "NCGEN_CACHE_DIR": tmp},
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        return time.perf_counter() - start


def pyramid_bench(t_end: float, rounds: int, ncgen_steps: list[float], mj_coarse: list[float], fine: int) -> None:
    """The 10-box pyramid against its MuJoCo twin, each at its largest resting step (see the
    module docstring); prints the search, the figures and the interleaved RATIO line."""
    import ncgen as nc

    print(f"\n=== pyramid of 10 boxes ({'-'.join(map(str, PYR_ROWS))}, {CUBE:g} m cubes of {CUBE_M:g} kg, "
          f"mu = {PYR_MU}) resting on the ground, {t_end:g} s")
    cold = first_run_cold()
    print(f"ncgen first run, fresh process and empty cache (import, build, C generation, compile, one step): "
          f"{cold:.1f} s wall; load average {os.getloadavg()[0]:.2f}")
    model = pyramid()
    nc.simulate(model, SAMPLE, SAMPLE, method="stepper", substeps=1, kernels=KERNELS[0])        # compile outside the timings
    ours = {}
    h_nc, log = largest_resting_step(lambda h: ours.setdefault(h, pyramid_ncgen(model, h, t_end))["rests"],
                                     ncgen_steps, 0)
    print(f"ncgen step search (drift of a box sideways <= {PYR_SIDEWAYS:g} m, speeds at the end <= {PYR_VMAX:g} m/s, "
          f"no solve at the sweep cap): {', '.join(log)} -> h = {h_nc * 1e3:g} ms")
    for h, r in sorted(ours.items()):
        if "refused" in r:
            print(f"ncgen at h = {h * 1e3:g} ms refused by the stepper's checks: {r['refused']}")
    theirs, best = {}, None
    for integrator in ("Euler", "implicitfast"):
        h, log = largest_resting_step(
            lambda h: theirs.setdefault((integrator, h), pyramid_mujoco(h, t_end, integrator))["rests"], mj_coarse, fine)
        t = min(mujoco_time(pyramid_mjcf(h, integrator), t_end) for _ in range(3))
        print(f"MuJoCo step search, Newton solver, elliptic cones, {integrator} (same criterion): {', '.join(log)} "
              f"-> h = {h * 1e3:.4g} ms, {t / t_end * 1e3:.2f} ms per simulated s")
        if best is None or t < best[2]:
            best = (integrator, h, t)
    integrator, h_mj, _ = best
    h_shape, log = largest_resting_step(
        lambda h: theirs.setdefault((integrator, h), pyramid_mujoco(h, t_end, integrator))["shape"], mj_coarse, fine)
    print(f"MuJoCo step search, Newton {integrator}, keeping the shape (also no box centre moved by more than "
          f"{PYR_SHAPE:g} m): {', '.join(log)} -> h = {h_shape * 1e3:.4g} ms")
    xml = pyramid_mjcf(h_mj, integrator)
    a, b = ours[h_nc], theirs[(integrator, h_mj)]
    for name, r, h in ((f"ncgen stepper, h = {h_nc * 1e3:g} ms", a, h_nc),
                       (f"MuJoCo Newton {integrator}, h = {h_mj * 1e3:.4g} ms", b, h_mj),
                       (f"MuJoCo, shape kept, h = {h_shape * 1e3:.4g} ms", theirs[(integrator, h_shape)], h_shape)):
        print(f"{name:<36} penetration {r['penetration']:.2e} m, drift of a box centre {r['drift']:.2e} m "
              f"(sideways {r['sideways']:.2e} m), largest speed at the end {r['v_end']:.1e} m/s, "
              f"energy gain {r['energy_gain']:.2e} J")
    print(f"ncgen bilateral constraint drift max |phi| = {a['phi']:.2e} m^2; contact solves at the sweep cap: {a['cap']}; "
          f"point contacts {a['contacts']}")
    ratios, shaped = [], []
    xml_shape = pyramid_mjcf(h_shape, integrator)
    for _ in range(rounds):
        t_ours = pyramid_ncgen(model, h_nc, t_end)["cpu"]
        ratios.append(t_ours / mujoco_time(xml, t_end, time.process_time))
        shaped.append(t_ours / mujoco_time(xml_shape, t_end, time.process_time))
    print(f"ncgen stepper CPU per simulated s {t_ours / t_end * 1e3:.1f} ms ({t_ours / t_end * h_nc * 1e3:.2f} ms per step)")
    print(f"RATIO ncgen / MuJoCo CPU interleaved (pyramid of 10, each at its largest resting step, {rounds} rounds): "
          f"min {min(ratios):.2f}, median {float(np.median(ratios)):.2f}; load average {os.getloadavg()[0]:.2f}")
    print(f"RATIO ncgen / MuJoCo CPU interleaved (pyramid of 10, MuJoCo at its largest step keeping the shape, "
          f"{rounds} rounds): min {min(shaped):.2f}, median {float(np.median(shaped)):.2f}")
    ratio = a["penetration"] / b["penetration"] if b["penetration"] > 0 else float("nan")
    print(f"RATIO ncgen / MuJoCo penetration (pyramid of 10): {ratio:.3g}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", type=int, nargs="*", default=[5, 20], help="numbers of bars (default 5 20; none: no chain)")
    parser.add_argument("--pile", type=int, default=20, help="spheres in the pile (default 20; 0: no pile)")
    parser.add_argument("--heap", type=int, default=20, help="spheres in the heap with friction (default 20; 0: none)")
    parser.add_argument("--sparse", type=int, default=0, help="spheres of the sparse scene (default 0: none)")
    parser.add_argument("--t-end", type=float, default=2.0, help="simulated time, s (default 2)")
    parser.add_argument("--h", type=float, default=1e-3, help="fixed step of both, s (default 1e-3)")
    parser.add_argument("--repeat", type=int, default=3, help="runs per timing, the best kept (default 3)")
    parser.add_argument("--pyramid", action="store_true", help="the 10-box pyramid against its MuJoCo twin only "
                        "(see the module docstring)")
    parser.add_argument("--kernels", default="flat", choices=["flat", "auto", "tables"],
                        help="ncgen's stepper kernels (default flat: the model's package, compiled outside the timings)")
    parser.add_argument("--smoke", action="store_true", help="N = 3, 0.3 s, one run (CI)")
    args = parser.parse_args(argv)
    KERNELS[0] = args.kernels
    if args.smoke:
        args.sizes, args.pile, args.heap, args.t_end, args.repeat = [3], 4, 4, 0.3, 1
    print(machine())
    if args.pyramid:
        t_end = 0.3 if args.smoke else PYR_T
        pyramid_bench(t_end, args.repeat, [1e-2] if args.smoke else [2.5e-3, 5e-3, 1e-2, 2e-2, 3e-2, 4e-2],
                      [4e-3, 8e-3] if args.smoke else [1e-3 * 2**k for k in range(8)], 1 if args.smoke else 5)
        return 0
    for n in args.sizes:
        print(f"\n=== chain of N = {n} bars falling on the ground, {args.t_end:g} s, h = {args.h:g} s")
        compare(f"chain N = {n}", chain_with_contacts(n), chain_mjcf(n, args.h), args.t_end, args.h, args.repeat)
    if args.pile:
        t_end = min(args.t_end, PILE_T)
        print(f"\n=== pile of {args.pile} frictionless spheres in a box, {t_end:g} s, h = {args.h:g} s")
        compare(f"pile of {args.pile}", pile(args.pile), pile_mjcf(args.pile, args.h), t_end, args.h, args.repeat)
    for rotating in (False, True) if args.heap else ():
        t_end = min(args.t_end, HEAP_T)
        kind = "rotating" if rotating else "non-rotating"
        print(f"\n=== heap of {args.heap} {kind} spheres with friction (mu = {HEAP_MU}) on the ground, {t_end:g} s, "
              f"h = {args.h:g} s")
        compare(f"heap of {args.heap}, {kind}", heap(args.heap, rotating), heap_mjcf(args.heap, args.h, rotating),
                t_end, args.h, args.repeat, centres=[f"ball{k}" for k in range(args.heap)])
    if args.sparse:
        t_end = min(args.t_end, HEAP_T)
        model = sparse(args.sparse)
        ours = run_ncgen(model, t_end, args.h, args.repeat)
        print(f"\n=== sparse scene: {args.sparse} spheres apart on the ground ({args.sparse * (args.sparse - 1) // 2} "
              f"sphere pairs, none close), {t_end:g} s, h = {args.h:g} s")
        print(f"ncgen stepper wall per simulated s {ours['stepper'] / t_end * 1e3:8.2f} ms, per step "
              f"{ours['stepper'] / t_end * args.h * 1e6:.2f} us; load average {os.getloadavg()[0]:.2f}")
    return 0


def compare(label: str, model, xml: str, t_end: float, h: float, repeat: int, centres: list[str] | None = None) -> None:
    """Runs both and prints the figures and the RATIO lines; the pure stepping times are then
    taken again interleaved (ncgen, MuJoCo, ... ``repeat`` rounds) for the min / median ratio."""
    ours = run_ncgen(model, t_end, h, repeat, centres)
    theirs = run_mujoco(xml, t_end, h, repeat)
    ratios = interleaved_ratios(model, xml, t_end, h, repeat)
    for name, r in (("ncgen stepper", ours), ("MuJoCo (Euler, soft contacts)", theirs)):
        print(f"{name:<30} wall per simulated s {r['stepper'] / t_end * 1e3:8.2f} ms "
              f"(with sampling {r['wall'] / t_end * 1e3:.2f} ms), penetration {r['penetration']:.2e} m, "
              f"energy gain {r['energy_gain']:.2e} J, E(0) = {r['E0']:.4f} J, E(end) = {r['E_end']:.4f} J, "
              f"mean height at the end {r['rest_height']:.4f} m")
    print(f"ncgen bilateral constraint drift max |phi| = {ours['drift']:.2e} m^2; contact solves at the sweep limit: "
          f"{ours['contacts']['pgs_unconverged']} (largest last change {ours['contacts']['pgs_residual']:.2g}); "
          f"deepest penetration at the end of any step {ours['contacts']['penetration']:.2e} m")
    print(f"RATIO ncgen / MuJoCo wall time per simulated second ({label}, equal step): "
          f"{ours['stepper'] / theirs['stepper']:.2f}")
    print(f"RATIO ncgen / MuJoCo CPU interleaved ({label}, {len(ratios)} rounds): min {min(ratios):.2f}, "
          f"median {float(np.median(ratios)):.2f}; load average {os.getloadavg()[0]:.2f}")
    ratio = ours["penetration"] / theirs["penetration"] if theirs["penetration"] > 0 else float("nan")
    print(f"RATIO ncgen / MuJoCo penetration ({label}): {ratio:.3g}")


def interleaved_ratios(model, xml: str, t_end: float, h: float, rounds: int) -> list[float]:
    """ncgen's stepping CPU time over MuJoCo's, one pair of runs per round, alternating."""
    import warnings

    import mujoco

    import ncgen as nc

    mj = mujoco.MjModel.from_xml_string(xml)
    steps, substeps = int(round(t_end / h)), int(round(SAMPLE / h))
    out = []
    for _ in range(rounds):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ours = nc.simulate(model, t_end, SAMPLE, method="stepper", substeps=substeps, kernels=KERNELS[0]).info["stepping_cpu_time"]
        data = mujoco.MjData(mj)
        start = time.process_time()
        mujoco.mj_step(mj, data, nstep=steps)
        out.append(ours / (time.process_time() - start))
    return out


if __name__ == "__main__":
    raise SystemExit(main())

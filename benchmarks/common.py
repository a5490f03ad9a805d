"""Shared pieces of the benchmarks: the machine, timing, the chain in ncgen and in MuJoCo.

The chain (examples/chain.toml generalised to N bars): N uniform 'rr' bars of length
L = 0.3 m and mass m = 0.2 kg (other lengths and masses by argument; work_precision.py
uses 1 m and 1 kg, and also writes the chain with explicit ``nc.Spherical`` joints), released from rest as a horizontal staircase in the x-y plane
(bar k along +x for odd k, +y for even k), consecutive bars sharing an end (a spherical
joint), the first end fixed at the origin, gravity (0, 0, −9.81) m/s².  The tip is the free
end of the last bar.

Its MuJoCo twin: one body per bar with a ball joint at the bar's first end, body frames
parallel to the world at rest, an explicit ``<inertial>`` at the bar's centre with mass m and
diagonal inertia m L²/12 about both transverse axes.  A natural-coordinate bar has no
rotational inertia about its own axis (that rotation is not a coordinate), but MuJoCo
requires positive inertias for a body with a ball joint, so the axial inertia is
``AXIAL_INERTIA`` = 1e-6 kg m² (L²m/12 = 1.5e-3 kg m²).  The spin about a bar's axis is
torque-free (joint forces act on the axis, gravity at the centre on the axis) and starts at
zero, so it stays zero and its inertia does not change the motion; the work–precision
benchmark checks this by comparing against 1e-4 kg m².  Geoms are visual only (no contact,
no mass); no damping, no armature.
"""
from __future__ import annotations

import os
import platform
import re
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Callable

import numpy as np

L, MASS = 0.3, 0.2
AXIAL_INERTIA = 1e-6
GRAVITY = (0.0, 0.0, -9.81)


# ---------------------------------------------------------------- SIGINT
def terminal_sigint() -> None:
    """Give SIGINT Python's own handler (``KeyboardInterrupt``), as in a run started from a
    terminal.  A background job (``cmd &`` in a non-interactive shell, ``nohup``) starts with
    SIGINT ignored, and ncgen then takes another path into its C loops
    (:func:`ncgen.interrupts.call_interruptibly`: no stop watcher), so a benchmark run so
    would time what a user at a terminal does not get.  Called at the start of the scripts
    that time ``simulate``, control or the doors; child processes inherit the default."""
    signal.signal(signal.SIGINT, signal.default_int_handler)


# ---------------------------------------------------------------- the Panda of issue 37
#: What a child process run on another ncgen tree executes first to have :func:`panda`
#: (this folder put on its path; ncgen comes from the tree's ``PYTHONPATH``).
MODEL_IMPORT = f"import sys; sys.path.insert(0, {str(Path(__file__).resolve().parent)!r}); from common import start_model\n"
#: Titles of :func:`start_model`'s models.
START_MODELS = {"fall": "panda (the fall's URDF)", "stock": "panda (the URDF as shipped)",
                "talos": "talos (talos_reduced.urdf as shipped, free-flyer base)",
                "solo12": "solo12 (solo12.urdf as shipped, free-flyer base)",
                "balls": "balls (4 bodies on spherical joints)"}


def start_model(which: str = "fall"):
    """``(model, start)``: a tree built by the ncgen on the path, and ``start(k) -> (q, v)``, its
    joints at ``linspace(-0.8, 0.9)`` (rad, m; quaternions normalised by ``from_joint_space``)
    moved by ``1e-3 k`` each, at rest, in natural coordinates (issue 37's runs:
    ``simulate_fixed_cost.py``, ``simulate_start_callgrind.py``).  ``which``
    (:data:`START_MODELS`): example-robot-data's Panda, ``"fall"`` with its ``<mimic>`` and
    ``<dynamics>`` tags dropped (joint_simulation.py's fall, as for MuJoCo) or ``"stock"`` as
    shipped (the second finger placed where its mimic map puts it); Talos reduced or Solo12 as
    shipped on a free-flyer base; ``"balls"``: a chain of 4 bodies on spherical joints."""
    import importlib.metadata as md

    import ncgen as nc

    if which == "balls":
        s = nc.System("balls", gravity=(0.0, 0.0, -9.81))
        prev = s.ground
        for k in range(4):
            b = s.add_body(f"b{k}", mass=1.0, inertia=np.diag([0.02, 0.03, 0.04]), position=(0.3 * k + 0.15, 0, 0))
            s.add_joint(nc.Spherical(prev, b, at=(0.3 * k, 0, 0), name=f"ball{k}"))
            prev = b
        model = s.build()
    else:
        rel = {"talos": "talos_data/robots/talos_reduced.urdf", "solo12": "solo_description/robots/solo12.urdf"}.get(
            which, "panda_description/urdf/panda.urdf")
        path = next(f.locate() for f in md.files("example-robot-data") if str(f).endswith(rel))
        text = Path(path).read_text()
        if which == "fall":
            text = re.sub(r"<dynamics[^>]*/>", "", re.sub(r"<mimic[^>]*/>", "", text))
        model = nc.System.from_urdf(text, floating_base=which in ("talos", "solo12")).build()
    js = model.joint_space
    sl = js.slices()

    def start(k: int):
        qj = np.linspace(-0.8, 0.9, js.nq) + 1e-3 * k
        if which == "stock":
            qj[sl["panda_finger_joint2"]] = qj[sl["panda_finger_joint1"]]
        return model.from_joint_space(qj, np.zeros(js.nv))
    return model, start


# ---------------------------------------------------------------- machine
def callgrind_trees(root: Path, before: Path | None, calls: int, smoke: bool):
    """``(calls, {"this tree": root[, "before": before]})`` of a callgrind comparison (2 calls for
    ``--smoke``), or None, said on stdout, when valgrind's callgrind is not installed."""
    if shutil.which("valgrind") is None or shutil.which("callgrind_control") is None:
        print("valgrind's callgrind is not installed: nothing counted")
        return None
    return (2 if smoke else calls), {"this tree": root} | ({"before": before.resolve()} if before else {})


def callgrind_rows(code: str, args: list[str], tree) -> list[tuple[int, str]]:
    """``(inclusive instructions, function)`` rows of ``callgrind_annotate`` for ``python -c code
    *args`` run under valgrind's callgrind on the ncgen ``tree`` (``PYTHONPATH``), counting only
    while the child switches the instrumentation on (``callgrind_control -i on``); the program's
    total is the row named ``PROGRAM TOTALS``.  Rows of fewer than 100 instructions are left out."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "callgrind.out"
        subprocess.run(["valgrind", "--tool=callgrind", "--instr-atstart=no", f"--callgrind-out-file={out}",
                        sys.executable, "-c", code, *args], env=env, cwd=tree, check=True, capture_output=True)
        text = subprocess.run(["callgrind_annotate", "--inclusive=yes", "--threshold=100", str(out)],
                              capture_output=True, text=True, check=True).stdout
    return [(int(m.group(1).replace(",", "")), m.group(2)) for row in text.splitlines()
            if (m := re.match(r"\s*([\d,]+)\s+\([^)]*\)\s+(.*)", row))]


def machine() -> str:
    """CPU, cores, memory and the versions that matter, one line each."""
    lines = []
    cpu = _lscpu()
    lines.append(f"CPU: {cpu.get('Model name', platform.processor() or '?')}, "
                 f"{cpu.get('CPU(s)', os.cpu_count())} logical CPUs"
                 + (f", hypervisor {cpu['Hypervisor vendor']}" if "Hypervisor vendor" in cpu else ""))
    try:
        with open("/proc/meminfo") as fh:
            kb = int(re.search(r"MemTotal:\s+(\d+)", fh.read()).group(1))
        lines.append(f"memory: {kb / 2**20:.1f} GiB")
    except (OSError, AttributeError):
        pass
    import casadi
    import numpy
    versions = [f"Python {platform.python_version()}", f"numpy {numpy.__version__}", f"casadi {casadi.__version__}"]
    try:
        import mujoco
        versions.append(f"mujoco {mujoco.__version__}")
    except ImportError:
        versions.append("mujoco not installed")
    cc = shutil.which(os.environ.get("CC", "gcc")) or shutil.which("cc")
    if cc:
        out = subprocess.run([cc, "--version"], capture_output=True, text=True).stdout.splitlines()
        versions.append(out[0] if out else cc)
    lines.append("versions: " + ", ".join(versions))
    lines.append(f"load average at start: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return "\n".join(lines)


def _lscpu() -> dict[str, str]:
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True).stdout
    except OSError:
        return {}
    return {k.strip(): v.strip() for k, _, v in (line.partition(":") for line in out.splitlines()) if v}


def best_time(fn: Callable[[], object], repeat: int) -> tuple[float, object]:
    """``(seconds, result)``: the fastest of ``repeat`` calls (the machine is shared; the
    minimum is the least disturbed run) and the last result."""
    best, result = float("inf"), None
    for _ in range(repeat):
        start = time.perf_counter()
        result = fn()
        best = min(best, time.perf_counter() - start)
    return best, result


def _cpu() -> float:
    me, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def timed(fn: Callable[[], object]) -> tuple[float, float, object]:
    """``(wall s, CPU s of the process and its children, result)`` of ``fn()``."""
    w, c = time.perf_counter(), _cpu()
    out = fn()
    return time.perf_counter() - w, _cpu() - c, out


def batches(fns: dict, calls: int, repeat: int, clock=time.perf_counter) -> dict[str, list[float]]:
    """Seconds per call of each function, ``repeat`` interleaved batches of ``calls`` calls, by
    ``clock`` (wall clock; ``time.process_time``: the process's CPU time)."""
    out = {k: [] for k in fns}
    for _ in range(repeat):
        for name, fn in fns.items():
            start = clock()
            for _ in range(calls):
                fn()
            out[name].append((clock() - start) / calls)
    return out


def report_ratios(title: str, t: dict[str, list[float]], ref: str, target: str) -> None:
    """Print each path's min and median of ``t`` (seconds, shown in ms) under ``title``, then
    ``ref``'s ratio to every MuJoCo path (min and median), with the ``target`` stated."""
    print(f"\n=== {title}")
    for name, ts in t.items():
        print(f"  {name:34s} min {1e3 * min(ts):9.3f} ms   median {1e3 * np.median(ts):9.3f} ms")
    for name in t:
        if name.startswith("mujoco"):
            print(f"  RATIO {ref} / {name}: min {min(t[ref]) / min(t[name]):.2f}, median "
                  f"{np.median(t[ref]) / np.median(t[name]):.2f} ({target})")


def in_turn(round_index: int, paths: dict[str, Callable[[], object]]) -> dict[str, object]:
    """Each path's result in one round of a comparison, the paths run in their order in even
    rounds and in reverse in odd ones (so that none always goes first on a shared machine)."""
    names = list(paths) if round_index % 2 == 0 else list(reversed(paths))
    return {name: paths[name]() for name in names}


# ---------------------------------------------------------------- chain
def ends(n: int, length: float = L) -> list[np.ndarray]:
    """The n + 1 joint positions of the staircase at rest (first one the fixed origin)."""
    pts = [np.zeros(3)]
    for k in range(1, n + 1):
        step = np.array([length, 0.0, 0.0]) if k % 2 else np.array([0.0, length, 0.0])
        pts.append(np.round(pts[-1] + step, 12))
    return pts


def chain_system(n: int, length: float = L, mass: float = MASS, joints: str = "shared"):
    """The chain as an ncgen System.  ``joints="shared"`` (model ``chain<n>``): consecutive
    bars share their common end, the first end is a ground point; ``"explicit"`` (model
    ``chain<n>_joints``): every bar has its own two ends, held by ``nc.Spherical`` joints to
    the ground and to the bar before it, as a user coming from MuJoCo writes it."""
    import ncgen as nc

    pts = ends(n, length)
    if joints == "shared":
        s = nc.System(f"chain{n}", gravity=GRAVITY)
        start = s.ground.point((0.0, 0.0, 0.0))
        for k, end in enumerate(pts[1:], start=1):
            start = s.add_bar(f"bar{k}", coords="rr", mass=mass, ends=[start, tuple(end)]).end(1)
        return s
    s = nc.System(f"chain{n}_joints", gravity=GRAVITY)
    previous = s.ground
    for k in range(1, n + 1):
        bar = s.add_bar(f"bar{k}", coords="rr", mass=mass, ends=[tuple(pts[k - 1]), tuple(pts[k])])
        s.add_joint(nc.Spherical(previous, bar, at=tuple(pts[k - 1])))
        previous = bar
    return s


def ncgen_tip(q: np.ndarray) -> np.ndarray:
    """World position of the tip from natural coordinates (its last point, m)."""
    return np.asarray(q)[..., -3:]


def chain_mjcf(n: int, *, integrator: str = "RK4", timestep: float = 1e-3, axial: float = AXIAL_INERTIA,
               energy: bool = False, length: float = L, mass: float = MASS) -> str:
    """MJCF of the chain's MuJoCo twin (see the module docstring)."""
    L, MASS = length, mass
    transverse = MASS * L**2 / 12
    body, close = "", ""
    for k in range(1, n + 1):
        along_x = k % 2 == 1
        d = (L, 0.0, 0.0) if along_x else (0.0, L, 0.0)
        pos = "0 0 0" if k == 1 else (f"{L} 0 0" if not along_x else f"0 {L} 0")
        inertia = (axial, transverse, transverse) if along_x else (transverse, axial, transverse)
        body += (f'<body name="bar{k}" pos="{pos}"><joint type="ball" damping="0" armature="0"/>'
                 f'<inertial pos="{d[0] / 2} {d[1] / 2} 0" mass="{MASS}" '
                 f'diaginertia="{inertia[0]!r} {inertia[1]!r} {inertia[2]!r}"/>'
                 f'<geom type="capsule" fromto="0 0 0 {d[0]} {d[1]} 0" size="0.01" mass="0" '
                 f'contype="0" conaffinity="0"/>')
        close += "</body>"
    flags = '<flag contact="disable"' + (' energy="enable"' if energy else "") + "/>"
    return (f'<mujoco model="chain{n}"><compiler inertiafromgeom="false" angle="radian"/>'
            f'<option timestep="{timestep!r}" integrator="{integrator}" gravity="{GRAVITY[0]} {GRAVITY[1]} '
            f'{GRAVITY[2]}">{flags}</option><worldbody>{body}{close}</worldbody></mujoco>')


def mujoco_tip(n: int, data, length: float = L) -> np.ndarray:
    """World position of the tip in MuJoCo (last body's frame origin + its bar vector)."""
    d = np.array([length, 0.0, 0.0]) if n % 2 else np.array([0.0, length, 0.0])
    return data.xpos[n] + data.xmat[n].reshape(3, 3) @ d


def chain_quaternions(points) -> np.ndarray:
    """MuJoCo ``qpos`` (a unit quaternion w, x, y, z per ball joint, relative to the parent
    body) that puts the twin's bars along ``points[k] - points[k - 1]`` (``points``: the
    n + 1 joint positions from the fixed origin, the bars of equal length): bar k's world
    rotation is the smallest turning its rest direction (+x for odd k, +y for even k) onto
    its direction (the turn about the bar's own axis is free: it starts without spin)."""
    def product(a, b):
        return np.concatenate([[a[0] * b[0] - a[1:] @ b[1:]], a[0] * b[1:] + b[0] * a[1:] + np.cross(a[1:], b[1:])])

    pts = np.asarray(points, float)
    previous, out = np.array([1.0, 0.0, 0.0, 0.0]), []
    for k in range(1, len(pts)):
        rest = np.array([1.0, 0.0, 0.0]) if k % 2 else np.array([0.0, 1.0, 0.0])
        u = (pts[k] - pts[k - 1]) / np.linalg.norm(pts[k] - pts[k - 1])
        if rest @ u < -1 + 1e-12:                 # half a turn, about any axis normal to both
            world = np.concatenate([[0.0], np.cross(rest, [0.0, 0.0, 1.0])])
        else:
            world = np.concatenate([[1.0 + rest @ u], np.cross(rest, u)])
        world /= np.linalg.norm(world)
        out.append(product(previous * [1, -1, -1, -1], world))
        previous = world
    return np.concatenate(out)


def mujoco_run(n: int, integrator: str, timestep: float, t_end: float, axial: float = AXIAL_INERTIA,
               length: float = L, mass: float = MASS, spin: float = 0.0, qpos=None):
    """``(seconds, tip)``: a fresh MuJoCo chain stepped to ``t_end`` by ``mj_step`` in one
    call (``nstep``, no Python in the loop); the model is compiled outside the timing.
    ``spin``: initial rigid rotation about the vertical (rad/s; the first ball joint's
    rate, body frames being parallel to the world at rest); ``qpos``: the initial joint
    quaternions (default the staircase; :func:`chain_quaternions`)."""
    import mujoco

    mujoco.set_mju_user_warning(_diverged)
    model = mujoco.MjModel.from_xml_string(chain_mjcf(n, integrator=integrator, timestep=timestep, axial=axial,
                                                      length=length, mass=mass))
    data = mujoco.MjData(model)
    if qpos is not None:
        data.qpos[:] = qpos
    data.qvel[2] = spin
    steps = int(round(t_end / timestep))
    start = time.perf_counter()
    mujoco.mj_step(model, data, nstep=steps)
    elapsed = time.perf_counter() - start
    return elapsed, mujoco_tip(n, data, length)


def _diverged(message: str) -> None:
    """MuJoCo's warnings (an unstable run resets its state): the run's tip error shows it."""


def time_at(errors, times, target: float) -> float:
    """Wall time at which a work–precision curve reaches ``target`` error, by log-log
    interpolation between the two runs bracketing it (sorted by error); NaN if no run of
    the curve is at least that accurate."""
    pts = sorted((e, t) for e, t in zip(errors, times) if np.isfinite(e) and e > 0)
    if not pts or pts[0][0] > target:
        return float("nan")
    if pts[-1][0] <= target:
        return min(t for e, t in pts)
    for (e1, t1), (e2, t2) in zip(pts, pts[1:]):
        if e1 <= target <= e2:
            w = np.log(target / e1) / np.log(e2 / e1) if e2 > e1 else 0.0
            return float(np.exp(np.log(t1) + w * (np.log(t2) - np.log(t1))))
    return float("nan")


def impose_contact_sequence(nlp, sequence) -> None:
    """Fix a contact-implicit NLP's contact sequence: for every complementarity pair of its
    transcription, the side that ``sequence`` says is zero (``True``: the first, else the
    second) set to zero, and the relaxation at its final value (the fixed-sequence problem
    the homotopy's optimum is compared with)."""
    import casadi as ca

    tr = nlp.ocp.transcription
    if [ca.MX(p.a).numel() for p in tr.pairs] != [len(z) for z in sequence]:
        raise ValueError("the sequence's pairs are not the problem's")
    nlp.opti.set_value(tr.sigma, tr.settings["sigma_final"])
    sides = {}
    for pair, a_zero in zip(tr.pairs, sequence):
        for i, zero in enumerate(a_zero):
            side = pair.a[i] if zero else pair.c[i]
            if ca.symvar(side):
                sides.setdefault(str(side), side)
    nlp.opti.subject_to(ca.vertcat(*sides.values()) == 0)

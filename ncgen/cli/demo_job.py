"""``ncgen demo``: the heavy symmetric top on a fixed tip, end to end.

The built-in model is one ``ruvw`` body whose basic point ``r_i`` is the tip, shared with a
ground point (so the tip is fixed without a joint): 9 coordinates (the unit vectors u, v, w),
6 rigid-body constraints, 3 degrees of freedom.  :func:`run_demo` builds it, writes and
compiles its C package, simulates it with IDAS on the compiled DAE, checks the motion
against the top's exact first integrals (energy, the angular momentum about the vertical
through the tip ``L_z`` and the spin ``ω₃ = ω·w``) and the exact turning points of its
nutation, and plots it.

Conventions: SI units; the symmetry axis is the body's w; tilt θ is the angle between w and
the vertical; inertia ``I1`` (transverse) and ``I3`` (axial) are about the centre of mass,
``I1' = I1 + m l²`` about the tip.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

NAME = "heavy_top"


@dataclass(frozen=True)
class Top:
    """A symmetric top: mass (kg), tip-to-centre-of-mass distance ``l`` (m), inertia about the
    centre of mass ``I1`` (transverse) and ``I3`` (axial) in kg m², initial tilt (rad), spin
    ``ω₃`` (rad/s) and gravity ``g`` (m/s²)."""

    mass: float = 0.5
    l: float = 0.04
    I1: float = 4e-4
    I3: float = 6e-4
    tilt: float = math.radians(30.0)
    spin: float = 80.0
    g: float = 9.81

    @property
    def I1_tip(self) -> float:
        """Transverse moment of inertia about the tip, ``I1 + m l²``."""
        return self.I1 + self.mass * self.l ** 2

    def steady_precession(self) -> float:
        """The slow steady-precession rate Ω (rad/s) at this tilt and spin: the smaller root of
        ``m g l = Ω (I3 ω₃ − I1' Ω cos θ)``."""
        a, b, c = self.I1_tip * math.cos(self.tilt), self.I3 * self.spin, self.mass * self.g * self.l
        disc = b * b - 4 * a * c
        if disc < 0:
            raise ValueError(f"no steady precession at spin {self.spin} rad/s: the top is too slow")
        return 2 * c / (b + math.sqrt(disc))

    def fast_top_precession(self) -> float:
        """The fast-top estimate of the (mean) precession rate, ``m g l / (I3 ω₃)`` (rad/s)."""
        return self.mass * self.g * self.l / (self.I3 * self.spin)

    def nutation_frequency(self) -> float:
        """The fast-top nutation frequency ``I3 ω₃ / I1'`` (rad/s)."""
        return self.I3 * self.spin / self.I1_tip

    def nutation_limits(self) -> tuple[float, float]:
        """Exact tilt limits (rad) of the top released at ``tilt`` without precession.

        With ``u = cos θ``, ``a = I3 ω₃ / I1'``, ``α = 2 m g l / I1'`` and ``L_z = I3 ω₃ u₀``,
        energy conservation gives ``u̇² = (u₀ − u) (α (1 − u²) − a² (u₀ − u))``; θ oscillates
        between θ₀ and the root ``u₁ < u₀`` of ``α u² − a² u + a² u₀ − α = 0``."""
        u0 = math.cos(self.tilt)
        a2 = (self.I3 * self.spin / self.I1_tip) ** 2
        alpha = 2 * self.mass * self.g * self.l / self.I1_tip
        c = a2 * u0 - alpha
        u1 = 2 * c / (a2 + math.sqrt(a2 * a2 - 4 * alpha * c))
        return self.tilt, math.acos(u1)


def heavy_top(top: Top = Top(), precession: float = 0.0):
    """The top as a :class:`~ncgen.model.system.System` named ``heavy_top``: tilted towards +x,
    spinning at ``top.spin`` about its axis and precessing at ``precession`` rad/s about the
    vertical (``top.steady_precession()`` for steady precession, 0 to release it and watch it
    nutate).  A marker ``crown`` sits on the axis, ``2 l`` from the tip."""
    from ncgen.model.system import System

    th = top.tilt
    axis = np.array([math.sin(th), 0.0, math.cos(th)])
    R = np.array([[math.cos(th), 0.0, math.sin(th)], [0.0, 1.0, 0.0], [-math.sin(th), 0.0, math.cos(th)]])
    omega = precession * np.array([0.0, 0.0, 1.0]) + (top.spin - precession * math.cos(th)) * axis
    com = top.l * axis
    s = System(NAME, gravity=(0.0, 0.0, -top.g))
    body = s.add_body("top", coords="ruvw", mass=top.mass, inertia=np.diag([top.I1, top.I1, top.I3]),
                      position=com, rotation=R, angular_velocity=omega, velocity=np.cross(omega, com),
                      basis=[(0.0, 0.0, -top.l), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)],
                      share={"r_i": s.ground.point((0.0, 0.0, 0.0))})
    body.add_marker("crown", (0.0, 0.0, top.l))
    return s


def frames(model, q: np.ndarray, v: np.ndarray, member: str = "top"):
    """The body axes ``X = [u v w]`` ``(n_t, 3, 3)`` and angular velocity ω (world, rad/s)
    ``(n_t, 3)`` of a ``ruvw`` member with orthonormal base vectors: ``ω = ½ Σ x_k × ẋ_k``."""
    names = model.coordinate_names
    idx = [[names.index(f"{member}.{a}.{c}") for c in "xyz"] for a in "uvw"]
    X = np.stack([q[:, i] for i in idx], axis=2)
    Xd = np.stack([v[:, i] for i in idx], axis=2)
    omega = 0.5 * sum(np.cross(X[:, :, k], Xd[:, :, k]) for k in range(3))
    return X, omega


def invariants(top: Top, model, traj) -> dict[str, np.ndarray]:
    """Tilt θ (rad), precession angle φ (rad, unwrapped azimuth of the axis), spin ω₃ (rad/s)
    and ``L_z`` (kg m²/s, angular momentum about the vertical through the tip) per step."""
    X, omega = frames(model, traj.q, traj.v)
    w = X[:, :, 2]
    I_body = np.diag([top.I1_tip, top.I1_tip, top.I3])
    L = np.einsum("nij,jk,nlk,nl->ni", X, I_body, X, omega)
    return {"tilt": np.arccos(np.clip(w[:, 2], -1, 1)), "phi": np.unwrap(np.arctan2(w[:, 1], w[:, 0])),
            "spin": np.einsum("ni,ni->n", omega, w), "L_z": L[:, 2]}


@dataclass
class DemoResult:
    """What :func:`run_demo` did: timings (s) by stage, whether the library came from the
    compile cache (``None``: not compiled), files written and the checks."""

    model: object
    trajectory: object
    timings: dict[str, float] = field(default_factory=dict)
    cached: bool | None = None
    package: Path | None = None
    files: list[Path] = field(default_factory=list)
    checks: dict[str, float] = field(default_factory=dict)

    def summary(self) -> str:
        m, tr, c, t = self.model, self.trajectory, self.checks, self.timings
        info = tr.info
        return "\n".join([
            "ncgen demo: heavy symmetric top on a fixed tip (built-in model)",
            f"  model    {m.dim}D, nq = {m.nq} natural coordinates, nc = {m.nc} constraints, "
            f"dof = {m.dof}: one 'ruvw' body whose tip is a shared ground point",
            f"  build    {t['build']:.2f} s   (SymPy derivation -> CasADi functions, consistent initial state)",
            f"  generate {t['generate']:.2f} s   C package {self.package} "
            f"({len(list(self.package.iterdir()))} files)",
            f"  compile  {t['compile']:.2f} s   ({_cache_text(self.cached)})",
            f"  simulate {t['simulate']:.2f} s   {tr.t[-1]:g} s of motion, IDAS on the {info['backend']} DAE, "
            f"{info['stats'].get('nsteps', 0)} steps",
            f"  energy   E = {tr.energy[0]:.6f} J, max |E - E0| = {c['energy_drift']:.2e} J "
            f"({c['energy_drift_rel']:.1e} relative)",
            f"  integrals  max |L_z - L_z0| / |L_z0| = {c['L_z_drift_rel']:.1e},  "
            f"max |w3 - w3_0| / w3_0 = {c['spin_drift_rel']:.1e}",
            f"  constraints  max |phi| = {c['constraint_residual']:.1e} m^2",
            f"  nutation  tilt {math.degrees(c['tilt_min']):.3f} .. {math.degrees(c['tilt_max']):.3f} deg; "
            f"exact turning points {math.degrees(c['tilt_exact'][0]):.3f} .. "
            f"{math.degrees(c['tilt_exact'][1]):.3f} deg",
            f"  precession  mean rate {c['precession']:.3f} rad/s",
            "  wrote    " + ", ".join(str(f) for f in self.files),
        ])


def _cache_text(cached: bool | None) -> str:
    return {True: "cache hit", False: "cache miss: built", None: "skipped: vm backend"}[cached]


def run_demo(out_dir, *, animate: bool = False, t_end: float = 1.4, dt: float = 0.002,
             top: Top = Top(), backend: str = "auto", cflags=None) -> DemoResult:
    """Build, generate, compile, simulate, check and plot the top released without
    precession (it nutates: the crown traces cusps; 1.4 s is about one turn of precession);
    files go to ``out_dir``.  ``backend``: ``"compiled"``, ``"vm"`` or ``"auto"`` (compiled,
    or the VM with a one-line warning when there is no C compiler: the demo shows the whole
    pipeline, compiling included)."""
    from ncgen.codegen.compile_cache import compile_package
    from ncgen.codegen.load import warn_no_compiler
    from ncgen.errors import CompilerNotFound
    from ncgen.codegen.model_package import generate
    from ncgen.runtime import simulate

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    timings = {}
    start = time.perf_counter()
    model = heavy_top(top).build()
    timings["build"] = time.perf_counter() - start

    start = time.perf_counter()
    pkg = generate(model, out / NAME)
    timings["generate"] = time.perf_counter() - start

    cached = None
    start = time.perf_counter()
    if backend != "vm":
        try:
            cached = compile_package(pkg, cflags=cflags).cached
            backend = "compiled"
        except CompilerNotFound as e:
            if backend == "compiled":
                raise
            warn_no_compiler(e)
            backend = "vm"
    timings["compile"] = time.perf_counter() - start

    start = time.perf_counter()
    traj = simulate(model, t_end=t_end, dt=dt, backend=backend, rtol=1e-10, atol=1e-12)
    timings["simulate"] = time.perf_counter() - start

    result = DemoResult(model=model, trajectory=traj, timings=timings, cached=cached, package=pkg.path)
    result.checks = _checks(top, model, traj)
    result.files.append(traj.save(out / f"{NAME}.npz"))
    result.files.append(plot(top, model, traj, out / f"{NAME}.png"))
    if animate:
        from ncgen.viz import animate as make_animation
        result.files.append(Path(make_animation(traj, out / f"{NAME}.gif")))
    return result


def _checks(top: Top, model, traj) -> dict[str, float]:
    inv = invariants(top, model, traj)
    L0, s0 = inv["L_z"][0], inv["spin"][0]
    drift = traj.energy_drift
    return {"energy_drift": drift, "energy_drift_rel": drift / traj.energy_scale,
            "L_z_drift_rel": float(np.max(np.abs(inv["L_z"] - L0)) / abs(L0)),
            "spin_drift_rel": float(np.max(np.abs(inv["spin"] - s0)) / abs(s0)),
            "constraint_residual": float(np.max(traj.constraint_residual)),
            "precession": float((inv["phi"][-1] - inv["phi"][0]) / (traj.t[-1] - traj.t[0])),
            "tilt_min": float(inv["tilt"].min()), "tilt_max": float(inv["tilt"].max()),
            "tilt_exact": top.nutation_limits()}


def plot(top: Top, model, traj, path) -> Path:
    """Four panels: the crown seen from above, the tilt, the drift of the first integrals and
    the constraint residual; written to ``path`` atomically."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ncgen.files import atomic_path

    inv = invariants(top, model, traj)
    crown = traj.marker("top.crown")
    t = traj.t
    fig, ax = plt.subplots(2, 2, figsize=(10, 8), layout="constrained")
    ax[0, 0].plot(crown[:, 0], crown[:, 1], lw=0.8)
    ax[0, 0].set(aspect="equal", xlabel="x (m)", ylabel="y (m)", title="crown of the top, seen from above")
    ax[0, 1].plot(t, np.degrees(inv["tilt"]), lw=0.8)
    ax[0, 1].set(xlabel="t (s)", ylabel="tilt θ (deg)", title="nutation")
    for key, label in (("energy", "energy E"), ("L_z", "momentum L_z"), ("spin", "spin ω₃")):
        series = traj.energy if key == "energy" else inv[key]
        scale = traj.energy_scale if key == "energy" else abs(series[0])
        ax[1, 0].semilogy(t[1:], np.abs(series[1:] - series[0]) / scale, lw=0.8, label=label)
    ax[1, 0].set(xlabel="t (s)", ylabel="relative drift", title="first integrals (exactly conserved)")
    ax[1, 0].legend()
    ax[1, 1].semilogy(t[1:], traj.constraint_residual[1:], lw=0.8)
    ax[1, 1].set(xlabel="t (s)", ylabel="max |Φ| (m²)", title="constraint residual")
    fig.suptitle(f"ncgen demo: heavy top, spin {top.spin:g} rad/s, tilt {math.degrees(top.tilt):g}°, "
                 f"nq = {model.nq}, {traj.info['backend']} backend")
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=90)
    finally:
        plt.close(fig)
    return Path(path)

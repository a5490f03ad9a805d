"""``plot(traj, path)``: a PNG (PDF, SVG) summary of a simulation: energy (its drift, or the
balance of a dissipative run: work of contacts, dampers, inputs and the residual), constraint
drift and the motion of chosen points (or, without any, the joint positions and the path of
the last member's centre of mass); contact runs add contact forces and gaps.

Small numbers are shown as such: a panel whose values are all tiny or huge is drawn in a
stated unit (``E − E(t0) (1e-07 J)``), never with matplotlib's offset text, and paths are
drawn with equal scales on every axis, so that a 1e-7 m wobble of a 0.1 m motion is flat."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ncgen.errors import NcgenError
from ncgen.files import atomic_path
from ncgen.viz.draw import figure


#: File types ``plot`` writes (by suffix).
FORMATS = (".png", ".pdf", ".svg")


def plot(traj, path, points=None, *, dpi: int = 100) -> Path:
    """Write a PNG (or PDF, SVG) with four panels: ``E − E(t0)`` (J), the constraint drift ``|Φ|∞`` and
    ``|A v + Φ_t|∞`` (log scale), the coordinates of ``points`` over time and their paths
    (x–y plane in 2D, a 3D view in 3D).

    ``points``: marker names (``"b1.tip"``) and/or ``(member, local_xyz)`` pairs; default:
    every marker of the model.  Returns the path written."""
    path = Path(path)
    if path.suffix.lower() not in FORMATS:
        raise NcgenError(f"plot: {path}: expected a file name ending in {', '.join(FORMATS)}")
    fig = summary_figure(traj, points)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi, format=path.suffix.lower()[1:])
    return path


def summary_figure(traj, points=None):
    """The figure :func:`plot` writes: the energy, constraint drift, points (or joints) and
    paths panels, and the contact panels of a run with contacts."""
    curves = _point_curves(traj, points)
    rows = 3 if traj.contact_names else 2
    joint_panel = not curves and bool(traj.joint_position_names)
    if not curves and traj.model is not None and traj.model.member_names:
        last = traj.model.member_names[-1]
        curves = [(f"{last} (centre of mass)", traj.poses()[1][:, -1])]
    fig = figure(11, 4 * rows)
    _energy_panel(fig.add_subplot(rows, 2, 1), traj)
    _drift_panel(fig.add_subplot(rows, 2, 2), traj)
    if joint_panel:
        ax = fig.add_subplot(rows, 2, 3)
        _joint_panel(ax, traj)
        ax.ticklabel_format(axis="y", useOffset=False)
        ax.grid(True, alpha=0.3)
    else:
        _points_panel(fig.add_subplot(rows, 2, 3), traj, curves)
    _paths_panel(fig.add_subplot(rows, 2, 4, projection="3d" if traj.dim == 3 else None), traj, curves, joint_panel)
    if traj.contact_names:
        _contact_panels(fig, traj, rows)
    fig.suptitle(f"{traj.model_name}: t = {traj.t[0]:g} ... {traj.t[-1]:g} s"
                 + ("" if traj.complete else "  (INCOMPLETE: the integration failed)"))
    fig.tight_layout()
    return fig


def _energy_panel(ax, traj) -> None:
    """``E − E(t0)`` in a stated unit; for a dissipative run, the work of each class and the
    balance's residual ``E − E(t0) − W``."""
    t, scale = traj.t, traj.energy_scale
    drift = traj.energy - traj.energy[0]
    factor, unit = unit_scale(drift, "J")
    ax.plot(t, drift / factor, color="tab:red", label="E - E(t0)")
    works = traj.info.get("energy", {}).get("works")
    if traj.info.get("energy", {}).get("conservative") is False and works:
        w = {k: np.asarray(x, float) for k, x in works.items()}
        for key, style in (("contacts", ":"), ("friction", ":"), ("dampers", "--"), ("inputs", "-."),
                           ("drives", "-."), ("push_out", ":")):
            if key in w and np.any(w[key] != 0):
                ax.plot(t, w[key] / factor, style, lw=0.9, label=f"work of {key}")
        ax.plot(t, (drift - w["total"]) / factor, color="k", lw=0.8, label="residual E - E(t0) - W")
        ax.legend(fontsize=7)
        ax.set_title(f"energy balance (E(t0) = {traj.energy[0]:.4g} J)")
    else:
        ax.set_title(f"energy, conservative (E(t0) = {traj.energy[0]:.4g} J"
                     + (f", max relative change {traj.energy_drift / scale:.2g})" if scale > 0 else ")"))
    ax.set_xlabel("t (s)")
    ax.set_ylabel(f"E - E(t0) ({unit})")
    ax.ticklabel_format(axis="y", useOffset=False)
    ax.grid(True, alpha=0.3)


def _drift_panel(ax, traj) -> None:
    """The constraint drift ``|Φ|∞`` and ``|A v + Φ_t|∞`` on a log scale (exact zeros left out)."""
    for values, label in ((traj.constraint_residual, "|phi|_inf (m^2)"),
                          (traj.velocity_residual, "|A v + phi_t|_inf (m^2/s)")):
        ax.semilogy(traj.t, np.where(values > 0, values, np.nan), label=label)
    ax.set_title("constraint drift")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("residual (m², m²/s)")
    ax.legend(loc="best", fontsize="small")
    ax.grid(True, which="both", alpha=0.3)


def _points_panel(ax, traj, curves: list) -> None:
    """Each point's coordinates over time (m)."""
    for label, xyz in curves:
        for j, line_style in zip(range(traj.dim), ("-", "--", ":")):
            ax.plot(traj.t, xyz[:, j], line_style, label=f"{label} {'xyz'[j]}")
    ax.set_title("points")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("position (m)")
    if curves:
        ax.legend(loc="best", fontsize="x-small", ncol=traj.dim)
        _least_span(ax, np.concatenate([xyz.ravel() for _, xyz in curves]))
    ax.ticklabel_format(axis="y", useOffset=False)
    ax.grid(True, alpha=0.3)


def _paths_panel(ax, traj, curves: list, joint_panel: bool) -> None:
    """The points' paths (the x–y plane in 2D, a 3D view in 3D) at equal scales, starts marked."""
    for label, xyz in curves:
        ax.plot(*xyz.T, label=label)
        ax.scatter(*xyz[0], marker="o", s=15)
    ax.set_title("paths (o: start)" if not joint_panel else f"path of {curves[0][0]} (o: start)")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    if curves:
        _equal_box(ax, np.concatenate([xyz for _, xyz in curves]), traj.dim)
    if traj.dim == 3:
        ax.set_zlabel("z (m)")
    else:
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(True, alpha=0.3)


def _contact_panels(fig, traj, rows: int) -> None:
    """Normal and tangential contact forces (N), and gaps (m), per contact."""
    ax = fig.add_subplot(rows, 2, 5)
    for k, name in enumerate(traj.contact_names):
        line, = ax.plot(traj.t, traj.contact_normal[:, k], label=f"{name} normal")
        ax.plot(traj.t, np.linalg.norm(traj.contact_tangent[:, k], axis=1), ":", color=line.get_color(),
                label=f"{name} |tangential|")
    ax.set_title("contact forces")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("force (N)")
    ax.legend(loc="best", fontsize="x-small")
    ax.grid(True, alpha=0.3)
    ax = fig.add_subplot(rows, 2, 6)
    for k, name in enumerate(traj.contact_names):
        ax.plot(traj.t, traj.gap[:, k], label=name)
    ax.axhline(0, color="k", lw=0.8)
    ax.set_title("gaps (< 0: penetration)")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("gap (m)")
    ax.legend(loc="best", fontsize="x-small")
    ax.grid(True, alpha=0.3)


def _point_curves(traj, points) -> list[tuple[str, np.ndarray]]:
    """``(label, positions (n_t, dim))`` of the requested points."""
    if points is None:
        return [(name, traj.marker(name)) for name in traj.marker_names]
    curves = []
    for item in points:
        if isinstance(item, str):
            curves.append((item, traj.marker(item)))
        elif isinstance(item, (tuple, list)) and len(item) == 2 and isinstance(item[0], str):
            member, local = item
            label = f"{member}{tuple(float(x) for x in np.asarray(local, float))}"
            curves.append((label, traj.point(member, local)))
        else:
            raise NcgenError(f"plot: points: expected marker names or (member, local_xyz) pairs, got {item!r}")
    return curves


def unit_scale(values: np.ndarray, unit: str) -> tuple[float, str]:
    """``(factor, label)`` to draw ``values / factor`` in ``label`` units: 1 and ``unit`` for
    values between 1e-2 and 1e4 in size, else a power of ten stated (``1e-07 J``)."""
    big = float(np.nanmax(np.abs(values))) if np.size(values) else 0.0
    if big == 0 or not np.isfinite(big) or 1e-2 <= big < 1e4:
        return 1.0, unit
    exponent = int(np.floor(np.log10(big)))
    return 10.0 ** exponent, f"1e{exponent:+03d} {unit}"


def _least_span(ax, values: np.ndarray, fraction: float = 1e-3) -> None:
    """Widen the y range to at least ``fraction`` of the values' size, so round-off-sized
    variations are drawn flat instead of filling the panel."""
    lo, hi = float(np.nanmin(values)), float(np.nanmax(values))
    least = fraction * max(abs(lo), abs(hi), 1e-12)
    if hi - lo < least:
        mid = (lo + hi) / 2
        ax.set_ylim(mid - least / 2, mid + least / 2)


def _equal_box(ax, pts: np.ndarray, dim: int) -> None:
    """Equal spans on every axis around ``pts`` (3D; 2D uses an equal aspect)."""
    if dim != 3:
        return
    lo, hi = np.nanmin(pts, axis=0), np.nanmax(pts, axis=0)
    half = max(float(np.max(hi - lo)) / 2, 1e-3 * max(float(np.max(np.abs(pts))), 1e-9)) * 1.05
    centre = (lo + hi) / 2
    for set_lim, c in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), centre):
        set_lim(c - half, c + half)
    ax.set_box_aspect((1, 1, 1))
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        axis.get_major_formatter().set_useOffset(False)


def _joint_panel(ax, traj) -> None:
    """Joint positions over time (rad for rotations, m for translations), at most 12 curves."""
    names = traj.joint_position_names[:12]
    for c, name in enumerate(names):
        ax.plot(traj.t, traj.qj[:, c], label=name)
    more = len(traj.joint_position_names) - len(names)
    ax.set_title("joint positions" + (f" (first {len(names)}, {more} more)" if more else ""))
    ax.set_xlabel("t (s)")
    ax.set_ylabel("joint position (rad or m)")
    ax.legend(loc="best", fontsize="x-small", ncol=2)

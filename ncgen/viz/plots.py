"""``plot(traj, path)``: a PNG (PDF, SVG) summary of a simulation: energy (drift, or balance of a dissipative run), constraint drift and
the motion of chosen points."""
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
    curves = _point_curves(traj, points)
    rows = 3 if traj.contact_names else 2
    fig = figure(11, 4 * rows)
    t = traj.t
    ax = fig.add_subplot(rows, 2, 1)
    scale = traj.energy_scale
    ax.plot(t, traj.energy - traj.energy[0], color="tab:red", label="E - E(t0)")
    if traj.info.get("energy", {}).get("conservative") is False and traj.model is not None:
        from ncgen.runtime.energy_balance import works
        w = works(traj.model, t, traj.q, traj.v, traj.lam, traj.u, traj.p)
        for key, style in (("contacts", ":"), ("dampers", "--"), ("inputs", "-."), ("drives", "-.")):
            if np.any(w[key] != 0):
                ax.plot(t, w[key], style, lw=0.9, label=f"work of {key}")
        ax.plot(t, traj.energy - traj.energy[0] - w["total"], color="k", lw=0.8, label="residual E - E(t0) - W")
        ax.legend(fontsize=7)
        ax.set_title(f"energy balance (E(t0) = {traj.energy[0]:.4g} J)")
    else:
        ax.set_title(f"energy, conservative (E(t0) = {traj.energy[0]:.4g} J"
                     + (f", max relative change {traj.energy_drift / scale:.2g})" if scale > 0 else ")"))
    ax.set_xlabel("t (s)")
    ax.set_ylabel("E - E(t0) (J)")
    ax.grid(True, alpha=0.3)

    ax = fig.add_subplot(rows, 2, 2)
    for values, label in ((traj.constraint_residual, "|phi|_inf (m^2)"),
                          (traj.velocity_residual, "|A v + phi_t|_inf (m^2/s)")):
        ax.semilogy(t, np.where(values > 0, values, np.nan), label=label)     # exact zeros left out
    ax.set_title("constraint drift")
    ax.set_xlabel("t (s)")
    ax.legend(loc="best", fontsize="small")
    ax.grid(True, which="both", alpha=0.3)

    ax = fig.add_subplot(rows, 2, 3)
    for label, xyz in curves:
        for j, line_style in zip(range(traj.dim), ("-", "--", ":")):
            ax.plot(t, xyz[:, j], line_style, label=f"{label} {'xyz'[j]}")
    ax.set_title("points")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("position (m)")
    if curves:
        ax.legend(loc="best", fontsize="x-small", ncol=traj.dim)
    ax.grid(True, alpha=0.3)

    ax = fig.add_subplot(rows, 2, 4, projection="3d" if traj.dim == 3 else None)
    for label, xyz in curves:
        ax.plot(*xyz.T, label=label)
        ax.scatter(*xyz[0], marker="o", s=15)
    ax.set_title("paths (o: start)")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    if traj.dim == 3:
        ax.set_zlabel("z (m)")
    else:
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(True, alpha=0.3)

    if traj.contact_names:
        _contact_panels(fig, traj, rows)
    fig.suptitle(f"{traj.model_name}: t = {t[0]:g} ... {t[-1]:g} s"
                 + ("" if traj.complete else "  (INCOMPLETE: the integration failed)"))
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi, format=path.suffix.lower()[1:])
    return path


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

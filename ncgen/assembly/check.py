"""A model's structural and initial-state report (``ncgen check MODEL.toml``).

:func:`check_system` builds the system twice at most: once with the default tolerance, to
know whether the initial state as given is consistent (the same rule as ``System.build``),
and, if not, once more without a limit to report everything else.  The report lists the
members, coordinates, constraints, what coordinate sharing eliminated (joints, and nq and
nc before and after, :mod:`ncgen.model.sharing`), the rank of ``A``, the degrees of freedom, redundant
constraints and the residuals of the given initial state: ``max |Φ(q)|`` (m²) and
``max |A v + Φ_t|`` (m²/s).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np

from ncgen.assembly.kinematics import DofReport, dof_report
from ncgen.errors import NcgenError

DEFAULT_TOLERANCE = 1e-6


@dataclass
class CheckReport:
    """What :func:`check_system` found; ``ok`` when the model builds and its initial state
    is consistent within the tolerance."""

    system: object
    model: object = None
    dof: DofReport | None = None
    inconsistency: str | None = None      # the build's message when the state is not consistent
    error: str | None = None              # the build's message when it cannot be built at all
    warnings: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return self.error is None and self.inconsistency is None

    def render(self, source: str | None = None) -> str:
        s, m = self.system, self.model
        where = f" ({source})" if source else ""
        lines = [f"model {s.name!r}{where}: {'planar' if s.dim == 2 else '3D'}, gravity "
                 f"{_fmt(s.gravity)} m/s²", *_system_lines(s)]
        if m is None:
            lines.append(f"error: {self.error}")
            lines.append("consistent: no (the model cannot be built)")
            return "\n".join(lines) + "\n"
        lines += self._model_lines()
        for w in self.warnings:
            lines.append(f"warning: {w}")
        if self.inconsistency:
            lines.append(f"consistent: no: {self.inconsistency}")
        else:
            lines.append("consistent: yes")
        return "\n".join(lines) + "\n"

    def _model_lines(self) -> list[str]:
        """The built model: its coordinates, constraints, sharing, rank and DOF, mass matrix,
        redundant constraints, the initial state's residuals and corrections, initial gaps."""
        m, d = self.model, self.dof
        lines = [f"coordinates (nq = {m.nq}):", *_wrap(m.coordinate_names),
                 f"constraints (nc = {m.nc + len(d.dropped)}):", *_wrap([*m.constraint_names, *d.dropped])]
        lines += _sharing(m, m.nc + len(d.dropped))
        lines.append(f"rank A = {d.rank}, DOF = {d.dof}")
        if d.rolling_summary():
            lines.append(d.rolling_summary())
        if not m.mass_factor.regular:
            flat = ", ".join(m.mass_factor.flat) or "coordinates without inertia"
            lines.append(f"mass matrix: singular ({flat}), positive definite on the constraint tangent space "
                         "(augmented mass matrix, docs/architecture.md)")
        lines.append("redundant constraints: " + (", ".join(d.redundant) or "none")
                     + (" (dropped when building)" if d.dropped else ""))
        phi_res, vel_res = m.initial_residual
        dq, dv = m.initial_correction
        lines.append(f"initial state as given: max |Φ| = {phi_res:.3g} m², max |A v + Φ_t| = {vel_res:.3g} m²/s")
        lines.append(f"  corrections making it consistent: {dq:.3g} m (positions), {dv:.3g} m/s (velocities)")
        if "gap" in m.functions:
            gaps = np.array(m.functions["gap"](m.q0, m.p0), float).reshape(-1)
            lines.append("initial gaps (m, < 0 penetrating): " + ", ".join(
                f"{c['name']} {g:.6g}" for c, g in zip(m.contacts, gaps)))
        return lines


def _system_lines(s) -> list[str]:
    """The system as written: its members, joints, forces, contacts, parameters and inputs."""
    lines = _members(s)
    if s.joints:
        lines.append(f"joints ({len(s.joints)}):")
        lines += [f"  {j.name:<16} {j.kind:<16} {' – '.join(_mname(x) for x in j.members())}"
                  + (" (driven)" if j.options.get("drive") is not None or j.kind == "CoordinateDriver" else "")
                  for j in s.joints]
    if s.forces:
        lines.append(f"forces ({len(s.forces)}): " + ", ".join(f"{f.name} ({f.kind})" for f in s.forces))
    if getattr(s, "contacts", None):
        lines.append(f"contacts ({len(s.contacts)}):")
        lines += [f"  {c.name:<16} {c.kind:<16} {' – '.join(_mname(x) for x in c.members())}  "
                  f"mu = {c.mu:g}, e = {c.restitution:g}" for c in s.contacts]
    if s.parameters:
        lines.append("parameters: " + ", ".join(f"{n} = {_fmt(v)}" for n, (_, v) in s.parameters.items()))
    if s.inputs:
        lines.append("inputs: " + ", ".join(f"{n} ({u.numel()})" for n, u in s.inputs.items()))
    return lines


def check_system(system, *, tolerance: float = DEFAULT_TOLERANCE, share: bool = True) -> CheckReport:
    """Build ``system`` (with coordinate sharing unless ``share=False``) and report on it
    (see the module docstring)."""
    report = CheckReport(system)
    caught: list = []
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            report.model = system.build(tolerance=tolerance, share=share)
    except NcgenError as e:
        if "inconsistent initial" not in str(e):
            report.error = str(e)
            return report
        report.inconsistency = str(e)
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                report.model = system.build(tolerance=np.inf, share=share)
        except NcgenError as e2:
            report.error = str(e2)
            return report
    report.warnings = [str(w.message) for w in caught if "dropping redundant" not in str(w.message)]
    report.dof = dof_report(report.model)
    return report


def _fmt(v) -> str:
    a = np.atleast_1d(np.asarray(v, float))
    return f"{a[0]:g}" if a.size == 1 else "[" + ", ".join(f"{x:g}" for x in a) + "]"


def _mname(m) -> str:
    return "ground" if m.is_ground else m.name


def _members(s) -> list[str]:
    lines = [f"members ({len(s.members)}):"]
    for m in s.members.values():
        shared = [f"{m.ctype.slots[k]} = {ref.label}" for k, ref in sorted(m.shared.items())]
        lines.append(f"  {m.name:<16} {m.kind:<5} {m.ctype.name:<4} mass {m.rigid.mass:g} kg"
                     + (f"; shares {', '.join(shared)}" if shared else "")
                     + (f"; markers {', '.join(m.markers)}" if m.markers else ""))
    return lines


def _sharing(model, nc: int) -> list[str]:
    """What coordinate sharing did (``model.sharing``, :mod:`ncgen.model.sharing`)."""
    plan = model.sharing
    if plan is None:
        return ["coordinate sharing: off (build(share=False))"]
    if plan.off:
        return [f"coordinate sharing: none ({plan.off})"]
    lines = [f"coordinate sharing: nq {plan.nq_before} -> {model.nq}, nc {nc + plan.nc_removed} -> {nc}"]
    if plan.eliminated:
        lines.append(f"  joints eliminated ({len(plan.eliminated)}): "
                     + ", ".join(f"{n} ({how})" for n, how in plan.eliminated.items()))
    lines += [f"  joint {n} partly: {how}" for n, how in plan.partial.items()]
    if plan.rebased:
        lines.append("  bodies re-based on their joints: "
                     + ", ".join(f"{n} ({how})" for n, how in plan.rebased.items()))
    return lines


def _wrap(names: list[str], width: int = 96) -> list[str]:
    lines, line = [], "  "
    for n in names:
        if len(line) + len(n) + 1 > width and line.strip():
            lines.append(line.rstrip())
            line = "  "
        line += n + " "
    if line.strip():
        lines.append(line.rstrip())
    return lines

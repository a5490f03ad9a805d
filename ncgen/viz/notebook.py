"""Rich display in Jupyter: a :class:`~ncgen.runtime.trajectory.Trajectory` shows as its
interactive 3D page (:mod:`ncgen.viz.html`) in a static HTML cell — an ``<iframe>`` whose
``srcdoc`` is the whole offline page, so it needs no server or widget and stays in a saved
notebook — and a :class:`~ncgen.model.model.Model` as a short table of its sizes."""
from __future__ import annotations

import html

#: Height of a trajectory's cell (px); the page fills the cell's width.
CELL_HEIGHT = 520


def trajectory_cell(traj, height: int = CELL_HEIGHT) -> str | None:
    """The HTML of ``traj``'s cell, or None (the text ``repr`` is shown instead) for an empty
    trajectory or one loaded without its model, which has nothing to draw."""
    if not len(traj.t) or traj.model is None:
        return None
    from ncgen.viz.html import page_data, render_page

    page = render_page(page_data(traj), f"{traj.model_name} — ncgen")
    caption = html.escape(repr(traj))
    return (f'<iframe srcdoc="{html.escape(page, quote=True)}" title="{caption}" '
            f'style="width:100%;height:{int(height)}px;border:0"></iframe>')


def model_table(model) -> str:
    """An HTML table of ``model``'s name and sizes (coordinates q, constraints, degrees of
    freedom, inputs, parameters, members, joints, contacts; with rolling elements, the
    degrees of freedom of :func:`ncgen.assembly.kinematics.dof_report`, their heights counted,
    and the velocity degrees of freedom)."""
    dof = [("degrees of freedom", model.dof)]
    if model.rolling:
        from ncgen.assembly.kinematics import dof_report
        report = dof_report(model)
        dof = [("degrees of freedom", report.dof), ("velocity degrees of freedom", report.velocity_dof),
               ("rolling elements", ", ".join(e.name for e in model.rolling))]
    rows = [("name", model.name), ("dimension", f"{model.dim}D"),
            ("coordinates q", model.nq), ("constraints", model.nc), *dof,
            ("inputs", ", ".join(model.input_names) or "none"),
            ("parameters", ", ".join(model.parameter_names) or "none"),
            ("members", ", ".join(model.member_names)),
            ("joints", ", ".join(model.joint_names) or "none"),
            ("contacts", ", ".join(model.contact_names) or "none")]
    body = "".join(f"<tr><th style='text-align:left'>{html.escape(k)}</th><td style='text-align:left'>"
                   f"{html.escape(_short(str(v)))}</td></tr>" for k, v in rows)
    return f"<table>{body}</table>"


def _short(text: str, limit: int = 200) -> str:
    return text if len(text) <= limit else text[:limit - 3] + "..."

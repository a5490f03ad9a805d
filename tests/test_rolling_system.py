"""Rolling elements as part of a model: written in TOML (``[[rolling]]``) or added by
``System.add_rolling``, carried by the built model, simulated by ``nc.simulate`` through the
integrator seam (``method="rolling"``), checked against the steady precession's closed form,
energy conservation and the constraint residual; bad input named."""
import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import ModelError, NcgenError
from ncgen.runtime.rolling_integrator import simulate_rolling
from test_rolling import A_d, C_d, a, g, m, steady_precession

BETA, W3 = 0.2, 30.0


def disc_toml(beta=BETA, w3=W3, precession=None, wobble=0.0, rolling=None) -> str:
    """The disc of :mod:`test_rolling` (tilted by ``beta`` about x, contact at the origin,
    spin ``w3`` about its axle, precessing at the closed-form rate unless ``precession`` is
    given, ``wobble`` rad/s about the rolling direction) as a model file."""
    omega = steady_precession(beta, w3) if precession is None else precession
    ex, ey, ez = np.eye(3)
    k = np.cos(beta) * ey + np.sin(beta) * ez
    d = np.cos(beta) * ez - np.sin(beta) * ey
    R = np.column_stack([ex, k, d])
    w = omega * ez + (w3 - omega * np.sin(beta)) * k + wobble * ex
    vec = lambda x: "[" + ", ".join(repr(float(c)) for c in x) + "]"      # noqa: E731
    if rolling is None:
        rolling = f'type = "RollingDisc"\nbody = "disc"\nradius = {a}\naxle = [0.0, 1.0, 0.0]'
    return f"""
[system]
name = "rolling_disc"
gravity = [0.0, 0.0, {-g}]

[[members]]
name = "disc"
kind = "body"
mass = {m}
inertia = [{vec([A_d, 0, 0])}, {vec([0, C_d, 0])}, {vec([0, 0, A_d])}]
position = {vec(a * d)}
rotation = [{vec(R[0])}, {vec(R[1])}, {vec(R[2])}]
velocity = {vec(a * w3 * ex + a * wobble * ey)}
angular_velocity = {vec(w)}

[[rolling]]
{rolling}
"""


@pytest.fixture(scope="module")
def model():
    return nc.System.from_toml(disc_toml()).build()


def axle(model, q):
    return q[:, model.layout.member_indices("disc")[6:9]]


def test_a_disc_written_in_toml_precesses_at_the_closed_form_rate(model):
    """``nc.simulate`` picks the rolling integrator for a model with rolling elements: the
    tilt stays, the heading turns at the closed-form rate, energy is conserved and both
    constraint levels (the disc's height and its two rolling rows) hold at round-off."""
    assert [e.spec()["type"] for e in model.rolling] == ["RollingDisc"]
    omega = steady_precession(BETA, W3)
    tr = nc.simulate(model, 0.3, 0.02, rtol=1e-9, atol=1e-11, backend="vm")
    assert tr.info["method"] == "rolling" and tr.info["rolling_names"] == ["disc.rolling"]
    assert tr.info["backend"] == "vm"
    k = axle(model, tr.q)
    assert np.max(np.abs(np.arcsin(k[:, 2]) - BETA)) < 1e-8
    heading = np.unwrap(np.arctan2(-k[:, 0], k[:, 1]))
    assert abs(np.polyfit(tr.t, heading, 1)[0] / omega - 1) < 1e-7
    assert np.ptp(tr.energy) <= 1e-9 * np.max(np.abs(tr.energy))
    assert np.max(tr.constraint_residual) <= 1e-12 and np.max(tr.velocity_residual) <= 1e-12
    # every multiplier (the model's: none, a free body; then the disc's height and rolling rows)
    assert tr.lam.shape == (len(tr.t), model.nc + 3)
    assert tr.constraint_names[model.nc:] == ["disc.rolling.height", "disc.rolling.x", "disc.rolling.y"]
    assert np.allclose(tr.point("disc", (0, 0, 0))[:, 2], a * np.cos(BETA), atol=1e-9)
    # the contact carries the weight and the centre's centripetal force m Ω |v_c| (its
    # circle's radius is |v_c| / Ω), normal to the centre's velocity
    normal, friction = -tr.lam[:, model.nc], -tr.lam[:, model.nc + 1:]
    np.testing.assert_allclose(normal, m * g, rtol=1e-9)
    v_c = tr.v[:, model.layout.member_indices("disc")[:2]]          # the centre r_i's velocity along the plane
    speed = np.linalg.norm(v_c, axis=1)
    np.testing.assert_allclose(np.linalg.norm(friction, axis=1), m * abs(omega) * speed, rtol=1e-9)
    assert np.max(np.abs(np.sum(friction * v_c, axis=1)) / (m * abs(omega) * speed ** 2)) < 1e-9


def test_simulate_runs_what_simulate_rolling_runs(model):
    """The seam adds nothing to the numbers: RK4 with two substeps per output equals
    ``simulate_rolling`` with ``h = dt / 2`` (to round-off: the two grids' times differ in
    their last bits), both on the constraints to round-off."""
    from ncgen.assembly.nonholonomic import rolling_system
    tr = nc.simulate(model, 0.1, 0.02, method="rolling", integrator="rk4", substeps=2)
    ref = simulate_rolling(rolling_system(model), 0.1, 0.02, method="rk4", h=0.01)
    np.testing.assert_allclose(tr.q, ref.q, rtol=0, atol=1e-12)
    np.testing.assert_allclose(tr.v, ref.v, rtol=0, atol=1e-11)
    assert max(tr.constraint_residual.max(), tr.velocity_residual.max(), ref.residual.max()) < 1e-13
    assert tr.info["integrator"] == "rk4" and tr.info["substeps"] == 2


def test_toml_round_trip_and_the_python_api_give_the_same_model(model):
    s = nc.System.from_toml(disc_toml())
    again = nc.System.from_toml(s.to_toml())
    assert [e.spec() for e in again.rolling] == [e.spec() for e in s.rolling]
    assert "[[rolling]]" in s.to_toml() and "rolling=1" in repr(s)
    by_hand = nc.System.from_toml(disc_toml().split("[[rolling]]")[0])
    by_hand.add_rolling(nc.RollingDisc("disc", radius=a, axle=(0, 1, 0)))
    built = by_hand.build()
    assert built.content_hash == model.content_hash
    plain = nc.System.from_toml(disc_toml().split("[[rolling]]")[0]).build()
    assert plain.rolling == () and plain.content_hash != model.content_hash


def test_a_ball_and_a_knife_edge_from_toml():
    """A ball rolling straight keeps its speed (no force along the plane); a sleigh blade
    written in TOML gives one velocity row."""
    ball = nc.System("ball")
    ball.add_body("disc", mass=m, inertia=0.4 * m * a * a * np.eye(3), position=(0, 0, a), velocity=(0.5, 0, 0),
                  angular_velocity=(0, 0.5 / a, 0))
    ball.add_rolling(nc.RollingSphere("disc", radius=a))
    back = nc.System.from_toml(ball.to_toml())
    assert [e.spec() for e in back.rolling] == [{"type": "RollingSphere", "name": "disc.rolling", "body": "disc",
                                                 "radius": a}]
    tr = nc.simulate(back.build(), 0.2, 0.1)
    np.testing.assert_allclose(tr.point("disc", (0, 0, 0))[:, 0], 0.5 * tr.t, rtol=0, atol=1e-10)
    knife = nc.System.from_toml(disc_toml(rolling='type = "KnifeEdge"\nbody = "disc"\nat = [0.0, 0.0, 0.0]\n'
                                                   'blade = [1.0, 0.0, 0.0]\nname = "blade"'))
    assert [e.name for e in knife.rolling] == ["blade"] and knife.rolling[0].kind == "KnifeEdge"


@pytest.mark.parametrize("rolling, message", [
    ('type = "RollingDisk"\nbody = "disc"\nradius = 0.1', r"rolling\[0\]\.type: unknown rolling element 'RollingDisk'"
                                                          r" \(did you mean 'RollingDisc'\?\)"),
    ('type = "RollingDisc"\nbody = "disc"', r"rolling\[0\]\.radius: missing \(required\)"),
    ('type = "RollingDisc"\nbody = "disc"\nradius = -1.0', r"rolling\[0\]: RollingDisc on disc: radius: expected a "
                                                           r"positive number \(m\), found -1.0"),
    ('type = "RollingDisc"\nbody = "wheel"\nradius = 0.1', r"rolling\[0\]: add_rolling: .*body: expected a body of "
                                                           r"system 'rolling_disc' \(bodies: disc\), found no member"),
    ('type = "RollingDisc"\nbody = "disc"\nradius = 0.1\nspokes = 3', r"rolling\[0\]\.spokes: unknown key"),
    ('type = "KnifeEdge"\nbody = "disc"\nblade = [1.0, 0.0]', r"rolling\[0\]\.blade: expected 3 numbers"),
])
def test_bad_rolling_tables_are_named(rolling, message):
    with pytest.raises(ModelError, match=message):
        nc.System.from_toml(disc_toml(rolling=rolling))


def test_bad_uses_are_named(model):
    s = nc.System("planar", gravity=(0, -g))
    s.add_body("disc", coords="ruv", mass=1.0, inertia=0.1, position=(0, 0))
    with pytest.raises(ModelError, match="rolling elements need a 3D system; system 'planar' is planar"):
        s.add_rolling(nc.RollingDisc("disc", radius=0.1))
    s = nc.System("points")
    s.add_point("p", mass=1.0, position=(0, 0, 0))
    with pytest.raises(ModelError, match=r"body: expected a body of system 'points' \(bodies: none\), found a point"):
        s.add_rolling(nc.RollingSphere("p", radius=0.1))
    with pytest.raises(ModelError, match="add_rolling: expected a nonholonomic element"):
        s.add_rolling(nc.SpherePlane(s.member("p"), radius=0.1))
    two = nc.System.from_toml(disc_toml())
    with pytest.raises(ModelError, match="name 'disc.rolling' is already used"):
        two.add_rolling(nc.RollingSphere("disc", radius=a))
    for method in ("joint",):
        with pytest.raises(NcgenError, match=rf"method='{method}': model 'rolling_disc' has rolling elements "
                                             r"\(disc.rolling\), whose velocity constraints only method='rolling' "
                                             r"\(the default for it\), 'idas' and 'stepper' keep"):
            nc.simulate(model, 0.1, 0.05, method=method)
    with pytest.raises(NcgenError, match="method='rolling' does not take joint_dynamics=True"):
        nc.simulate(model, 0.1, 0.05, joint_dynamics=True)
    with pytest.raises(NcgenError, match=r"integrator: expected one of dopri5, rk4 \(method='joint' or 'rolling'\)"):
        nc.simulate(model, 0.1, 0.05, integrator="euler")


def test_the_viewer_draws_the_disc_and_the_plane(model):
    """The page shows the disc as a cylinder of its radius about its axle (in place of the
    inertia box) and the plane it rolls on."""
    from ncgen.viz.html import page_data
    tr = nc.simulate(model, 0.04, 0.02)
    data = page_data(tr, with_plots=False)
    (disc,) = data["members"]
    assert [(p["kind"], p["size"]) for p in disc["parts"]] == [("cylinder", [a, 0.1 * a])]
    np.testing.assert_allclose(np.array(disc["parts"][0]["R"]) @ [0, 0, 1], [0, 1, 0], atol=1e-15)
    assert data["contacts"]["planes"] == [[[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]]


def test_the_documented_toml_table_builds():
    """docs/rolling.md's ``[[rolling]]`` example: an upright disc rolling along x."""
    from pathlib import Path
    doc = (Path(__file__).resolve().parent.parent / "docs" / "rolling.md").read_text(encoding="utf-8")
    text = doc.split("```toml\n", 1)[1].split("```", 1)[0]
    model = nc.System.from_toml(text).build()
    assert [e.spec() for e in model.rolling] == [{"type": "RollingDisc", "name": "disc.rolling", "body": "disc",
                                                  "radius": 0.1, "axle": [0.0, 1.0, 0.0]}]
    from ncgen.assembly.nonholonomic import rolling_system
    assert max(rolling_system(model).residuals(model.q0, model.v0)) < 1e-15


@pytest.mark.slow               # compiles the two steps (25-45 s each from an empty compile cache)
@pytest.mark.parametrize("method", ["dopri5", "rk4"])
def test_the_compiled_step_takes_the_python_steps(model, method):
    """Each step compiled (stages and projection in one C call, the accelerations by the
    Schur complement, a fixed three Newton steps) gives the Python-driven steps' motion to
    round-off, the same number of steps, and keeps the constraints."""
    from ncgen.assembly.nonholonomic import rolling_system
    system = rolling_system(model)
    kw = dict(rtol=1e-9, atol=1e-11) if method == "dopri5" else dict(h=0.005)
    fast = simulate_rolling(system, 0.2, 0.02, method=method, compiled=True, **kw)
    slow = simulate_rolling(system, 0.2, 0.02, method=method, compiled=False, **kw)
    assert fast.compiled and not slow.compiled and fast.steps == slow.steps
    np.testing.assert_allclose(fast.q, slow.q, rtol=0, atol=1e-12)
    np.testing.assert_allclose(fast.v, slow.v, rtol=0, atol=1e-10)
    assert fast.residual.max() < 1e-13


@pytest.mark.slow               # the target; ~4-7 s compiled at load 20 on 2 cores (64-132 s before)
def test_ten_seconds_of_the_toml_disc_at_rtol_1e_8(model):
    tr = nc.simulate(model, 10.0, 0.05, rtol=1e-8, atol=1e-10, backend="compiled")
    assert tr.info["backend"] == "compiled" and tr.complete
    assert max(tr.constraint_residual.max(), tr.velocity_residual.max()) <= 1e-10
    assert np.ptp(tr.energy) <= 1e-7 * np.max(np.abs(tr.energy))
    k = axle(model, tr.q)
    heading = np.unwrap(np.arctan2(-k[:, 0], k[:, 1]))
    assert abs(np.polyfit(tr.t, heading, 1)[0] / steady_precession(BETA, W3) - 1) < 1e-7


@pytest.mark.parametrize("method", ["dopri5", "rk4"])
def test_auto_asks_for_the_compiled_step_once_when_the_pace_says_it_pays(model, method, monkeypatch):
    """``backend="auto"`` compiles the step when the Python steps' pace (trusted after
    ``PACE_AFTER`` s) projects the run beyond ``COMPILE_PAYS`` s: both set here, so that the
    decision does not depend on the machine's speed; asked once per run, and without a
    compiler the run goes on in Python."""
    from ncgen.assembly.nonholonomic import rolling_system
    from ncgen.errors import CompilerNotFound
    from ncgen.runtime import rolling_integrator
    monkeypatch.setattr(rolling_system(model), "compiled_steps", {})      # none compiled in this process
    tried = []

    def no_compiler(system, method):
        tried.append(method)
        raise CompilerNotFound("no C compiler (test)")

    monkeypatch.setattr(rolling_integrator, "compiled_step", no_compiler)
    monkeypatch.setattr(rolling_integrator, "PACE_AFTER", 0.0)
    options = dict(rtol=1e-9, atol=1e-11) if method == "dopri5" else dict(substeps=4)
    for pays, asked in ((1e9, []), (0.0, [method])):
        monkeypatch.setattr(rolling_integrator, "COMPILE_PAYS", pays)
        tried.clear()
        tr = nc.simulate(model, 0.1, 0.02, integrator=method, **options)
        assert tried == asked and tr.info["backend"] == "vm" and tr.complete
        assert tr.info["steps"] >= 5 and max(tr.constraint_residual.max(), tr.velocity_residual.max()) <= 1e-12


def test_the_compiled_steps_function_agrees_with_the_python_step(model):
    """The function that is compiled (evaluated here on CasADi's virtual machine, no compile):
    its Schur-complement accelerations equal the KKT solve, its projection the Newton and
    least-squares projection, and one RK4 step the Python-driven step."""
    from ncgen.assembly.nonholonomic import rolling_system
    from ncgen.assembly.rolling_step import accel_function, projection_function, step_function
    from ncgen.runtime.rolling_integrator import project
    system = rolling_system(model)
    q, v = project(system, model.q0, model.v0)
    a_kkt = np.asarray(system.accel(q, v, np.zeros(system.nq))[0]).ravel()
    np.testing.assert_allclose(np.asarray(accel_function(system)(q, v)).ravel(), a_kkt, rtol=0,
                               atol=1e-12 * np.max(np.abs(a_kkt)))
    rng = np.random.default_rng(3)
    q_off, v_off = q + 1e-6 * rng.normal(size=q.size), v + 1e-4 * rng.normal(size=v.size)
    qp, vp = (np.asarray(x).ravel() for x in projection_function(system)(q_off, v_off))
    q_ref, v_ref = project(system, q_off, v_off)
    np.testing.assert_allclose(qp, q_ref, rtol=0, atol=1e-14)
    np.testing.assert_allclose(vp, v_ref, rtol=0, atol=1e-12)
    y_next, err = step_function(system, "rk4")(np.concatenate([q, v]), 0.01)
    ref = simulate_rolling(system, 0.01, 0.01, q0=q, v0=v, method="rk4", compiled=False)
    np.testing.assert_allclose(np.asarray(y_next).ravel(), np.concatenate([ref.q[-1], ref.v[-1]]), rtol=0, atol=1e-12)
    assert not np.any(np.asarray(err))


def test_the_command_line_simulates_a_rolling_model(tmp_path, capsys):
    from ncgen.cli import main
    path = tmp_path / "disc.toml"
    path.write_text(disc_toml())
    assert main(["simulate", str(path), "--t-end", "0.04", "--dt", "0.02", "--integrator", "rk4", "--substeps", "2",
                 "-o", str(tmp_path / "disc.npz")]) == 0
    out = capsys.readouterr().out
    assert "integrator: rolling" in out
    tr = nc.Trajectory.load(tmp_path / "disc.npz")
    assert tr.info["method"] == "rolling" and tr.info["substeps"] == 2 and len(tr.t) == 3

"""Feedback laws and controllers (issue 35, classes 4 and 5): a Python feedback that raises,
returns NaN or the wrong shape mid-run is named (the time of the call, what it returned or
raised against what was expected) and the run up to the last state reached is attached, equal
to the same run with a law that does not fail (joint loop, IDAS and stepper paths); PD gains
that are negative, not finite or not numbers are refused by name through the Python API,
the TOML [controller] table and ``ncgen simulate --controller``."""
from __future__ import annotations

import numpy as np
import pytest

import ncgen as nc
from ncgen.cli import main
from ncgen.errors import NcgenError, SimulationError

T_FAIL = 0.3
LINK_TOML = """
[system]
name = "hold"
gravity = [0.0, -9.81]

[inputs]
tau = 1

[[members]]
name = "rod"
kind = "body"
coords = "ruv"
mass = 2.0
inertia = 0.1
position = [0.4, 0.0]

[[joints]]
type = "Revolute"
name = "hinge"
between = ["ground", "rod"]
at = [0.0, 0.0]
effort = "tau"
"""


@pytest.fixture(scope="module")
def arm():
    return nc.System.from_toml(LINK_TOML).build()


def law(broken):
    """A PD law u(t, qj, vj) that from T_FAIL on does ``broken`` instead."""
    def u(t, qj, vj):
        if t >= T_FAIL - 1e-12 and broken is not None:
            return broken()
        return [40.0 * (0.2 - qj[0]) - 5.0 * vj[0]]
    return u


def _raise():
    raise ZeroDivisionError("the law divided by zero")


BROKEN = {
    "raises": (_raise, r"raised ZeroDivisionError: the law divided by zero"),
    "nan": (lambda: [float("nan")], r"returned \[nan\]: expected 1 finite input value"),
    "shape": (lambda: [1.0, 2.0], r"returned an array of shape \(2,\): expected 1 input value"),
    "text": (lambda: "push", r"returned 'push': expected 1 finite number"),
}
RUN = {"joint": {"rtol": 1e-10}, "idas": {"rtol": 1e-8}, "stepper": {"substeps": 4}}


@pytest.mark.parametrize("method", list(RUN))
@pytest.mark.parametrize("kind", list(BROKEN))
def test_failing_feedback_is_named_and_the_run_before_it_kept(arm, method, kind):
    broken, said = BROKEN[kind]
    good = nc.simulate(arm, 0.5, 0.05, method=method, u=law(None), **RUN[method])
    with pytest.raises(SimulationError, match=r"the feedback u\(t, qj, vj\) called at t = 0.3 s " + said) as err:
        nc.simulate(arm, 0.5, 0.05, method=method, u=law(broken), **RUN[method])
    kept = err.value.trajectory
    assert err.value.time == pytest.approx(T_FAIL) and kept is not None
    assert "attached to this error as .trajectory" in str(err.value)
    assert kept.info["complete"] is False and kept.t[-1] == pytest.approx(T_FAIL)
    k = len(kept.t)
    assert k == 7 and np.array_equal(kept.t, good.t[:k])
    assert np.allclose(kept.q, good.q[:k], rtol=0, atol=1e-12) and np.allclose(kept.v, good.v[:k], rtol=0, atol=1e-12)
    assert np.all(np.isfinite(kept.q)) and np.all(np.isfinite(kept.u))


@pytest.mark.parametrize("method", list(RUN))
@pytest.mark.parametrize("kind", list(BROKEN))
def test_feedback_failing_at_its_first_call_keeps_the_initial_state(arm, method, kind):
    """The first call fails: the error names it and carries the initial state alone (one
    row, input zero since none was given), on every path; its multipliers are those of the
    horizontal rod released with no torque: the hinge carries ``m (g − a)`` with the centre's
    acceleration ``a = m g l² / (I + m l²)`` (closed form)."""
    broken, said = BROKEN[kind]
    for name, u in (("qj, vj", lambda t, qj, vj: broken()), ("q, v", lambda t, q, v: broken())):
        with pytest.raises(SimulationError, match=r"the feedback u\(t, " + name + r"\) called at t = 0 s " + said +
                           r".*The initial state \(t = 0 s; no input was applied, its u is zero\) is attached") as err:
            nc.simulate(arm, 0.5, 0.05, method=method, u=u, **RUN[method])
        kept = err.value.trajectory
        assert err.value.time == 0.0 and kept is not None and kept.info["complete"] is False
        assert len(kept.t) == 1 and np.array_equal(kept.q[0], arm.q0) and np.array_equal(kept.v[0], arm.v0)
        assert np.array_equal(kept.u, np.zeros((1, 1)))
        m, g, lc, inertia = 2.0, 9.81, 0.4, 0.1
        hinge = kept.reaction("hinge")[0][0]              # the hinge's force on the rod
        assert np.allclose(hinge, [0.0, m * (g - m * g * lc ** 2 / (inertia + m * lc ** 2))], rtol=0, atol=1e-9)


def test_natural_feedback_failing_at_the_start_is_named(arm):
    with pytest.raises(SimulationError, match=r"the feedback u\(t, q, v\) called at t = 0 s returned \[inf\]"):
        nc.simulate(arm, 0.5, 0.05, method="idas", u=lambda t, q, v: [np.inf])


@pytest.mark.parametrize("kw, said", [
    ({"kp": -400.0, "kd": 25.0}, r"pd: kp: expected gains >= 0 \(a negative gain drives the joint away"),
    ({"kp": 400.0, "kd": [-1.0]}, r"pd: kd: expected gains >= 0"),
    ({"kp": float("nan"), "kd": 25.0}, r"pd: kp: expected finite numbers, got nan"),
    ({"kp": "400", "kd": 25.0}, r"pd: kp: expected a number, one per actuated joint rate"),
    ({"kp": {"hinge": -1.0}, "kd": 1.0}, r"pd: kp\['hinge'\]: expected gains >= 0"),
    ({"kp": 1.0, "kd": 1.0, "target": float("inf")}, r"pd: target: expected finite numbers, got inf"),
    ({"kp": 1.0, "kd": None}, r"pd: kd: expected real numbers, got NoneType None"),
])
def test_bad_pd_gains_are_refused_by_name(kw, said):
    with pytest.raises(NcgenError, match=said):
        nc.PD(**kw)
    with pytest.raises(NcgenError, match=said.replace("pd:", "computed_torque:")):
        nc.ComputedTorque(**kw)


def test_pd_with_valid_gains_still_holds_the_arm(arm):
    """kd = 0 and kp > 0 are allowed: the arm oscillates about the static sag
    ``kp θ = −m g l_c cos θ`` (closed form), with no damping to settle it."""
    traj = nc.simulate(arm, 1.0, 0.01, u=nc.PD(kp=400.0, kd=0.0), rtol=1e-10)
    from scipy.optimize import brentq
    sag = brentq(lambda th: 400.0 * th + 2.0 * 9.81 * 0.4 * np.cos(th), -1.0, 0.0)
    assert traj.qj.min() < sag < traj.qj.max() and traj.qj.max() <= 1e-9       # about the sag, from 0


@pytest.mark.parametrize("table, said", [
    ('kind = "pd"\nkp = -400.0\nkd = 60.0\n', r"controller\.kp: expected gains >= 0"),
    ('kind = "pd"\nkp = nan\nkd = 60.0\n', r"controller\.kp: expected finite numbers, got nan"),
    ('kind = "pd"\nkp = "fast"\nkd = 60.0\n', r"controller\.kp: expected a number"),
    ('kind = "pd"\nkp = 400.0\nkd = [1.0, -1.0]\n', r"controller\.kd: expected gains >= 0"),
    ('kind = "computed_torque"\nkp = 400.0\nkd = 60.0\nacceleration = inf\n',
     r"controller\.acceleration: expected finite numbers, got inf"),
])
def test_bad_toml_controller_gains_are_refused_by_key(tmp_path, capsys, table, said):
    text = LINK_TOML + "\n[controller]\n" + table
    with pytest.raises(NcgenError, match=said):
        nc.System.from_toml(text)
    path = tmp_path / "hold.toml"
    path.write_text(text)
    assert main(["simulate", str(path), "--t-end", "0.1", "-o", str(tmp_path / "run.npz")]) != 0
    assert "Traceback" not in capsys.readouterr().err
    path.write_text(LINK_TOML)
    inline = table.strip().replace("\n", ", ")
    assert main(["simulate", str(path), "--t-end", "0.1", "-o", str(tmp_path / "run.npz"),
                 "--controller", inline]) != 0
    import re
    assert re.search(said.replace(r"controller\.", r"--controller\."), capsys.readouterr().err)
    assert not (tmp_path / "run.npz").exists()


def test_a_failed_rk4_joint_run_keeps_only_its_trusted_rows(arm):
    """A stiff PD (kp = 4e4: ω ≈ 310 rad/s, h ω ≈ 3.1 past RK4's limit 2.83) makes the joint
    loop's fixed RK4 steps grow until the accelerations overflow; only the rows before the
    run departs from an error-controlled one by 1 % of the model's size are attached (they
    used to run to |qj| ~ 1e47 rad), and they agree with IDAS under the same law to that."""
    import re
    pd = nc.PD(kp=4e4, kd=0.0)
    with pytest.raises(SimulationError, match=r"accelerations are not finite\. Before that, the RK4 run departed from "
                                              r"an error-controlled run .* so only the rows before it are kept") as err:
        nc.simulate(arm, 10.0, 0.01, method="joint", integrator="rk4", u=pd)
    kept = err.value.trajectory
    failed_at = float(re.search(r"failed between t = ([0-9.]+) s", str(err.value)).group(1))
    assert 3 <= len(kept.t) and kept.t[-1] < failed_at and err.value.time == kept.t[-1]
    assert np.all(np.isfinite(kept.qj)) and kept.info["complete"] is False
    idas = nc.simulate(arm, float(kept.t[-1]) + 0.01, 0.01, method="idas", u=pd, rtol=1e-10, atol=1e-12)
    assert np.max(np.abs(kept.q - idas.q[:len(kept.t)])) < 0.01 * np.max(np.abs(arm.q0))


def test_a_compiled_controller_giving_nan_is_named(arm):
    """The joint loop's accelerations are not finite because the controller's law is not
    (sqrt of a negative number from t = 0.2 s): the message says so, not that the mass
    matrix is singular, and the rows before are kept (they equal a run of the finite law)."""
    import casadi as ca
    law = nc.Controller(lambda t, qj, vj, p: ca.if_else(t < 0.2, -40 * qj[0], ca.sqrt(-1 - qj[0] ** 2)))
    good = nc.Controller(lambda t, qj, vj, p: -40 * qj[0])
    with pytest.raises(SimulationError, match=r"the compiled controller's inputs are not finite: at the state reached "
                                              r"at t = 0.15 s, taken at t = 0.2 s, its law gives \[nan\]") as err:
        nc.simulate(arm, 0.5, 0.05, method="joint", u=law)
    kept = err.value.trajectory
    ref = nc.simulate(arm, 0.5, 0.05, method="joint", u=good)
    assert len(kept.t) == 4 and np.array_equal(kept.qj, ref.qj[:4])

"""The C doors of ``nc.forward_dynamics(..., backend="compiled")``, a table ``StepFunction`` (its
call and ``.jacobians``) and ``nc.JointStep`` (its call and ``.jacobians``), issue 37: one C
call each (checks, kernel, the result's finiteness or the step's convergence, fresh outputs or
``out=``), the same results to the last bit as their checked paths, ``out=`` written in place
and bit-identical to the fresh outputs, a bad ``out`` or argument refused by name.

References: the forward dynamics against the KKT system assembled and solved in NumPy
(``backend="numpy"``) and the kernel called through its checked DirectFunction path; the step
against the table stepper called through ctypes (``TableStep.__call__``), its ``A`` and ``B``
against central differences of the door's own steps; the joint step against ``x⁺`` written in
NumPy from ``nc.aba``."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import ModelError, NcgenError, ShapeError
from ncgen.runtime import dynamics_at_state
from ncgen.runtime.dynamics_at_state import forward_dynamics_kernel

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"

TWO_LINK = """<robot name="door_two_link">
  <link name="base"><inertial><mass value="1"/>
    <inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="upper"><inertial><origin xyz="0.25 0 0.01"/><mass value="1.5"/>
    <inertia ixx="0.01" iyy="0.03" izz="0.03" ixy="0.001" ixz="0" iyz="0"/></inertial></link>
  <link name="fore"><inertial><origin xyz="0.2 0 0.02"/><mass value="0.8"/>
    <inertia ixx="0.005" iyy="0.02" izz="0.02" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="12" velocity="5"/></joint>
  <joint name="elbow" type="revolute"><parent link="upper"/><child link="fore"/><origin xyz="0.5 0 0"/>
    <axis xyz="0 0.6 0.8"/><limit lower="-3" upper="3" effort="4" velocity="5"/></joint>
</robot>"""


@pytest.fixture(scope="module")
def chain():
    return nc.System.from_toml(EXAMPLES / "chain.toml").build()


@pytest.fixture(scope="module")
def cartpole():
    return nc.System.from_toml(EXAMPLES / "cartpole.toml").build()


def moving(model, st, u, steps: int = 4) -> np.ndarray:
    """A moving state on the constraint manifold: ``steps`` steps of ``st`` from the initial one."""
    x = np.concatenate([model.q0, model.v0])
    for _ in range(steps):
        x = st(x, u)
    return x


def bad_outs(shapes):
    """``(what, out)`` pairs each wrong in one way for outputs of ``shapes`` (a tuple for several)."""
    several = isinstance(shapes, list)
    shapes = shapes if several else [shapes]
    good = [np.empty(s) for s in shapes]

    def with_(k, a):
        outs = list(good)
        outs[k] = a
        return tuple(outs) if several else outs[0]

    read_only = np.empty(shapes[0])
    read_only.flags.writeable = False
    cases = [("shape", with_(0, np.empty((shapes[0][0] + 1,) + shapes[0][1:]))),
             ("dtype", with_(0, np.empty(shapes[0], dtype=np.float32))),
             ("non-contiguous", with_(0, np.empty((shapes[0][0] * 2,) + shapes[0][1:])[::2])),
             ("read-only", with_(0, read_only))]
    if several:
        cases += [("an array, not a tuple", good[0]), ("too few", tuple(good[:-1]))]
    return cases


def test_forward_dynamics_door_equals_the_kernel_and_the_kkt_solve(chain, monkeypatch):
    st = nc.step_function(chain, 0.01)
    x = moving(chain, st, None)
    q, v = x[:chain.nq], x[chain.nq:]
    a, lam = nc.forward_dynamics(chain, q, v, backend="compiled")
    door = chain.data.forward_dynamics_door
    if not door:
        pytest.skip("no fast-call extension here (no Python headers or compiler)")
    k = forward_dynamics_kernel(chain)
    ref_a, ref_lam = (o.copy() for o in k.checked(0.0, q, v, np.zeros(chain.nu), chain.p0))
    assert np.array_equal(a, ref_a) and np.array_equal(lam, ref_lam)
    na, nlam = nc.forward_dynamics(chain, q, v)                  # the KKT system in NumPy
    np.testing.assert_allclose(a, na, rtol=0, atol=1e-9 * (1 + np.abs(na).max()))
    np.testing.assert_allclose(lam, nlam, rtol=0, atol=1e-9 * (1 + np.abs(nlam).max()))
    out = (np.full(chain.nq, np.nan), np.full(chain.nc, np.nan))
    got = nc.forward_dynamics(chain, list(q), v, backend="compiled", out=out)
    assert got is out and np.array_equal(out[0], a) and np.array_equal(out[1], lam)
    # a good call is the door alone: the checked path's conversions are not reached
    monkeypatch.setattr(dynamics_at_state, "as_vector", lambda *a: pytest.fail("checked path taken"))
    assert np.array_equal(nc.forward_dynamics(chain, q, v, backend="compiled", t=0.25)[0], a)
    assert np.array_equal(nc.forward_dynamics(chain, q, v, backend="compiled", out=out)[1], lam)


def test_forward_dynamics_refuses_a_bad_out_or_argument_by_name(chain):
    q, v = np.array(chain.q0, float), np.array(chain.v0, float)
    a, lam = nc.forward_dynamics(chain, q, v, backend="compiled")
    for what, out in bad_outs([(chain.nq,), (chain.nc,)]):
        with pytest.raises(ShapeError, match="forward_dynamics: out"):
            nc.forward_dynamics(chain, q, v, backend="compiled", out=out)
    bad = q.copy()
    bad[3] = np.nan
    with pytest.raises(ShapeError, match="^q: expected finite numbers"):
        nc.forward_dynamics(chain, bad, v, backend="compiled")
    with pytest.raises(ShapeError, match="^v: expected finite numbers"):
        nc.forward_dynamics(chain, q, np.full(chain.nq, np.inf), backend="compiled")
    with pytest.raises(ShapeError, match=f"^v: expected {chain.nq} numbers"):
        nc.forward_dynamics(chain, q, v[:-1], backend="compiled")
    with pytest.raises(ShapeError, match="^t"):
        nc.forward_dynamics(chain, q, v, t=float("nan"), backend="compiled")
    door = chain.data.forward_dynamics_door
    if door:                                 # q = 0: every bar of zero length, the KKT matrix singular
        assert door.call(np.zeros(chain.nq), v, door.zero_u) is None          # its NaN found in C
    with pytest.raises(ModelError, match="KKT matrix .* is singular at this state"):
        nc.forward_dynamics(chain, np.zeros(chain.nq), v, backend="compiled")
    a2, lam2 = nc.forward_dynamics(chain, q, v, backend="compiled")       # the door still works after them
    assert np.array_equal(a2, a) and np.array_equal(lam2, lam)


@pytest.mark.parametrize("name", ["chain", "cartpole"])
def test_step_door_equals_the_table_stepper_and_writes_out(name, request, monkeypatch):
    model = request.getfixturevalue(name)
    st = nc.step_function(model, 0.01)
    assert st.kernels == "tables"
    if st._doors is None:
        pytest.skip("no fast-call extension here (no Python headers or compiler)")
    u = np.full(model.nu, 0.7)
    x = moving(model, st, u)
    for t in (None, 0.3):
        x1 = st(x, u, t=t)
        ref = st._table(x, u, model.t0 if t is None else t, True)
        assert ref[0] == 0 and np.array_equal(x1, ref[1])
        J = st.jacobians(x, u, t=t)
        assert [j.shape for j in J] == [(st.nx,), (st.nx, st.nx), (st.nx, st.nu)]
        assert all(np.array_equal(j, r) and j.flags.c_contiguous for j, r in zip(J, (ref[1], ref[4], ref[5])))
    out = np.full(st.nx, np.nan)
    assert st(x, u, out=out) is out and np.array_equal(out, st(x, u))
    outs = tuple(np.full(j.shape, np.nan) for j in J)
    assert st.jacobians(x, u, out=outs) is outs and all(np.array_equal(o, j) for o, j in zip(outs, st.jacobians(x, u)))
    # a good call is the door alone: the ctypes path is not reached
    monkeypatch.setattr(st, "_table_solve", lambda *a: pytest.fail("checked path taken"))
    assert np.array_equal(st(x, u.tolist()), x1) and np.array_equal(st.jacobians(x, u, out=outs)[1], J[1])


def test_step_door_jacobians_against_central_differences(cartpole):
    st = nc.step_function(cartpole, 0.01)
    u = np.array([0.7])
    x = moving(cartpole, st, u)
    _, A, B = st.jacobians(x, u)
    eps = 1e-6
    dA = np.column_stack([(st(x + eps * e, u) - st(x - eps * e, u)) / (2 * eps) for e in np.eye(st.nx)])
    dB = (st(x, u + eps) - st(x, u - eps)) / (2 * eps)
    np.testing.assert_allclose(A, dA, rtol=0, atol=1e-6 * (1 + np.abs(A).max()))
    np.testing.assert_allclose(B[:, 0], dB, rtol=0, atol=1e-6 * (1 + np.abs(B).max()))


def test_step_refuses_a_bad_out_or_argument_and_a_step_that_fails(cartpole):
    st = nc.step_function(cartpole, 0.01)
    x, u = np.concatenate([cartpole.q0, cartpole.v0]), np.array([0.5])
    for what, out in bad_outs((st.nx,)):
        with pytest.raises(ShapeError, match="StepFunction: out"):
            st(x, u, out=out)
    for what, out in bad_outs([(st.nx,), (st.nx, st.nx), (st.nx, st.nu)]):
        with pytest.raises(ShapeError, match="StepFunction.jacobians: out"):
            st.jacobians(x, u, out=out)
    bad = x.copy()
    bad[2] = np.nan
    with pytest.raises(NcgenError, match="^x: expected 16 finite number"):
        st(bad, u)
    with pytest.raises(NcgenError, match="^u: expected 1 finite number"):
        st.jacobians(x, [np.inf])
    with pytest.raises(NcgenError, match="^u: expected 1 finite number"):
        st(x, [0.1, 0.2])
    far = x.copy()
    far[:cartpole.nq] += 5.0                 # far off the constraints: one Newton iteration cannot reach them
    short = nc.step_function(cartpole, 0.02, max_iter=1)
    with pytest.raises(nc.StepDidNotConverge, match="residual"):
        short(far, u)
    with pytest.raises(nc.StepDidNotConverge, match="residual"):
        short.jacobians(far, u)
    assert np.all(np.isfinite(st(x, u)))     # the door still works after them


@pytest.fixture(scope="module")
def two_link():
    pytest.importorskip("yourdfpy")
    return nc.System.from_urdf(TWO_LINK).build()


def test_joint_step_call_and_jacobians_doors_write_out(two_link, monkeypatch):
    h, n = 0.01, 2
    st = nc.JointStep(two_link, h)
    rng = np.random.default_rng(3)
    x, tau = rng.uniform(-1, 1, 2 * n), rng.uniform(-2, 2, n)
    x1 = st(x, tau)
    v1 = x[n:] + h * nc.aba(two_link, x[:n], x[n:], tau)
    np.testing.assert_allclose(x1, np.concatenate([x[:n] + h * v1, v1]), rtol=0, atol=1e-14)
    J = st.jacobians(x, tau)
    assert np.array_equal(J[0], x1)                     # one formula for x⁺ in both
    ref = st.unchecked_jacobians(x, tau)
    assert all(np.array_equal(a, b) for a, b in zip(J, ref))
    out = np.full(2 * n, np.nan)
    assert st(x, tau, out=out) is out and np.array_equal(out, x1)
    outs = tuple(np.full(j.shape, np.nan) for j in J)
    assert st.jacobians(x, tau, out=outs) is outs and all(np.array_equal(o, j) for o, j in zip(outs, J))
    for what, bad in bad_outs((2 * n,)):
        with pytest.raises(ShapeError, match="JointStep: out"):
            st(x, tau, out=bad)
    for what, bad in bad_outs([(2 * n,), (2 * n, 2 * n), (2 * n, n)]):
        with pytest.raises(ShapeError, match="JointStep.jacobians: out"):
            st.jacobians(x, tau, out=bad)
    nan_x = x.copy()
    nan_x[1] = np.nan
    with pytest.raises(ShapeError, match=r"^x \(joint positions and rates"):
        st(nan_x, tau)
    with pytest.raises(ShapeError, match=r"^tau \(efforts"):
        st.jacobians(x, np.array([1.0, np.inf]))
    with pytest.raises(ShapeError, match=r"^x \(joint positions and rates"):
        st(x[:-1], tau)
    if st._straight_call is not None and st._straight_jacobians is not None:    # the C callers alone
        monkeypatch.setattr(st, "unchecked", lambda *a, **k: pytest.fail("checked path taken"))
        monkeypatch.setattr(st, "unchecked_jacobians", lambda *a, **k: pytest.fail("checked path taken"))
        assert np.array_equal(st(list(x), tau), x1) and np.array_equal(st.jacobians(x, tau, out=outs)[2], J[2])

"""The Python doors of the compiled tree algorithms (``nc.rnea``, ``nc.aba``, ``nc.crba``,
``nc.inverse_dynamics``, ``nc.joint_forward_dynamics`` and the kernels of ``nc.algorithm_kernel``;
issue 37): the arguments
go straight to C, whose copy checks their kinds, sizes and magnitudes, and every bad value
still gets the message naming the argument, what was expected and what was found; time and
parameters reach the kernel whichever path set them last; results are copies.

Reference: a 3D hinged body in closed form, ``τ = J a − m g ℓ cos θ + ℓ cos θ (k + sin t)``
(``J`` about the hinge, the lifting force ``k + sin t`` (N, up) applied at the centre of mass,
lever ``ℓ = 0.5`` m)."""
from __future__ import annotations

import re

import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import NcgenError
from ncgen.runtime.tree_algorithm_kernels import door
from test_reliability_arrays import bad_values

M, L, G, IYY, K0 = 2.0, 0.5, 9.81, 0.03, 3.0


@pytest.fixture(scope="module")
def hinge():
    """A body on a hinge about y at the origin, its centre of mass 0.5 m along x, with the
    parameter ``k`` and the time in its applied force."""
    s = nc.System("hinge3d", gravity=(0, 0, -G))
    b = s.add_body("link", mass=M, inertia=np.diag([0.01, IYY, 0.02]), position=(L, 0, 0), coords="ruvw")
    k = s.add_parameter("k", K0)
    s.add_input("tau")
    s.add_joint(nc.Revolute(s.ground, b, at=(0, 0, 0), axis=(0, 1, 0), name="hinge", effort="tau"))
    s.add_force(nc.PointForce(b, (0, 0, 0), force=[0, 0, k], name="lift"))
    s.add_force(nc.PointForce(b, (0, 0, 0), force=[0, 0, "sin(t)"], name="wind"))
    return s.build()


def closed_form(theta, a, t, k):
    c = np.cos(theta)
    return (IYY + M * L**2) * a - M * G * L * c + L * c * (k + np.sin(t))


def test_time_and_parameters_reach_the_kernel_whatever_set_them_last(hinge):
    th, v, a = 0.3, 0.2, 0.7
    for t, p in ((0.0, None), (0.4, [5.0]), (0.4, None), (1.3, None), (1.3, np.array([-2.0])), (0.0, None)):
        k = K0 if p is None else float(np.ravel(p)[0])
        want = closed_form(th, a, t, k)
        for f in (nc.rnea, nc.inverse_dynamics):
            got = f(hinge, [th], [v], [a], t=t, p=p)
            assert got == pytest.approx([want], abs=1e-12), (f.__name__, t, p)
        tau = 1.7                                            # and back: the forward dynamics
        want_a = (tau + M * G * L * np.cos(th) - L * np.cos(th) * (k + np.sin(t))) / (IYY + M * L**2)
        assert nc.aba(hinge, [th], [v], [tau], t=t, p=p) == pytest.approx([want_a], abs=1e-12)
        assert nc.joint_forward_dynamics(hinge, [th], [v], [tau], t=t, p=p) == pytest.approx([want_a], abs=1e-12)
    assert door(hinge, "aba").free is None                   # its ABA depends on t and p: never straight to C
    kernel = nc.algorithm_kernel(hinge, "rnea")              # the kernel's own set() changes what it uses,
    kernel.set(t=2.0, p=[7.0])                               # and the functions put back their own
    assert kernel([th], [v], [a]) == pytest.approx([closed_form(th, a, 2.0, 7.0)], abs=1e-12)
    assert nc.rnea(hinge, [th], [v], [a]) == pytest.approx([closed_form(th, a, 0.0, K0)], abs=1e-12)


def test_results_are_copies(hinge):
    first = nc.rnea(hinge, np.array([0.1]), np.array([0.0]), np.array([1.0]))
    kept = first.copy()
    nc.rnea(hinge, np.array([1.0]), np.array([0.0]), np.array([-3.0]))
    np.testing.assert_array_equal(first, kept)
    M1 = nc.crba(hinge, [0.2])
    assert M1.shape == (1, 1) and M1[0, 0] == pytest.approx(IYY + M * L**2, abs=1e-12)
    nc.crba(hinge, [0.4])[...] = 0.0
    np.testing.assert_array_equal(nc.crba(hinge, [0.2]), M1)


def test_accepted_forms_agree(hinge):
    """Float arrays, lists, ints, NumPy scalars in a list, float32 and columns' values: one answer."""
    want = nc.rnea(hinge, np.array([0.5]), np.array([0.0]), np.array([2.0]))
    for qj, aj in (([0.5], [2]), ((0.5,), [np.float64(2.0)]), ([np.float32(0.5)], [np.int64(2)]),
                   (np.array([0.5], np.float32), np.array([2]))):
        assert nc.rnea(hinge, qj, [0.0], aj) == pytest.approx(want, abs=1e-6)


ENTRIES = {
    "rnea qj": ("qj", lambda m, x: nc.rnea(m, x, [0.0], [0.0])),
    "rnea vj": ("vj", lambda m, x: nc.rnea(m, [0.1], x, [0.0])),
    "rnea aj": ("aj", lambda m, x: nc.rnea(m, [0.1], [0.0], x)),
    "inverse_dynamics qj": ("qj", lambda m, x: nc.inverse_dynamics(m, x, [0.0], [0.0])),
    "inverse_dynamics aj": ("aj", lambda m, x: nc.inverse_dynamics(m, [0.1], [0.0], x)),
    "aba tau": ("tau", lambda m, x: nc.aba(m, [0.1], [0.0], x)),
    "crba qj": ("qj", lambda m, x: nc.crba(m, x)),
    "rnea_derivatives vj": ("vj", lambda m, x: nc.rnea_derivatives(m, [0.1], x, [0.0])),
    "kernel aj": ("rnea: aj", lambda m, x: nc.algorithm_kernel(m, "rnea")([0.1], [0.0], x)),
    "joint_forward_dynamics qj": ("qj", lambda m, x: forward_twice(m, x, [0.0], [0.0])),
    "joint_forward_dynamics vj": ("vj", lambda m, x: forward_twice(m, [0.1], x, [0.0])),
    "joint_forward_dynamics u": ("u", lambda m, x: forward_twice(m, [0.1], [0.0], x)),
}


def forward_twice(m, qj, vj, u):
    """``nc.joint_forward_dynamics`` once with good arguments (its kernel built), then with these."""
    nc.joint_forward_dynamics(m, [0.1], [0.0], [0.0])
    return nc.joint_forward_dynamics(m, qj, vj, u)
EXTRA = {"too large": (np.array([1e101]), r"magnitude at most"),
         "bools in a list": ([True], r"expected real numbers, got (booleans|bool True)"),
         "huge int": ([10**400], r"too large"),
         "nested": ([[0.1]], r"expected 1 numbers, got shape \(1, 1\)|expected .*1.*got"),
         "0-d": (np.array(0.1), r"expected 1 numbers, got a scalar|expected .*1.*got")}
KINDS = {**bad_values(1), **EXTRA}
CASES = [(e, k) for e in ENTRIES for k in KINDS
         if not (e.startswith("kernel") and k in ("nested", "0-d", "wrong shape"))
         and (e, k) != ("crba qj", "nested")]        # crba's only argument (1, nq): one row per state, a batch of one


@pytest.mark.parametrize("entry, kind", CASES, ids=[f"{e}-{k}" for e, k in CASES])
def test_bad_values_are_named(hinge, entry, kind):
    name, call = ENTRIES[entry]
    value, found = KINDS[kind]
    with pytest.raises(NcgenError) as info:
        call(hinge, value)
    message = str(info.value)
    assert re.search(re.escape(name), message), message
    assert re.search(found, message), message


def test_the_kernel_without_the_accelerator_checks_the_same(hinge, monkeypatch):
    from ncgen.codegen import fast_call

    fast = nc.algorithm_kernel(hinge, "rnea")
    monkeypatch.setattr(fast_call, "_MODULE", [None])
    slow = fast.copy()
    assert slow._fast is None
    for k in (fast, slow):
        for value, found in (([np.nan], "finite"), ([np.inf], "finite"), ([True], "real numbers"),
                             ([1e200], "magnitude")):
            with pytest.raises(NcgenError, match=found):
                k([0.1], value, [0.0])
        assert k([0.3], [0.2], [0.7]) == pytest.approx([closed_form(0.3, 0.7, 0.0, K0)], abs=1e-12)


# ------------------------------------------------------------------ many states in one call
@pytest.mark.slow      # robot scale (Solo-12's derivative kernels at -O1); fast: the hinge's rows below
def test_one_row_per_state_equals_pinocchio_state_by_state():
    """``nc.rnea``/``crba``/``aba`` and the derivatives with one row per state: one C loop,
    equal to Pinocchio's state by state (a floating-base robot: quaternions normalised per
    row), and to the single-state call."""
    pin = pytest.importorskip("pinocchio")
    from pinocchio_robots import JointMap, pinocchio_models, random_configuration, urdf_text

    model = nc.System.from_urdf(urdf_text("solo12"), floating_base=True).build()
    pm = pinocchio_models("solo12")[1]
    data, jm, rng = pm.createData(), JointMap(model, pm), np.random.default_rng(1)
    n = 20
    QP = np.array([random_configuration(pm, rng) for _ in range(n)])
    QJ = np.array([jm.q_to_ncgen(q) for q in QP])
    QJ[:, 3:7] *= 1.0 + rng.random((n, 1))                       # the base quaternion not of unit norm
    VJ, AJ = rng.normal(size=(n, jm.nv)), rng.normal(size=(n, jm.nv))
    tau, M = nc.rnea(model, QJ, VJ, AJ), nc.crba(model, QJ)
    acc = nc.aba(model, QJ, VJ, tau)
    d_tau = nc.rnea_derivatives(model, QJ, VJ, AJ)
    assert tau.shape == (n, jm.nv) and M.shape == (n, jm.nv, jm.nv) and d_tau[1].shape == (n, jm.nv, jm.nv)
    for i in range(n):
        vp, ap = jm.P @ VJ[i], jm.P @ AJ[i]
        assert np.allclose(jm.P @ tau[i], pin.rnea(pm, data, QP[i], vp, ap), atol=1e-9)
        assert np.allclose(jm.P @ M[i] @ jm.P.T, pin.crba(pm, data, QP[i]), atol=1e-9)
        assert np.allclose(acc[i], AJ[i], atol=1e-8)                # ABA inverts RNEA
        single = nc.rnea_derivatives(model, QJ[i], VJ[i], AJ[i])
        assert all(np.array_equal(b[i], s) for b, s in zip(d_tau, single))


def test_a_bad_row_is_named(hinge):
    Q, V, A = np.zeros((5, 1)), np.zeros((5, 1)), np.zeros((5, 1))
    Q[3, 0] = np.nan
    with pytest.raises(NcgenError, match=r"rnea: qj \(joint positions, joint_names order\): row 3: expected finite"):
        nc.rnea(hinge, Q, V, A)
    with pytest.raises(NcgenError, match=r"rnea: vj .*: expected 5 rows \(the rows of qj\) of 1 values, got shape "
                                         r"\(4, 1\)"):
        nc.rnea(hinge, np.zeros((5, 1)), np.zeros((4, 1)), A)
    theta = np.linspace(-1.0, 1.0, 5)[:, None]
    assert np.allclose(nc.rnea(hinge, theta, V, np.ones((5, 1)))[:, 0],
                       closed_form(theta[:, 0], 1.0, 0.0, K0), rtol=1e-12)


def test_rows_without_the_accelerator_give_the_same(hinge, monkeypatch):
    theta = np.linspace(-1.0, 1.0, 4)[:, None]
    with_c = nc.rnea_derivatives(hinge, theta, np.ones((4, 1)), np.ones((4, 1)))
    from ncgen.runtime import tree_algorithm_kernels as tree_algorithms
    k = tree_algorithms.algorithm_kernel(hinge, "rnea_derivatives")
    monkeypatch.setattr(k, "_fast", None)
    without = tree_algorithms.batch(hinge, k, (theta, np.ones((4, 1)), np.ones((4, 1))), None, 0.0)
    assert all(np.array_equal(a, b) for a, b in zip(with_c, without))

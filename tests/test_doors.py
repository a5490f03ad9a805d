"""The doors of the compiled tree algorithms (issue 37): ``nc.rnea``, ``nc.crba``, ``nc.aba``,
their derivatives, ``nc.inverse_dynamics`` and ``nc.joint_forward_dynamics`` take one C call
(:class:`ncgen.runtime.tree_algorithm_kernels.Door`: checks, quaternion normalisation, kernel,
pivot check and fresh outputs or ``out=`` in C), and give what the checked Python path and
Pinocchio give.

References: Pinocchio's ``rnea``, ``crba``, ``aba``, ``computeRNEADerivatives`` and
``computeABADerivatives`` on the same URDF (a free-flying three-link tree whose base
quaternion is given unnormalised and with ``qw < 0``), to 1e-10; the checked Python path
(``Door.checked``: ``unit_quaternions`` in NumPy) bit for bit."""
from __future__ import annotations

import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import ModelError, NcgenError, ShapeError
from ncgen.model.data import model_data
from ncgen.runtime import tree_algorithm_kernels as rta

URDF = """<robot name="door_tree">
  <link name="base"><inertial><mass value="3.0"/><origin xyz="0.01 0 0.02"/>
    <inertia ixx="0.05" iyy="0.06" izz="0.07" ixy="0.001" ixz="0" iyz="0.002"/></inertial></link>
  <link name="a"><inertial><mass value="1.2"/><origin xyz="0 0.02 0.15" rpy="0.1 0.2 0.3"/>
    <inertia ixx="0.011" iyy="0.012" izz="0.004" ixy="0.0005" ixz="0" iyz="0"/></inertial></link>
  <link name="b"><inertial><mass value="0.8"/><origin xyz="0.02 0 0.1"/>
    <inertia ixx="0.006" iyy="0.007" izz="0.002" ixy="0" ixz="0.0003" iyz="0"/></inertial></link>
  <link name="c"><inertial><mass value="0.5"/><origin xyz="0.05 0.01 0"/>
    <inertia ixx="0.002" iyy="0.003" izz="0.0025" ixy="0" ixz="0" iyz="0.0001"/></inertial></link>
  <joint name="ja" type="revolute"><parent link="base"/><child link="a"/>
    <origin xyz="0.1 0 0.05" rpy="0.2 0 0.1"/>
    <axis xyz="0 1 0"/><limit effort="50" velocity="3" lower="-3" upper="3"/></joint>
  <joint name="jb" type="revolute"><parent link="a"/><child link="b"/>
    <origin xyz="0 0 0.3" rpy="0 0.3 0"/>
    <axis xyz="1 0 1"/><limit effort="50" velocity="3" lower="-3" upper="3"/></joint>
  <joint name="jc" type="prismatic"><parent link="base"/><child link="c"/>
    <origin xyz="-0.1 0.05 0" rpy="0 0 0.4"/>
    <axis xyz="0 0 1"/><limit effort="50" velocity="3" lower="-1" upper="1"/></joint>
</robot>"""

TOL = 1e-10


@pytest.fixture(scope="module")
def tree():
    return nc.System.from_urdf(URDF, floating_base=True).build()


def state(model, seed=0):
    """``(qj, vj, aj, tau)`` with the base quaternion of norm 1.7 and ``qw < 0``."""
    rng = np.random.default_rng(seed)
    js = model.joint_space
    qj = rng.uniform(-1, 1, js.nq)
    s = js.slices()["root"]
    quat = rng.normal(size=4)
    quat[3] = -abs(quat[3])
    qj[s.stop - 4:s.stop] = 1.7 * quat / np.linalg.norm(quat)
    return qj, rng.normal(size=js.nv), rng.normal(size=js.nv), rng.normal(size=js.nv)


CALLS = {
    "rnea": lambda m, x, out=None: nc.rnea(m, x[0], x[1], x[2], out=out),
    "crba": lambda m, x, out=None: nc.crba(m, x[0], out=out),
    "aba": lambda m, x, out=None: nc.aba(m, x[0], x[1], x[3], out=out),
    "rnea_derivatives": lambda m, x, out=None: nc.rnea_derivatives(m, x[0], x[1], x[2], out=out),
    "aba_derivatives": lambda m, x, out=None: nc.aba_derivatives(m, x[0], x[1], x[3], out=out),
    "inverse_dynamics": lambda m, x, out=None: nc.inverse_dynamics(m, x[0], x[1], x[2], joints="all", out=out),
    "joint_forward_dynamics": lambda m, x, out=None: nc.joint_forward_dynamics(m, x[0], x[1], out=out),
}


def close(got, ref):
    np.testing.assert_allclose(got, ref, rtol=0, atol=TOL * max(1.0, float(np.abs(ref).max())))


def test_every_door_equals_pinocchio(tree):
    pin = pytest.importorskip("pinocchio")
    from pinocchio_robots import JointMap

    pm = pin.buildModelFromXML(URDF, pin.JointModelFreeFlyer())
    d, jm = pm.createData(), JointMap(tree, pm)
    P = jm.P
    for seed in range(3):
        x = state(tree, seed)
        qj, vj, aj, tau = x
        qu = qj.copy()
        s = tree.joint_space.slices()["root"]
        qu[s.stop - 4:s.stop] /= np.linalg.norm(qu[s.stop - 4:s.stop])       # Pinocchio takes unit quaternions
        qp, vp, ap = jm.q_to_pin(qu, pm.nq), P @ vj, P @ aj
        M = P.T @ pin.crba(pm, d, qp) @ P
        M = np.triu(M) + np.triu(M, 1).T
        a_ref = P.T @ pin.aba(pm, d, qp, vp, P @ tau)
        close(CALLS["rnea"](tree, x), P.T @ pin.rnea(pm, d, qp, vp, ap))
        close(CALLS["inverse_dynamics"](tree, x), P.T @ pin.rnea(pm, d, qp, vp, ap))
        close(CALLS["crba"](tree, x), M)
        close(CALLS["aba"](tree, x), a_ref)
        close(nc.joint_forward_dynamics(tree, qj, vj, np.zeros(tree.nu)), P.T @ pin.aba(pm, d, qp, vp, np.zeros(pm.nv)))
        rdq, rdv, _ = pin.computeRNEADerivatives(pm, d, qp, vp, ap)
        for got, ref in zip(CALLS["rnea_derivatives"](tree, x), (P.T @ pin.rnea(pm, d, qp, vp, ap), P.T @ rdq @ P,
                                                                  P.T @ rdv @ P, M)):
            close(got, ref)
        adq, adv, aM = pin.computeABADerivatives(pm, d, qp, vp, P @ tau)
        for got, ref in zip(CALLS["aba_derivatives"](tree, x), (a_ref, P.T @ adq @ P, P.T @ adv @ P,
                                                                 P.T @ (np.triu(aM) + np.triu(aM, 1).T) @ P)):
            close(got, ref)


def test_auto_rnea_takes_the_tables_and_both_kernels_equal_pinocchio(tree):
    """``kernels="auto"`` runs RNEA (and ``inverse_dynamics``) on the tree tables, which measure
    faster than the flat kernel (:data:`~ncgen.runtime.tree_algorithm_kernels.TABLES_FIRST`),
    says why, and keeps the flat CRBA; the tables and the flat kernel, one state and rows of
    states, equal Pinocchio's ``rnea`` to 1e-10."""
    pin = pytest.importorskip("pinocchio")
    from pinocchio_robots import JointMap

    assert rta.algorithm_kernels(tree, "rnea") == "tables"
    assert "measures faster" in rta.kernels_reason(tree, "rnea")
    nc.inverse_dynamics(tree, *state(tree)[:3], joints="all")
    assert rta.door(tree, "rnea").tables and model_data(tree).rnea_efforts["all"] is True
    assert rta.algorithm_kernels(tree, "crba") == "flat" and rta.kernels_reason(tree, "rnea", "flat") == "chosen (kernels=)"
    pm = pin.buildModelFromXML(URDF, pin.JointModelFreeFlyer())
    d, jm = pm.createData(), JointMap(tree, pm)
    s = tree.joint_space.slices()["root"]
    xs = [state(tree, seed) for seed in range(4)]
    refs = []
    for qj, vj, aj, _ in xs:
        qu = qj.copy()
        qu[s.stop - 4:s.stop] /= np.linalg.norm(qu[s.stop - 4:s.stop])
        refs.append(jm.P.T @ pin.rnea(pm, d, jm.q_to_pin(qu, pm.nq), jm.P @ vj, jm.P @ aj))
    Q, V, A = (np.array([x[i] for x in xs]) for i in range(3))
    for kernels in ("tables", "flat"):
        for x, ref in zip(xs, refs):
            close(nc.rnea(tree, *x[:3], kernels=kernels), ref)
        close(nc.rnea(tree, Q, V, A, kernels=kernels), np.array(refs))


@pytest.mark.parametrize("name", list(CALLS))
def test_out_is_written_in_place_and_equals_the_checked_path(tree, name):
    """``out=`` receives the result and is returned; the C door (quaternion normalised in C)
    equals the checked Python path bit for bit, fresh results are new arrays, matrices row-major."""
    x = state(tree, 3)
    fresh = CALLS[name](tree, x)
    several = type(fresh) is tuple
    out = tuple(np.full_like(f, np.nan) for f in fresh) if several else np.full_like(fresh, np.nan)
    got = CALLS[name](tree, x, out)
    assert got is out
    for f, o in zip(fresh if several else (fresh,), out if several else (out,)):
        np.testing.assert_array_equal(o, f)
        assert f.flags.c_contiguous and f.flags.owndata
    if name in rta.ALGORITHMS:
        args = {"rnea": x[:3], "crba": x[:1], "aba": (x[0], x[1], x[3]), "rnea_derivatives": x[:3],
                "aba_derivatives": (x[0], x[1], x[3])}[name]
        checked = rta.door(tree, name).checked(tuple(args), None, 0.0, None)
        for f, c in zip(fresh if several else (fresh,), checked if several else (checked,)):
            np.testing.assert_array_equal(f, c)
    again = CALLS[name](tree, x)                                     # a second call: new arrays, the first kept
    for a, f in zip(again if several else (again,), fresh if several else (fresh,)):
        assert a is not f and np.array_equal(a, f)


def test_rows_of_states_write_out_too(tree):
    X = [np.array([state(tree, s)[i] for s in range(4)]) for i in range(4)]
    fresh = nc.rnea(tree, X[0], X[1], X[2])
    out = np.empty_like(fresh)
    assert nc.rnea(tree, X[0], X[1], X[2], out=out) is out
    np.testing.assert_array_equal(out, fresh)
    for i in range(4):
        np.testing.assert_array_equal(fresh[i], nc.rnea(tree, X[0][i], X[1][i], X[2][i]))


@pytest.mark.parametrize("name", ["rnea", "crba", "aba"])
def test_rows_are_normalised_and_checked_in_c_and_a_bad_row_is_named(tree, name):
    """Rows of states through the door's C loop (quaternions of norm 1.7 with ``qw < 0``
    normalised row by row in C) equal the one-state doors bit for bit, on the tables (RNEA) and
    the flat kernels (CRBA, ABA); a zero quaternion or a value out of bound in row 2 is named
    with its row, as the NumPy check names it.  The tables' RNEA checks and normalises the rows in
    its own loop (the library's ``rnea_rows``), the others in the door's caller."""
    X = [np.array([state(tree, s)[i] for s in range(4)]) for i in range(4)]
    args = {"rnea": X[:3], "crba": X[:1], "aba": [X[0], X[1], X[3]]}[name]
    rows = getattr(nc, name)(tree, *args)
    assert (getattr(rta.door(tree, name).kernel, "_rows", None) is not None) == (name == "rnea")
    for i in range(4):
        np.testing.assert_array_equal(rows[i], getattr(nc, name)(tree, *(x[i] for x in args)))
    s = tree.joint_space.slices()["root"]
    zero = [x.copy() for x in args]
    zero[0][2, s.stop - 4:s.stop] = 0.0
    with pytest.raises(ModelError, match=r"qj\['root'\]: the quaternion \[qx, qy, qz, qw\] is zero in row 2"):
        getattr(nc, name)(tree, *zero)
    huge = [x.copy() for x in args]
    huge[-1][2, 0] = np.inf
    with pytest.raises(ShapeError, match=r"row 2: expected finite numbers"):
        getattr(nc, name)(tree, *huge)


BAD_OUTS = {
    "float32": (lambda r: r.astype(np.float32), r"got float32 array"),
    "shape": (lambda r: np.zeros(r.size + 1), r"got float64 array of shape \(10,\)"),
    "strided": (lambda r: np.zeros(2 * r.size)[::2], r"not C-contiguous"),
    "read-only": (lambda r: np.frombuffer(bytes(8 * r.size)), r"read-only"),
    "list": (lambda r: [0.0] * r.size, r"got list"),
}


@pytest.mark.parametrize("kind", list(BAD_OUTS))
def test_a_bad_out_is_named(tree, kind):
    x = state(tree, 4)
    make, found = BAD_OUTS[kind]
    ref = nc.rnea(tree, *x[:3])
    out = make(ref)
    before = np.array(out, dtype=float, copy=True)
    for f in (lambda: nc.rnea(tree, *x[:3], out=out), lambda: nc.inverse_dynamics(tree, *x[:3], joints="all", out=out),
              lambda: nc.aba(tree, x[0], x[1], x[3], out=out), lambda: nc.joint_forward_dynamics(tree, x[0], x[1], out=out)):
        with pytest.raises(ShapeError, match=r"(rnea|inverse_dynamics|aba|joint_forward_dynamics): out: expected a "
                                             r"writable C-contiguous "
                                             r"float64 array of shape \(9,\), " + ".*" + found):
            f()
    np.testing.assert_array_equal(np.asarray(out, dtype=float), before)            # nothing written
    with pytest.raises(ShapeError, match=r"rnea_derivatives: out: expected a tuple of 4 arrays"):
        nc.rnea_derivatives(tree, *x[:3], out=np.zeros(9))
    with pytest.raises(ShapeError, match=r"rnea_derivatives: out: .* of shape \(9, 9\), got float64 array of shape "
                                         r"\(9,\)"):
        nc.rnea_derivatives(tree, *x[:3], out=tuple(np.zeros(9) for _ in range(4)))


BAD_MATRIX_OUTS = {
    "float32": (lambda r: r.astype(np.float32), r"got float32 array"),
    "shape": (lambda r: np.zeros((9, 10)), r"got float64 array of shape \(9, 10\)"),
    "transposed": (lambda r: np.zeros((9, 9)).T, r"not C-contiguous"),
    "strided": (lambda r: np.zeros((18, 9))[::2], r"not C-contiguous"),
    "a vector": (lambda r: np.zeros(81), r"got float64 array of shape \(81,\)"),
}


@pytest.mark.parametrize("kind", list(BAD_MATRIX_OUTS))
def test_a_bad_matrix_out_is_named(tree, kind):
    """CRBA's ``out`` and a matrix of the derivatives' ``out`` refused by name, nothing written."""
    x = state(tree, 4)
    make, found = BAD_MATRIX_OUTS[kind]
    M = nc.crba(tree, x[0])
    out = make(M)
    before = out.copy()
    with pytest.raises(ShapeError, match=r"crba: out: expected a writable C-contiguous float64 array of shape "
                                         r"\(9, 9\), .*" + found):
        nc.crba(tree, x[0], out=out)
    outs = (np.zeros(9), np.zeros((9, 9)), out, np.zeros((9, 9)))
    with pytest.raises(ShapeError, match=r"aba_derivatives: out: .* of shape \(9, 9\), .*" + found):
        nc.aba_derivatives(tree, x[0], x[1], x[3], out=outs)
    np.testing.assert_array_equal(out, before)


def test_bad_arguments_are_named_at_the_door(tree):
    qj, vj, aj, tau = state(tree, 5)
    for f in (nc.rnea, nc.aba):
        bad = vj.copy()
        bad[2] = np.nan
        with pytest.raises(ShapeError, match=r"vj \(joint rates, joint_names order\): expected finite numbers, "
                                             r"got \[.*, nan, "):
            f(tree, qj, bad, aj)
        with pytest.raises(ShapeError, match=r"vj \(joint rates, joint_names order\): expected 9 numbers, got 8"):
            f(tree, qj, vj[:8], aj)
        with pytest.raises(NcgenError, match=r"vj.*expected real numbers"):
            f(tree, qj, vj.astype(complex), aj)
    zero = qj.copy()
    s = tree.joint_space.slices()["root"]
    zero[s.stop - 4:s.stop] = 0.0
    with pytest.raises(ModelError, match=r"qj\['root'\]: the quaternion \[qx, qy, qz, qw\] is zero"):
        nc.rnea(tree, zero, vj, aj)
    with pytest.raises(ModelError, match=r"qj\['root'\]: the quaternion \[qx, qy, qz, qw\] is zero"):
        nc.joint_forward_dynamics(tree, zero, vj)


def test_a_good_call_takes_the_c_door_only(tree, monkeypatch):
    """Arrays of the right sizes at the last call's time and parameters never reach the
    Python checks (which would cost microseconds)."""
    x = state(tree, 6)
    for name in ("rnea", "crba", "aba", "rnea_derivatives", "aba_derivatives", "inverse_dynamics"):
        CALLS[name](tree, x)                                                     # doors built, kernels compiled

    def refused(*args, **kwargs):
        raise AssertionError("the checked path was taken")

    monkeypatch.setattr(rta.Door, "checked", refused)
    monkeypatch.setattr(rta, "as_vector", refused)
    for name in ("rnea", "crba", "aba", "rnea_derivatives", "aba_derivatives", "inverse_dynamics"):
        CALLS[name](tree, x)
        CALLS[name](tree, [list(v) for v in x])                                  # lists of floats too
    with pytest.raises(AssertionError, match="checked path"):
        nc.aba(tree, x[0], x[1], x[3], p=tree.p0)                                # parameters given: the checked path
    with pytest.raises(AssertionError, match="checked path"):
        nc.crba(tree, x[0], p=tree.p0)
    nc.rnea(tree, *x[:3], t=1.0)                        # the tables' RNEA depends on no time: the C door still
    nc.aba(tree, x[0], x[1], x[3], t=1.0)               # nor does this tree's ABA, CRBA or derivatives
    nc.crba(tree, x[0], t=1.0)
    nc.rnea_derivatives(tree, *x[:3], t=1.0)
    nc.aba_derivatives(tree, x[0], x[1], x[3], t=2.0)


def _recorded_flags(kernel) -> list[str]:
    """The -O flags in the compile cache's record of ``kernel``'s library (what gcc was given)."""
    import json

    from ncgen.codegen.compile_cache import BUILD_RECORD, recorded_flags
    return recorded_flags(json.loads((kernel.direct.library.parent / BUILD_RECORD).read_text()))


def test_a_kernel_compiled_at_O0_is_never_the_choice_of_a_default_run(monkeypatch):
    """A flat kernel compiled at -O0 (``$NCGEN_CFLAGS``, the test suite's fast tier) in this
    process is not "the flat kernel is built" once the flags are ncgen's defaults: the door
    is bound again to a kernel compiled with optimisation (the compile cache's record of its
    build), whose accelerations equal the -O0 kernel's."""
    model = nc.System.from_urdf(URDF, floating_base=True).build()
    x = state(model, 7)
    monkeypatch.setenv("NCGEN_CFLAGS", "-O0")
    slow = nc.aba(model, x[0], x[1], x[3])
    assert _recorded_flags(rta.door(model, "aba").kernel) == ["-O0"]
    assert not rta.door(model, "aba").kernel.optimised
    monkeypatch.delenv("NCGEN_CFLAGS")
    assert rta.kernels_reason(model, "aba") != "the flat kernel is built (faster than the tables')"
    fast = nc.aba(model, x[0], x[1], x[3])
    k = rta.door(model, "aba").kernel
    assert k.optimised and _recorded_flags(k) and "-O0" not in _recorded_flags(k)
    assert rta.kernels_reason(model, "aba") == "the flat kernel is built (faster than the tables')"
    close(fast, slow)


def test_the_tables_rnea_goes_straight_to_its_c_caller(tree, monkeypatch):
    """``nc.rnea`` and ``nc.inverse_dynamics`` on the tables' RNEA (which depends on no time)
    call the door's C caller without the :class:`Door` frame, at any ``t``; an argument it
    refuses still reaches the door, whose checked path names it."""
    assert rta.algorithm_kernels(tree, "rnea") == "tables"
    x = state(tree, 8)
    ref = nc.rnea(tree, *x[:3])
    entered = []
    door_call = rta.Door.__call__
    monkeypatch.setattr(rta.Door, "__call__", lambda self, *a: entered.append(1) or door_call(self, *a))
    np.testing.assert_array_equal(nc.rnea(tree, *x[:3], t=2.0), ref)
    np.testing.assert_array_equal(nc.inverse_dynamics(tree, *x[:3], joints="all"), ref)
    assert entered == []
    with pytest.raises(ShapeError, match="vj"):
        nc.rnea(tree, x[0], x[1][:-1], x[2])
    assert entered == [1]


def test_the_flat_aba_goes_straight_to_its_c_caller(tree, monkeypatch):
    """``nc.aba`` on a flat kernel whose outputs depend on neither the time nor the parameters
    (a tree without time-dependent forces or parameters) calls the door's C caller without the
    :class:`Door` frame, at any ``t``, with the result of the checked path; an argument it refuses
    still reaches the door, whose checked path names it.  (A kernel that depends on ``t`` and
    ``p``: ``test_algorithm_calls.py::test_time_and_parameters_reach_the_kernel_whatever_set_them_last``.)"""
    assert rta.algorithm_kernels(tree, "aba") == "flat"
    d = rta.door(tree, "aba")
    assert d.free is d.fast is not None
    x = state(tree, 9)
    ref = rta.call(tree, d.kernel, (x[0], x[1], x[3]), None, 0.0)
    entered = []
    door_call = rta.Door.__call__
    monkeypatch.setattr(rta.Door, "__call__", lambda self, *a: entered.append(1) or door_call(self, *a))
    np.testing.assert_array_equal(nc.aba(tree, x[0], x[1], x[3], t=2.0), ref)
    out = np.empty(tree.joint_space.nv)
    assert nc.aba(tree, x[0], x[1], x[3], out=out) is out
    np.testing.assert_array_equal(out, ref)
    assert entered == []
    with pytest.raises(ShapeError, match="tau"):
        nc.aba(tree, x[0], x[1], x[3][:-1])
    assert entered == [1]


def _sliders(name: str, masses, frames) -> nc.Model:
    """Bodies of ``masses`` on prismatic joints along z, joint k from the body ``frames[k]`` (−1: the ground)."""
    s = nc.System(name, gravity=(0.0, 0.0, -9.81))
    bodies = [s.add_body(f"b{k}", mass=m, inertia=np.diag([0.1, 0.2, 0.25]) * m, position=(0.5, 0.0, 0.0))
              for k, m in enumerate(masses)]
    for k, (b, f) in enumerate(zip(bodies, frames)):
        s.add_joint(nc.Prismatic(s.ground if f < 0 else bodies[f], b, at=(0.5, 0.0, 0.0), axis=(0, 0, 1),
                                 name=f"z{k}"))
    return s.build()


def test_a_singular_or_non_finite_aba_on_the_c_caller_is_refused_naming_why():
    """On the straight path a singular mass matrix and a non-finite result still raise the
    :class:`ModelError` saying which: two coaxial sliders with a massless (1e-15 kg) body
    between them (M = [[m1 + m2, m2], [m2, m2]]: relative pivot m1 / (m1 + m2)), and one slider
    of 1e-250 kg pushed by 1e100 N (a = τ / m = 1e350 overflows; 1 N gives the closed form 1e250 − g)."""
    coaxial = _sliders("coaxial_sliders", (1e-15, 1.0), (-1, 0))
    assert rta.door(coaxial, "aba").free is not None
    with pytest.raises(ModelError, match="mass matrix is singular"):
        nc.aba(coaxial, [0.0, 0.0], [0.0, 0.0], [0.0, 0.0])
    feather = _sliders("feather_slider", (1e-250,), (-1,))
    assert rta.door(feather, "aba").free is not None
    assert nc.aba(feather, [0.0], [0.0], [1.0]) == pytest.approx([1e250 - 9.81], rel=1e-12)
    with pytest.raises(ModelError, match="result is not finite"):
        nc.aba(feather, [0.0], [0.0], [1e100])


def test_a_door_is_found_again_until_its_kernels_or_the_flags_change(monkeypatch):
    """A door is bound once per model, algorithm and ``kernels=`` and found again on every call
    (the same object, the same kernel); another ``kernels=`` has its own door; a door bound
    under ``$NCGEN_CFLAGS`` is bound again when they change (to a kernel built under the new
    flags) and back (to the kernel of the old ones), kept when they are set again to the same
    text; a door bound at ncgen's defaults is kept when they are set.  Every result is the
    closed form of a 2 kg slider on z: ``a = τ / m − g``."""
    model = _sliders("door_slider", (2.0,), (-1,))
    tau, g = 3.0, 9.81

    def aba_flat():
        a = nc.aba(model, [0.1], [0.2], [tau], kernels="flat")
        assert a == pytest.approx([tau / 2.0 - g], abs=1e-12)
        return rta.door(model, "aba", "flat")

    monkeypatch.setenv("NCGEN_CFLAGS", "-O0")
    first = aba_flat()
    assert first.flags == "-O0" and aba_flat() is first and rta.door(model, "aba", "flat") is first
    assert nc.aba(model, [0.1], [0.2], [tau]) == pytest.approx([tau / 2.0 - g], abs=1e-12)
    assert rta.door(model, "aba") is not first and rta.door(model, "aba", "flat") is first
    monkeypatch.setenv("NCGEN_CFLAGS", "-O1")
    other = aba_flat()
    assert other is not first and other.flags == "-O1" and other.kernel is not first.kernel
    assert _recorded_flags(other.kernel) == ["-O1"]
    monkeypatch.setenv("NCGEN_CFLAGS", "-O0")
    back = aba_flat()
    assert back is not other and back.kernel is first.kernel
    monkeypatch.setenv("NCGEN_CFLAGS", "-O0")          # the same text again: a new value object, the same door
    assert aba_flat() is back
    monkeypatch.delenv("NCGEN_CFLAGS")
    default = aba_flat()
    assert default.flags is None and default.kernel.optimised
    monkeypatch.setenv("NCGEN_CFLAGS", "-O0")
    assert aba_flat() is default


def test_the_flags_reader_is_the_environments_value_and_follows_its_changes(monkeypatch):
    """The doors' check of ``$NCGEN_CFLAGS`` (:func:`ncgen.environment.key_reader`) gives the
    environment's own value object (that of ``getenv_key``, decoded ``os.environ.get``'s text):
    the same one while the variable is unchanged, a new one after every change (also to the same
    text), None once it is removed."""
    import os

    from ncgen.environment import decoded, getenv_key, key_reader
    read = key_reader("NCGEN_DOOR_TEST")
    monkeypatch.delenv("NCGEN_DOOR_TEST", raising=False)
    assert read() is None
    monkeypatch.setenv("NCGEN_DOOR_TEST", "-O0 é")
    first = read()
    assert first is getenv_key("NCGEN_DOOR_TEST") and read() is first
    assert decoded(first) == os.environ.get("NCGEN_DOOR_TEST") == "-O0 é"
    monkeypatch.setenv("NCGEN_DOOR_TEST", "-O0 é")
    assert read() is not first and decoded(read()) == "-O0 é"
    monkeypatch.delenv("NCGEN_DOOR_TEST")
    assert read() is None

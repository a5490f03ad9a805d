"""The element tables (issue 34): Φ, A, Φ_t, γ and M of a model evaluated by the element library
(one kernel per kind of element, hand-written loops over the model's tables) equal the flat
CasADi functions of the model to 1e-12 on every shipped example whose kinds are covered and
on systems using every covered joint kind (γ too); A equals central differences of the tables'
Φ and γ those of A v;
models with uncovered kinds are refused by name; a new model of covered kinds is evaluated
with no compiler on PATH once the library is cached."""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

import ncgen as nc
from ncgen.codegen.element_kernels import (
    JOINT_KINDS, MEMBER_KINDS, joint_kind, member_constant_names, member_constants, member_kind, torque_constant_names,
    torque_constants,
)
from ncgen.codegen.model_tables import UnsupportedElements, model_tables
from ncgen.codegen.compiler import CANDIDATES
from ncgen.symbolic.coordinates import coordinate_type
from ncgen.runtime.table_library import TableFunctions, load_element_library, table_functions
from no_compiler import run_without_compiler

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = sorted(p for p in (ROOT / "examples").glob("*.toml") if "[system]" in p.read_text())
#: Shipped examples with an element kind the tables do not cover, and the kinds named.
REFUSED = {"slider_crank": {"driven Revolute": ["joint 'motor'"]}}

pytestmark = pytest.mark.skipif(not any(shutil.which(c) for c in CANDIDATES) and not os.environ.get("CC"),
                                reason="no C compiler to build the element library")


@pytest.fixture(scope="module")
def library():
    return load_element_library()


def flat_values(model, q, v):
    f = model.functions
    return (np.array(f["phi"](0.0, q, model.p0)).reshape(-1), np.array(ca.densify(f["A"](0.0, q, model.p0))),
            np.array(f["phi_t"](0.0, q, model.p0)).reshape(-1), np.array(f["gamma"](0.0, q, v, model.p0)).reshape(-1),
            model.M)


def assert_equal_to_flat(model, library, seed=0):
    tf = table_functions(model, library)
    rng = np.random.default_rng(seed)
    for q, v in ((model.q0, model.v0), (model.q0 + 0.3 * rng.standard_normal(model.nq), rng.standard_normal(model.nq))):
        phi, A, phi_t, gamma, M = flat_values(model, q, v)
        np.testing.assert_allclose(tf.phi(q), phi, rtol=0, atol=1e-12)
        np.testing.assert_allclose(tf.tables.dense_A(tf.A(q)), A, rtol=0, atol=1e-12)
        np.testing.assert_allclose(tf.phi_t(), phi_t, rtol=0, atol=1e-12)
        np.testing.assert_allclose(tf.gamma(q, v), gamma, rtol=0, atol=1e-12)
        np.testing.assert_allclose(tf.tables.dense_M(tf.M()), M, rtol=0, atol=1e-12)
    return tf


@pytest.mark.parametrize("path", [pytest.param(p, marks=pytest.mark.slow) if p.stem == "box_stack" else p   # the largest;
                                  for p in EXAMPLES], ids=[p.stem for p in EXAMPLES])            # fast: boxes
def test_examples_equal_the_flat_functions_or_are_refused_by_kind(path, library):
    model = nc.System.from_toml(path).build()
    if path.stem in REFUSED:
        with pytest.raises(UnsupportedElements) as info:
            model_tables(model)
        assert info.value.kinds == REFUSED[path.stem]
        assert ("driven Revolute (joint 'motor') (a driven joint's rows depend on time through its drive"
                in str(info.value))
        return
    assert_equal_to_flat(model, library)


def _body(s, name, position, coords="ruvw", **kw):
    return s.add_body(name, coords=coords, mass=1.3, inertia=np.diag([0.1, 0.2, 0.25]), position=position,
                      rotation=np.eye(3), **kw)


def _systems_3d():
    """One small system per covered 3D joint kind (with bodies, bars and a point member)."""
    out = {}
    s = nc.System("spherical")
    b = _body(s, "b", (0.1, 0.2, 0.3))
    s.add_joint(nc.Spherical(s.ground, b, at=(0.0, 0.0, 0.5)))
    out["Spherical"] = s
    s = nc.System("revolute")
    b = _body(s, "b", (0.1, 0.2, 0.3), coords="rrvw")
    bar = s.add_bar("bar", coords="rr", mass=0.7, ends=[(0.4, 0.2, 0.3), (0.4, 1.2, 0.5)])
    s.add_joint(nc.Revolute(s.ground, b, at=(0.0, 0.2, 0.3), axis=(1.0, 0.0, 0.0)))
    s.add_joint(nc.Revolute(b, bar, at=(0.4, 0.2, 0.3), axis=(1.0, 0.0, 0.0)))
    out["Revolute"] = s
    s = nc.System("prismatic")
    b = _body(s, "b", (0.1, 0.2, 0.3), coords="rrrw")
    s.add_joint(nc.Prismatic(s.ground, b, at=(0.1, 0.2, 0.3), axis=(0.0, 0.6, 0.8)))
    out["Prismatic"] = s
    s = nc.System("cylindrical")
    b = _body(s, "b", (0.1, 0.2, 0.3), coords="rrrr")
    s.add_joint(nc.Cylindrical(s.ground, b, at=(0.1, 0.2, 0.0), axis=(0.0, 0.0, 1.0)))
    out["Cylindrical"] = s
    s = nc.System("universal")
    b = _body(s, "b", (0.1, 0.2, 0.3))
    s.add_joint(nc.Universal(s.ground, b, at=(0.1, 0.2, 0.8), axis_a=(1.0, 0.0, 0.0), axis_b=(0.0, 1.0, 0.0)))
    out["Universal"] = s
    s = nc.System("planar")
    b = _body(s, "b", (0.1, 0.2, 0.3))
    s.add_joint(nc.Planar(s.ground, b, at=(0.1, 0.2, 0.3), normal=(0.0, 0.0, 1.0)))
    out["Planar"] = s
    s = nc.System("fixed")
    a = _body(s, "a", (0.1, 0.2, 0.3))
    b = _body(s, "b", (0.5, 0.2, 0.3), coords="rrvw")
    s.add_joint(nc.Spherical(s.ground, a, at=(0.1, 0.2, 0.6)))
    s.add_joint(nc.Fixed(a, b, at=(0.3, 0.2, 0.3)))
    out["Fixed"] = s
    s = nc.System("distance")
    b = _body(s, "b", (0.1, 0.2, 0.3))
    p = s.add_point("p", mass=0.4, position=(1.0, 0.5, 0.3))
    s.add_joint(nc.Distance(b, p, at=[(0.2, 0.2, 0.3), (1.0, 0.5, 0.3)]))
    out["Distance"] = s
    s = nc.System("point_on_line")
    p = s.add_point("p", mass=0.4, position=(1.0, 0.5, 0.3))
    s.add_joint(nc.PointOnLine(s.ground, p, at=(1.0, 0.5, 0.3), axis=(1.0, 1.0, 0.0)))
    out["PointOnLine"] = s
    s = nc.System("point_on_plane")
    bar = s.add_bar("bar", coords="ru", mass=0.7, ends=[(0.0, 0.0, 0.3), (1.0, 0.0, 0.3)])
    s.add_joint(nc.PointOnPlane(s.ground, bar, at=(1.0, 0.0, 0.3), normal=(0.0, 0.0, 1.0)))
    out["PointOnPlane"] = s
    s = nc.System("mimic")
    a = _body(s, "a", (0.1, 0.2, 0.3))
    b = _body(s, "b", (0.5, 0.2, 0.3), coords="rrvw")
    lead = s.add_joint(nc.Prismatic(s.ground, a, at=(0.1, 0.2, 0.3), axis=(1.0, 0.0, 0.0)))
    follow = s.add_joint(nc.Prismatic(a, b, at=(0.5, 0.2, 0.3), axis=(0.0, 0.6, 0.8)))
    s.add_joint(nc.Mimic(lead, follow, multiplier=-0.7))
    out["Mimic"] = s
    return out


def _systems_2d():
    out = {}
    s = nc.System("planar_mechanism", gravity=(0.0, -9.81))
    a = s.add_body("a", coords="rrv", mass=1.0, inertia=0.1, position=(0.0, 0.5), rotation=0.3)
    b = s.add_body("b", coords="rrr", mass=1.0, inertia=0.1, position=(1.0, 0.5), rotation=0.0)
    bar = s.add_bar("bar", coords="ru", mass=0.5, ends=[(2.0, 0.5), (2.0, 1.5)])
    p = s.add_point("p", mass=0.2, position=(3.0, 1.0))
    s.add_joint(nc.Revolute(s.ground, a, at=(0.0, 0.0)))
    s.add_joint(nc.Prismatic(a, b, at=(1.0, 0.5), axis=(1.0, 0.0)))
    s.add_joint(nc.Fixed(b, bar, at=(2.0, 0.5)))
    s.add_joint(nc.Distance(bar, p, at=[(2.0, 1.5), (3.0, 1.0)]))
    s.add_joint(nc.PointOnLine(s.ground, p, at=(3.0, 1.0), axis=(0.0, 1.0)))
    out["planar"] = s
    s = nc.System("planar_mimic", gravity=(0.0, -9.81))
    a = s.add_body("a", coords="rrv", mass=1.0, inertia=0.1, position=(0.0, 0.5), rotation=0.3)
    b = s.add_body("b", coords="rrr", mass=0.5, inertia=0.05, position=(1.0, 0.5), rotation=0.1)
    lead = s.add_joint(nc.Prismatic(s.ground, a, at=(0.0, 0.5), axis=(1.0, 0.0)))
    follow = s.add_joint(nc.Prismatic(a, b, at=(1.0, 0.5), axis=(0.6, 0.8)))
    s.add_joint(nc.Mimic(lead, follow, multiplier=1.5))
    out["planar_mimic"] = s
    return out


@pytest.mark.parametrize("share", [True, pytest.param(False, marks=pytest.mark.slow)], ids=["shared", "unshared"])   # fast: shared
def test_every_covered_joint_kind_equals_the_flat_functions(share, library):
    used = set()
    for kind, system in {**_systems_3d(), **_systems_2d()}.items():
        model = system.build(share=share, redundant="keep")
        tf = assert_equal_to_flat(model, library, seed=len(kind))
        used |= set(tf.tables.kinds)
    if not share:          # every joint primitive of both dimensions is exercised
        assert {joint_kind(p, d).name for p, d in JOINT_KINDS} <= used


def test_jacobian_and_gamma_against_central_differences(library):
    for system in (_systems_3d()["Revolute"], _systems_3d()["Cylindrical"], _systems_2d()["planar"]):
        model = system.build(share=False)
        tf = table_functions(model, library)
        q = model.q0 + 0.2 * np.random.default_rng(3).standard_normal(model.nq)
        A = tf.tables.dense_A(tf.A(q))
        h = 1e-6
        fd = np.column_stack([(tf.phi(q + h * e) - tf.phi(q - h * e)) / (2 * h) for e in np.eye(model.nq)])
        np.testing.assert_allclose(A, fd, rtol=0, atol=1e-7 * max(1.0, np.abs(A).max()))
        v = np.random.default_rng(4).standard_normal(model.nq)        # γ = −(∂(A v)/∂q) v
        Av = lambda x: tf.tables.dense_A(tf.A(x)) @ v  # noqa: E731
        np.testing.assert_allclose(tf.gamma(q, v), -(Av(q + h * v) - Av(q - h * v)) / (2 * h), rtol=0,
                                   atol=1e-7 * max(1.0, np.abs(tf.gamma(q, v)).max()))


def test_member_kernels_equal_the_members_own_formulas():
    """Each member kind's kernels against RigidMember's NumPy forms of the same derivation."""
    from ncgen.codegen.element_kernels import member_constants

    s3 = nc.System("kinds3")
    members = [_body(s3, f"b_{t}", (0.1 * k, 0.2, 0.3), coords=t) for k, t in enumerate(("ruvw", "rrvw", "rrrw", "rrrr"))]
    members += [s3.add_bar(f"bar_{t}", coords=t, mass=0.7, ends=[(0.0, 1.0, 0.0), (0.3, 1.4, 0.2)]) for t in ("ru", "rr")]
    members += [s3.add_point("pt", mass=0.3, position=(0.0, 0.0, 2.0))]
    rng = np.random.default_rng(5)
    for m in members:
        k = member_kind(m.dim, m.ctype.name)
        values = m.rigid.constants()
        c = [float(values[s]) for s in member_constants(m.dim, m.ctype.name)]
        q = m.q0 + 0.1 * rng.standard_normal(m.q0.size)
        np.testing.assert_allclose(np.array(k.mass(c)), m.rigid.M, rtol=0, atol=1e-13)
        if k.phi is not None:
            phi, J = k.phi(q, c)
            np.testing.assert_allclose(np.array(phi).reshape(-1), m.rigid.phi(q), rtol=0, atol=1e-13)
            np.testing.assert_allclose(np.array(J), m.rigid.phi_q(q), rtol=0, atol=1e-13)
            np.testing.assert_allclose(-np.array(k.hvv(q, c)).reshape(-1), m.rigid.gamma(q), rtol=0, atol=1e-13)
    assert {(3, m.ctype.name) for m in members} == {k for k in MEMBER_KINDS if k[0] == 3}


def test_member_constant_names_are_the_derivation_s():
    """The constants a model's tables are packed with (read from the shipped numeric forms,
    no SymPy) are, in order, the derivation's constant symbols of Φ and M that the member
    kernels take, and of W that the torque kernels take."""
    for dim, ctype in MEMBER_KINDS:
        names = member_constant_names(dim, ctype)
        assert names == tuple(map(str, member_constants(dim, ctype))) == member_kind(dim, ctype).constants, \
            (dim, ctype)
        if coordinate_type(ctype, dim).derivation.W is not None:
            assert torque_constant_names(dim, ctype) == tuple(map(str, torque_constants(dim, ctype))), (dim, ctype)


def test_uncovered_kinds_are_refused_by_name():
    s = nc.System("uncovered", gravity=(0.0, -9.81))
    a = s.add_bar("a", coords="rr", mass=1.0, ends=[(0.0, 0.0), (1.0, 0.0)])
    b = s.add_bar("b", coords="rr", mass=1.0, ends=[(1.0, 0.0), (2.0, 0.0)])
    s.add_joint(nc.Revolute(s.ground, a, at=(0.0, 0.0), drive="0.5*t", name="motor"))
    s.add_joint(nc.Revolute(a, b, at=(1.0, 0.0)))
    s.add_joint(nc.CoordinateDriver(b, "r_j", "y", name="hold"))
    model = s.build(share=False)
    with pytest.raises(UnsupportedElements) as info:
        model_tables(model)
    assert info.value.kinds == {"driven Revolute": ["joint 'motor'"], "CoordinateDriver": ["joint 'hold'"]}
    assert "model 'uncovered'" in str(info.value) and "flat functions" in str(info.value)


def test_bad_q_is_refused(library):
    model = _systems_3d()["Spherical"].build()
    tf = TableFunctions(model_tables(model), library)
    with pytest.raises(nc.errors.ShapeError, match=f"q: expected {model.nq} values"):
        tf.phi(np.zeros(model.nq + 1))
    with pytest.raises(nc.errors.ShapeError, match=f"v: expected {model.nq} values"):
        tf.gamma(model.q0, np.zeros(model.nq - 1))


def test_inconsistent_tables_are_refused(library):
    model = _systems_3d()["Revolute"].build()
    tables = model_tables(model)
    tables.arrays["el_arg"] = tables.arrays["el_arg"] + 10_000
    with pytest.raises(nc.errors.CodegenError, match="inconsistent"):
        TableFunctions(tables, library)


CHILD = r"""
import json
import numpy as np, casadi as ca
from no_compiler import chain, forbid_compiler, fourbar
from ncgen.runtime.table_library import table_functions

forbid_compiler()
out = {}
for system in (chain("new_chain13", 13, (0.37, 0.11, -0.05)), fourbar("new_fourbar")):
    model = system.build()
    tf = table_functions(model)
    q = model.q0 + 0.1 * np.random.default_rng(1).standard_normal(model.nq)
    f = model.functions
    out[model.name] = [
        float(np.abs(tf.phi(q) - np.array(f["phi"](0, q, model.p0)).ravel()).max()),
        float(np.abs(tf.tables.dense_A(tf.A(q)) - np.array(ca.densify(f["A"](0, q, model.p0)))).max()),
        float(np.abs(tf.tables.dense_M(tf.M()) - model.M).max())]
print(json.dumps(out))
"""


@pytest.mark.slow      # a subprocess without a compiler; fast:
#                       tests/test_tree_tables.py::test_a_new_tree_needs_no_compiler (the same no-compiler loading of
#                       a cached library)
def test_a_new_model_needs_no_compiler(library, tmp_path):
    """Once the library is cached, a new chain and a new four-bar are evaluated in a process
    with no compiler on PATH (and compile_package replaced by a failure)."""
    errors = run_without_compiler(CHILD, tmp_path)
    assert set(errors) == {"new_chain13", "new_fourbar"}
    for name, (e_phi, e_A, e_M) in errors.items():
        assert max(e_phi, e_A, e_M) <= 1e-12, (name, e_phi, e_A, e_M)


@pytest.mark.slow
@pytest.mark.timeout(1800)
def test_benchmark_smoke(tmp_path):
    """benchmarks/element_tables.py --smoke runs and prints its comparisons (nothing timed)."""
    env = {**os.environ, "NCGEN_CACHE_DIR": str(tmp_path / "cache"),
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    out = subprocess.run([sys.executable, "element_tables.py", "--smoke"], cwd=ROOT / "benchmarks", env=env,
                         capture_output=True, text=True, timeout=1800)
    assert out.returncode == 0, out.stderr[-3000:]
    for line in ("CPU:", "=== chain of N = 6 bars", "max |A_tables - A_flat| = 0.0e+00",
                 "RATIO flat / tables, cached cache, N = 6", "RATIO tables / flat, one A(q) evaluation, N = 6",
                 "load average at the end"):
        assert line in out.stdout, (line, out.stdout[-3000:])


@pytest.mark.slow      # writes the package twice, compiles it at -Werror; fast:
#                       test_examples_equal_the_flat_functions_or_are_refused_by_kind (the library compiled and
#                       checked), tests/test_c_binding.py (its tables against the template)
@pytest.mark.parametrize("contacts", [False, pytest.param(True, marks=pytest.mark.slow)],
                         ids=["elements", "contacts"])
def test_element_package_is_deterministic_and_warning_free(tmp_path, contacts):
    """The element library's package (and the contact library's, slow: ≈ 20 CPU-s of gcc): the
    same bytes when written twice, and its C compiles with -Wall -Wextra -Werror."""
    from ncgen.codegen.element_kernels import write_element_package

    a, b = (write_element_package(tmp_path / k, contacts=contacts) for k in "ab")
    files = sorted(p.name for p in a.path.iterdir())
    assert files == sorted(p.name for p in b.path.iterdir())
    for name in files:
        assert (a.path / name).read_bytes() == (b.path / name).read_bytes(), name
    cc = os.environ.get("CC") or next(shutil.which(c) for c in CANDIDATES if shutil.which(c))
    for src in a.manifest["build"]["sources"]:
        out = subprocess.run([*cc.split(), "-std=c99", "-Wall", "-Wextra", "-Werror", "-O1", "-I.", "-c", src, "-o",
                              str(tmp_path / f"{src}.o")], cwd=a.path, capture_output=True, text=True, timeout=600)
        assert out.returncode == 0, out.stderr[-3000:]


def urdfs_of_the_test_extras() -> list:
    """``(id, path)`` of every URDF the test extras ship: example-robot-data's robots (ids their
    paths under ``robots/``) and MuJoCo's test model; ``(package, None)`` for a package not
    installed."""
    import importlib.metadata as md
    import importlib.util

    try:
        files = md.files("example-robot-data") or []
    except md.PackageNotFoundError:
        files = None
    out = [("example-robot-data", None)] if files is None else sorted(
        (str(f).split("/robots/", 1)[1], f.locate()) for f in files
        if str(f).endswith(".urdf") and "/robots/" in str(f))
    spec = importlib.util.find_spec("mujoco")
    mujoco = spec and Path(spec.origin).parent / "testdata" / "model.urdf"
    return out + [("mujoco/testdata/model.urdf", mujoco) if mujoco and mujoco.exists() else ("mujoco", None)]


#: URDFs built with a floating base (the others' root link fixed to the world): quadrotors and Solo-12.
FLOATING = {"hector_description/robots/quadrotor_base.urdf", "iris_description/robots/iris.urdf",
            "iris_description/robots/iris_simple.urdf", "solo_description/robots/solo12.urdf"}
_MIMIC_REVOLUTE = "Mimic of a Revolute joint (its angle, an atan2, is not a quadratic form of q)"
#: URDFs whose element kinds the tables refuse (the Panda's finger mimic is of two Prismatic
#: joints, the slider_ratio primitive, and is covered).
TABLES_REFUSE = {"pr2_description/urdf/pr2.urdf": _MIMIC_REVOLUTE,
                 "talos_data/robots/talos_full_v2.urdf": _MIMIC_REVOLUTE,
                 "talos_data/robots/talos_full_v2_box.urdf": _MIMIC_REVOLUTE,
                 "tiago_pro_description/robots/tiago_pro.urdf": _MIMIC_REVOLUTE}
_INERTIA = "the inertia tensor is not physical"
#: URDFs ncgen refuses to import, and what the refusal must say (the files' own defects, or a
#: model ncgen cannot build: the G1's waist joints are dependent at the URDF's zero pose).
IMPORT_REFUSES = {
    "alex_description/urdf/alex_psyonic_hands.urdf": "joint 'Left_index_q2': mimics 'index_q1', which is not a movable",
    "g1_description/urdf/g1_29dof_rev_1_0.urdf": "the initial configuration is singular",
    "g1_description/urdf/g1_29dof_with_hand_rev_1_0.urdf": "the initial configuration is singular",
    "human_description/robots/human.urdf": "link(s) left_upperleg_virtual (moved by joint 'left_hip_Z') have no mass",
    "icub_description/robots/icub.urdf": f"link 'head': {_INERTIA}",
    "icub_description/robots/icub_reduced.urdf": f"link 'head': {_INERTIA}",
    "romeo_description/urdf/romeo.urdf": "link(s) LFinger11Link (moved by joint 'LHand') have no mass",
    "romeo_description/urdf/romeo_laas_small.urdf": f"link 'body': {_INERTIA}",
    "romeo_description/urdf/romeo_small.urdf": f"link 'RShoulderYawLink': {_INERTIA}",
    "tiago_description/robots/tiago.urdf": f"link 'base_antenna_left_link': {_INERTIA}",
    "tiago_description/robots/tiago_dual.urdf": f"link 'base_antenna_left_link': {_INERTIA}",
    "tiago_description/robots/tiago_no_hand.urdf": f"link 'base_antenna_left_link': {_INERTIA}",
    "ur_description/urdf/ur3.urdf": "expected one root link (a tree), found []",      # the file has no links
    "mujoco/testdata/model.urdf": "system 'tool' has no members",                      # one link, fixed
}
#: The URDFs checked in the fast tier (a few coordinates, or refused while reading the file);
#: every other one in the slow tier.
FAST_URDFS = {"asr_twodof_description/urdf/TwoDofs.urdf", "borinot_description/urdf/borinot_flying_arm_2.urdf",
              "double_pendulum_description/urdf/double_pendulum.urdf",
              "double_pendulum_description/urdf/double_pendulum_continuous.urdf",
              "double_pendulum_description/urdf/double_pendulum_simple.urdf",
              "finger_edu_description/robots/finger_edu.urdf", *FLOATING - {"solo_description/robots/solo12.urdf"},
              *(k for k in IMPORT_REFUSES if not k.startswith(("g1_", "alex_")))}
EXTRA_URDFS = urdfs_of_the_test_extras()


def test_the_urdf_expectations_name_shipped_files():
    """Every URDF named in :data:`FLOATING`, :data:`TABLES_REFUSE`, :data:`IMPORT_REFUSES`
    and :data:`FAST_URDFS` is one the installed extras ship (a misspelt name would leave a
    robot checked against the wrong expectation)."""
    found = {r for r, p in EXTRA_URDFS if p is not None}
    if "a1_description/urdf/a1.urdf" not in found:
        pytest.skip("example-robot-data is not installed")
    missing = (FLOATING | set(TABLES_REFUSE) | set(IMPORT_REFUSES) | FAST_URDFS) - found
    if ("mujoco", None) in EXTRA_URDFS:
        missing.discard("mujoco/testdata/model.urdf")
    assert not missing, missing


@pytest.mark.parametrize("rel, path", [pytest.param(r, p, marks=() if r in FAST_URDFS else pytest.mark.slow)
                                       for r, p in EXTRA_URDFS], ids=[r for r, _ in EXTRA_URDFS])
def test_urdf_robots_equal_the_flat_functions_or_are_refused(rel, path, library):
    """Every URDF of the test extras: its element tables' Φ, A, Φ_t, γ and M equal the flat
    CasADi functions to 1e-12 (relative to the largest entry, or 1), or the tables refuse it
    by kind (:data:`TABLES_REFUSE`), or ncgen refuses to import it saying why
    (:data:`IMPORT_REFUSES`)."""
    if path is None:
        pytest.skip(f"{rel} is not installed")
    if rel in IMPORT_REFUSES:
        with pytest.raises(nc.ModelError, match=re.escape(IMPORT_REFUSES[rel])):
            nc.System.from_urdf(str(path), floating_base=rel in FLOATING).build()
        return
    model = nc.System.from_urdf(str(path), floating_base=rel in FLOATING).build()
    if rel in TABLES_REFUSE:
        with pytest.raises(UnsupportedElements) as info:
            model_tables(model)
        assert set(info.value.kinds) == {TABLES_REFUSE[rel]}
        return
    tf = table_functions(model, library)
    rng = np.random.default_rng(2)
    q, v = model.q0 + 0.1 * rng.standard_normal(model.nq), rng.standard_normal(model.nq)
    phi, A, phi_t, gamma, M = flat_values(model, q, v)
    for got, want in ((tf.phi(q), phi), (tf.tables.dense_A(tf.A(q)), A), (tf.phi_t(), phi_t),
                      (tf.gamma(q, v), gamma), (tf.tables.dense_M(tf.M()), M)):
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * max(1.0, np.abs(want).max(initial=0.0)))

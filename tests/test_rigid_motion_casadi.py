"""Rigid-motion algebra: NumPy, CasADi and compiled C forms agree; CasADi derivatives are finite
and correct at the singular points of exp and log."""
import os
import subprocess
import sys

import casadi as ca
import numpy as np
import pytest

import ncgen.rigid_motion as rm
from ncgen.codegen.rigid_motion_package import write_c_package
from ncgen.rigid_motion import casadi_forms as crm
from ncgen.codegen import compile_package, load_functions
from ncgen.errors import CompilerNotFound
from ncgen.symbolic.rigid_motion_forms import NAMES, form

RNG = np.random.default_rng(7)


def _rotation(rng, angle=None):
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    return rm.exp_so3(axis * (rng.uniform(0, np.pi) if angle is None else angle))


def _mass_matrix(rng):
    M_c = rm.box(rng.uniform(0.1, 1, 3), rng.uniform(0.5, 2))
    return rm.transport_mass_matrix(M_c, rm.homogeneous(_rotation(rng), rng.normal(size=3)))


def sample(arg, rng):
    """A valid random value for an argument (``Arg``) of the forms table."""
    arg_name = arg.name
    if arg_name == "H_ab":
        return rm.homogeneous(_rotation(rng), rng.normal(size=3))
    if arg_name == "R_ab":
        return _rotation(rng)
    if arg_name in ("M", "M_a", "M_b"):
        return _mass_matrix(rng)
    if arg_name in ("I_o", "I_c"):
        return _mass_matrix(rng)[:3, :3]
    if arg_name in ("m", "length", "radius"):
        return rng.uniform(0.5, 2)
    if arg_name in ("half_extents", "semi_axes"):
        return rng.uniform(0.1, 1, 3)
    if arg_name in ("angle", "az", "ay", "ax"):
        return rng.uniform(-1.5, 1.5)
    if arg_name == "Omega":
        return rng.normal(size=(3, 3))
    if arg_name == "T_hat":
        return rm.se3_hat(rng.normal(size=6))
    return rng.normal(size=arg.shape)


def as_list(x):
    return list(x) if isinstance(x, tuple) else [x]


def assert_same(numeric, other, tol=1e-12):
    for a, b in zip(as_list(numeric), as_list(other), strict=True):
        b = np.array(b, dtype=float)
        a = np.asarray(a, dtype=float)
        np.testing.assert_allclose(b.reshape(a.shape), a, atol=tol, rtol=0)


@pytest.mark.parametrize("name", NAMES)
def test_numpy_and_casadi_agree(name):
    for _ in range(3):
        args = [sample(a, RNG) for a in form(name).args]
        assert_same(getattr(rm, name)(*args), getattr(crm, name)(*args))


def test_newton_euler_acceleration_casadi():
    M, T, W = _mass_matrix(RNG), RNG.normal(size=6), RNG.normal(size=6)
    assert_same(rm.newton_euler_acceleration(M, T, W), crm.newton_euler_acceleration(M, T, W))


@pytest.mark.parametrize("kind", [ca.SX, ca.MX])
def test_symbolic_type_in_same_type_out(kind):
    H, T = kind.sym("H", 4, 4), kind.sym("T", 6)
    for out in (crm.Ad(H), crm.exp_se3(T), crm.log_se3(H), crm.transport_wrench(H, T), crm.inverse(H)):
        assert isinstance(out, kind)
    m, r, I_c = crm.mass_matrix_parts(kind.sym("M", 6, 6))
    assert all(isinstance(x, kind) for x in (m, r, I_c))


def _numeric_jacobian(f, x, h=1e-6):
    cols = [(np.ravel(f(x + h * e), order="F") - np.ravel(f(x - h * e), order="F")) / (2 * h)
            for e in np.eye(len(x))]
    return np.column_stack(cols)


@pytest.mark.parametrize("kind", [ca.SX, ca.MX])
@pytest.mark.parametrize("scale", [0.0, 1e-9, 1e-3, 1e-2, 0.5])
def test_exp_jacobian_finite_and_correct(kind, scale):
    T = kind.sym("T", 6)
    H = crm.exp_se3(T)
    f = ca.Function("f", [T], [ca.jacobian(H, T), ca.hessian(ca.sumsqr(H), T)[0]])
    T0 = np.r_[scale * np.array([0.6, 0.0, -0.8]), 1.0, -2.0, 0.5]
    J, Hess = (np.array(v) for v in f(T0))
    assert np.all(np.isfinite(J)) and np.all(np.isfinite(Hess))
    np.testing.assert_allclose(J, _numeric_jacobian(rm.exp_se3, T0), atol=1e-8)


@pytest.mark.parametrize("kind", [ca.SX, ca.MX])
def test_exp_jacobian_at_zero_twist_is_the_generators(kind):
    """∂ exp(T̂)/∂Tᵢ at T = 0 is the i-th generator of se(3), exactly."""
    T = kind.sym("T", 6)
    J = np.array(ca.Function("f", [T], [ca.jacobian(crm.exp_se3(T), T)])(np.zeros(6)))
    generators = np.column_stack([np.ravel(rm.se3_hat(e), order="F") for e in np.eye(6)])
    np.testing.assert_array_equal(J, generators)


@pytest.mark.parametrize("angle", [0.0, 1e-9, 1e-2, 1.0, np.pi - 1e-3])
def test_log_jacobian_finite_and_correct(angle):
    """d log(exp(T))/dT = 1 through the chain rule of the two CasADi forms."""
    T = ca.SX.sym("T", 6)
    f = ca.Function("f", [T], [ca.jacobian(crm.log_se3(crm.exp_se3(T)), T)])
    T0 = np.r_[angle * np.array([0.0, 0.6, 0.8]), 0.3, 1.0, -1.0]
    J = np.array(f(T0))
    assert np.all(np.isfinite(J))
    np.testing.assert_allclose(J, np.eye(6), atol=1e-9)


# --- generated C ---------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def compiled(tmp_path_factory):
    out = tmp_path_factory.mktemp("rigid_motion_c")
    pkg = write_c_package(out / "pkg")
    mp = pytest.MonkeyPatch()
    mp.setenv("NCGEN_CACHE_DIR", str(out / "cache"))
    try:
        build = compile_package(pkg, cflags="-O1 -Wall -Wextra -Werror")
    except CompilerNotFound:
        pytest.skip("no C compiler")
    finally:
        mp.undo()
    return load_functions(build)


SPECIAL_TWISTS = [np.zeros(6), np.r_[1e-9, 0, 0, 1, 2, 3], np.r_[0, 0, np.pi - 1e-9, 1, 2, 3],
                  np.r_[0, np.pi, 0, -1, 0, 2], np.r_[0.006, -0.008, 0, 1, 1, 1]]


def test_c_package_core_functions(compiled):
    assert set(compiled) == set(rm.C_CORE)


@pytest.mark.parametrize("name", rm.C_CORE)
def test_numpy_casadi_and_c_agree(compiled, name):
    cases = [[sample(a, RNG) for a in form(name).args] for _ in range(5)]
    if name in ("exp_se3",):
        cases += [[T] for T in SPECIAL_TWISTS]
    if name in ("log_se3", "inverse", "Ad", "Ad_inv"):
        cases += [[rm.exp_se3(T)] for T in SPECIAL_TWISTS]
    for args in cases:
        numeric = getattr(rm, name)(*args)
        assert_same(numeric, getattr(crm, name)(*args))
        assert_same(numeric, compiled[name](*args))


@pytest.mark.slow      # two fresh interpreters writing the package; fast: test_numpy_casadi_and_c_agree compiles and
#                       checks the same package; tests/test_codegen_package.py::test_same_bytes_from_another_process
def test_c_package_is_deterministic(tmp_path):
    """Same package bytes from separate processes with different hash seeds."""
    script = ("import sys; from ncgen.codegen.rigid_motion_package import write_c_package; "
              "print(write_c_package(sys.argv[1]).content_hash)")
    hashes = set()
    for seed in ("1", "2"):
        run = subprocess.run([sys.executable, "-c", script, str(tmp_path / seed)], capture_output=True,
                             text=True, env={**os.environ, "PYTHONHASHSEED": seed}, check=True)
        hashes.add(run.stdout.strip())
    assert len(hashes) == 1

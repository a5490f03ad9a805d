"""The direct ctypes call path of compiled functions and the compiled forward dynamics."""
from __future__ import annotations

import tempfile
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

import ncgen as nc
from ncgen.codegen.compiler import find_compiler
from ncgen.errors import CompilerNotFound

try:
    find_compiler()
except CompilerNotFound:
    pytest.skip("no C compiler", allow_module_level=True)

G, L, MASS = 9.81, 1.2, 2.0


def test_direct_function_matches_casadi():
    from ncgen.codegen.compile_cache import compile_package
    from ncgen.codegen.direct import DirectFunction
    from ncgen.codegen.package import write_package

    x, y = ca.SX.sym("x", 3), ca.SX.sym("y", 2, 2)
    f = ca.Function("g", [x, y], [ca.sin(x) * ca.trace(y), ca.mtimes(y, y), ca.dot(x, x)],
                    ["x", "y"], ["s", "yy", "n"])
    with tempfile.TemporaryDirectory() as tmp:
        pkg = write_package("direct_test", [f], Path(tmp) / "pkg")
        built = compile_package(pkg)
        c_name = pkg.manifest["functions"][0]["c_name"]
    d = DirectFunction(built.path, c_name, f)
    rng = np.random.default_rng(0)
    for _ in range(3):
        xv, yv = rng.normal(size=3), rng.normal(size=(2, 2))
        out = d(xv, yv.T.reshape(-1))                        # nonzeros, column-major
        ref = f(xv, yv)
        for o, r in zip(out, ref):
            np.testing.assert_allclose(o, np.array(r).T.reshape(-1), rtol=1e-14, atol=1e-15)
    assert d.input_names == ["x", "y"] and d.output_names == ["s", "yy", "n"]


def test_compiled_forward_dynamics_closed_form():
    s = nc.System("direct_pendulum", gravity=(0, -G))
    tau = s.add_input("tau")
    bar = s.add_bar("bar", mass=MASS, ends=[(0, 0), (L, 0)])
    s.add_joint(nc.Revolute(s.ground, bar, at=(0, 0), name="pivot", effort=tau))
    model = s.build()
    for th, om, t in ((0.4, 1.3, 0.5), (-1.0, 0.0, -2.0)):
        q, v = model.from_joint_space([th], [om])
        a, lam = nc.forward_dynamics(model, q, v, u=[t], backend="compiled")
        a_np, lam_np = nc.forward_dynamics(model, q, v, u=[t])
        _, _, aj = model.to_joint_space(q, v, a)
        expected = (t - MASS * G * L / 2 * np.cos(th)) / (MASS * L**2 / 3)
        assert abs(aj[0] - expected) < 1e-10
        np.testing.assert_allclose(lam, lam_np, rtol=1e-9, atol=1e-9)
    with pytest.raises(nc.ModelError, match="backend"):
        nc.forward_dynamics(model, q, v, backend="fast")


def test_compiled_joint_space_forward_dynamics():
    """Joint space in and out in one compiled call, against from_joint_space +
    forward_dynamics + to_joint_space; a floating base with a quaternion and a hinge."""
    s = nc.System("jfd")
    b0 = s.add_body("b0", mass=2.0, inertia=np.diag([0.1, 0.2, 0.25]), position=(0, 0, 1))
    b1 = s.add_body("b1", mass=1.0, inertia=np.diag([0.05, 0.06, 0.07]), position=(0.5, 0, 1))
    tau = s.add_input("tau")
    s.add_joint(nc.Free(s.ground, b0, at=(0, 0, 1), name="root"))
    s.add_joint(nc.Revolute(b0, b1, at=(0.25, 0, 1), axis=(0, 1, 0), name="hinge", effort=tau))
    model = s.build()
    k = nc.forward_dynamics_kernel(model, joint_space=True)
    quat = np.array([0.1, -0.2, 0.3, 0.9]) / np.linalg.norm([0.1, -0.2, 0.3, 0.9])
    qj = np.concatenate([[0.1, 0.2, 1.3], quat, [0.7]])
    vj = np.array([0.3, -0.1, 0.2, 0.5, -0.4, 0.6, 1.1])
    aj = k(0.0, qj, vj, [2.0], model.p0)[0].copy()
    q, v = model.from_joint_space(qj, vj)
    a, _ = nc.forward_dynamics(model, q, v, u=[2.0])
    np.testing.assert_allclose(aj, model.to_joint_space(q, v, a)[2], rtol=1e-9, atol=1e-9)

"""Compiled and VM backends of nc.simulate give the same motion."""
import shutil
import warnings

import numpy as np
import pytest

import ncgen as nc
from ncgen.codegen import NoCompilerWarning
from ncgen.runtime import simulate
from ncgen.runtime.dae import load_dae

needs_gcc = pytest.mark.skipif(shutil.which("gcc") is None, reason="gcc not installed")


@pytest.fixture(autouse=True)
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("NCGEN_CACHE_DIR", str(tmp_path / "cache"))


def driven_chain():
    """A 3D chain of two bars with a spring, a damper and an input torque: every DAE term."""
    s = nc.System("driven")
    b1 = s.add_bar("b1", mass=1.0, ends=[s.ground.point((0, 0, 0)), (0.5, 0.1, 0.0)])
    b2 = s.add_bar("b2", mass=0.5, ends=[b1.end(1), (0.8, 0.4, 0.2)])
    k = s.add_parameter("k", 30.0)
    s.add_force(nc.Spring(s.ground, (0.0, 0.5, 0.5), b2, (0.2, 0, 0), k=k, rest_length=0.3, damping=0.5))
    tau = s.add_input("tau", 3)
    s.add_force(nc.Torque(b1, tau))
    return s.build()


@needs_gcc
def test_compiled_equals_vm():
    model = driven_chain()
    kw = dict(u=lambda t: [0.0, 0.0, np.sin(3 * t)], p={"k": 40.0}, rtol=1e-10, atol=1e-12)
    vm = simulate(model, 2.0, 0.01, backend="vm", **kw)
    compiled = simulate(model, 2.0, 0.01, backend="compiled", **kw)
    assert vm.info["backend"] == "vm" and compiled.info["backend"] == "compiled"
    assert np.ptp(vm.q) > 0.1
    np.testing.assert_allclose(compiled.q, vm.q, atol=1e-8)
    np.testing.assert_allclose(compiled.lam, vm.lam, atol=1e-6 * np.max(np.abs(vm.lam)))


@needs_gcc
def test_compiled_dae_and_its_jacobian_equal_the_vm():
    model = driven_chain()
    vm, _ = load_dae(model, "vm")
    compiled, used = load_dae(model, "compiled")
    assert used == "compiled" and compiled.is_a("External")
    rng = np.random.default_rng(3)
    args = [rng.standard_normal(vm.size1_in(i)) for i in range(vm.n_in())]
    for a, b in zip(vm(*args), compiled(*args)):
        np.testing.assert_allclose(np.array(b), np.array(a), rtol=1e-12, atol=1e-12)
    jac_vm, jac_c = vm.jacobian(), compiled.jacobian()
    outs = [np.zeros(vm.size1_out(i)) for i in range(vm.n_out())]
    for a, b in zip(jac_vm(*args, *outs), jac_c(*args, *outs)):
        np.testing.assert_allclose(np.array(b), np.array(a), rtol=1e-12, atol=1e-12)


def test_auto_without_compiler_falls_back_to_vm(monkeypatch):
    monkeypatch.setattr("ncgen.runtime.backend_policy.VM_EXTRA_SECONDS", 1.0)   # compiling "pays"
    monkeypatch.setenv("CC", "/nonexistent/cc")
    monkeypatch.setenv("PATH", "/nonexistent")
    monkeypatch.setattr("ncgen.codegen.load._warned_no_compiler", False)
    model = driven_chain()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        traj = simulate(model, 0.2, 0.05, backend="auto")
    assert traj.info["backend"] == "vm" and traj.info["backend_reason"] == "no C compiler"
    assert any(issubclass(w.category, NoCompilerWarning) for w in caught)

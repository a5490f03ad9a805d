"""write_package(jacobians=...): exact derivatives of compiled functions through casadi.external."""
import shutil
import subprocess

import casadi as ca
import numpy as np
import pytest

from ncgen.codegen import load_functions, write_package
from ncgen.errors import CodegenError
from test_codegen_samples import chain_doc, chain_functions, random_inputs

needs_gcc = pytest.mark.skipif(shutil.which("gcc") is None, reason="gcc not installed")


@pytest.fixture(autouse=True)
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("NCGEN_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv("NCGEN_CFLAGS", raising=False)


def test_manifest_and_header_name_the_jacobian(tmp_path):
    pkg = write_package("chain", chain_functions(), tmp_path / "p", doc=chain_doc(), jacobians=["force"])
    entries = {f["name"]: f for f in pkg.manifest["functions"]}
    assert entries["force"]["jacobian"] == "jac_chain_force"
    assert "jacobian" not in entries["phi"]
    header = (pkg.path / "chain.h").read_text()
    assert "Jacobian: jac_chain_force()" in header
    kernel = (pkg.path / entries["force"]["file"]).read_text()
    assert "int jac_chain_force(" in kernel


def test_without_jacobians_the_package_is_unchanged(tmp_path):
    a = write_package("chain", chain_functions(), tmp_path / "a", doc=chain_doc())
    b = write_package("chain", chain_functions(), tmp_path / "b", doc=chain_doc(), jacobians=())
    c = write_package("chain", chain_functions(), tmp_path / "c", doc=chain_doc(), jacobians=["phi"])
    assert a.content_hash == b.content_hash != c.content_hash


@pytest.mark.parametrize("bad", [["nope"], ["phi", "phi"]])
def test_bad_jacobian_names(tmp_path, bad):
    with pytest.raises(CodegenError, match="jacobians must name"):
        write_package("chain", chain_functions(), tmp_path / "p", jacobians=bad)


@needs_gcc
def test_compiled_function_has_exact_derivatives(tmp_path):
    pkg = write_package("chain", chain_functions(), tmp_path / "p", jacobians=["force"])
    compiled = load_functions(pkg, ["force", "phi"], backend="compiled")
    vm = load_functions(pkg, ["force"], backend="vm")["force"]
    q, v = ca.MX.sym("q", 6), ca.MX.sym("v", 6)
    l, k = ca.MX.sym("l", 3), ca.MX.sym("k")
    args = random_inputs(vm, np.random.default_rng(1))
    J_compiled, J_vm = (np.array(ca.Function("J", [q, v, l, k], [
        ca.jacobian(f(q, v, l, k)[0], ca.vertcat(q, v))])(*args)) for f in (compiled["force"], vm))
    assert np.count_nonzero(J_vm) > 0
    np.testing.assert_allclose(J_compiled, J_vm, rtol=1e-13, atol=1e-13)
    with pytest.raises(RuntimeError, match="cannot be calculated"):
        ca.jacobian(compiled["phi"](q, l)[0], q)


@needs_gcc
def test_jacobian_kernels_compile_without_warnings(tmp_path):
    pkg = write_package("chain", chain_functions(), tmp_path / "p", jacobians=["force", "phi"])
    for src in pkg.manifest["build"]["sources"]:
        out = subprocess.run(["gcc", "-std=c99", "-Wall", "-Wextra", "-pedantic", "-Werror", "-fsyntax-only",
                              src], cwd=pkg.path, capture_output=True, text=True)
        assert out.returncode == 0 and out.stderr == "", (src, out.stderr)

"""nc.generate: a model's C package — compiled vs VM values, determinism, documentation,
metadata, main.c without Python, warning-free C, compile=True, refusal to clobber."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

import ncgen as nc
from ncgen.assembly.functions import DOCS, IN
from ncgen.codegen import load_functions
from ncgen.codegen.model_package import SYSTEM_FUNCTIONS, model_hash
from ncgen.errors import CodegenError
from ncgen.assembly.stepper_equations import KERNELS as STEPPER_KERNELS

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples"
needs_cc = pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None,
                              reason="no C compiler")


def example(name: str):
    return nc.System.from_toml(EXAMPLES / f"{name}.toml").build()


@pytest.fixture(autouse=True)
def private_cache(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("NCGEN_CACHE_DIR", str(tmp_path_factory.getbasetemp() / "ncgen-cache"))


def files_of(directory: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(directory.iterdir())}


def random_inputs(f: ca.Function, rng: np.random.Generator) -> list[ca.DM]:
    return [ca.DM(f.sparsity_in(i), rng.standard_normal(f.nnz_in(i))) for i in range(f.n_in())]


# ----------------------------------------------------------------- compiled vs VM
@needs_cc
@pytest.mark.parametrize("name,cflags", [("tensegrity", "-O0"),
                                         # fast: the tensegrity case, the same comparison
                                         pytest.param("cartpole", None, marks=pytest.mark.slow)])
def test_compiled_matches_vm_on_random_inputs(tmp_path, name, cflags):
    """Every function of the package (parameters and cables in the tensegrity, an input in
    the cart-pole) gives the VM's values to 1e-12, and the dae Jacobian IDAS uses too.
    (The tensegrity's large Jacobian kernel is compiled at -O0 to keep the test quick.)"""
    model = example(name)
    pkg = nc.generate(model, tmp_path / name)
    compiled = load_functions(pkg, backend="compiled", cflags=cflags)
    vm = load_functions(pkg, backend="vm")
    assert set(compiled) == set(SYSTEM_FUNCTIONS) | set(STEPPER_KERNELS)
    rng = np.random.default_rng(7)
    for fname in SYSTEM_FUNCTIONS:
        assert compiled[fname].is_a("External")
        for _ in range(3):
            args = random_inputs(vm[fname], rng)
            for a, b in zip(compiled[fname].call(args), vm[fname].call(args)):
                a, b = np.array(ca.densify(a)), np.array(ca.densify(b))
                assert np.all(np.abs(a - b) <= 1e-12 * np.maximum(1.0, np.abs(b))), fname
    jc, jv = compiled["dae"].jacobian(), vm["dae"].jacobian()
    args = random_inputs(vm["dae"], rng)
    nominal = vm["dae"](*args)
    for a, b in zip(jc(*args, *nominal), jv(*args, *nominal)):
        a, b = np.array(ca.densify(a)), np.array(ca.densify(b))
        assert np.all(np.abs(a - b) <= 1e-12 * np.maximum(1.0, np.abs(b)))


# ------------------------------------------------------------------ determinism
@pytest.mark.slow      # a second interpreter building the model; fast:
#                       tests/test_codegen_package.py::test_same_bytes_from_another_process
def test_same_model_same_bytes_in_two_processes(tmp_path):
    script = ("import sys, ncgen as nc\n"
              f"m = nc.System.from_toml({str(EXAMPLES / 'slider_crank.toml')!r}).build()\n"
              "nc.generate(m, sys.argv[1])\n")
    for out in ("a", "b"):
        subprocess.run([sys.executable, "-c", script, str(tmp_path / out)], check=True)
    nc.generate(example("slider_crank"), tmp_path / "c")
    assert files_of(tmp_path / "a") == files_of(tmp_path / "b") == files_of(tmp_path / "c")


def test_model_hash_tells_models_apart():
    a, b = example("chain"), example("chain")
    assert model_hash(a) == model_hash(b)
    changed = nc.System.from_toml((EXAMPLES / "chain.toml").read_text().replace("mass = 0.2", "mass = 0.25", 1))
    assert model_hash(changed.build()) != model_hash(a)


# ------------------------------------------------------------ header and metadata
def test_docs_cover_every_system_function():
    model = example("cartpole")
    assert set(DOCS) == set(model.functions)
    for name, f in model.functions.items():
        assert set(f.name_in()) <= set(IN), name
        assert set(f.name_out()) == set(DOCS[name][1]), name


def test_header_documents_functions_and_model(tmp_path):
    model = example("cartpole")
    header = (nc.generate(model, tmp_path / "cp").path / "cartpole.h").read_text()
    for name in SYSTEM_FUNCTIONS:
        assert f"---- cartpole_{name} " in header
        purpose = DOCS[name][0]
        assert " ".join(purpose.split())[:40] in " ".join(header.split())
    # 8 coordinates: coordinate sharing makes the hinge the pole's first end, a point of the cart
    assert "arg[1] q: 8x1, nnz 8 [m] natural coordinates" in header
    assert "res[0] A: 6x8" in header and "(sparse)" in header
    assert "Jacobian: jac_cartpole_dae()" in header
    for macro, value in (("NQ", 8), ("NC", 6), ("DOF", 2), ("NU", 1), ("NP", 0), ("DIM", 2)):
        assert f"#define CARTPOLE_{macro} {value}\n" in header
    assert "extern const casadi_real cartpole_q0[8];" in header
    assert "extern const char *const cartpole_coordinate_names[8];" in header


def test_manifest_metadata_is_the_model(tmp_path):
    model = example("tensegrity")
    meta = json.loads((nc.generate(model, tmp_path / "t").path / "manifest.json").read_text())["metadata"]
    assert meta["nq"] == model.nq and meta["nc"] == model.nc and meta["dof"] == model.dof
    assert np.array_equal(meta["q0"], model.q0) and np.array_equal(meta["v0"], model.v0)
    assert np.array_equal(meta["x0"], np.concatenate([model.q0, model.v0]))
    assert "M" not in meta   # M is the (sparse) function 'mass': O(nnz), not O(nq²), in the package
    assert np.array_equal(np.array(model.functions["mass"]()["M"]), model.M)
    assert meta["coordinate_names"] == model.coordinate_names
    assert meta["constraint_names"] == model.constraint_names
    assert meta["parameter_names"] == ["tension", "k_cable", "c_cable"]
    assert np.array_equal(meta["p0"], model.p0)
    assert meta["marker_names"] == ["strut1.top"]
    assert meta["model_hash"] == model_hash(model)


def test_vector_inputs_get_one_name_per_value(tmp_path):
    s = nc.System("pushed", gravity=(0.0, 0.0, -9.81))
    ball = s.add_point("ball", mass=1.0, position=(0.0, 0.0, 0.0))
    f = s.add_input("f", 3)
    s.add_parameter("k", [1.0, 2.0])
    s.add_force(nc.PointForce(ball, (0.0, 0.0, 0.0), force=f))
    meta = nc.generate(s.build(), tmp_path / "p").manifest["metadata"]
    assert meta["input_names"] == ["f[0]", "f[1]", "f[2]"]
    assert meta["parameter_names"] == ["k[0]", "k[1]"]


# ------------------------------------------------------------- C without Python
@pytest.mark.slow      # make builds and runs the slider-crank's main.c; fast:
#                       test_main_c_builds_without_constraints_parameters_or_markers (the same Makefile and main.c)
@needs_cc
@pytest.mark.skipif(shutil.which("make") is None, reason="no make")
def test_main_c_evaluates_accel_at_the_initial_state(tmp_path):
    """``make`` builds <model>_main, which prints accel at (t0, q0, v0, u = 0, p0): the
    model's consistent initial accelerations and multipliers."""
    model = example("slider_crank")
    pkg = nc.generate(model, tmp_path / "sc")
    subprocess.run(["make", "-s"], cwd=pkg.path, check=True, capture_output=True)
    out = subprocess.run([str(pkg.path / "slider_crank_main")], check=True, capture_output=True,
                         text=True).stdout
    values: dict[str, list[float]] = {}
    current = None
    for line in out.splitlines():
        if line.startswith("output "):
            current = line.split()[1]
            values[current] = []
        elif line.startswith("input "):
            current = None
        elif current and line.startswith("  "):
            values[current].append(float(line.split()[2]))
    a, lam = model.accel(model.q0, model.v0)
    assert np.allclose(values["a"], a, rtol=1e-12, atol=1e-12)
    assert np.allclose(values["lam"], lam, rtol=1e-12, atol=1e-12)
    assert np.allclose(values["a"], model.a0, atol=1e-9)


@pytest.mark.slow      # a package compiled at -Werror; fast: test_compile_true_builds_the_library,
#                       tests/test_reliability_optimized_warnings.py (-O2 -Werror)
@needs_cc
def test_package_compiles_warning_free(tmp_path):
    pkg = nc.generate(example("heavy_top"), tmp_path / "ht")
    cc = shutil.which("cc") or shutil.which("gcc")
    for src in pkg.manifest["build"]["sources"]:
        out = subprocess.run([cc, "-std=c99", "-Wall", "-Wextra", "-pedantic", "-Werror", "-O0", "-c", src,
                              "-o", str(tmp_path / f"{src}.o")], cwd=pkg.path, capture_output=True, text=True)
        assert out.returncode == 0, out.stderr


# ------------------------------------------------------------------- compile=True
@needs_cc
def test_compile_true_builds_the_library(tmp_path):
    pkg = nc.generate(example("heavy_top"), tmp_path / "ht", compile=True, cflags="-O0")
    assert pkg.path == tmp_path / "ht" and (pkg.path / "manifest.json").is_file()
    f = load_functions(pkg, ["energy"], backend="compiled", cflags="-O0")["energy"]
    assert f.is_a("External")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ht"]


@needs_cc
def test_compile_failure_leaves_no_package(tmp_path):
    with pytest.raises(CodegenError, match="C compilation failed"):
        nc.generate(example("heavy_top"), tmp_path / "ht", compile=True, cflags="-fno-such-flag-ncgen")
    assert list(tmp_path.iterdir()) == []


def test_refuses_to_replace_a_directory_that_is_not_a_package(tmp_path):
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("keep me")
    for compile_ in (False, True):
        with pytest.raises(CodegenError, match="not an ncgen package"):
            nc.generate(example("heavy_top"), tmp_path / "mine", compile=compile_)
    assert (tmp_path / "mine" / "notes.txt").read_text() == "keep me"


def test_replaces_an_older_package(tmp_path):
    nc.generate(example("chain"), tmp_path / "pkg")
    pkg = nc.generate(example("heavy_top"), tmp_path / "pkg")
    assert pkg.name == "heavy_top" and (tmp_path / "pkg" / "heavy_top.h").is_file()
    assert not (tmp_path / "pkg" / "chain.h").exists()


@needs_cc
@pytest.mark.skipif(shutil.which("make") is None, reason="no make")
def test_main_c_builds_without_constraints_parameters_or_markers(tmp_path):
    """Empty metadata arrays (no p0, no lam0) are not C definitions: main.c uses zeros."""
    s = nc.System("free", gravity=(0.0, 0.0, -9.81))
    s.add_point("ball", mass=1.0, position=(0.0, 0.0, 0.0), velocity=(1.0, 0.0, 0.0))
    pkg = nc.generate(s.build(), tmp_path / "free")
    assert "Default: free_p0" not in (pkg.path / "free.h").read_text()
    subprocess.run(["make", "-s"], cwd=pkg.path, check=True, capture_output=True)
    out = subprocess.run([str(pkg.path / "free_main")], check=True, capture_output=True, text=True).stdout
    assert "output a 3x1 nnz=3\n  0 0 0\n  1 0 0\n  2 0 -9.81" in out

"""The generated package builds with make and CMake, and main.c prints what Python computes."""
import shutil
import subprocess
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from ncgen.codegen import Package, write_package
from test_codegen_samples import chain_doc, chain_functions

needs = pytest.mark.skipif(shutil.which("gcc") is None or shutil.which("make") is None,
                           reason="gcc and make needed")


@pytest.fixture(scope="module")
def pkg(tmp_path_factory) -> Package:
    return write_package("chain", chain_functions(), tmp_path_factory.mktemp("native") / "chain",
                         doc=chain_doc(), max_file_instructions=100)


def parse(stdout: str) -> dict[str, ca.DM]:
    """``main.c`` output as {"input q": DM, "output F": DM, ...}."""
    out, counts, current = {}, {}, None
    for line in stdout.splitlines()[1:]:
        if not line.startswith(" "):
            kind, name, shape, nnz = line.split()
            nrow, ncol = map(int, shape.split("x"))
            current = f"{kind} {name}"
            out[current], counts[current] = ca.DM(nrow, ncol), [int(nnz.removeprefix("nnz=")), 0]
        else:
            r, c, v = line.split()
            out[current][int(r), int(c)] = float(v)
            counts[current][1] += 1
    assert all(n == seen for n, seen in counts.values()), counts
    return out


def expected(pkg: Package, name: str) -> dict[str, ca.DM]:
    f = pkg.functions[name]
    meta, defaults = pkg.manifest["metadata"], chain_doc().defaults
    args = [ca.DM(meta[defaults[f.name_in(i)]]) for i in range(f.n_in())]
    res = {f"input {f.name_in(i)}": a for i, a in enumerate(args)}
    res.update({f"output {f.name_out(i)}": r for i, r in enumerate(f.call(args))})
    return res


def check_main(executable: Path, pkg: Package) -> None:
    for name, argv in (("force", []), ("phi", ["phi"]), ("mass", ["mass"])):
        out = subprocess.run([str(executable), *argv], capture_output=True, text=True, check=True)
        assert out.stdout.splitlines()[0] == f"function {name}"
        got, want = parse(out.stdout), expected(pkg, name)
        assert set(got) == set(want)
        for key in want:
            np.testing.assert_allclose(np.array(got[key]), np.array(want[key]), rtol=1e-12, atol=1e-12, err_msg=key)
    bad = subprocess.run([str(executable), "nope"], capture_output=True, text=True)
    assert bad.returncode == 2 and "available: phi gamma force mass" in bad.stderr


@needs
def test_make(tmp_path, pkg):
    work = tmp_path / "chain"
    shutil.copytree(pkg.path, work)
    out = subprocess.run(["make", "-j2"], cwd=work, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert "warning" not in out.stderr
    assert (work / "libchain.so").is_file()
    check_main(work / "chain_main", pkg)


@needs
@pytest.mark.skipif(shutil.which("cmake") is None, reason="cmake needed")
def test_cmake(tmp_path, pkg):
    build = tmp_path / "build"
    subprocess.run(["cmake", "-S", str(pkg.path), "-B", str(build)], check=True, capture_output=True)
    out = subprocess.run(["cmake", "--build", str(build)], capture_output=True, text=True)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "warning" not in out.stdout + out.stderr
    assert (build / "libchain.so").is_file()
    check_main(build / "chain_main", pkg)

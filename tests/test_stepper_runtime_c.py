"""The stepper's model-independent C (``templates/c/runtime/``) compiled and unit-tested on
its own, without CasADi or a generated model: the C programs in ``tests/c/`` give it
hand-written kernels of tiny models (a Cartesian pendulum; two point masses on the floor)
and check it against closed forms and an independent Runge–Kutta reference — the Newton
step, step splitting, second order, the work and error estimates, the error controller's
step-size rule and local error, the projection; projected Gauss–Seidel on two contacts with
known solutions (sliding, sticking, redundant), the contact step (Coulomb sliding to rest,
a bounce with restitution), for both ways of building the Delassus matrix; the MPC driver
(``ncgen_mpc.h``) on a hand-written iteration (input checks, the guess kept on failure); the
joint-space loop (RK4 and Dormand–Prince) on ODEs with closed-form solutions; the element tables'
loops (``ncgen_element_tables.h``) on hand-written kernels of a tiny planar model; the sparse
QR and LU of the table-driven stepper (``ncgen_sparse_qr.h``, ``ncgen_sparse_lu.h``: solutions,
singular and ill-conditioned matrices refused) on hand-analysed patterns, and that
stepper (``ncgen_table_stepper.h``) on the hand-made tables of a planar pendulum with a spring, and
its step Jacobians (``ncgen_table_jacobians.h``) on the same with inputs and actuators (the
columns also in blocks of three, so that they span several), and
its nonsmooth contacts (``ncgen_table_contacts.h``: an element's rows from a pair kind on canonical
coordinates, a frictional drop to rest) on the tables of a planar point over the floor; the
tree loops (``ncgen_tree_tables.h``: RNEA, CRBA, forward dynamics, derivatives) on hand-written
kernels of a tree of sliders with a mimic joint (through their kernels and as the loops' own
z sliders; the articulated-body algorithm without the mimic map), and the spatial algebra of
its local recursion (``ncgen_spatial.h``) by its identities; the many-column solve with sparse
LU factors (``ncgen_lu_columns.h``) on hand-made factors.  Each program is
built with ``-Wall -Wextra -Werror -pedantic`` under AddressSanitizer and
UndefinedBehaviorSanitizer and must print that all its checks passed."""
from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
TESTS = Path(__file__).resolve().parent / "c"
RUNTIME = ROOT / "templates" / "c" / "runtime"
CC = os.environ.get("CC") or shutil.which("gcc") or shutil.which("clang") or shutil.which("cc")
FLAGS = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O0", "-g",
         "-fsanitize=address,undefined", "-fno-sanitize-recover=all", "-fno-omit-frame-pointer"]
ENV = {**os.environ, "ASAN_OPTIONS": "detect_leaks=0:abort_on_error=0",
       "UBSAN_OPTIONS": "print_stacktrace=1:halt_on_error=1"}
#: The second and third builds of a program (other -D paths) in the slow tier; fast: the generated
#: packages take the Schur path and the pair kernels (tests/test_contact*.py), the table step's
#: Jacobians by rows (tests/test_table_step_jacobians.py), and the first build of each program here.
#: Slow: the program's variants, and the four largest programs (42–60 s each at load ≈ 20, stop 53; the same C
#: runs in the fast tier inside the packages of tests/test_contact.py, test_table_stepper.py,
#: test_table_step_jacobians.py and test_tree_tables.py, without the sanitizers).
SLOW_BUILD = pytest.mark.slow
PROGRAMS = [("test_rattle.c", []), pytest.param("test_contact.c", [], marks=SLOW_BUILD),
            pytest.param("test_contact.c", ["-DSCHUR_FACTORED"], marks=SLOW_BUILD),
            pytest.param("test_contact.c", ["-DPAIRS"], marks=SLOW_BUILD),
            ("test_cone_newton.c", []), ("test_mpc.c", []), ("test_joint_loop.c", []),
            ("test_element_tables.c", []), ("test_sparse_qr.c", []), ("test_sparse_lu.c", []),
            pytest.param("test_table_stepper.c", [], marks=SLOW_BUILD),
            pytest.param("test_table_contacts.c", [], marks=SLOW_BUILD),
            pytest.param("test_table_jacobians.c", ["-DTAB_JAC_ROWS"], marks=SLOW_BUILD),
            pytest.param("test_table_jacobians.c", ["-DTAB_JAC_COLUMNS", "-DTAB_JAC_BLOCK=3"], marks=SLOW_BUILD),
            pytest.param("test_tree_tables.c", [], marks=SLOW_BUILD),
            ("test_spatial.c", []), ("test_lu_columns.c", []), ("test_condense.c", []), ("test_tree_start.c", [])]

pytestmark = pytest.mark.skipif(CC is None, reason="no C compiler (gcc, clang or cc) on PATH")


@pytest.fixture(scope="module")
def sanitizers(tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("runtime_c")
    (tmp / "probe.c").write_text("int main(void) { return 0; }\n")
    built = subprocess.run([CC, *FLAGS, "probe.c", "-o", "probe"], cwd=tmp, capture_output=True)
    if built.returncode or subprocess.run(["./probe"], cwd=tmp, env=ENV).returncode:
        pytest.skip(f"{CC} cannot build and run -fsanitize=address,undefined programs here")
    return tmp


@pytest.mark.parametrize("source, defines", PROGRAMS, ids=["rattle", "contact-kkt", "contact-schur", "contact-pairs",
                                                          "cone-newton", "mpc", "joint-loop", "element-tables",
                                                          "sparse-qr", "sparse-lu", "table-stepper", "table-contacts",
                                                          "table-jacobians",
                                                          "table-jacobians-columns", "tree-tables", "spatial",
                                                          "lu-columns", "condense", "tree-start"])
def test_runtime_c_unit_tests_pass_under_sanitizers(sanitizers, source, defines):
    exe = sanitizers / (Path(source).stem + "".join(d.lower().replace("-d", "_") for d in defines))
    built = subprocess.run([CC, *FLAGS, *defines, f"-I{RUNTIME}", f"-I{TESTS}", str(TESTS / source),
                            "-o", str(exe), "-lm"], capture_output=True, text=True, timeout=300)
    assert built.returncode == 0, built.stderr[-4000:]
    out = subprocess.run([str(exe)], capture_output=True, text=True, env=ENV, timeout=300)
    text = out.stdout + out.stderr
    assert "runtime error" not in text and "AddressSanitizer" not in text, text[-4000:]
    assert out.returncode == 0 and "all" in out.stdout and "checks passed" in out.stdout, text[-4000:]


def test_every_runtime_file_is_unit_tested():
    """Every C file of the runtime is included by one of the unit-test programs
    (ncgen_adaptive.h by test_rattle.c; ncgen_contact.h by test_contact.c;
    ncgen_joint_loop.h by test_joint_loop.c)."""
    included = "".join((TESTS / s).read_text() for s, _ in (getattr(p, "values", p) for p in PROGRAMS))
    for path in sorted(RUNTIME.glob("*.h")):
        assert f'#include "{path.name}"' in included, path.name


def test_packages_carry_the_runtime_verbatim(tmp_path):
    """A model package holds the runtime files as they are in templates/c/runtime (under the
    do-not-edit banner), the contact half only with nonsmooth contacts; <model>_stepper.c
    includes them, <model>.h does not; the build lists them as headers (Makefile dependencies,
    compile-cache key)."""
    import ncgen as nc
    from ncgen.codegen.render import banner

    s = nc.System("ball")
    b = s.add_point("ball", mass=1.0, position=(0.0, 0.0, 0.5))
    s.add_contact(nc.SpherePlane(b, None, 0.1))
    for contacts, files in [("smooth", ["ncgen_rattle.h", "ncgen_fixed.h", "ncgen_adaptive.h"]),
                            ("nonsmooth", ["ncgen_rattle.h", "ncgen_cone_newton.h", "ncgen_contact_pairs.h", "ncgen_contact.h",
                                          "ncgen_fixed.h", "ncgen_adaptive.h"])]:
        pkg = nc.generate(s.build(contacts=contacts), tmp_path / contacts)
        stepper = (pkg.path / "ball_stepper.c").read_text()
        assert sorted(p.name for p in pkg.path.glob("ncgen_*.h")) == sorted(files)
        for f in files:
            text = (pkg.path / f).read_text()
            assert text == banner(f"c/runtime/{f}", f) + (RUNTIME / f).read_text()
            assert f'#include "{f}"' in stepper and f not in (pkg.path / "ball.h").read_text()
            assert f in pkg.manifest["build"]["headers"] and f in (pkg.path / "Makefile").read_text()


def test_included_sources_are_checked():
    from ncgen.codegen.package import ExtraSource, _check_extra_sources
    from ncgen.errors import CodegenError

    for bad in (ExtraSource("runtime/ncgen_rattle.h", "x.c", included=True),
                ExtraSource("runtime/ncgen_rattle.h", "x.h", {"a": 1}, included=True)):
        with pytest.raises(CodegenError, match="included by another source"):
            _check_extra_sources("m", [bad])

"""The stepper's C API in the generated package: ``<model>_step`` (one step, called through
ctypes) agrees with ``<model>_simulate``, reports bad input by status, is documented in the
header; example programs (``ExtraSource(program=True)``) are validated and built."""
from __future__ import annotations

import ctypes
import shutil

import numpy as np
import pytest

import ncgen as nc
from ncgen.codegen import ExtraSource, compile_package, write_package
from ncgen.errors import CodegenError
from ncgen.assembly.stepper_equations import stepper_functions
from ncgen.codegen.stepper_package import write_stepper_package
from ncgen.runtime.stepper_library import load_stepper

needs_cc = pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None,
                              reason="no C compiler")


def double_pendulum():
    s = nc.System("dp", gravity=(0.0, 0.0, -9.81))
    b1 = s.add_bar("b1", "rr", mass=1.0, ends=[s.ground.point((0.0, 0.0, 0.0)), (1.0, 0.0, 0.0)])
    s.add_bar("b2", "rr", mass=0.5, ends=[b1.end(1), (1.0, 0.0, -0.8)], velocity=(0.0, 0.3, 0.0),
              angular_velocity=(0.75, 0.0, 0.0))
    return s.build()


def c_array(x):
    x = np.ascontiguousarray(x, dtype=float)
    return x, x.ctypes.data_as(ctypes.POINTER(ctypes.c_double))


@needs_cc
def test_single_step_agrees_with_simulate(tmp_path):
    model = double_pendulum()
    stepper = load_stepper(model)
    lib = ctypes.CDLL(stepper.library)
    step = lib.dp_step
    step.restype = ctypes.c_int
    lib.dp_step_work_bytes.restype = ctypes.c_size_t
    h = 1e-3
    q, qp = c_array(model.q0)
    v, vp = c_array(model.v0)
    q1, q1p = c_array(np.zeros(model.nq))
    v1, v1p = c_array(np.zeros(model.nq))
    lam, lamp = c_array(np.zeros(model.nc))
    iters = ctypes.c_int(-1)
    work = ctypes.create_string_buffer(lib.dp_step_work_bytes())
    status = step(qp, vp, ctypes.c_double(0.0), None, None, ctypes.c_double(h), q1p, v1p, lamp,
                  ctypes.byref(iters), None, work)
    assert status == 0 and iters.value >= 1
    Q, V, LAM, ITER, status, done, splits = stepper.simulate(model.q0, model.v0, 0.0, h, 1, 1, None, model.p0,
                                                             1e-10, 12, 4, scheme=1)   # the C default: rattle4
    assert status == 0 and done == 1 and splits == 0 and ITER[0] == iters.value
    np.testing.assert_array_equal(Q[0], q1)
    np.testing.assert_array_equal(V[0], v1)
    np.testing.assert_array_equal(LAM[0], lam)
    assert np.max(np.abs(model.phi(q1))) <= 1e-10
    # without a workspace the call allocates its own; a non-positive step is bad input (5)
    assert step(qp, vp, ctypes.c_double(0.0), None, None, ctypes.c_double(h), q1p, v1p, None, None, None,
                None) == 0
    assert step(qp, vp, ctypes.c_double(0.0), None, None, ctypes.c_double(0.0), q1p, v1p, None, None, None,
                None) == 5


def test_header_documents_the_api(tmp_path):
    model = double_pendulum()
    pkg = write_stepper_package(model, tmp_path / "dp")
    header = (pkg.path / "dp_stepper.h").read_text()
    for text in ("int dp_step(", "int dp_simulate(", "size_t dp_step_work_bytes(void)", "#define DP_STEP_OK 0",
                 "#define DP_STEP_NO_CONVERGENCE 1", "dp_step_options", "zero-order hold", "RATTLE"):
        assert text in header
    assert '#include "dp_stepper.h"' in (pkg.path / "dp.h").read_text()
    assert pkg.manifest["build"]["programs"] == ["dp_simulate.c"]
    assert "dp_simulate.c" not in pkg.manifest["build"]["sources"]


def test_kernel_patterns_match():
    """The second half-step's KKT matrix is stored in the Newton matrix's pattern, which the
    solve kernel expects."""
    newton, velocity, _, solve, project, *_ = stepper_functions(double_pendulum())
    assert velocity.sparsity_out("K") == newton.sparsity_out("K") == solve.sparsity_in("K")
    assert project.sparsity_out("K") == newton.sparsity_out("K")
    assert newton.sparsity_out("r").is_dense() and velocity.sparsity_out("b").is_dense()


@pytest.mark.parametrize("output", ["prog.h", "x_main.c"])
def test_program_outputs_are_checked(tmp_path, output):
    f = stepper_functions(double_pendulum())[2]
    with pytest.raises(CodegenError, match="program"):
        write_package("x", [f], tmp_path / "p", extra_sources=[ExtraSource("main.c.j2", output, program=True)])


@needs_cc
def test_programs_are_not_in_the_library(tmp_path):
    (tmp_path / "tpl").mkdir()
    (tmp_path / "tpl" / "prog.c.j2").write_text("int main(void) { return 0; }\n")
    f = stepper_functions(double_pendulum())[2]
    pkg = write_package("x", [f], tmp_path / "p", template_dirs=[tmp_path / "tpl"],
                        extra_sources=[ExtraSource("prog.c.j2", "x_demo.c", program=True)])
    assert "x_demo: x_demo.o $(OBJS)" in (pkg.path / "Makefile").read_text()
    assert "add_executable(x_demo x_demo.c)" in (pkg.path / "CMakeLists.txt").read_text()
    ctypes.CDLL(str(compile_package(pkg).path))   # no second main() linked into the library

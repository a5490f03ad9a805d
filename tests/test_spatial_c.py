"""The spatial algebra of the tree tables' local recursion, plain C in
``templates/c/runtime/ncgen_spatial.h``, against ncgen.rigid_motion's forms of the SymPy
formulas (``ncgen/symbolic/rigid_motion.py``, ``spatial_inertia.py``) to 1e-12 on random
poses, twists, wrenches and inertias: the one source of its formulas is the symbolic layer,
and this test holds the C to it (docs/architecture.md, "Element tables")."""
from __future__ import annotations

import ctypes
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from ncgen import rigid_motion as rm
from ncgen.codegen.compiler import CANDIDATES

ROOT = Path(__file__).resolve().parent.parent
RUNTIME = ROOT / "templates" / "c" / "runtime"
CC = next((shutil.which(c) for c in CANDIDATES if shutil.which(c)), None)
pytestmark = pytest.mark.skipif(CC is None, reason="no C compiler on PATH")

WRAPPERS = """#include "ncgen_spatial.h"
void w_cross(const double *a, const double *b, double *c) { sp_cross(a, b, c); }
void w_rot(const double *R, const double *x, double *y) { sp_rot(R, x, y); }
void w_rot_t(const double *R, const double *x, double *y) { sp_rot_t(R, x, y); }
void w_twist_in(const double *R, const double *p, const double *T, double *Y) { sp_twist_in(R, p, T, Y); }
void w_wrench_out_add(const double *R, const double *p, const double *W, double *Y) { sp_wrench_out_add(R, p, W, Y); }
void w_ad(const double *T, const double *X, double *Y) { sp_ad(T, X, Y); }
void w_ad_star(const double *T, const double *W, double *Y) { sp_ad_star(T, W, Y); }
void w_inertia_apply(const double *I, const double *T, double *W) { sp_inertia_apply(I, T, W); }
void w_inertia_out_add(const double *R, const double *p, const double *I, double *J) { sp_inertia_out_add(R, p, I, J); }
void w_inertia_matrix(const double *I, double *M) { sp_inertia_matrix(I, M); }
void w_twist_out(const double *R, const double *p, const double *T, double *Y) { sp_twist_out(R, p, T, Y); }
void w_inertia_rotate(const double *R, const double *I, double *J) { sp_inertia_rotate(R, I, J); }
void w_inertia_shift_add(const double *d, const double *I, double *J) { sp_inertia_shift_add(d, I, J); }
void w_wrench_shift(const double *d, const double *W, double *Y) { int i; for (i = 0; i < 6; ++i) Y[i] = W[i]; sp_wrench_shift(d, Y); }
"""


@pytest.fixture(scope="module")
def lib(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("spatial")
    (tmp / "w.c").write_text(WRAPPERS)
    built = subprocess.run([CC, "-O2", "-Wall", "-Wextra", "-Werror", "-Wno-unused-function", "-shared", "-fPIC",
                            f"-I{RUNTIME}", "w.c", "-o", "w.so"], cwd=tmp, capture_output=True, text=True)
    assert built.returncode == 0, built.stderr
    return ctypes.CDLL(str(tmp / "w.so"))


def call(lib, name, out_size, *args, out=None):
    """``name(*args, out)`` with column-major float arrays; the output (accumulated into ``out`` if given)."""
    arrays = [np.asfortranarray(np.asarray(a, float)).reshape(-1, order="F").copy() for a in args]
    y = np.zeros(out_size) if out is None else np.asarray(out, float).reshape(-1, order="F").copy()
    getattr(lib, name)(*(a.ctypes.data_as(ctypes.c_void_p) for a in arrays), y.ctypes.data_as(ctypes.c_void_p))
    return y


def pose(rng):
    return rm.exp_so3(rng.normal(size=3)), rng.normal(size=3)


def rigid(rng):
    """A rigid inertia as the C holds it, ``[m; h; I_o]``, and its mass matrix (symbolic form)."""
    m, c = rng.uniform(0.5, 3.0), rng.normal(size=3) * 0.3
    Q = rm.exp_so3(rng.normal(size=3))
    I_c = Q @ np.diag(rng.uniform(0.8, 1.2, 3)) @ Q.T
    I_o = rm.inertia_about_point(m, c, I_c)
    return np.concatenate([[m], m * c, I_o.reshape(-1, order="F")]), rm.mass_matrix(m, c, I_o)


def close(a, b):
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-12 * max(1.0, np.abs(b).max()))


@pytest.mark.parametrize("seed", range(5))
def test_spatial_algebra_equals_the_symbolic_forms(lib, seed):
    rng = np.random.default_rng(seed)
    R, p = pose(rng)
    H = rm.homogeneous(R, p)
    T, X, W = rng.normal(size=6), rng.normal(size=6), rng.normal(size=6)
    a, b = rng.normal(size=3), rng.normal(size=3)
    close(call(lib, "w_cross", 3, a, b), rm.so3_hat(a) @ b)
    close(call(lib, "w_rot", 3, R, a), R @ a)
    close(call(lib, "w_rot_t", 3, R, a), R.T @ a)
    close(call(lib, "w_twist_in", 6, R, p, T), rm.Ad_inv(H) @ T)
    close(call(lib, "w_wrench_out_add", 6, R, p, W, out=X), X + rm.transport_wrench(rm.inverse(H), W))
    close(call(lib, "w_ad", 6, T, X), rm.ad(T) @ X)
    close(call(lib, "w_ad_star", 6, T, W), -rm.ad(T).T @ W)
    I, M = rigid(rng)
    close(call(lib, "w_inertia_matrix", 36, I).reshape(6, 6, order="F"), M)
    close(call(lib, "w_inertia_apply", 6, I, T), M @ T)
    J, N = rigid(rng)
    moved = call(lib, "w_inertia_out_add", 13, R, p, I, out=J)
    close(call(lib, "w_inertia_matrix", 36, moved).reshape(6, 6, order="F"),
          N + rm.transport_mass_matrix(M, rm.inverse(H)))
    turned = call(lib, "w_inertia_rotate", 13, R, I)    # a rotation alone
    close(call(lib, "w_inertia_matrix", 36, turned).reshape(6, 6, order="F"),
          rm.transport_mass_matrix(M, rm.inverse(rm.homogeneous(R, np.zeros(3)))))
    close(call(lib, "w_twist_out", 6, R, p, T), rm.Ad(H) @ T)
    D = rm.homogeneous(np.eye(3), p)                 # a translation alone
    shifted = call(lib, "w_inertia_shift_add", 13, p, I, out=J)
    close(call(lib, "w_inertia_matrix", 36, shifted).reshape(6, 6, order="F"),
          N + rm.transport_mass_matrix(M, rm.inverse(D)))
    close(call(lib, "w_wrench_shift", 6, p, W), rm.transport_wrench(rm.inverse(D), W))

"""Compiled kernels called from Python check their arguments: arity, sizes (no
broadcasting of a length-1 vector), and, on the checked call, finiteness; a valid call after
a refused one is not contaminated by the refused values."""
from __future__ import annotations

import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import NcgenError, ShapeError


@pytest.fixture(scope="module")
def arm():
    s = nc.System("arm2")
    a = s.add_body("a", mass=1.0, inertia=np.diag([0.01, 0.02, 0.02]), position=(0.5, 0, 0))
    b = s.add_body("b", mass=0.7, inertia=np.diag([0.01, 0.02, 0.02]), position=(1.5, 0, 0))
    s.add_input("tau", 2)
    s.add_joint(nc.Revolute(s.ground, a, at=(0, 0, 0), axis=(0, 1, 0), effort="tau[0]"))
    s.add_joint(nc.Revolute(a, b, at=(1, 0, 0), axis=(0, 1, 0), effort="tau[1]"))
    return s.build()


def test_kernel_arguments_are_checked(arm):
    k = nc.forward_dynamics_kernel(arm)          # k(t, q, v, u, p) -> a, lam
    q, v, u, p = arm.q0, np.linspace(-0.1, 0.1, arm.nq), np.array([1.0, -0.5]), np.zeros(0)
    v = v - arm.A(q).T @ np.linalg.lstsq(arm.A(q).T, v, rcond=None)[0]
    a_ref, _ = nc.forward_dynamics(arm, q, v, u=u)
    with pytest.raises(ShapeError, match=r"expected 5 arguments \(t, q, v, u, p\), got 4"):
        k(0.0, q, v, u)
    with pytest.raises(ShapeError, match=r"expected 5 arguments"):
        k(0.0, q, v, u, p, p)
    with pytest.raises(ShapeError, match=r"argument 'q': expected 12 values, got 1"):
        k(0.0, q[:1], v, u, p)
    with pytest.raises(ShapeError, match=r"argument 'u': expected 2 values, got 3"):
        k(0.0, q, v, np.ones(3), p)
    with pytest.raises(ShapeError, match=r"argument 'q': expected real numbers, got complex numbers"):
        k.checked(0.0, q + 0j, v, u, p)          # NumPy would drop the imaginary part
    with pytest.raises(ShapeError, match=r"argument 'u': expected real numbers, got booleans"):
        k.checked(0.0, q, v, np.array([True, False]), p)
    with pytest.raises(ShapeError, match=r"argument 'v': expected real numbers, got NoneType None at index 0"):
        k(0.0, q, [None] * arm.nq, u, p)         # not a number: the careful path names it
    with pytest.raises(ShapeError, match=r"argument 'v': expected finite numbers, found nan at index 4"):
        k.checked(0.0, q, np.where(np.arange(arm.nq) == 4, np.nan, v), u, p)
    a = np.array(k(0.0, list(q), v, u, p)[0]).reshape(-1)        # a list, after the refusals
    np.testing.assert_allclose(a, np.asarray(a_ref).reshape(-1), rtol=1e-10, atol=1e-10)
    a2 = np.array(k(np.array([0.0]), q.reshape(-1, 1), v, u, p)[0]).reshape(-1)   # a column is fine
    np.testing.assert_allclose(a2, a, rtol=0, atol=0)


def test_tree_kernel_refuses_what_is_not_real(arm):
    """The joint-space kernel's C fast path copies float64 arrays as they are and reads other
    sequences number by number: complex and boolean arrays are refused, not cast."""
    k = nc.joint_forward_dynamics_kernel(arm)
    qj, vj = np.array([0.3, -0.2]), np.array([0.1, 0.0])
    expected = np.array(k(qj, vj)).copy()
    for bad, found in ((qj + 1j, "complex numbers"), (np.array([True, False]), "booleans"),
                       ([None, 0.1], "NoneType None at index 0")):
        with pytest.raises(ShapeError, match=rf"qj: expected real numbers, got {found}"):
            k(bad, vj)
    np.testing.assert_array_equal(k(list(qj), vj), expected)      # not contaminated by the refusals


@pytest.mark.parametrize("raw", [bytes, bytearray, memoryview], ids=["bytes", "bytearray", "memoryview"])
def test_fast_calls_refuse_raw_bytes(arm, raw):
    """Two doubles' worth of bytes has the length of qj, but is not two numbers: the C fast
    path (joint forward dynamics, the tree algorithms) refuses it (issue 35), and a valid call
    after it is not contaminated."""
    k = nc.joint_forward_dynamics_kernel(arm)
    rnea = nc.algorithm_kernel(arm, "rnea")
    direct = nc.forward_dynamics_kernel(arm)                 # the ctypes path
    qj, vj = np.array([0.3, -0.2]), np.array([0.1, 0.0])
    expected, torques = np.array(k(qj, vj)).copy(), np.array(rnea(qj, vj, vj)).copy()
    for length in (2, 16):                                   # as many bytes as values, or as the doubles
        data = raw(np.arange(length, dtype=np.uint8).tobytes())
        said = rf"expected real numbers, got {raw.__name__} \(raw bytes are not read as numbers\)"
        with pytest.raises(ShapeError, match=r"joint forward dynamics: qj: " + said):
            k(data, vj)
        with pytest.raises(NcgenError, match=said):
            rnea(data, vj, vj)
        with pytest.raises(ShapeError, match=r"argument 'q': " + said):
            direct(0.0, raw(np.zeros(arm.nq).tobytes()[:arm.nq]), arm.v0, np.zeros(2), np.zeros(0))
    np.testing.assert_array_equal(k(qj, vj), expected)
    np.testing.assert_array_equal(rnea(qj, vj, vj), torques)

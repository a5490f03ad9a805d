"""Rotations given to printed precision: one rule everywhere (``nearest_rotation``): up to
``PRINTED_ROTATION_TOL`` projected onto SO(3) with a warning, beyond it refused saying what
was found; the rigid-motion algebra and the model API agree."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import RotationError
from ncgen.rigid_motion import Ad, homogeneous, inverse
from ncgen.validation import PRINTED_ROTATION_TOL, RotationProjected


def exact_rotation(rng):
    Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return Q * np.sign(np.linalg.det(Q))


def printed(R, digits=8):
    return np.round(R, digits)


def test_inverse_and_adjoint_of_a_printed_homogeneous_matrix():
    rng = np.random.default_rng(3)
    for _ in range(20):
        R, p = exact_rotation(rng), rng.normal(size=3)
        H = np.eye(4)
        H[:3, :3], H[:3, 3] = printed(R, 8), p
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RotationProjected)
            Hi = inverse(H)
            Ad_H = Ad(H)
        # the result is that of the nearest rotation, which is within 1e-8 of the exact one
        assert np.allclose(Hi @ homogeneous(R, p), np.eye(4), atol=1e-7)
        Rp = Hi[:3, :3].T
        assert np.max(np.abs(Rp.T @ Rp - np.eye(3))) < 1e-13
        assert np.allclose(Ad_H[:3, :3], Rp, atol=0) and np.allclose(Ad_H[3:, 3:], Rp, atol=0)


def test_projection_warns_and_is_the_nearest_rotation():
    R = exact_rotation(np.random.default_rng(7))
    E = 3e-7 * np.array([[0.0, 1, 0], [1, 0, 0], [0, 0, 1]])       # symmetric: the nearest rotation is R back
    with pytest.warns(RotationProjected, match="projected to the nearest rotation"):
        H = inverse(homogeneous(R @ (np.eye(3) + E), np.zeros(3)))
    assert np.allclose(H[:3, :3], R.T, atol=1e-12)


def test_beyond_printed_precision_is_refused_with_what_was_found():
    R = exact_rotation(np.random.default_rng(1)) * (1 + 10 * PRINTED_ROTATION_TOL)
    with pytest.raises(RotationError, match=r"H_ab\[:3, :3\]: expected an orthonormal matrix, \|RᵀR - 1\| = 0\.0002"):
        inverse(np.block([[R, np.zeros((3, 1))], [np.zeros((1, 3)), np.ones((1, 1))]]))
    with pytest.raises(RotationError, match="reflection"):
        inverse(np.diag([1.0, 1.0, -1.0, 1.0]))


def test_a_body_given_a_printed_rotation_builds_on_the_projected_one():
    R = exact_rotation(np.random.default_rng(11))
    s = nc.System("b")
    with pytest.warns(RotationProjected):
        s.add_body("b", mass=1.0, inertia=np.diag([1.0, 2.0, 2.5]), position=(0, 0, 0), rotation=printed(R, 7))
    model = s.build()
    Rm, _ = model.poses(model.q0)
    assert np.max(np.abs(Rm[0] - R)) < 1e-7
    assert np.max(np.abs(Rm[0].T @ Rm[0] - np.eye(3))) < 1e-12

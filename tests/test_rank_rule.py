"""One rank rule (``ncgen.assembly.manifold.RANK_TOL``) for ``Model.rank``, ``dof_report``
and the null-space basis, so they cannot disagree near a singular position (issue 33).

The reference is the geometry of a tethered two-bar chain (two unit bars from the origin and
a tether from the origin to the far end): bent by ``θ`` it has one degree of freedom (rank 3
of 4 coordinates), stretched (``θ = 0``) the tether's direction is the bars' and the rank
drops to 2.  At ``θ = 1e-12`` rad the smallest singular value of ``A`` is ~1e-12 of the
largest: NumPy's default rank (``σ > 4 ε σ_max``) still counted 3 while the null basis
(``σ > 1e-10 σ_max``) had two columns; now every route says 2."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

import ncgen as nc
from ncgen.assembly.manifold import RANK_TOL, null_basis, numerical_rank, tangent_basis
from test_reliability_redundancy import tethered_chain


def chain(angle):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")             # the stretched chain's tether is named as dependent
        return tethered_chain(angle).build(redundant="keep")


@pytest.mark.parametrize("angle, rank", [(0.3, 3), (1e-12, 2), (0.0, 2)])
def test_rank_and_null_space_agree(angle, rank):
    model = chain(angle)
    A = model.A(model.q0)
    s = np.linalg.svd(A, compute_uv=False)
    assert (s[-1] / s[0] < RANK_TOL) == (rank == 2)
    assert model.rank == rank
    assert nc.dof_report(model).rank == rank
    assert numerical_rank(A) == rank
    assert null_basis(A, model.nq).shape[1] == model.nq - rank == tangent_basis(model, model.q0).shape[1]
    assert model.dof == model.nq - rank


def test_the_old_rules_disagreed_there():
    """What the test above guards against: NumPy's default tolerance, which ``Model.rank`` and
    ``dof_report`` used, counts the near-stretched chain as regular."""
    model = chain(1e-12)
    A = model.A(model.q0)
    assert np.linalg.matrix_rank(A) == 3 and null_basis(A, A.shape[1]).shape[1] == 2


def test_numerical_rank_of_an_empty_matrix_is_zero():
    assert numerical_rank(np.zeros((0, 4))) == 0
    assert null_basis(np.zeros((0, 4)), 4).shape == (4, 4)

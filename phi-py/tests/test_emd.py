"""phi_rs.emd against an independent exact solver, and its refusals."""

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment
from scipy.spatial.distance import cdist

import phi_rs


def reference(a, b, metric):
    cost = cdist(a, b, metric=metric)
    rows, cols = linear_sum_assignment(cost)
    return cost[rows, cols].mean()


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("cost", ["sqeuclidean", "euclidean"])
def test_emd_equals_linear_sum_assignment(dim, cost):
    rng = np.random.default_rng(7 + dim)
    a = rng.uniform(0.0, 1.0, size=(120, dim))
    b = rng.uniform(0.2, 1.3, size=(120, dim))
    got = phi_rs.emd(a, b, cost=cost)
    expected = reference(a, b, cost)
    assert got == pytest.approx(expected, rel=1e-9, abs=1e-12)


def test_emd_takes_float32_and_lists():
    a = np.array([[0.0, 0.0], [1.0, 0.0]], dtype=np.float32)
    b = [[1.0, 1.0], [0.0, 1.0]]
    # Each point moves by 1: mean squared distance 1.
    assert phi_rs.emd(a, b) == 1.0
    assert phi_rs.emd(a, a) == 0.0


def test_emd_wrong_shape_names_the_argument():
    with pytest.raises(phi_rs.PointSetError, match=r"emd: b: shape \(6,\)"):
        phi_rs.emd(np.zeros((3, 2)), np.zeros(6))


def test_emd_different_sizes_is_refused():
    with pytest.raises(phi_rs.PointSetError, match=r"\(3, 2\) and b \(4, 2\)"):
        phi_rs.emd(np.zeros((3, 2)), np.zeros((4, 2)))


def test_emd_non_finite_and_unknown_cost():
    a = np.zeros((2, 2))
    b = np.array([[0.0, np.nan], [1.0, 1.0]])
    with pytest.raises(phi_rs.PointSetError):
        phi_rs.emd(a, b)
    with pytest.raises(phi_rs.PointSetError, match="'manhattan' is not a ground cost"):
        phi_rs.emd(a, a, cost="manhattan")

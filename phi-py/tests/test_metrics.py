"""phi_rs.sinkhorn against an independent NumPy log-domain Sinkhorn and against emd as
epsilon -> 0; phi_rs.position_mse against NumPy."""

import numpy as np
import pytest

import phi_rs


def logsumexp(x, axis):
    top = x.max(axis=axis, keepdims=True)
    return (top + np.log(np.exp(x - top).sum(axis=axis, keepdims=True))).squeeze(axis)


def ot_potentials(x, y, eps, iterations=5000):
    """Log-domain Sinkhorn for uniform measures and cost ½|x − y|²: the dual potentials."""
    cost = 0.5 * ((x[:, None, :] - y[None, :, :]) ** 2).sum(-1)
    log_a, log_b = -np.log(len(x)), -np.log(len(y))
    f, g = np.zeros(len(x)), np.zeros(len(y))
    for _ in range(iterations):
        f = -eps * logsumexp(log_b + (g[None, :] - cost) / eps, axis=1)
        g_new = -eps * logsumexp(log_a + (f[:, None] - cost) / eps, axis=0)
        if np.abs(g_new - g).max() < 1e-12:
            g = g_new
            break
        g = g_new
    return f, g


def numpy_sinkhorn_divergence(a, b, eps):
    """S = OT(a, b) − ½ OT(a, a) − ½ OT(b, b), OT = ⟨α, f⟩ + ⟨β, g⟩ at convergence."""
    def ot(x, y):
        f, g = ot_potentials(x, y, eps)
        return f.mean() + g.mean()
    return ot(a, b) - 0.5 * ot(a, a) - 0.5 * ot(b, b)


@pytest.fixture(scope="module")
def points():
    rng = np.random.default_rng(5)
    a = rng.uniform(0, 1, (24, 2)).astype(np.float32)
    b = (rng.uniform(0, 1, (17, 2)) * 0.6 + 0.3).astype(np.float32)
    return a, b


def test_sinkhorn_equals_numpy_log_domain_sinkhorn(points):
    a, b = points
    for eps in (0.5, 0.05):
        expected = numpy_sinkhorn_divergence(a.astype(np.float64), b.astype(np.float64), eps)
        got = phi_rs.sinkhorn(a, b, epsilon=eps, tolerance=1e-12, max_iterations=5000)
        assert got == pytest.approx(expected, rel=1e-6, abs=1e-9), eps


def test_sinkhorn_approaches_half_the_emd_as_epsilon_shrinks():
    rng = np.random.default_rng(11)
    a = rng.uniform(0, 1, (40, 2))
    b = rng.uniform(0, 1, (40, 2)) * 0.5 + 0.4
    half_w2 = 0.5 * phi_rs.emd(a, b)
    gaps = [abs(phi_rs.sinkhorn(a, b, epsilon=eps) - half_w2) for eps in (1e-2, 1e-3, 1e-4)]
    assert gaps[0] > gaps[1] > gaps[2], gaps
    assert gaps[2] < 1e-3 * half_w2, (gaps, half_w2)


def test_sinkhorn_of_a_set_with_itself_is_zero_and_errors(points):
    a, b = points
    assert abs(phi_rs.sinkhorn(a, a, epsilon=0.01)) < 1e-9
    assert phi_rs.sinkhorn(a, b, epsilon=0.01) > 0
    with pytest.raises(phi_rs.PointSetError, match=r"sinkhorn: a: shape \(48,\): expected \[N, d\]"):
        phi_rs.sinkhorn(a.ravel(), b)
    with pytest.raises(phi_rs.PointSetError, match="same dimension"):
        phi_rs.sinkhorn(a, np.zeros((3, 3)))
    with pytest.raises(phi_rs.PointSetError, match="epsilon"):
        phi_rs.sinkhorn(a, b, epsilon=0.0)
    with pytest.raises(phi_rs.PointSetError, match="not finite"):
        phi_rs.sinkhorn(np.full((2, 2), np.nan), b)


def test_position_mse_against_numpy():
    rng = np.random.default_rng(3)
    truth = rng.normal(size=(6, 10, 2)).astype(np.float32)
    predicted = (truth + rng.normal(scale=0.1, size=truth.shape)).astype(np.float32)
    types = np.array([1] * 7 + [0] * 3, dtype=np.int64)
    liquid = types == 1
    error = (predicted.astype(np.float64) - truth.astype(np.float64)) ** 2
    curve = error[:, liquid].mean(axis=(1, 2))
    assert np.allclose(phi_rs.position_mse(predicted, truth, types, per_frame=True), curve,
                       rtol=1e-12)
    assert phi_rs.position_mse(predicted, truth, types) == pytest.approx(curve.mean(), rel=1e-12)
    assert phi_rs.position_mse(predicted, truth) == pytest.approx(error.mean(), rel=1e-12)
    assert phi_rs.position_mse(predicted[0], truth[0], types) == pytest.approx(curve[0], rel=1e-12)
    with pytest.raises(phi_rs.PointSetError, match="expected the same"):
        phi_rs.position_mse(predicted, truth[:-1])
    with pytest.raises(phi_rs.PointSetError, match="particle_type"):
        phi_rs.position_mse(predicted, truth, types[:-1])

"""HumanML3D-protocol metrics against hand-computed values on tiny arrays."""

from __future__ import annotations

import numpy as np
import pytest

from motok_robot.eval import metrics as M


def test_fid_identical_sets_is_zero_and_shift_adds_squared_distance():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(500, 4))
    assert M.fid(x, x) == pytest.approx(0.0, abs=1e-6)
    # a pure shift by d adds exactly ||d||^2 (covariances identical)
    d = np.array([1.0, 2.0, 0.0, -2.0])
    assert M.fid(x, x + d) == pytest.approx(9.0, rel=1e-6)


def test_frechet_distance_of_known_gaussians():
    # 1-D: (mu1-mu2)^2 + s1 + s2 - 2 sqrt(s1 s2)
    value = M.frechet_distance(np.array([0.0]), np.array([[4.0]]), np.array([1.0]), np.array([[1.0]]))
    assert value == pytest.approx(1.0 + 4.0 + 1.0 - 2.0 * 2.0)


def test_r_precision_perfect_and_reversed_matches():
    rng = np.random.default_rng(1)
    m = rng.normal(size=(64, 8)) * 10
    np.testing.assert_allclose(M.r_precision(m, m), [1.0, 1.0, 1.0])
    # 1-D hand case: text i at 10 i, motion i at 10 i + 7. For i >= 1 motion i-1 (distance 3)
    # is nearer than the match (distance 7); for i = 0 the match is nearest.
    t = np.arange(32, dtype=float)[:, None] * 10
    r = M.r_precision(t, t + 7.0, top_k=3)
    np.testing.assert_allclose(r, [1 / 32, 1.0, 1.0])


def test_r_precision_drops_incomplete_batch_and_validates():
    x = np.zeros((40, 2))
    x[:, 0] = np.arange(40)
    assert M.r_precision(x, x)[0] == 1.0  # 8 leftover pairs ignored
    with pytest.raises(ValueError, match="at least 32"):
        M.r_precision(x[:10], x[:10])
    with pytest.raises(ValueError, match="same shape"):
        M.r_precision(x, x[:, :1])


def test_matching_score_diversity_multimodality_hand_values():
    t = np.array([[0.0, 0.0], [1.0, 1.0]])
    m = np.array([[3.0, 4.0], [1.0, 1.0]])
    assert M.matching_score(t, m) == pytest.approx(2.5)
    same = np.ones((300, 3))
    assert M.diversity(same) == 0.0
    grouped = np.zeros((2, 10, 1))
    grouped[0, :, 0] = np.arange(10)
    value = M.multimodality(grouped, times=10, rng=np.random.default_rng(0))
    assert 0.0 < value < 9.0
    assert M.multimodality(np.ones((3, 10, 2)), times=10) == 0.0


def test_confidence_interval():
    mean, half = M.confidence_interval(np.array([1.0, 3.0]))
    assert mean == 2.0
    assert half == pytest.approx(1.96 * 1.0 / np.sqrt(2))


def test_metrics_reject_nan():
    x = np.ones((40, 2))
    x[3, 1] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        M.fid(x, x)

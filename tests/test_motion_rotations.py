"""Rotation helpers: round trips, conventions, edge cases."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from motok_robot.motion import rotations as R


def _random_quats(n, seed=0):
    q = np.random.default_rng(seed).normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def test_quat_to_matrix_matches_scipy_wxyz():
    q = _random_quats(50)
    ref = Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix()  # scipy is xyzw
    np.testing.assert_allclose(R.quat_to_matrix(q), ref, atol=1e-12)


def test_matrix_quat_round_trip_including_half_turns():
    q = _random_quats(200, seed=1)
    # include exact half turns (w = 0) where the trace-based branch is singular
    q[:3] = [[0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]
    m = R.quat_to_matrix(q)
    q2 = R.matrix_to_quat(m)
    assert np.all(q2[:, 0] >= 0)
    np.testing.assert_allclose(np.abs(np.sum(q * q2, axis=-1)), 1.0, atol=1e-12)


def test_quat_mul_and_rotate_agree_with_matrices():
    a, b = _random_quats(20, 2), _random_quats(20, 3)
    v = np.random.default_rng(4).normal(size=(20, 3))
    np.testing.assert_allclose(R.quat_to_matrix(R.quat_mul(a, b)), R.quat_to_matrix(a) @ R.quat_to_matrix(b), atol=1e-12)
    np.testing.assert_allclose(R.quat_rotate(a, v), np.einsum("nij,nj->ni", R.quat_to_matrix(a), v), atol=1e-12)
    np.testing.assert_allclose(R.quat_mul(a, R.quat_inverse(a)), R.quat_identity((20,)), atol=1e-12)


def test_axis_angle_round_trip_and_small_angles():
    aa = np.random.default_rng(5).normal(size=(100, 3))
    aa *= (np.random.default_rng(6).uniform(0, np.pi - 1e-3, (100, 1)) / np.linalg.norm(aa, axis=-1, keepdims=True))
    aa[0] = 0.0
    aa[1] = [1e-10, 0, 0]
    np.testing.assert_allclose(R.quat_to_axis_angle(R.quat_from_axis_angle(aa)), aa, atol=1e-9)
    ref = Rotation.from_rotvec(aa).as_matrix()
    np.testing.assert_allclose(R.axis_angle_to_matrix(aa), ref, atol=1e-12)
    np.testing.assert_allclose(R.matrix_to_axis_angle(ref), aa, atol=1e-9)


def test_cont6d_is_first_two_columns_and_gram_schmidt_recovers():
    m = R.quat_to_matrix(_random_quats(30, 7))
    d6 = R.matrix_to_cont6d(m)
    np.testing.assert_allclose(d6[:, :3], m[:, :, 0])
    np.testing.assert_allclose(d6[:, 3:], m[:, :, 1])
    np.testing.assert_allclose(R.matrix_from_cont6d(d6), m, atol=1e-12)
    # a perturbed, non-orthonormal 6-vector still maps to a proper rotation
    noisy = R.matrix_from_cont6d(d6 * 1.7 + 0.05)
    np.testing.assert_allclose(noisy @ np.swapaxes(noisy, -1, -2), np.tile(np.eye(3), (30, 1, 1)), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(noisy), 1.0, atol=1e-12)


def test_quat_between_maps_v0_onto_v1_and_handles_opposite():
    rng = np.random.default_rng(8)
    v0, v1 = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    v1[0] = -v0[0] * 3.0  # exactly opposite
    v1[1] = v0[1] * 0.5  # same direction
    q = R.quat_between(v0, v1)
    assert np.all(np.isfinite(q))
    out = R.quat_rotate(q, v0)
    np.testing.assert_allclose(out / np.linalg.norm(out, axis=-1, keepdims=True),
                               v1 / np.linalg.norm(v1, axis=-1, keepdims=True), atol=1e-9)
    np.testing.assert_allclose(q[1], [1, 0, 0, 0], atol=1e-12)
    # shortest arc: the rotation axis is perpendicular to both vectors
    axis = q[2:, 1:]
    np.testing.assert_allclose(np.sum(axis * v0[2:], -1), 0, atol=1e-9)


def test_slerp_endpoints_midpoint_and_shortest_path():
    q0 = R.quat_from_axis_angle(np.array([0.0, 0.0, 0.2]))
    q1 = R.quat_from_axis_angle(np.array([0.0, 0.0, 1.0]))
    np.testing.assert_allclose(R.quat_slerp(q0, q1, 0.0), q0, atol=1e-12)
    np.testing.assert_allclose(R.quat_slerp(q0, q1, 1.0), q1, atol=1e-12)
    np.testing.assert_allclose(R.quat_to_axis_angle(R.quat_slerp(q0, q1, 0.5)), [0, 0, 0.6], atol=1e-12)
    # -q1 is the same rotation: slerp must take the short way
    np.testing.assert_allclose(R.quat_to_axis_angle(R.quat_slerp(q0, -q1, 0.5)), [0, 0, 0.6], atol=1e-12)
    # batched t
    out = R.quat_slerp(q0, q1, np.array([0.0, 0.25, 1.0]))
    assert out.shape == (3, 4)


def test_quat_fix_makes_sequence_sign_continuous():
    q = R.quat_from_axis_angle(np.linspace(0, 2, 10)[:, None] * [0, 1, 0])
    flipped = q.copy()
    flipped[3:6] *= -1
    fixed = R.quat_fix(flipped)
    np.testing.assert_allclose(fixed, q)


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_rotation_about_axis_is_right_handed(axis):
    m = R.rotation_about_axis(np.pi / 2, axis)
    e = np.eye(3)
    nxt = (axis + 1) % 3
    after = (axis + 2) % 3
    np.testing.assert_allclose(m @ e[nxt], e[after], atol=1e-12)
    np.testing.assert_allclose(R.geodesic_angle(np.eye(3), m), np.pi / 2)


def test_wrap_angle():
    np.testing.assert_allclose(R.wrap_angle(np.array([0.0, 3 * np.pi / 2, -3 * np.pi / 2, 7.0])),
                               [0.0, -np.pi / 2, np.pi / 2, 7.0 - 2 * np.pi])

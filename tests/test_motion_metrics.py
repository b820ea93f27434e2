"""Joint-space metrics, checked against hand-computed values on tiny arrays."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import uniform_filter1d

from motok_robot.errors import InputError
from motok_robot.motion import metrics as M
from motok_robot.motion import synthetic

LF, RF = 10, 11


def _still(frames: int) -> np.ndarray:
    j = np.zeros((frames, 22, 3))
    j[..., 2] = 0.5  # every joint 50 cm up; tests move the feet explicitly
    return j


def test_mpjpe_with_and_without_root_alignment():
    target = _still(2)
    pred = target.copy()
    pred[..., 0] += 0.3  # whole body shifted 30 cm
    pred[1, 5, 1] += 0.4  # one joint in one frame off by a further 40 cm sideways
    # shifted joints: 0.3 everywhere, except the one joint: sqrt(0.3^2 + 0.4^2) = 0.5
    expected = (43 * 0.3 + 0.5) / 44
    assert M.mpjpe(pred, target) == pytest.approx(expected)
    # root-aligned: the global shift cancels, only the 40 cm remains on 1 of 44 joint-frames
    assert M.mpjpe(pred, target, align_root=True) == pytest.approx(0.4 / 44)


def test_skating_hand_computed():
    j = _still(4)
    j[:, [LF, RF], 2] = 0.02  # both feet on the ground
    # left foot slides 3 cm per frame (0.6 m/s > 0.5 m/s), right foot still
    j[:, LF, 0] = [0.0, 0.03, 0.06, 0.09]
    # without the averaging window every step skates
    assert M.foot_skating_ratio(j, average_window=1) == pytest.approx(1.0)
    # GMD's 5-step window, zero padded: averages are 0.36, 0.36, 0.36 m/s for 3 steps -> none skate
    assert M.foot_skating_ratio(j) == 0.0
    # 2 cm per frame (0.4 m/s) never skates
    j[:, LF, 0] = [0.0, 0.02, 0.04, 0.06]
    assert M.foot_skating_ratio(j, average_window=1) == 0.0


def test_skating_needs_contact_in_both_frames():
    j = _still(5)
    j[:, RF, 2] = 0.02
    j[:, RF, 1] = 0.04 * np.arange(5)  # 0.8 m/s sideways, always on the ground
    j[:, LF, 2] = 0.02
    flags = M.foot_skating_frames(j, average_window=1)
    np.testing.assert_array_equal(flags, [True, True, True, True])
    j[2, RF, 2] = 0.06  # lifted at frame 2: steps 1->2 and 2->3 are not contacts
    flags = M.foot_skating_frames(j, average_window=1)
    np.testing.assert_array_equal(flags, [True, False, False, True])
    assert M.foot_skating_ratio(j, average_window=1) == pytest.approx(0.5)


def test_skating_window_matches_scipy_uniform_filter():
    x = np.random.default_rng(0).uniform(size=(3, 2, 17))
    for size in (2, 3, 5):
        np.testing.assert_allclose(M._centred_mean(x, size), uniform_filter1d(x, size, axis=-1, mode="constant"), atol=1e-12)


def test_skating_on_a_long_glide_and_on_synthetic_walk():
    j = _still(40)
    j[:, [LF, RF], 2] = 0.0
    j[..., 0] += 0.04 * np.arange(40)[:, None]  # whole body glides at 0.8 m/s with feet down
    # zero padding: the first and last steps average 3 x 0.8 / 5 = 0.48 m/s < 0.5, all others skate
    assert M.foot_skating_ratio(j) == pytest.approx(37 / 39)
    walk = synthetic.walking_clip(60)
    ratio = M.foot_skating_ratio(walk)
    assert 0.0 <= ratio <= 1.0


def test_penetration_and_floating_mm():
    j = _still(4)
    j[:, [7, 8, 10, 11], 2] = 0.1
    j[0, 7, 2] = -0.02  # 20 mm below the floor
    j[1, 11, 2] = 0.0  # on the floor
    j[2, 8, 2] = 0.004  # within the 5 mm tolerance
    j[3, 10, 2] = 0.105  # lowest foot joint is at 100 mm -> floating 95 mm
    out = M.foot_ground_distances(j)
    assert out["penetration_max_mm"] == pytest.approx(20.0)
    assert out["penetration_mean_mm"] == pytest.approx(5.0)
    assert out["floating_max_mm"] == pytest.approx(95.0)
    assert out["floating_mean_mm"] == pytest.approx(95.0 / 4)


def test_root_trajectory_error():
    target = _still(3)
    pred = target.copy()
    pred[:, 0, 0] += [0.0, 0.3, 0.0]
    pred[:, 0, 1] += [0.0, 0.4, 0.1]
    pred[:, 0, 2] += 0.06
    out = M.root_trajectory_error(pred, target)
    assert out["mean_m"] == pytest.approx(0.6 / 3)
    assert out["max_m"] == pytest.approx(0.5)
    assert out["final_m"] == pytest.approx(0.1)
    assert out["height_mean_m"] == pytest.approx(0.06)


def test_joint_speed_percentiles():
    j = _still(3)
    j[1:, :11, 0] = 0.1  # half the joints move 10 cm in step 0 (2 m/s), nothing else moves
    out = M.joint_speed_percentiles(j, percentiles=(50, 100))
    assert out["p100"] == pytest.approx(2.0)
    assert out["p50"] == pytest.approx(0.0)


def test_summary_and_errors():
    out = M.motion_summary(synthetic.walking_clip(41))
    assert out["seconds"] == pytest.approx(2.0)
    assert 1.5 < out["root_path_m"] < 3.0  # 1.2 m/s for 2 s
    assert all(np.isfinite(v) for v in out.values())
    with pytest.raises(InputError, match="same shape"):
        M.mpjpe(_still(3), _still(4))
    with pytest.raises(InputError, match=r"\[\.\.\., T, 22, 3\]"):
        M.foot_skating_ratio(np.zeros((3, 21, 3)))
    bad = _still(3)
    bad[2, 4, 0] = np.nan
    with pytest.raises(InputError, match=r"frame 2, joint 4 \(left_knee\)"):
        M.foot_ground_distances(bad)
    with pytest.raises(InputError, match="at least 2"):
        M.foot_skating_ratio(_still(1))

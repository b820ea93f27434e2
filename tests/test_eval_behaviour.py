"""The behaviour checks on procedural motions with known answers (no models needed)."""

from __future__ import annotations

import numpy as np
import pytest

from motok_robot.eval import behaviour as B
from motok_robot.motion import skeleton
from motok_robot.motion.synthetic import standing_clip, walking_clip

J = skeleton.JOINT_INDEX
T = 120  # 6 s at 20 fps


def _standing() -> np.ndarray:
    return standing_clip(frames=T).astype(np.float64)


def _pitched(pitch_deg: np.ndarray) -> np.ndarray:
    """A standing clip whose upper body rotates forward about the pelvis by ``pitch_deg[t]``."""
    joints = _standing()
    up = np.array([0.0, 0.0, 1.0])
    for t, deg in enumerate(pitch_deg):
        f = np.append(B.facing(joints[t:t + 1])[0], 0.0)
        axis = np.cross(up, f)
        th = np.radians(deg)
        pelvis = joints[t, J["pelvis"]].copy()
        for i in skeleton.UPPER_BODY:
            v = joints[t, i] - pelvis
            # Rodrigues' rotation about ``axis`` (unit, horizontal)
            joints[t, i] = pelvis + v * np.cos(th) + np.cross(axis, v) * np.sin(th) + axis * axis.dot(v) * (1 - np.cos(th))
    return joints


def _with_wrists(right_up: np.ndarray, left_up: np.ndarray, sway: float = 0.0) -> np.ndarray:
    joints = _standing()
    for side, up in (("right", right_up), ("left", left_up)):
        joints[up, J[f"{side}_wrist"], 2] = joints[up, J[f"{side}_shoulder"], 2] + 0.2
    if sway:
        f = B.facing(joints)
        left_dir = np.stack([-f[:, 1], f[:, 0]], axis=1)
        joints[:, J["right_wrist"], :2] += left_dir * sway * np.sin(np.linspace(0, 6 * np.pi, T))[:, None]
    return joints


def test_torso_pitch_follows_a_known_forward_rotation():
    pitch = 40.0 * np.sin(np.linspace(0, np.pi, T))
    measured = B.torso_pitch_deg(_pitched(pitch))
    # the pelvis-to-neck line of the rest pose leans slightly; the change follows the rotation
    np.testing.assert_allclose(measured - measured[0], pitch - pitch[0], atol=0.5)


def test_bow_passes_a_bow_and_names_what_a_bad_one_misses():
    there_and_back = B.check_bow(_pitched(45.0 * np.sin(np.linspace(0, np.pi, T))))
    assert there_and_back.passed, there_and_back.reason
    assert there_and_back.values["peak_deg"] > 40
    shallow = B.check_bow(_pitched(20.0 * np.sin(np.linspace(0, np.pi, T))))
    assert not shallow.passed and "at most" in shallow.reason
    held = B.check_bow(_pitched(np.minimum(np.linspace(0, 90, T), 45.0) + np.linspace(0, 1, T)))
    assert not held.passed and "did not come back up" in held.reason
    late = np.concatenate([np.full(T // 2, 25.0), 25.0 + 20.0 * np.sin(np.linspace(0, np.pi, T - T // 2))])
    started_bent = B.check_bow(_pitched(late - np.linspace(0, 20, T) * (np.arange(T) > 90)))
    assert not started_bent.passed and "start upright" in started_bent.reason


def test_walk_checks_on_a_walk_and_on_standing():
    walk = walking_clip(frames=T, speed=1.2).astype(np.float64)
    stand = _standing()
    assert B.check_walk(walk).passed, B.check_walk(walk).reason
    assert B.check_walk(walk).values["lead_swaps"] >= 4
    assert not B.check_walk(stand).passed and "walked only" in B.check_walk(stand).reason
    assert B.check_run_faster(walk, stand).passed
    assert not B.check_run_faster(stand, walk).passed
    assert B.check_walk_planted(stand).passed  # both feet on the floor and still
    sliding = stand.copy()
    sliding[:, :, 0] += 0.1 * np.arange(T)[:, None]  # gliding at 2 m/s: feet never still, never planted
    result = B.check_walk_planted(sliding)
    assert not result.passed and result.values["unplanted"] == 1.0


def test_hand_checks():
    t = np.arange(T)
    half = t < T // 2
    assert B.check_raise_both_hands(_with_wrists(half, half)).passed
    one = B.check_raise_both_hands(_with_wrists(half, np.zeros(T, bool)))
    assert not one.passed and one.values["both_up"] == 0.0
    assert B.check_wave_right_hand(_with_wrists(half, np.zeros(T, bool), sway=0.15)).passed
    still = B.check_wave_right_hand(_with_wrists(half, np.zeros(T, bool)))
    assert not still.passed and "changed direction" in still.reason
    both = B.check_wave_right_hand(_with_wrists(half, half, sway=0.15))
    assert not both.passed and "left wrist" in both.reason


def test_check_all_generates_each_prompt_once_at_its_length():
    calls = []

    def fake(text: str, seconds: float) -> np.ndarray:
        calls.append((text, seconds))
        return _standing()

    results = B.check_all(fake)
    assert list(results) == list(B.CHECKS)
    assert sorted(calls, key=str) == sorted([(B.WALK, 6.0), (B.RUN, 6.0), (B.WAVE, 6.0), (B.BOTH_HANDS, None), (B.BOW, None)],
                                            key=str)
    assert not any(r.passed for name, r in results.items() if name != "walk_planted")

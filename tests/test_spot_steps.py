"""Steps of a motion on the spot (:mod:`motok_robot.feasibility.spot_steps`): support phases read
from the reference, pauses for the weight to move, the ZMP reference, and the stage's option.

Synthetic phases and the shipped op3_like model; nothing from ../shared.
"""

from __future__ import annotations

import numpy as np
import pytest

from motok_robot.errors import InputError
from motok_robot.feasibility.config import FeasibilityConfig, SpotStepConfig
from motok_robot.feasibility.spot_steps import runs, spot_zmp_reference, support_phases, weight_shift_frames
from motok_robot.feasibility.stage import make_feasible
from motok_robot.feasibility.geometry import convex_hull, signed_distance
from motok_robot.feasibility.zmp_shift import _kinematics
from motok_robot.robots import load
from motok_robot.robots.index import index_robot
from retarget.retime import hold_frames

FPS = 20.0
PHASES = dict(contact_height_m=0.005, slide_speed_per_leg=0.2, min_swing_s=0.3, min_stance_s=0.15,
              min_double_support_s=0.25)


@pytest.fixture(scope="module")
def op3():
    return index_robot(load("op3_like"))


def test_runs_lists_each_stretch_of_true():
    assert runs(np.array([0, 1, 1, 0, 1], dtype=bool)) == [(1, 2), (4, 4)]
    assert runs(np.zeros(3, dtype=bool)) == []


def test_a_shuffle_along_the_floor_becomes_a_step_of_the_shortest_swing():
    T = 40
    low = np.zeros((T, 2))
    xy = np.zeros((T, 2, 2))
    xy[:, 1, 1] = -0.1
    xy[20:, 0, 0] = 0.04  # the left foot slides 4 cm in one frame, never lifting
    down = support_phases(low, xy, FPS, 0.25, **PHASES)
    swings = runs(~down[:, 0])
    assert len(swings) == 1 and swings[0][1] - swings[0][0] + 1 == round(0.3 * FPS)
    assert swings[0][0] <= 19 and swings[0][1] >= 20  # around the slide
    assert down[:, 1].all()


def test_a_swing_waits_for_the_double_support_and_one_foot_is_always_down():
    T = 60
    low = np.zeros((T, 2))
    low[10:25, 1] = 0.1  # the right foot kicks ...
    low[24:30, 0] = 0.01  # ... and the left lifts before the right has landed (a hop in the data)
    down = support_phases(low, np.zeros((T, 2, 2)), FPS, 0.25, **PHASES)
    assert down.any(axis=1).all()
    (right,) = runs(~down[:, 1])
    (left,) = runs(~down[:, 0])
    assert right == (10, 24)
    assert left[0] == 25 + round(0.25 * FPS)  # the touchdown, then 0.25 s on both feet


def test_a_double_support_too_short_for_the_weight_to_move_pauses_the_reference():
    T = 30
    contacts = np.ones((T, 2), dtype=bool)
    contacts[5:12, 0] = False   # on the right foot
    contacts[14:22, 1] = False  # two frames later on the left, 0.2 m away
    centre = np.zeros((T, 2, 2))
    centre[:, 0] = [0.0, 0.1]
    centre[:, 1] = [0.0, -0.1]
    frames = weight_shift_frames(contacts, centre, FPS, zmp_speed_m_s=0.1, min_double_support_s=0.25)
    assert frames[0] == 0 and frames[-1] == T - 1 and set(np.diff(frames)) <= {0, 1}
    held = np.bincount(frames, minlength=T) - 1
    assert held[12] == int(np.ceil(0.2 / 0.1 * FPS)) - 2  # the middle of frames 12-13: 2 s at 0.1 m/s
    # between the feet and a stance foot (0.1 m, 1 s) before the first lift-off and after the
    # last touchdown: 5 and 8 frames there, so 15 and 12 more
    assert held[2] == 15 and held[25] == 12 and held.sum() == 38 + 15 + 12


def test_the_zmp_reference_stands_on_the_stance_foot_and_crosses_in_double_support():
    T = 60
    contacts = np.ones((T, 2), dtype=bool)
    contacts[30:40, 1] = False  # the left foot carries the robot for 10 frames
    centre = np.zeros((T, 2, 2))
    centre[:, 0] = [0.0, 0.05]
    centre[:, 1] = [0.0, -0.05]
    zmp = spot_zmp_reference(contacts, centre, transfer=8)
    np.testing.assert_allclose(zmp[30:40], centre[30:40, 0])
    np.testing.assert_allclose(zmp[:22, 1], 0.0, atol=1e-12)  # between the feet while standing ...
    np.testing.assert_allclose(zmp[29], centre[29, 0])       # ... then onto the stance foot before lift-off
    assert 0.0 < zmp[25, 1] < 0.05
    np.testing.assert_allclose(zmp[52:, 1], 0.0, atol=1e-12)  # and back between the feet after touchdown


def test_hold_frames_repeats_poses_without_changing_the_speed(retargeted, op3):
    qpos = np.tile(op3.nominal_qpos, (5, 1))
    qpos[:, 0] = np.arange(5) * 0.01
    trajectory = retargeted(op3, qpos)
    held = hold_frames(trajectory, np.array([0, 1, 2, 2, 2, 3, 4]))
    assert held.qpos.shape[0] == 7 and np.allclose(held.qpos[2:5, 0], 0.02)
    assert held.retime_factor == trajectory.retime_factor
    with pytest.raises(ValueError):
        hold_frames(trajectory, np.array([0, 2, 1, 4]))


def _lift_right_foot(index, seconds: float = 4.0) -> np.ndarray:
    """The nominal pose with the right foot raised on the spot for a second (hip and knee)."""
    T = int(round(seconds * FPS))
    qpos = np.tile(index.nominal_qpos, (T, 1))
    names = list(index.joint_names)
    bump = np.zeros(T)
    up = np.arange(int(1.5 * FPS), int(2.5 * FPS))
    bump[up] = np.sin(np.pi * (up - up[0] + 1) / (len(up) + 1))
    for name, amount in (("r_hip_pitch", -0.5), ("r_knee", 1.0), ("r_ank_pitch", -0.5)):
        qpos[:, index.qpos_adr[names.index(name)]] += amount * bump
    return qpos


def test_the_stage_moves_the_weight_onto_the_stance_foot_before_a_foot_lifts_on_the_spot(op3, retargeted):
    qpos = _lift_right_foot(op3)
    on = FeasibilityConfig(spot_steps=SpotStepConfig(enabled=True))
    result = make_feasible(retargeted(op3, qpos), op3, on)
    record = result.record["spot_steps"]
    assert record["steps"] == 1 and record["swings"][0]["foot"] == "right"
    com, corners, _, _ = _kinematics(op3, result.trajectory.task_qpos)
    first = int(round(record["swings"][0]["start_s"] * FPS))
    last = int(round(record["swings"][0]["end_s"] * FPS))
    # the planned CoM stands over the left sole while the right foot is up ...
    margins = [signed_distance(com[t, :2], convex_hull(corners[t, 0, :, :2])) for t in range(first, last + 1)]
    assert min(margins) > 0.0, min(margins)
    # ... where the reference's stays between the feet
    ref_com, ref_corners, _, _ = _kinematics(op3, result.trajectory.reference_qpos)
    mid = (first + last) // 2
    assert signed_distance(ref_com[mid, :2], convex_hull(ref_corners[mid, 0, :, :2])) < 0.0
    off = make_feasible(retargeted(op3, qpos), op3, FeasibilityConfig())
    assert "spot_steps" not in off.record  # off by default


def test_spot_step_settings_are_bounded():
    with pytest.raises(InputError, match="min_swing_s"):
        SpotStepConfig(min_swing_s=-1.0)
    assert FeasibilityConfig().with_settings({"spot_steps": {"enabled": True}}, "test").spot_steps.enabled


def test_feasible_spot_steps_flag_plans_the_steps(op3, retargeted, tmp_path, capsys):
    from motok_robot.cli import main
    from retarget.io import write_robot_npz

    path = write_robot_npz(tmp_path / "robot.npz", retargeted(op3, _lift_right_foot(op3)))
    assert main(["feasible", str(path), "--robot", "op3_like", "--spot-steps", "--out", str(tmp_path / "on")]) == 0
    assert "spot steps: 1 swing(s)" in capsys.readouterr().out
    record = __import__("json").loads((tmp_path / "on" / "feasibility.json").read_text())
    assert record["spot_steps"]["steps"] == 1

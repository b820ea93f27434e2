"""Arms kept clear of the legs on the robot's own walk (motok_robot.feasibility.clearance)."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from motok_robot.feasibility.clearance import ArmLegPairs, keep_arms_clear
from motok_robot.robots import load
from motok_robot.robots.index import index_robot
from motok_robot.sim import synthetic as S

FPS = 20.0


@pytest.fixture(scope="module")
def op3():
    return index_robot(load("op3_like"))


def _closest(index, pairs, q) -> float:
    data = mujoco.MjData(index.kin_model)
    data.qpos[:] = q
    mujoco.mj_kinematics(index.kin_model, data)
    return float(pairs.distances(data, 0.05).min())


def test_an_arm_driven_into_the_thigh_is_moved_out_by_its_own_joints_and_back(op3):
    qpos = S.standing(op3, 4.0, FPS)
    adr = {n: op3.qpos_adr[j] for j, n in enumerate(op3.joint_names)}
    hit = slice(30, 46)  # 1.5-2.3 s: the left arm swung in against the thigh, in and out over 0.4 s
    roll = qpos[0, adr["l_sho_roll"]]
    qpos[:, adr["l_sho_roll"]] = roll + (-0.3 - roll) * np.interp(np.arange(qpos.shape[0]), [22, 30, 45, 53], [0, 1, 1, 0])
    pairs = ArmLegPairs(op3)
    assert min(_closest(op3, pairs, q) for q in qpos[hit]) < 0  # it does collide
    close = np.nonzero([_closest(op3, pairs, q) < 0.01 for q in qpos])[0]

    out, record = keep_arms_clear(op3, qpos, FPS, 0.01)

    assert record["frames_before"] == close.size >= 16 and record["frames_after"] == 0
    assert min(_closest(op3, pairs, q) for q in out) >= 0.0099
    moved = np.nonzero(np.abs(out - qpos).max(axis=0) > 1e-9)[0]
    left_arm = {adr["l_sho_pitch"], adr["l_sho_roll"], adr["l_el"]}
    assert moved.size and set(moved.tolist()) <= left_arm  # legs, base, head and the other arm untouched
    changed = np.nonzero(np.abs(out - qpos).max(axis=1) > 1e-9)[0]
    assert changed.min() >= close.min() - 10 and changed.max() <= close.max() + 10  # held 0.25 s, eased over 0.25 s
    speed = lambda q: np.abs(np.diff(q[:, sorted(left_arm)], axis=0)).max() * FPS
    assert speed(out) < 1.5 * speed(qpos)  # no jump


def test_an_arm_that_stays_clear_is_left_alone(op3):
    qpos = S.standing(op3, 1.0, FPS)
    out, record = keep_arms_clear(op3, qpos, FPS, 0.01)
    assert record["frames_before"] == 0 and record["max_correction_rad"] == 0.0
    np.testing.assert_array_equal(out, qpos)

"""Continuity between frames: the validation check ``base_continuity`` (the largest base rotation
between consecutive frames) and the retargeter, which turns the base and a planted foot through a
spin without a flip (``retarget.pivot`` and the sole turn rows of ``retarget.problem``)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mujoco")
pytest.importorskip("casadi")

from motok_robot.motion.skeleton import JOINT_INDEX, rest_pose  # noqa: E402
from motok_robot.sim.config import ValidationConfig  # noqa: E402
from motok_robot.sim.kinematic import base_rotation_steps  # noqa: E402
from retarget.config import CollisionConfig, ContactConfig, RetargetConfig  # noqa: E402
from retarget.metrics import base_turns, planted_sole_turns  # noqa: E402
from retarget.solve import Retargeter  # noqa: E402
from tests.test_retarget import toy_robot  # noqa: E402


def _yaw_quat(yaw):
    yaw = np.asarray(yaw, dtype=np.float64)
    return np.stack([np.cos(yaw / 2), 0 * yaw, 0 * yaw, np.sin(yaw / 2)], axis=-1)


def test_base_rotation_steps_measure_turns_and_ignore_the_quaternion_sign():
    yaw = np.radians([0, 10, 20, 180, 190])
    q = _yaw_quat(yaw)
    q[2] *= -1  # the same rotation
    steps = base_rotation_steps(q)
    np.testing.assert_allclose(steps, [10, 10, 160, 10], atol=1e-9)
    assert (steps > ValidationConfig().max_base_rotation_step_deg).tolist() == [False, False, True, False]
    assert base_rotation_steps(q[:1]).shape == (0,)


RIGHT_LEG = [JOINT_INDEX[n] for n in ("right_knee", "right_ankle", "right_foot")]


def _smoothstep(t, a, b):
    s = np.clip((t - a) / (b - a), 0.0, 1.0)
    return s * s * (3 - 2 * s)


def spin_on_left_foot(T: int = 50) -> np.ndarray:
    """A person [T, 22, 3] who lifts the right leg, spins one full turn (heading 0 -> 360 degrees,
    through +-180, up to 22 degrees a frame at 20 fps) on the ball of the planted left foot, and
    puts the right foot down again."""
    rest = rest_pose()
    t = np.arange(T, dtype=np.float64)
    lift = _smoothstep(t, 4, 10) - _smoothstep(t, 40, 46)
    turn = 2 * np.pi * _smoothstep(t, 12, 37)
    pivot = rest[JOINT_INDEX["left_foot"]]
    hip = rest[JOINT_INDEX["right_hip"]]
    out = np.empty((T, 22, 3))
    for i in range(T):
        pose = rest.copy()
        a = 0.5 * lift[i]  # right thigh forward about the hip (the leg keeps its lengths)
        rel = pose[RIGHT_LEG] - hip
        pose[RIGHT_LEG] = hip + np.stack([rel[:, 0] * np.cos(a) + rel[:, 2] * np.sin(a), rel[:, 1],
                                          -rel[:, 0] * np.sin(a) + rel[:, 2] * np.cos(a)], axis=-1)
        c, s = np.cos(turn[i]), np.sin(turn[i])
        rel = pose - pivot
        out[i] = pivot + np.stack([c * rel[:, 0] - s * rel[:, 1], s * rel[:, 0] + c * rel[:, 1], rel[:, 2]], axis=-1)
    return out


def _sole_yaw(kin, x):
    T = len(x)
    fwd = np.array(kin.frame.map(T)(x.T)[2]).reshape(3, 2, T, order="F").transpose(2, 1, 0)
    return np.arctan2(fwd[..., 1], fwd[..., 0])  # [T, 2]


@pytest.fixture(scope="module")
def spin_result():
    config = RetargetConfig(window=20, overlap=5, collision=CollisionConfig(enabled=False))
    rt = Retargeter(toy_robot(), config, cache=False)
    return rt, rt.run(spin_on_left_foot(), 20.0, progress=False)


def test_spin_turns_the_base_and_the_planted_foot_without_a_flip(spin_result):
    rt, res = spin_result
    assert res.contacts[12:38, 0].all() and not res.contacts[12:38, 1].any()  # spinning on the left foot
    steps = base_rotation_steps(res.qpos[:, 3:7])
    assert steps.max() <= ValidationConfig().max_base_rotation_step_deg, (steps.max(), np.flatnonzero(steps > 45))
    assert res.success, res.failed_windows()
    # the robot spins with the person: the base turns the full turn, not back and forth
    assert abs((res.x[-1, 3] - res.x[0, 3]) - 2 * np.pi) < 0.5
    np.testing.assert_allclose(base_turns(res.x), steps, atol=1e-6)  # retargeting's own measure agrees
    assert planted_sole_turns(rt.kin, res.x, res.contacts).max() < 30.0  # smoothly (the person: <= 22 a frame)
    yaw = _sole_yaw(rt.kin, res.x)
    assert abs(np.unwrap(yaw[:, 0])[-1] - np.unwrap(yaw[:, 0])[0] - 2 * np.pi) < 0.6  # ... the whole turn
    site = np.array(rt.kin.frame.map(len(res.x))(res.x.T)[1]).reshape(3, 2, -1, order="F")
    left = site[:2, 0, :].T
    assert np.linalg.norm(left - left[0], axis=1).max() < 1e-3  # pivoting about the sole site, not sliding


def test_pivot_bounds_follow_the_person_only_where_the_body_spins():
    from retarget.pivot import MAX_PIVOT_STEP, pivot_bounds

    T, fps = 6, 20.0
    heading = np.radians([0, 1, 2, 22, 42, 43])  # 20 degrees a frame (400 deg/s) in steps 2-3 and 3-4
    foot = np.radians([[0, 0], [5, 0], [10, 0], [40, -15], [50, -30], [51, -30]])  # left turns with it, right against
    foot_dir = np.stack([np.cos(foot), np.sin(foot)], axis=-1)
    contacts = np.ones((T, 2), dtype=bool)
    b = np.degrees(pivot_bounds(heading, foot_dir, contacts, fps))
    np.testing.assert_allclose(b[:, 0], [0, 0, 0, 20, 10, 0], atol=1e-9)  # slow turns: none; else the smaller turn
    np.testing.assert_allclose(b[:, 1], 0, atol=1e-12)  # a foot turning against the body keeps its yaw
    contacts[3, 0] = False
    b = pivot_bounds(heading, foot_dir, contacts, fps)
    assert b[3, 0] == 0 and b[4, 0] == 0  # only between two contact frames
    assert not pivot_bounds(heading, foot_dir, np.ones((T, 2), bool), fps, ContactConfig(pivot_speed=None)).any()
    quick = np.radians([[0, 0], [90, 90]])  # a turn beyond the cap: held below the quarter turn
    b = pivot_bounds(np.radians([0, 80]), np.stack([np.cos(quick), np.sin(quick)], -1), np.ones((2, 2), bool), fps)
    np.testing.assert_allclose(b[1], MAX_PIVOT_STEP)


def test_a_planted_sole_turned_round_violates_its_rows():
    """The no-slip rows: a sole turned by 180 degrees about its site has the same sole edge
    direction up to sign (a zero cross product, what the yaw-slip row measures); the turn row
    (dot product >= 0) is what rules it out."""
    from retarget.config import CostWeights
    from retarget.problem import RobotKinematics, StageFunctions

    kin = RobotKinematics.build(toy_robot())
    stage = StageFunctions(kin, CostWeights(), "exact", True, (), 0.0, False)
    x0 = kin.nominal_x.copy()
    site = np.array(kin.frame(x0)[1])[:, 0]
    flipped = x0.copy()
    flipped[3] += np.pi  # turned round about the left sole site
    flipped[:2] = 2 * site[:2] - x0[:2]
    s = np.zeros(stage.ns)
    _, g = stage.fg(np.concatenate([x0, x0, flipped]), s)
    g = np.array(g).ravel()
    row = {n: i for i, n in enumerate(stage.names)}
    assert abs(g[row["left sole slip x"]]) < 1e-9 and abs(g[row["left sole slip y"]]) < 1e-9
    assert abs(g[row["left sole yaw slip"]]) < 1e-9
    assert g[row["left sole turn"]] == pytest.approx(-1.0)
    _, g = stage.fg(np.concatenate([x0, x0, x0]), s)
    assert np.array(g).ravel()[row["left sole turn"]] == pytest.approx(1.0)

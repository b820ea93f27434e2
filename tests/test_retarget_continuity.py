"""The validation check ``base_continuity``: the largest base rotation between consecutive frames."""

from __future__ import annotations

import numpy as np

from motok_robot.sim.config import ValidationConfig
from motok_robot.sim.kinematic import base_rotation_steps


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

"""Fidelity: did the robot in physics do the motion it was asked to do?

The physics checks of :mod:`motok_robot.sim.report` judge the rollout against the reference
(``fall``, ``tracking`` of the joint angles, ``base_drift`` of the root path).  These add the
pose of the whole body and the heading, so that an executed trajectory that stays upright by
doing something else does not pass:

* ``fidelity_pose``: mean over frames (before any fall) of the mean distance between each body
  of the robot in the rollout and in the reference, both expressed in their own root's heading
  frame (so a root-path error is not counted twice), divided by the robot's height;
* ``fidelity_heading``: the largest heading (yaw) difference between the rollout's root and the
  reference's.

A robot that stands still while the reference walks fails ``base_drift``; one that walks but
holds its arms down through a wave fails ``fidelity_pose``; one that turns the wrong way fails
``fidelity_heading``.
"""

from __future__ import annotations

import mujoco
import numpy as np

from motok_robot.feasibility.geometry import heading


def _body_positions_in_heading_frame(index, qpos: np.ndarray) -> np.ndarray:
    """[T, nbody - 1, 3] body positions relative to the root, rotated by minus the root heading."""
    model = index.kin_model
    data = mujoco.MjData(model)
    yaw = heading(qpos)
    out = np.zeros((qpos.shape[0], model.nbody - 1, 3))
    for t in range(qpos.shape[0]):
        data.qpos[:] = qpos[t]
        mujoco.mj_kinematics(model, data)
        rel = data.xpos[1:] - qpos[t, :3]
        c, s = np.cos(yaw[t]), np.sin(yaw[t])
        out[t, :, 0] = c * rel[:, 0] + s * rel[:, 1]
        out[t, :, 1] = -s * rel[:, 0] + c * rel[:, 1]
        out[t, :, 2] = rel[:, 2]
    return out


def fidelity_measures(index, executed: np.ndarray, reference: np.ndarray, valid: np.ndarray) -> dict:
    """Per-frame pose error [T] (m), heading error [T] (rad) of ``executed`` against
    ``reference`` (both [T, nq]); summaries over the ``valid`` frames."""
    pose = np.linalg.norm(_body_positions_in_heading_frame(index, executed)
                          - _body_positions_in_heading_frame(index, reference), axis=2).mean(axis=1)
    dyaw = np.angle(np.exp(1j * (heading(executed) - heading(reference))))
    dyaw = np.abs(dyaw)
    v = np.asarray(valid, dtype=bool)
    return {"pose_error_m": pose, "heading_error_rad": dyaw,
            "pose_error_mean_m": float(pose[v].mean()) if v.any() else float("nan"),
            "heading_error_max_rad": float(dyaw[v].max()) if v.any() else float("nan")}

"""Fidelity: did the robot in physics do the motion it was asked to do?

The physics checks of :mod:`motok_robot.sim.report` judge the rollout against the reference
(``fall``, ``tracking`` of the joint angles, ``base_drift`` of the root path).  These add the
pose of the whole body and the heading, so that an executed trajectory that stays upright by
doing something else does not pass:

* ``fidelity_pose``: mean over frames (before any fall) of the mean distance between each body
  of the robot in the rollout and in the reference, both expressed in their own root's heading
  frame (so a root-path error is not counted twice), divided by the robot's height;
* ``fidelity_heading``: the largest heading (yaw) difference between the rollout's root and the
  reference's;
* ``fidelity_foot_lift``: for each foot, how much lower its highest lift stayed in the rollout
  than in the reference (a lift is the foot's lowest sole corner above that corner's lowest
  point in the clip, so the floor cancels); the larger of the two feet.  The mean pose error
  hides a short kick that was never done (a kick of 0.3 s is a few percent of the frames); this
  does not.  It compares the highest lifts of the whole clip, not their timing: the feasibility
  stage re-plans walks with steps of its own, at other times than the reference's.

A robot that stands still while the reference walks fails ``base_drift``; one that walks but
holds its arms down through a wave fails ``fidelity_pose``; one that turns the wrong way fails
``fidelity_heading``; one that walks through a kick without kicking fails ``fidelity_foot_lift``.
"""

from __future__ import annotations

import mujoco
import numpy as np

from motok_robot.feasibility.geometry import heading


def _bodies_and_soles(index, qpos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """[T, nbody - 1, 3] body positions relative to the root, rotated by minus the root heading,
    and [T, 2] the height of each foot's lowest sole corner."""
    model = index.kin_model
    data = mujoco.MjData(model)
    yaw = heading(qpos)
    out = np.zeros((qpos.shape[0], model.nbody - 1, 3))
    sole = np.zeros((qpos.shape[0], 2))
    for t in range(qpos.shape[0]):
        data.qpos[:] = qpos[t]
        mujoco.mj_kinematics(model, data)
        sole[t] = data.site_xpos[index.corner_sites][:, :, 2].min(axis=1)
        rel = data.xpos[1:] - qpos[t, :3]
        c, s = np.cos(yaw[t]), np.sin(yaw[t])
        out[t, :, 0] = c * rel[:, 0] + s * rel[:, 1]
        out[t, :, 1] = -s * rel[:, 0] + c * rel[:, 1]
        out[t, :, 2] = rel[:, 2]
    return out, sole


def _peak_lift(sole: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each foot's highest lift [2] (m) over the ``valid`` frames of ``sole`` [T, 2] and its frame [2]."""
    lift = np.where(valid[:, None], sole - sole[valid].min(axis=0), -np.inf)
    frame = lift.argmax(axis=0)
    return lift[frame, [0, 1]], frame


def fidelity_measures(index, executed: np.ndarray, reference: np.ndarray, valid: np.ndarray) -> dict:
    """Per-frame pose error [T] (m), heading error [T] (rad) of ``executed`` against
    ``reference`` (both [T, nq]); summaries over the ``valid`` frames; each foot's highest lift
    in both [2] (m), the frames of the reference's [2] and the larger shortfall of the two (m)."""
    body_exe, sole_exe = _bodies_and_soles(index, executed)
    body_ref, sole_ref = _bodies_and_soles(index, reference)
    pose = np.linalg.norm(body_exe - body_ref, axis=2).mean(axis=1)
    dyaw = np.angle(np.exp(1j * (heading(executed) - heading(reference))))
    dyaw = np.abs(dyaw)
    v = np.asarray(valid, dtype=bool)
    out = {"pose_error_m": pose, "heading_error_rad": dyaw,
           "pose_error_mean_m": float(pose[v].mean()) if v.any() else float("nan"),
           "heading_error_max_rad": float(dyaw[v].max()) if v.any() else float("nan"),
           "foot_lift_shortfall_m": float("nan"), "reference_lift_m": None, "executed_lift_m": None,
           "reference_lift_frame": None}
    if v.any():
        ref_lift, ref_frame = _peak_lift(sole_ref, v)
        exe_lift, _ = _peak_lift(sole_exe, v)
        out.update(foot_lift_shortfall_m=float(np.clip(ref_lift - exe_lift, 0.0, None).max()),
                   reference_lift_m=ref_lift, executed_lift_m=exe_lift, reference_lift_frame=ref_frame)
    return out

"""Control metrics: the GMD / OmniControl protocol, on joints ``[T, 22, 3]`` (metres, z up, 20 fps).

Foot skating and foot penetration / floating come from :mod:`motok_robot.motion.metrics` (one
implementation for the whole project); this module adds what needs the constraints:

* keyframe errors: distance between the generated and the imposed position of every
  constrained (frame, joint), over the constrained coordinates only (the root's height counts
  only where it was given);
* trajectory error (fraction of clips whose largest keyframe error exceeds 50 cm, also 20 cm),
  location error (fraction of keyframes over 50 cm), average error (m and cm);
* obstacle penetration: the deepest any joint goes into an obstacle (m), and whether it does.

:func:`control_table` pools per-clip results into one table row.
"""

from __future__ import annotations

import numpy as np
import torch

from motok_robot.control.constraints import Constraints
from motok_robot.control.losses import ConstraintTensors, obstacle_distance
from motok_robot.errors import InputError
from motok_robot.motion.metrics import foot_ground_distances, foot_skating_ratio
from motok_robot.motion.skeleton import FPS, PARENTS

#: thresholds of the trajectory / location error (m)
FAIL_FAR = 0.5
FAIL_NEAR = 0.2


def _check(joints, constraints: Constraints) -> np.ndarray:
    j = np.asarray(joints, dtype=np.float64)
    if j.ndim != 3 or j.shape[1:] != (22, 3):
        raise InputError(f"joints must be [T, 22, 3], got {list(j.shape)}")
    if len(j) != constraints.frames:
        raise InputError(f"joints have {len(j)} frames but the constraints {constraints.frames}")
    return j


def keyframe_errors(joints, constraints: Constraints) -> np.ndarray:
    """Error (m) of every constrained (frame, joint) of ``constraints`` in ``joints [T, 22, 3]``,
    ``[K]`` in frame-major order (empty when nothing is constrained)."""
    j = _check(joints, constraints)
    weight = np.repeat(constraints.joint_mask[..., None], 3, axis=-1).astype(np.float64)
    weight[:, 0, 2] = (constraints.joint_mask[:, 0] & constraints.root_height_mask).astype(np.float64)
    diff = np.linalg.norm((j - constraints.joint_targets) * weight, axis=-1)  # [T, 22]
    return diff[constraints.joint_mask]


def obstacle_penetration(joints, constraints: Constraints) -> float:
    """Deepest penetration (m, >= 0) of any joint into any obstacle of ``constraints``
    (the obstacles themselves, without the safety margin); 0 when there are none."""
    j = _check(joints, constraints)
    if not constraints.obstacles:
        return 0.0
    ct = ConstraintTensors.from_constraints(constraints, dtype=torch.float64)
    d = obstacle_distance(torch.as_tensor(j[..., :2]), ct)
    return float((-d).clamp(min=0.0).max())


def bone_length_change(joints) -> float:
    """Mean absolute change (m) of the 21 bone lengths of ``joints [T, 22, 3]`` around their
    per-clip median: 0 for a rigid skeleton. Position-space edits (refinement, imputation) act on
    joint positions that are not tied together, so this shows whether they stretch limbs."""
    j = np.asarray(joints, dtype=np.float64)
    child = np.arange(1, len(PARENTS))
    lengths = np.linalg.norm(j[:, child] - j[:, [PARENTS[c] for c in child]], axis=-1)  # [T, 21]
    return float(np.abs(lengths - np.median(lengths, axis=0)).mean())


def clip_metrics(joints, constraints: Constraints, fps: float = FPS) -> dict[str, float]:
    """Per-clip numbers: ``max_error_m``, ``mean_error_m``, ``keyframes``, ``keyframes_far``
    (over 50 cm), ``foot_skating_ratio``, foot ``penetration_mean_mm`` / ``floating_mean_mm``,
    ``obstacle_depth_m``, ``bone_change_m``."""
    j = _check(joints, constraints)
    errors = keyframe_errors(j, constraints)
    ground = foot_ground_distances(j)
    return {
        "keyframes": float(len(errors)),
        "max_error_m": float(errors.max()) if len(errors) else 0.0,
        "mean_error_m": float(errors.mean()) if len(errors) else 0.0,
        "keyframes_far": float((errors > FAIL_FAR).sum()),
        "foot_skating_ratio": foot_skating_ratio(j, fps) if len(j) > 1 else 0.0,
        "penetration_mean_mm": ground["penetration_mean_mm"],
        "floating_mean_mm": ground["floating_mean_mm"],
        "obstacle_depth_m": obstacle_penetration(j, constraints),
        "bone_change_m": bone_length_change(j),
    }


def control_table(per_clip: list[dict[str, float]]) -> dict[str, float]:
    """One row of the protocol table from :func:`clip_metrics` results of several clips.

    ``traj_fail_50cm`` / ``traj_fail_20cm``: fraction of clips whose largest keyframe error
    exceeds 50 / 20 cm; ``location_fail_50cm``: fraction of all keyframes over 50 cm;
    ``avg_error_m`` / ``avg_error_cm``: mean over clips of the clip's mean keyframe error;
    ``max_error_cm``: the largest keyframe error of all clips;
    ``foot_skating_ratio``, ``penetration_mm``, ``floating_mm``: means over clips;
    ``obstacle_hit_fraction``: fraction of clips where a joint entered an obstacle
    (deeper than 1 mm), ``obstacle_depth_max_cm``: the deepest; ``bone_change_cm``: mean
    :func:`bone_length_change` (a check that control does not stretch the skeleton).
    """
    if not per_clip:
        raise InputError("control_table: no clips")
    keyed = [m for m in per_clip if m["keyframes"] > 0]
    n_key = sum(m["keyframes"] for m in keyed)
    avg = float(np.mean([m["mean_error_m"] for m in keyed])) if keyed else float("nan")
    return {
        "clips": float(len(per_clip)),
        "traj_fail_50cm": float(np.mean([m["max_error_m"] > FAIL_FAR for m in keyed])) if keyed else float("nan"),
        "traj_fail_20cm": float(np.mean([m["max_error_m"] > FAIL_NEAR for m in keyed])) if keyed else float("nan"),
        "location_fail_50cm": float(sum(m["keyframes_far"] for m in keyed) / n_key) if n_key else float("nan"),
        "avg_error_m": avg,
        "avg_error_cm": avg * 100.0,
        "max_error_cm": float(max(m["max_error_m"] for m in keyed) * 100.0) if keyed else float("nan"),
        "foot_skating_ratio": float(np.mean([m["foot_skating_ratio"] for m in per_clip])),
        "penetration_mm": float(np.mean([m["penetration_mean_mm"] for m in per_clip])),
        "floating_mm": float(np.mean([m["floating_mean_mm"] for m in per_clip])),
        "obstacle_hit_fraction": float(np.mean([m["obstacle_depth_m"] > 1e-3 for m in per_clip])),
        "obstacle_depth_max_cm": float(max(m["obstacle_depth_m"] for m in per_clip) * 100.0),
        "bone_change_cm": float(np.mean([m["bone_change_m"] for m in per_clip]) * 100.0),
    }

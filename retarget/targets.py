"""Human joints -> robot-sized keypoint targets, heading and foot directions.

Scaling (``scale=True``):

* a global factor ``s = robot leg length / human leg length`` (hip-knee-ankle, robot lengths
  measured between the keypoint sites of the nominal pose, human lengths the median over
  the clip);
* ``mode="segments"`` (default): each bone chain between two mapped joints (for example
  hip -> knee, spine3 -> collar -> shoulder) is scaled so that its length equals the distance
  between the two robot keypoint sites in the nominal pose; the targets then have the
  robot's own segment lengths and the keypoint error measures pose, not proportions. Bones
  to unmapped joints fall back to the per-limb factors below;
* ``mode="limbs"``: per-limb factors from the robot description: ``limb_scale`` holds robot length / canonical
  human length per limb (``legs``, ``arms``, ``torso``, ``head``), so the bones of a limb are
  scaled by ``s * limb_scale[limb] / limb_scale["legs"]`` (the legs keep ``s``, measured on
  the clip; the other limbs keep the robot's proportions relative to its legs; a missing
  entry means the leg ratio);
* the scaled body is rebuilt bone by bone from the pelvis, the pelvis trajectory itself
  scaled by ``s * legs`` (so a foot that stands still in the human motion stands still in
  the targets too);
* finally the targets are shifted vertically so that the ankles in contact frames are at
  the height of the robot's ankle keypoint sites in the nominal pose.

All arrays: ``[T, 22, 3]`` metres, z up, frames at the clip's fps.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from motok_robot.errors import InputError
from motok_robot.motion.skeleton import JOINT_INDEX, JOINT_NAMES, PARENTS, leg_length

LIMB_OF_JOINT = {
    **{n: "legs" for n in JOINT_NAMES if any(k in n for k in ("hip", "knee", "ankle", "foot"))},
    **{n: "arms" for n in JOINT_NAMES if any(k in n for k in ("shoulder", "elbow", "wrist"))},
    **{n: "torso" for n in ("spine1", "spine2", "spine3", "neck", "left_collar", "right_collar")},
    "head": "head",
}


@dataclass
class HumanTargets:
    """Robot-sized targets of a clip.

    ``joints``: ``[T, 22, 3]`` scaled human joints (metres, z up); ``heading``: ``[T]`` unwrapped
    facing angle about z (rad, 0 = +x); ``foot_dir``: ``[T, 2, 2]`` unit horizontal ankle->toe
    direction of the left / right foot; ``scale``: the global factor used (1 without scaling).
    """

    joints: np.ndarray
    heading: np.ndarray
    foot_dir: np.ndarray
    scale: float


def heading_angles(joints: np.ndarray) -> np.ndarray:
    """Unwrapped facing angle ``[T]`` (rad about +z, 0 = facing +x) from the hips and shoulders."""
    j = np.asarray(joints, dtype=np.float64)
    across = (j[:, JOINT_INDEX["left_hip"]] - j[:, JOINT_INDEX["right_hip"]]) + (
        j[:, JOINT_INDEX["left_shoulder"]] - j[:, JOINT_INDEX["right_shoulder"]]
    )
    # forward = across rotated by -90 degrees about z (left is +y when facing +x)
    return np.unwrap(np.arctan2(-across[:, 0], across[:, 1]))


def foot_directions(joints: np.ndarray, heading: np.ndarray) -> np.ndarray:
    """Unit horizontal ankle->toe directions ``[T, 2, 2]`` (left, right); falls back to the heading
    when a foot points straight down."""
    j = np.asarray(joints, dtype=np.float64)
    out = np.zeros((len(j), 2, 2))
    fallback = np.stack([np.cos(heading), np.sin(heading)], axis=-1)
    for col, side in enumerate(("left", "right")):
        d = j[:, JOINT_INDEX[f"{side}_foot"], :2] - j[:, JOINT_INDEX[f"{side}_ankle"], :2]
        n = np.linalg.norm(d, axis=-1, keepdims=True)
        out[:, col] = np.where(n > 1e-3, d / np.maximum(n, 1e-9), fallback)
    return out


def robot_leg_length(site_positions: dict[str, np.ndarray]) -> float:
    """Mean hip-knee-ankle length (m) from ``{human joint name: robot site position (3,)}``."""
    total = []
    for side in ("left", "right"):
        names = [f"{side}_hip", f"{side}_knee", f"{side}_ankle"]
        if all(n in site_positions for n in names):
            p = [site_positions[n] for n in names]
            total.append(np.linalg.norm(p[1] - p[0]) + np.linalg.norm(p[2] - p[1]))
    if not total:
        raise InputError("the robot keypoint map has no hip, knee and ankle sites of one leg; cannot scale the motion")
    return float(np.mean(total))


def scale_joints(
    joints: np.ndarray,
    robot_sites: dict[str, np.ndarray],
    limb_scale: dict[str, float],
    contacts: np.ndarray | None = None,
    mode: str = "segments",
) -> tuple[np.ndarray, float]:
    """Scale ``joints[T, 22, 3]`` to the robot; returns (scaled joints, global factor).

    ``robot_sites``: nominal-pose world positions of the robot keypoint sites, keyed by human
    joint name; ``contacts``: ``[T, 2]`` bool (left, right) used for the vertical alignment;
    ``mode``: ``"segments"`` (default) or ``"limbs"`` (see the module doc).
    """
    j = np.asarray(joints, dtype=np.float64)
    human_leg = float(np.median(leg_length(j)))
    if not np.isfinite(human_leg) or human_leg < 1e-3:
        raise InputError(f"the human legs have zero length (median hip-knee-ankle {human_leg:.4g} m); cannot scale")
    s = robot_leg_length(robot_sites) / human_leg
    ref = float(limb_scale.get("legs", 1.0)) or 1.0
    factor = np.array([s * float(limb_scale.get(LIMB_OF_JOINT.get(n, "torso"), ref)) / ref for n in JOINT_NAMES])
    if mode == "segments":
        factor = _segment_factors(j, robot_sites, factor)
    elif mode != "limbs":
        raise InputError(f"unknown scaling mode {mode!r} (segments or limbs)")
    legs = s
    out = np.empty_like(j)
    out[:, 0] = j[:, 0] * legs
    for c in range(1, len(JOINT_NAMES)):
        p = PARENTS[c]
        out[:, c] = out[:, p] + factor[c] * (j[:, c] - j[:, p])
    # vertical alignment: ankles in contact at the robot's nominal ankle-site height
    ankle_heights, robot_heights = [], []
    for col, side in enumerate(("left", "right")):
        a = out[:, JOINT_INDEX[f"{side}_ankle"], 2]
        sel = contacts[:, col] if contacts is not None and contacts[:, col].any() else a <= np.percentile(a, 10)
        ankle_heights.append(np.median(a[sel]))
        if f"{side}_ankle" in robot_sites:
            robot_heights.append(robot_sites[f"{side}_ankle"][2])
    if robot_heights:
        out[..., 2] += float(np.mean(robot_heights)) - float(np.mean(ankle_heights))
    return out, s


def _segment_factors(j: np.ndarray, robot_sites: dict[str, np.ndarray], fallback: np.ndarray) -> np.ndarray:
    """Per-bone factors: every bone on the path between a mapped joint and its nearest mapped ancestor
    is scaled by (robot site distance) / (median human distance) of that segment."""
    factor = fallback.copy()
    assigned = np.zeros(len(JOINT_NAMES), dtype=bool)
    for c, name in enumerate(JOINT_NAMES):
        if c == 0 or name not in robot_sites:
            continue
        path = [c]
        a = PARENTS[c]
        while a > 0 and JOINT_NAMES[a] not in robot_sites:
            path.append(a)
            a = PARENTS[a]
        if JOINT_NAMES[a] not in robot_sites:
            continue
        human = float(np.median(np.linalg.norm(j[:, c] - j[:, a], axis=-1)))
        robot = float(np.linalg.norm(robot_sites[name] - robot_sites[JOINT_NAMES[a]]))
        if human < 1e-4:
            continue
        for b in path:
            if not assigned[b]:
                factor[b], assigned[b] = robot / human, True
    return factor


def make_targets(
    joints: np.ndarray,
    robot_sites: dict[str, np.ndarray],
    limb_scale: dict[str, float],
    contacts: np.ndarray | None,
    scale: bool = True,
    mode: str = "segments",
) -> HumanTargets:
    """Targets for a clip; with ``scale=False`` the joints are used as they are."""
    if scale:
        scaled, s = scale_joints(joints, robot_sites, limb_scale, contacts, mode)
    else:
        scaled, s = np.asarray(joints, dtype=np.float64).copy(), 1.0
    heading = heading_angles(scaled)
    return HumanTargets(joints=scaled, heading=heading, foot_dir=foot_directions(scaled, heading), scale=s)

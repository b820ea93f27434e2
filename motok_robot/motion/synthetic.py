"""Procedural test motions on the canonical body (numpy only).

Small, deterministic clips for tests, examples and benchmarks: a walk along a turning path,
a standing-still clip and random poses. All return joint positions ``[T, 22, 3]`` in metres,
z up, at 20 fps, built by forward kinematics on :data:`skeleton.REST_OFFSETS` (so bone lengths
are exactly canonical). They are not realistic human motion; they exercise every joint.
"""

from __future__ import annotations

import numpy as np

from motok_robot.motion import skeleton
from motok_robot.motion.rotations import axis_angle_to_matrix, rotation_about_axis

_J = skeleton.JOINT_INDEX


def forward_kinematics(local_rot: np.ndarray, root_pos: np.ndarray, offsets: np.ndarray | None = None) -> np.ndarray:
    """Joint positions from per-joint rotations.

    Args:
        local_rot: ``[T, 22, 3, 3]`` rotation of each joint relative to its parent's frame
            (row 0: the root's world rotation); identity everywhere gives the rest pose.
        root_pos: ``[T, 3]`` root position, metres (z up).
        offsets: ``[22, 3]`` rest offsets child - parent (default :data:`skeleton.REST_OFFSETS`).

    Returns:
        ``[T, 22, 3]`` metres.
    """
    offsets = skeleton.REST_OFFSETS if offsets is None else np.asarray(offsets, dtype=np.float64)
    t_count = local_rot.shape[0]
    glob = np.zeros((t_count, skeleton.NUM_JOINTS, 3, 3))
    pos = np.zeros((t_count, skeleton.NUM_JOINTS, 3))
    glob[:, 0] = local_rot[:, 0]
    pos[:, 0] = root_pos
    for k in range(1, skeleton.NUM_JOINTS):
        p = skeleton.PARENTS[k]
        glob[:, k] = glob[:, p] @ local_rot[:, k]
        pos[:, k] = pos[:, p] + glob[:, p] @ offsets[k]
    return pos


def _arms_down(rot: np.ndarray, angle: float = 1.2) -> None:
    """Lower both arms from the T-pose by ``angle`` rad (in place on ``rot[T, 22, 3, 3]``)."""
    rot[:, _J["left_shoulder"]] = rot[:, _J["left_shoulder"]] @ rotation_about_axis(np.full(len(rot), -angle), 0)
    rot[:, _J["right_shoulder"]] = rot[:, _J["right_shoulder"]] @ rotation_about_axis(np.full(len(rot), angle), 0)


def walking_clip(frames: int = 80, fps: float = skeleton.FPS, speed: float = 1.2, turn_rate: float = 0.4,
                 start_yaw: float = 0.3, start_xy: tuple[float, float] = (1.0, -2.0), step_hz: float = 0.9) -> np.ndarray:
    """A walking-like clip: sinusoidal leg and arm swing, pelvis bob, root on a turning path.

    Args:
        frames: number of frames T.
        fps: frame rate (Hz).
        speed: forward speed, m/s.
        turn_rate: yaw rate, rad/s (positive turns left, towards +y).
        start_yaw: initial heading, rad about +z (0 = +x).
        start_xy: initial ground position of the root, metres.
        step_hz: stride frequency, Hz.

    Returns:
        ``[T, 22, 3]`` metres, z up, feet near the floor.
    """
    t = np.arange(frames) / fps
    yaw = start_yaw + turn_rate * t
    step = speed / fps * np.stack([np.cos(yaw[:-1]), np.sin(yaw[:-1])], axis=-1)
    xy = np.asarray(start_xy, dtype=np.float64) + np.concatenate([np.zeros((1, 2)), np.cumsum(step, axis=0)])
    phase = 2 * np.pi * step_hz * t
    rot = np.tile(np.eye(3), (frames, skeleton.NUM_JOINTS, 1, 1))
    rot[:, 0] = rotation_about_axis(yaw, 2) @ axis_angle_to_matrix(np.stack([0.05 * np.sin(phase), 0 * t, 0 * t], -1))
    swing = 0.45 * np.sin(phase)
    for side, sign in (("left", 1.0), ("right", -1.0)):
        # about +y: a leg hanging along -z swings its foot forward (+x) for negative angles
        rot[:, _J[f"{side}_hip"]] = rotation_about_axis(-sign * swing, 1)
        knee = 0.6 * np.clip(np.sin(phase + sign * np.pi / 2 + np.pi), 0, None) + 0.05
        rot[:, _J[f"{side}_knee"]] = rotation_about_axis(knee, 1)
        rot[:, _J[f"{side}_ankle"]] = rotation_about_axis(-0.2 * np.sin(phase * sign), 1)
    _arms_down(rot)
    for side, sign in (("left", 1.0), ("right", -1.0)):
        rot[:, _J[f"{side}_shoulder"]] = rotation_about_axis(sign * 0.4 * swing, 1) @ rot[:, _J[f"{side}_shoulder"]]
        rot[:, _J[f"{side}_elbow"]] = rotation_about_axis(np.full(frames, -0.3), 1)
    rot[:, _J["spine2"]] = rotation_about_axis(0.1 * np.sin(phase), 2)
    rot[:, _J["head"]] = rotation_about_axis(0.2 * np.sin(0.5 * phase), 2)
    pelvis_height = skeleton.rest_pose()[0, 2] - 0.03 + 0.02 * np.cos(2 * phase)
    root = np.concatenate([xy, pelvis_height[:, None]], axis=-1)
    joints = forward_kinematics(rot, root)
    joints[..., 2] -= joints[..., 2].min() - 0.002
    return joints


def standing_clip(frames: int = 40, yaw: float = -1.0, xy: tuple[float, float] = (0.5, 0.5)) -> np.ndarray:
    """A person standing still (arms down), facing ``yaw`` rad about +z, ``[T, 22, 3]`` metres."""
    rot = np.tile(np.eye(3), (frames, skeleton.NUM_JOINTS, 1, 1))
    rot[:, 0] = rotation_about_axis(np.full(frames, yaw), 2)
    _arms_down(rot)
    root = np.tile([xy[0], xy[1], skeleton.rest_pose()[0, 2]], (frames, 1))
    return forward_kinematics(rot, root)


def random_poses(frames: int = 30, seed: int = 0, max_angle: float = 1.0, scale: float = 1.0) -> np.ndarray:
    """Independent random poses (no temporal coherence): random joint rotations up to
    ``max_angle`` rad, random heading and root position; bone lengths times ``scale``.
    Returns ``[T, 22, 3]`` metres, z up."""
    rng = np.random.default_rng(seed)
    aa = rng.normal(size=(frames, skeleton.NUM_JOINTS, 3))
    aa *= (rng.uniform(0, max_angle, size=(frames, skeleton.NUM_JOINTS, 1)) / np.linalg.norm(aa, axis=-1, keepdims=True))
    rot = axis_angle_to_matrix(aa)
    rot[:, 0] = rotation_about_axis(rng.uniform(-np.pi, np.pi, frames), 2) @ axis_angle_to_matrix(0.3 * aa[:, 0])
    root = np.concatenate([rng.uniform(-2, 2, (frames, 2)), rng.uniform(0.8, 1.0, (frames, 1))], axis=-1)
    return forward_kinematics(rot, root, skeleton.REST_OFFSETS * scale)

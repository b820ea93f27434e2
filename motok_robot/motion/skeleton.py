"""The canonical 22-joint human body (SMPL / HumanML3D joint order).

Conventions used everywhere in motok-robot (files on disk, public APIs):

* world frame: right-handed, **z up**, metres (the MuJoCo convention);
* a body "faces +x" at frame 0 after normalisation, its left side is +y;
* 20 frames per second (``FPS``).

HumanML3D itself is y-up with the body facing +z; the conversion between the two
frames is a cyclic axis permutation (a proper rotation, no mirroring) and happens
only in :mod:`motok_robot.motion.features` (feature space is HumanML3D's own) and in
the HumanML3D reader.  Use :func:`zup_from_yup` / :func:`yup_from_zup`.
"""

from __future__ import annotations

import numpy as np

FPS = 20

JOINT_NAMES: tuple[str, ...] = (
    "pelvis",
    "left_hip",
    "right_hip",
    "spine1",
    "left_knee",
    "right_knee",
    "spine2",
    "left_ankle",
    "right_ankle",
    "spine3",
    "left_foot",
    "right_foot",
    "neck",
    "left_collar",
    "right_collar",
    "head",
    "left_shoulder",
    "right_shoulder",
    "left_elbow",
    "right_elbow",
    "left_wrist",
    "right_wrist",
)
NUM_JOINTS = len(JOINT_NAMES)
JOINT_INDEX: dict[str, int] = {name: i for i, name in enumerate(JOINT_NAMES)}

#: parent index of every joint (-1 for the root), SMPL kinematic tree
PARENTS: tuple[int, ...] = (-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19)

#: kinematic chains as used by HumanML3D (for drawing and IK): right leg, left leg, spine, right arm, left arm
KINEMATIC_CHAINS: tuple[tuple[int, ...], ...] = (
    (0, 2, 5, 8, 11),
    (0, 1, 4, 7, 10),
    (0, 3, 6, 9, 12, 15),
    (9, 14, 17, 19, 21),
    (9, 13, 16, 18, 20),
)

#: left <-> right joint permutation (for mirroring)
MIRROR_PERMUTATION: tuple[int, ...] = tuple(
    JOINT_INDEX[n.replace("left_", "#").replace("right_", "left_").replace("#", "right_")] for n in JOINT_NAMES
)

FOOT_JOINTS = (JOINT_INDEX["left_ankle"], JOINT_INDEX["left_foot"], JOINT_INDEX["right_ankle"], JOINT_INDEX["right_foot"])
LOWER_BODY = tuple(JOINT_INDEX[n] for n in JOINT_NAMES if any(k in n for k in ("pelvis", "hip", "knee", "ankle", "foot")))
UPPER_BODY = tuple(i for i in range(NUM_JOINTS) if i not in LOWER_BODY)

# Reference rest pose of an average adult (~1.72 m tall), joint centres in metres, in the
# project frame (z up, facing +x, left = +y), arms in T-pose.  Values approximate the
# joint centres of the SMPL neutral template; they only fix the bone LENGTHS of the
# canonical skeleton (directions always come from the data).
_REST_POSITIONS = np.array(
    [
        # x (forward), y (left), z (up)
        [0.028, 0.000, 0.950],  # pelvis
        [0.024, 0.070, 0.859],  # left_hip
        [0.022, -0.068, 0.859],  # right_hip
        [0.012, -0.002, 1.069],  # spine1
        [0.015, 0.104, 0.470],  # left_knee
        [0.016, -0.106, 0.462],  # right_knee
        [0.002, 0.005, 1.198],  # spine2
        [-0.027, 0.088, 0.052],  # left_ankle
        [-0.032, -0.088, 0.041],  # right_ankle
        [0.031, 0.002, 1.252],  # spine3
        [0.093, 0.120, -0.009],  # left_foot
        [0.094, -0.124, -0.010],  # right_foot
        [-0.010, -0.002, 1.460],  # neck
        [-0.004, 0.082, 1.366],  # left_collar
        [-0.008, -0.081, 1.366],  # right_collar
        [0.045, 0.012, 1.539],  # head
        [-0.020, 0.175, 1.406],  # left_shoulder
        [-0.017, -0.174, 1.403],  # right_shoulder
        [-0.041, 0.437, 1.394],  # left_elbow
        [-0.045, -0.431, 1.387],  # right_elbow
        [-0.047, 0.686, 1.401],  # left_wrist
        [-0.050, -0.686, 1.398],  # right_wrist
    ],
    dtype=np.float64,
)
# make the body exactly left/right symmetric (mirroring must not change bone lengths)
_MIRRORED = _REST_POSITIONS * np.array([1.0, -1.0, 1.0])
_REST_POSITIONS = 0.5 * (_REST_POSITIONS + _MIRRORED[list(MIRROR_PERMUTATION)])
# put the lowest joint on the floor
_REST_POSITIONS[:, 2] -= _REST_POSITIONS[:, 2].min()

#: rest offsets child - parent (metres, z-up), row 0 is the root position
REST_OFFSETS = _REST_POSITIONS.copy()
for _j in range(1, NUM_JOINTS):
    REST_OFFSETS[_j] = _REST_POSITIONS[_j] - _REST_POSITIONS[PARENTS[_j]]

#: reference bone length (metres) of the bone ending at each joint; 0 for the root
BONE_LENGTHS = np.linalg.norm(REST_OFFSETS, axis=1)
BONE_LENGTHS[0] = 0.0


def rest_pose() -> np.ndarray:
    """Reference rest pose, ``[22, 3]`` metres, z-up, soles on the floor, facing +x."""
    return _REST_POSITIONS.copy()


def bone_length_table() -> dict[str, float]:
    """``{joint name: length of the bone from its parent, metres}`` (root excluded)."""
    return {JOINT_NAMES[j]: float(BONE_LENGTHS[j]) for j in range(1, NUM_JOINTS)}


def leg_length(joints: np.ndarray) -> np.ndarray:
    """Mean hip-knee-ankle length of both legs, metres; ``joints[..., 22, 3]`` -> ``[...]``."""
    j = np.asarray(joints)
    total = 0.0
    for hip, knee, ankle in (("left_hip", "left_knee", "left_ankle"), ("right_hip", "right_knee", "right_ankle")):
        h, k, a = (j[..., JOINT_INDEX[n], :] for n in (hip, knee, ankle))
        total = total + np.linalg.norm(k - h, axis=-1) + np.linalg.norm(a - k, axis=-1)
    return total / 2.0


def yup_from_zup(x: np.ndarray) -> np.ndarray:
    """Project frame (x fwd, y left, z up) -> HumanML3D frame (x left, y up, z fwd)."""
    x = np.asarray(x)
    return x[..., [1, 2, 0]]


def zup_from_yup(x: np.ndarray) -> np.ndarray:
    """HumanML3D frame (x left, y up, z fwd) -> project frame (x fwd, y left, z up)."""
    x = np.asarray(x)
    return x[..., [2, 0, 1]]


def mirror_joints(joints: np.ndarray) -> np.ndarray:
    """Left/right mirror of ``joints[..., 22, 3]`` (project frame): negate y, swap sides."""
    out = np.array(joints, copy=True)
    out[..., 1] *= -1.0
    return out[..., list(MIRROR_PERMUTATION), :]

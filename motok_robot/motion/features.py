# Size (497 lines): the 263-d feature layout and its inverse, which must change together.
"""HumanML3D's 263-d motion features, computed from joint positions (numpy only).

The feature space is HumanML3D's own (Guo et al., CVPR 2022), so a model trained on
HumanML3D's ``new_joint_vecs`` reads our features unchanged and vice versa.

Frames and units
----------------
* **Inputs and outputs of the public functions** are joint positions ``[T, 22, 3]`` in
  metres in the project's world frame: right-handed, **z up**, body facing **+x** at frame 0
  after normalisation (left = +y). Joint order: :data:`motok_robot.motion.skeleton.JOINT_NAMES`.
* **Inside the features** everything is in HumanML3D's frame: **y up**, body facing **+z**
  at frame 0, x = the body's left. The two frames differ by the cyclic permutation of
  :func:`~motok_robot.motion.skeleton.yup_from_zup` / :func:`~motok_robot.motion.skeleton.zup_from_yup`
  (a proper rotation, no mirroring); this module is the only place the features are converted.
* Time step: one frame at 20 fps (0.05 s). Velocities are per frame, not per second.

Layout of one feature frame (263 floats, see :data:`FEATURE_SLICES`)
-------------------------------------------------------------------
==========  ====  ============================================================================
dims        size  meaning
==========  ====  ============================================================================
0           1     root yaw velocity: **half** the change of the root yaw from frame t to t+1,
                  rad/frame (HumanML3D stores ``arcsin`` of the y component of the
                  yaw-change quaternion, i.e. half the angle; its recovery doubles it
                  implicitly). Sign: positive = the root frame turns clockwise seen from
                  above (the body turns to its right).
1:3         2     root planar velocity (x, z) from frame t to t+1, m/frame, expressed in the
                  root-facing frame **of frame t+1**
3           1     root (pelvis) height above the floor, m
4:67        63    joints 1..21 relative to the root's ground point (x, z minus root x, z;
                  y is absolute height), in the root-facing frame of frame t, m
67:193      126   per-joint "local" rotations of joints 1..21 as 6D (first two matrix
                  columns), see *Rotations* below
193:259     66    velocities of all 22 joints from frame t to t+1, m/frame, in the
                  root-facing frame of frame t
259:263     4     foot contacts (0 or 1) of left_ankle, left_foot, right_ankle, right_foot:
                  1 when the joint moves less than sqrt(0.002) m (4.47 cm) from frame t to
                  t+1 (HumanML3D's threshold on the squared displacement; no height test)
==========  ====  ============================================================================

Root-facing frame
-----------------
The root-facing frame of frame t is the world frame turned about the up axis so that the
body's forward direction points to +z. As in HumanML3D, the forward direction is the
horizontal perpendicular of the "across" vector ``(left_hip - right_hip) +
(right_shoulder - left_shoulder)`` -- HumanML3D's inverse kinematics unpacks its hip
indices in swapped order, so the hip term enters with the opposite sign to the shoulder
term; we keep that so the features match HumanML3D's -- smoothed over time with a
Gaussian (sigma = 20 frames, edges repeated), and the yaw at frame 0 is taken as exactly 0
(the clip was already turned to face +z there using the un-swapped across vector).

Rotations (dims 67:193)
-----------------------
For each kinematic chain (``skeleton.KINEMATIC_CHAINS``: right leg, left leg, spine, right arm,
left arm) and each bone parent -> child along it, let ``S_child`` be the shortest-arc rotation
taking the bone's HumanML3D rest direction (:data:`IK_REST_DIRECTIONS`; legs and arms point
down, feet and head forward) onto the bone's direction in the clip (world frame after
normalisation, y up). The stored rotation of ``child`` is ``R_child = S_prev^T S_child`` where
``S_prev`` is ``S`` of the previous bone of the chain, and for the first bone of a chain
(hips, spine1, collars) ``S_prev`` is the root-facing rotation of frame t (the matrix that turns
the world into the root-facing frame). Consequences, all inherited from HumanML3D:

* only the swing of each bone is encoded, never its twist about its own axis;
* the arm chains start from the root-facing rotation, not from spine3;
* the world direction of a first bone is ``Q_t R_child u`` with ``Q_t`` the root-facing
  rotation (not its inverse).

The rotations are finite for every input (an exactly opposite bone direction, e.g. an arm
pointing straight up, uses a fixed half-turn axis) and continuous in the bone directions
except at that opposite direction, where any shortest-arc construction is discontinuous.
They are redundant with the positions: :func:`joints_from_features` ignores them.

Round trip
----------
``features_from_joints(j)`` has ``T - 1`` frames (frame t also needs frame t + 1), and
``joints_from_features(features_from_joints(j))`` returns frames ``0 .. T-2`` of
``normalise_joints(j)`` (to float32 rounding, well under 1 mm).
"""

from __future__ import annotations

import numpy as np

from motok_robot.errors import InputError
from motok_robot.motion import skeleton
from motok_robot.motion.rotations import (
    matrix_from_cont6d,
    matrix_to_cont6d,
    quat_between,
    quat_to_matrix,
    rotation_about_axis,
    wrap_angle,
)

FEATURE_DIM = 263

#: named slices of the 263-d feature vector (see the module docstring)
FEATURE_SLICES: dict[str, slice] = {
    "root_yaw_velocity": slice(0, 1),
    "root_linear_velocity": slice(1, 3),
    "root_height": slice(3, 4),
    "ric_positions": slice(4, 67),
    "rotations_6d": slice(67, 193),
    "local_velocities": slice(193, 259),
    "foot_contacts": slice(259, 263),
}

#: HumanML3D's foot-contact threshold on the squared per-frame displacement, m^2
FOOT_CONTACT_THRESHOLD = 0.002
#: joints whose contacts are stored, in storage order (left ankle, left foot, right ankle, right foot)
CONTACT_JOINTS = (
    skeleton.JOINT_INDEX["left_ankle"],
    skeleton.JOINT_INDEX["left_foot"],
    skeleton.JOINT_INDEX["right_ankle"],
    skeleton.JOINT_INDEX["right_foot"],
)
#: sigma (frames) of the Gaussian that smooths the forward direction used for the root frame
FACING_SMOOTHING_SIGMA = 20.0

_L_HIP = skeleton.JOINT_INDEX["left_hip"]
_R_HIP = skeleton.JOINT_INDEX["right_hip"]
_L_SHOULDER = skeleton.JOINT_INDEX["left_shoulder"]
_R_SHOULDER = skeleton.JOINT_INDEX["right_shoulder"]

#: HumanML3D's rest direction of the bone ending at each joint, in its y-up frame (x left,
#: y up, z forward); row 0 (root) is unused. Legs and arms point down, feet and head forward.
IK_REST_DIRECTIONS = np.array(
    [
        [0, 0, 0],  # pelvis
        [1, 0, 0],  # left_hip
        [-1, 0, 0],  # right_hip
        [0, 1, 0],  # spine1
        [0, -1, 0],  # left_knee
        [0, -1, 0],  # right_knee
        [0, 1, 0],  # spine2
        [0, -1, 0],  # left_ankle
        [0, -1, 0],  # right_ankle
        [0, 1, 0],  # spine3
        [0, 0, 1],  # left_foot
        [0, 0, 1],  # right_foot
        [0, 1, 0],  # neck
        [1, 0, 0],  # left_collar
        [-1, 0, 0],  # right_collar
        [0, 0, 1],  # head
        [0, -1, 0],  # left_shoulder
        [0, -1, 0],  # right_shoulder
        [0, -1, 0],  # left_elbow
        [0, -1, 0],  # right_elbow
        [0, -1, 0],  # left_wrist
        [0, -1, 0],  # right_wrist
    ],
    dtype=np.float64,
)

_MIN_BONE = 1e-6  # m; shorter bones have no usable direction


# ----------------------------------------------------------------------------- validation


def _check_joints(joints, name: str = "joints", min_frames: int = 1) -> np.ndarray:
    """Validate ``joints[T, 22, 3]`` and return it as float64."""
    try:
        arr = np.asarray(joints, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} must be a numeric array of shape [T, 22, 3] (frames, joints, xyz metres): {exc}") from None
    if arr.ndim != 3 or arr.shape[1] != skeleton.NUM_JOINTS or arr.shape[2] != 3:
        raise InputError(
            f"{name} must have shape [T, {skeleton.NUM_JOINTS}, 3] (frames, joints in SMPL order, xyz metres); "
            f"got shape {list(arr.shape)}"
        )
    if arr.shape[0] < min_frames:
        raise InputError(f"{name} has {arr.shape[0]} frame(s); at least {min_frames} are needed")
    bad = ~np.isfinite(arr)
    if bad.any():
        t, j, _ = np.argwhere(bad)[0]
        n_frames = int(bad.any(axis=(1, 2)).sum())
        raise InputError(
            f"{name} contain NaN or inf at frame {t}, joint {j} ({skeleton.JOINT_NAMES[j]}) "
            f"({n_frames} frame(s) affected)"
        )
    return arr


def _check_features(features, name: str = "features") -> np.ndarray:
    try:
        arr = np.asarray(features)
    except (TypeError, ValueError) as exc:  # pragma: no cover - exotic inputs
        raise InputError(f"{name} must be a numeric array of shape [..., T, {FEATURE_DIM}]: {exc}") from None
    if arr.ndim < 2 or arr.shape[-1] != FEATURE_DIM:
        raise InputError(f"{name} must have shape [..., T, {FEATURE_DIM}] (frames, HumanML3D features); got shape {list(arr.shape)}")
    if arr.shape[-2] < 1:
        raise InputError(f"{name} has 0 frames")
    if not np.issubdtype(arr.dtype, np.floating):
        arr = arr.astype(np.float64)
    bad = ~np.isfinite(arr)
    if bad.any():
        idx = np.argwhere(bad)[0]
        raise InputError(f"{name} contain NaN or inf at frame {idx[-2]}, dim {idx[-1]} (index {tuple(int(i) for i in idx)})")
    return arr


# ----------------------------------------------------------------------------- helpers


def gaussian_smooth(x: np.ndarray, sigma: float, axis: int = 0, truncate: float = 4.0) -> np.ndarray:
    """Gaussian smoothing along ``axis`` with edge values repeated (``scipy.ndimage``'s
    ``gaussian_filter1d(..., mode="nearest")``, reimplemented in numpy)."""
    x = np.asarray(x, dtype=np.float64)
    radius = int(truncate * float(sigma) + 0.5)
    if radius == 0 or x.shape[axis] == 0:
        return x.copy()
    offsets = np.arange(-radius, radius + 1, dtype=np.float64)
    kernel = np.exp(-0.5 * (offsets / sigma) ** 2)
    kernel /= kernel.sum()
    moved = np.moveaxis(x, axis, 0)
    n = moved.shape[0]
    idx = np.clip(np.arange(-radius, n + radius), 0, n - 1)
    padded = moved[idx]  # [n + 2r, ...]
    out = np.zeros_like(moved)
    for k, w in enumerate(kernel):
        out += w * padded[k : k + n]
    return np.moveaxis(out, 0, axis)


def _fill_from_nearest(values: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Replace rows of ``values[T, ...]`` where ``valid[T]`` is False by the nearest valid row."""
    t = np.arange(len(valid))
    good = t[valid]
    nearest = good[np.clip(np.searchsorted(good, t), 0, len(good) - 1)]
    prev = good[np.clip(np.searchsorted(good, t) - 1, 0, len(good) - 1)]
    choose = np.where(np.abs(prev - t) <= np.abs(nearest - t), prev, nearest)
    return values[choose]


def planar_facing_yaw(j: np.ndarray) -> np.ndarray:
    """Yaw (rad, about +z, 0 = facing +x) of ``j[T, 22, 3]`` (z-up) from hips and shoulders,
    un-swapped across vector; degenerate frames take the nearest valid frame (else 0)."""
    across = (j[:, _R_HIP] - j[:, _L_HIP]) + (j[:, _R_SHOULDER] - j[:, _L_SHOULDER])
    # forward = up x across = (-across_y, across_x, 0)
    fx, fy = -across[:, 1], across[:, 0]
    valid = np.hypot(fx, fy) > 1e-9
    yaw = np.arctan2(fy, fx)
    if not valid.any():
        return np.zeros(len(j))
    if not valid.all():
        yaw = _fill_from_nearest(yaw, valid)
    return yaw


def resample(joints, src_fps: float, dst_fps: float = skeleton.FPS) -> np.ndarray:
    """Resample ``joints[T, 22, 3]`` from ``src_fps`` to ``dst_fps`` (Hz) by linear interpolation
    of positions.

    Output frame ``k`` is at time ``k / dst_fps`` s; the output covers ``[0, (T-1)/src_fps]``
    (``floor((T-1) * dst_fps / src_fps) + 1`` frames). Returns float64 ``[T', 22, 3]``.
    """
    j = _check_joints(joints, min_frames=1)
    for label, value in (("src_fps", src_fps), ("dst_fps", dst_fps)):
        if not np.isfinite(value) or value <= 0:
            raise InputError(f"{label} must be a positive frame rate in Hz; got {value}")
    if src_fps == dst_fps:
        return j.copy()
    t_count = j.shape[0]
    n_out = int(np.floor((t_count - 1) * dst_fps / src_fps + 1e-9)) + 1
    src_pos = np.arange(n_out) * (src_fps / dst_fps)  # fractional source frame index
    i0 = np.clip(np.floor(src_pos).astype(int), 0, t_count - 1)
    i1 = np.clip(i0 + 1, 0, t_count - 1)
    w = (src_pos - i0)[:, None, None]
    return (1.0 - w) * j[i0] + w * j[i1]


# ----------------------------------------------------------------------------- normalisation


def normalise_joints(joints, fps: float = skeleton.FPS) -> np.ndarray:
    """Skeleton-normalise, floor-align and face a clip forward (z-up metres in and out).

    Steps (the order HumanML3D uses):

    1. every bone gets its canonical length (:data:`skeleton.BONE_LENGTHS`), keeping its
       direction from the data, built root-first along the tree; the root trajectory is
       scaled by ``canonical leg length / clip leg length`` (median over frames of
       :func:`skeleton.leg_length`) so strides stay consistent with the new legs. A bone
       shorter than 1 micrometre has no direction: it takes its direction from the nearest
       frame where it has one, else its rest direction turned by the body's facing;
    2. the lowest joint over the whole clip is put on the floor (``z = 0``), HumanML3D's
       floor height (for normal clips this is a foot joint);
    3. the root's ground point (x, y) at frame 0 is moved to the origin;
    4. the clip is turned about z so the body faces +x at frame 0 (forward = up x across,
       across = (right_hip - left_hip) + (right_shoulder - left_shoulder)).

    Args:
        joints: ``[T, 22, 3]`` metres, z up, SMPL joint order, any facing and placement.
        fps: frame rate of ``joints`` (Hz); normalisation does not depend on it.

    Returns:
        float64 ``[T, 22, 3]`` metres, z up.
    """
    if not np.isfinite(fps) or fps <= 0:
        raise InputError(f"fps must be a positive frame rate in Hz; got {fps}")
    j = _check_joints(joints, min_frames=1)
    parents = np.asarray(skeleton.PARENTS[1:])
    bones = j[:, 1:] - j[:, parents]  # [T, 21, 3]
    lengths = np.linalg.norm(bones, axis=-1)  # [T, 21]
    valid = lengths > _MIN_BONE
    unit = bones / np.maximum(lengths, _MIN_BONE)[..., None]
    if not valid.all():
        yaw = planar_facing_yaw(j)
        for b in np.flatnonzero(~valid.all(axis=0)):
            if valid[:, b].any():
                unit[:, b] = _fill_from_nearest(unit[:, b], valid[:, b])
            else:
                rest = skeleton.REST_OFFSETS[b + 1] / skeleton.BONE_LENGTHS[b + 1]
                unit[:, b] = rotation_about_axis(yaw, 2) @ rest

    leg_clip = float(np.median(skeleton.leg_length(j)))
    leg_canon = float(skeleton.leg_length(skeleton.rest_pose()))
    if leg_clip < 1e-3:
        raise InputError(
            f"joints: the legs (hip-knee-ankle) are {leg_clip * 1000:.3f} mm long; the clip has no usable skeleton "
            "(check the joint mapping and units)"
        )
    out = np.empty_like(j)
    out[:, 0] = j[:, 0] * (leg_canon / leg_clip)
    for k in range(1, skeleton.NUM_JOINTS):  # parents precede children in SMPL order
        out[:, k] = out[:, skeleton.PARENTS[k]] + skeleton.BONE_LENGTHS[k] * unit[:, k - 1]

    out[..., 2] -= out[..., 2].min()
    out[..., :2] -= out[0, 0, :2]
    yaw0 = planar_facing_yaw(out[:1])[0]
    rot = rotation_about_axis(-yaw0, 2)
    return out @ rot.T


# ----------------------------------------------------------------------------- features


def _root_yaw_yup(g: np.ndarray) -> np.ndarray:
    """Facing angle phi_t (rad) about +y of the y-up clip ``g[T, 22, 3]``: forward direction
    ``(sin phi, 0, cos phi)``. HumanML3D's IK across vector (hip term swapped), Gaussian-smoothed."""
    across = (g[:, _L_HIP] - g[:, _R_HIP]) + (g[:, _R_SHOULDER] - g[:, _L_SHOULDER])
    norm = np.linalg.norm(across, axis=-1, keepdims=True)
    across = across / np.maximum(norm, 1e-12)
    forward = np.stack([across[:, 2], np.zeros(len(g)), -across[:, 0]], axis=-1)  # (0,1,0) x across
    smoothed = gaussian_smooth(forward, FACING_SMOOTHING_SIGMA, axis=0)
    planar = np.hypot(smoothed[:, 0], smoothed[:, 2])
    valid = planar > 1e-6
    if not valid.all():
        # a spin so fast that the smoothed forward cancels out: use the raw forward there
        smoothed[~valid] = forward[~valid]
        valid = np.hypot(smoothed[:, 0], smoothed[:, 2]) > 1e-9
    phi = np.arctan2(smoothed[:, 0], smoothed[:, 2])
    if not valid.any():
        return np.zeros(len(g))
    if not valid.all():
        phi = _fill_from_nearest(phi, valid)
    return phi


def _features_from_normalised_yup(g: np.ndarray) -> np.ndarray:
    """Features ``[T-1, 263]`` (float64) of a normalised clip ``g[T, 22, 3]`` in HumanML3D's frame."""
    t_count = g.shape[0]
    phi = _root_yaw_yup(g)
    phi[0] = 0.0  # HumanML3D: the root rotation of frame 0 is the identity
    dphi = wrap_angle(np.diff(phi))
    phi = np.concatenate([[0.0], np.cumsum(dphi)])
    # root-facing rotation Q_t: world -> facing frame = rotation by -phi_t about +y
    q_rot = rotation_about_axis(-phi, 1)  # [T, 3, 3]

    # root yaw velocity: half the angle of Q_{t+1} Q_t^T (= -dphi)
    root_yaw_velocity = -0.5 * dphi
    root_step = g[1:, 0] - g[:-1, 0]
    root_lin = np.einsum("tij,tj->ti", q_rot[1:], root_step)[:, [0, 2]]
    root_height = g[:, 0, 1]

    rel = g.copy()
    rel[..., 0] -= g[:, :1, 0]
    rel[..., 2] -= g[:, :1, 2]
    ric = np.einsum("tij,tkj->tki", q_rot, rel)[:, 1:]  # [T, 21, 3]

    steps = g[1:] - g[:-1]
    local_vel = np.einsum("tij,tkj->tki", q_rot[:-1], steps)  # [T-1, 22, 3]

    rot6d = np.zeros((t_count, skeleton.NUM_JOINTS, 6))
    for chain in skeleton.KINEMATIC_CHAINS:
        s_prev = q_rot
        for parent, child in zip(chain[:-1], chain[1:]):
            bone = g[:, child] - g[:, parent]
            s_child = quat_to_matrix(quat_between(np.broadcast_to(IK_REST_DIRECTIONS[child], bone.shape), bone))
            local = np.swapaxes(s_prev, -1, -2) @ s_child
            rot6d[:, child] = matrix_to_cont6d(local)
            s_prev = s_child

    foot = g[:, CONTACT_JOINTS]
    contacts = (np.sum((foot[1:] - foot[:-1]) ** 2, axis=-1) < FOOT_CONTACT_THRESHOLD).astype(np.float64)

    return np.concatenate(
        [
            root_yaw_velocity[:, None],
            root_lin,
            root_height[:-1, None],
            ric[:-1].reshape(t_count - 1, -1),
            rot6d[:-1, 1:].reshape(t_count - 1, -1),
            local_vel.reshape(t_count - 1, -1),
            contacts,
        ],
        axis=-1,
    )


def features_from_joints(joints, fps: float = skeleton.FPS) -> np.ndarray:
    """HumanML3D 263-d features of a clip.

    Args:
        joints: ``[T, 22, 3]`` metres, z up, SMPL joint order, ``T >= 2``, sampled at 20 fps
            (use :func:`resample` first for other rates). Any skeleton size, facing and
            placement: the clip is normalised by :func:`normalise_joints` first.
        fps: frame rate of ``joints``; must be 20.

    Returns:
        float32 ``[T - 1, 263]`` in HumanML3D's y-up frame; layout in the module docstring
        and :data:`FEATURE_SLICES`.
    """
    if not np.isclose(fps, skeleton.FPS, rtol=0, atol=1e-6):
        raise InputError(
            f"features are defined at {skeleton.FPS} fps but the joints are at {fps} fps; "
            f"resample first: motok_robot.motion.features.resample(joints, {fps}, {skeleton.FPS})"
        )
    j = _check_joints(joints, min_frames=2)
    g = skeleton.yup_from_zup(normalise_joints(j))
    return _features_from_normalised_yup(g).astype(np.float32)


def root_from_features(features) -> tuple[np.ndarray, np.ndarray]:
    """Root trajectory encoded in ``features[..., T, 263]``.

    Returns:
        ``(root_positions [..., T, 3], yaw [..., T])``: pelvis positions in metres (z up,
        world frame of the clip, the root's ground point at the origin at frame 0) and the
        body's heading in rad about +z (0 = facing +x, positive = turned towards +y).
        Computed in float64.
    """
    f = np.asarray(_check_features(features), dtype=np.float64)
    half = f[..., 0]
    a = np.zeros_like(half)  # angle of Q_t about +y (= -heading)
    a[..., 1:] = 2.0 * np.cumsum(half[..., :-1], axis=-1)
    c, s = np.cos(a), np.sin(a)
    vx = np.zeros_like(half)
    vz = np.zeros_like(half)
    vx[..., 1:] = f[..., :-1, 1]
    vz[..., 1:] = f[..., :-1, 2]
    # Q_t^T applied to (vx, 0, vz)
    wx = c * vx - s * vz
    wz = s * vx + c * vz
    root_yup = np.stack([np.cumsum(wx, axis=-1), f[..., 3], np.cumsum(wz, axis=-1)], axis=-1)
    return skeleton.zup_from_yup(root_yup), -a


def joints_from_features(features) -> np.ndarray:
    """Joint positions recovered from features (HumanML3D's ``recover_from_ric``), numpy.

    Args:
        features: ``[..., T, 263]`` HumanML3D features (any leading batch dimensions).

    Returns:
        ``[..., T, 22, 3]`` metres, z up (the dtype of ``features`` if floating, computed in
        float64). Frame t is the pose at frame t of the clip the features came from; the
        6D rotations and velocities are not used.
    """
    f = _check_features(features)
    out_dtype = f.dtype
    f64 = f.astype(np.float64)
    root_zup, heading = root_from_features(f64)
    root = skeleton.yup_from_zup(root_zup)
    a = -heading
    c, s = np.cos(a)[..., None], np.sin(a)[..., None]
    ric = f64[..., 4:67].reshape(f64.shape[:-1] + (21, 3))
    x = c * ric[..., 0] - s * ric[..., 2] + root[..., None, 0]
    z = s * ric[..., 0] + c * ric[..., 2] + root[..., None, 2]
    body = np.stack([x, ric[..., 1], z], axis=-1)
    joints_yup = np.concatenate([root[..., None, :], body], axis=-2)
    return skeleton.zup_from_yup(joints_yup).astype(out_dtype, copy=False)


def local_rotations_from_features(features) -> np.ndarray:
    """The 6D rotations of ``features[..., T, 263]`` as matrices ``[..., T, 22, 3, 3]``.

    Row 0 (the root) is the root-facing rotation ``Q_t`` recovered from the yaw velocities
    (y-up frame); rows 1..21 are the per-joint rotations defined in the module docstring
    (HumanML3D's y-up frame).
    """
    f = np.asarray(_check_features(features), dtype=np.float64)
    _, heading = root_from_features(f)
    root = rotation_about_axis(-heading, 1)
    d6 = f[..., 67:193].reshape(f.shape[:-1] + (21, 6))
    return np.concatenate([root[..., None, :, :], matrix_from_cont6d(d6)], axis=-3)

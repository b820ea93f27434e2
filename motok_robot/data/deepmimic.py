"""DeepMimic motion files (``{"Loop": ..., "Frames": [[...], ...]}``) on the 13-link humanoid.

Frame layout (44 numbers): ``dt`` (seconds this frame lasts), root position xyz (m),
root quaternion wxyz, chest quat, neck quat, right hip quat, right knee angle (rad),
right ankle quat, right shoulder quat, right elbow angle, left hip quat, left knee angle,
left ankle quat, left shoulder quat, left elbow angle.  World frame: **y up**, the character
faces **+x** in its rest pose and its right side is **+z**.  Joint quaternions are local
rotations relative to the parent link; knees and elbows are revolute about the link's
z axis (knee flexion is negative, elbow flexion positive in the data).

Rest offsets (metres, y-up, parent frame) are the humanoid3d character's published joint
attachment points (DeepMimic ``data/characters/humanoid3d.txt``: chest 0.236151 above
the root, neck 0.223894 above the chest, hips 0.084887 to the side, thigh 0.421546,
shin 0.40987, shoulders at (-0.02405, 0.2435, +-0.18311) from the chest, upper arm
0.274788, forearm 0.258947 to the wrist).

The canonical body has joints the 13-link model lacks; they are **derived** and listed in
``Clip.derived_joints``: spine1 (11.8 cm above the root, in the root frame), spine3
(5.5 cm above the chest joint, chest frame), the collars (45 % of the way from the chest
joint to each shoulder), the head (10 cm above the neck joint, neck frame) and the feet
(ball of the foot 12 cm forward and 5 cm down from the ankle, ankle frame: the front of
the humanoid's foot box).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from motok_robot.data.clip import Clip, check_joints, to_project_frame, zup_rotation
from motok_robot.errors import InputError
from motok_robot.motion.skeleton import FPS, JOINT_NAMES

FRAME_SIZE = 44

# link: (parent, offset in the parent frame, column of its rotation in a frame, kind)
_LINKS = {
    "root": (None, (0.0, 0.0, 0.0), 4, "quat"),
    "chest": ("root", (0.0, 0.236151, 0.0), 8, "quat"),
    "neck": ("chest", (0.0, 0.223894, 0.0), 12, "quat"),
    "right_hip": ("root", (0.0, 0.0, 0.084887), 16, "quat"),
    "right_knee": ("right_hip", (0.0, -0.421546, 0.0), 20, "angle"),
    "right_ankle": ("right_knee", (0.0, -0.40987, 0.0), 21, "quat"),
    "right_shoulder": ("chest", (-0.02405, 0.2435, 0.18311), 25, "quat"),
    "right_elbow": ("right_shoulder", (0.0, -0.274788, 0.0), 29, "angle"),
    "left_hip": ("root", (0.0, 0.0, -0.084887), 30, "quat"),
    "left_knee": ("left_hip", (0.0, -0.421546, 0.0), 34, "angle"),
    "left_ankle": ("left_knee", (0.0, -0.40987, 0.0), 35, "quat"),
    "left_shoulder": ("chest", (-0.02405, 0.2435, -0.18311), 39, "quat"),
    "left_elbow": ("left_shoulder", (0.0, -0.274788, 0.0), 43, "angle"),
}
#: points fixed in a link frame: name -> (link, offset); wrists are real link ends
_POINTS = {
    "right_wrist": ("right_elbow", (0.0, -0.258947, 0.0)),
    "left_wrist": ("left_elbow", (0.0, -0.258947, 0.0)),
    "spine1": ("root", (0.0, 0.118, 0.0)),
    "spine3": ("chest", (0.0, 0.055, 0.0)),
    "head": ("neck", (0.0, 0.10, 0.0)),
    "right_foot": ("right_ankle", (0.12, -0.05, 0.0)),
    "left_foot": ("left_ankle", (0.12, -0.05, 0.0)),
}
DERIVED = ["spine1", "spine3", "left_collar", "right_collar", "head", "left_foot", "right_foot"]
COLLAR_T = 0.45


def quat_to_matrix(q: np.ndarray, where: str = "") -> np.ndarray:
    """Quaternions ``[..., 4]`` (w, x, y, z; normalised here) -> rotation matrices ``[..., 3, 3]``."""
    q = np.asarray(q, dtype=np.float64)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(n < 1e-8):
        raise InputError(f"{where}: zero-length quaternion")
    w, x, y, z = np.moveaxis(q / n, -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def _rot_z(angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    o, z = np.ones_like(c), np.zeros_like(c)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2)


def read_frames(path: str | Path, text: str | None = None) -> np.ndarray:
    """The ``Frames`` array, float64 ``[T, 44]``; raises InputError naming the problem."""
    where = str(path)
    if text is None:
        text = Path(path).read_text(encoding="utf-8", errors="replace")
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"{where}: not valid JSON ({exc.msg} at line {exc.lineno}); truncated file?") from None
    if not isinstance(data, dict) or "Frames" not in data:
        raise InputError(f"{where}: no 'Frames' field (not a DeepMimic motion file)")
    frames = data["Frames"]
    if not isinstance(frames, list) or len(frames) == 0:
        raise InputError(f"{where}: 'Frames' is empty (zero frames)")
    for f, row in enumerate(frames):
        if not isinstance(row, list) or len(row) != FRAME_SIZE:
            n = len(row) if isinstance(row, list) else type(row).__name__
            raise InputError(f"{where}: frame {f} has {n} values, expected {FRAME_SIZE} (13-link humanoid layout)")
    try:
        arr = np.array(frames, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{where}: non-numeric value in 'Frames'") from None
    bad = ~np.isfinite(arr)
    if bad.any():
        f, c = np.argwhere(bad)[0]
        raise InputError(f"{where}: frame {f}: value {c} ({_column_name(c)}) is NaN or infinite")
    return arr


def _column_name(c: int) -> str:
    if c == 0:
        return "dt"
    if c < 4:
        return "root position"
    for name, (_p, _o, col, kind) in _LINKS.items():
        width = 4 if kind == "quat" else 1
        if col <= c < col + width:
            return f"{name} {'quaternion' if kind == 'quat' else 'angle'}"
    return "?"


def forward_kinematics(frames: np.ndarray, where: str = "") -> dict[str, np.ndarray]:
    """Positions ``{name: float64 [T, 3]}`` (metres, DeepMimic y-up frame) of links and points."""
    R: dict[str, np.ndarray] = {}
    P: dict[str, np.ndarray] = {}
    for name, (parent, offset, col, kind) in _LINKS.items():
        if kind == "quat":
            local = quat_to_matrix(frames[:, col : col + 4], f"{where}: {name}")
        else:
            local = _rot_z(frames[:, col])
        if parent is None:
            P[name] = frames[:, 1:4].copy()
            R[name] = local
        else:
            P[name] = P[parent] + np.einsum("tij,j->ti", R[parent], np.asarray(offset))
            R[name] = R[parent] @ local
    out = dict(P)
    for name, (link, offset) in _POINTS.items():
        out[name] = P[link] + np.einsum("tij,j->ti", R[link], np.asarray(offset))
    for side in ("left", "right"):
        out[f"{side}_collar"] = (1 - COLLAR_T) * P["chest"] + COLLAR_T * P[f"{side}_shoulder"]
    out["pelvis"], out["spine2"] = P["root"], P["chest"]
    return out


def frame_times(frames: np.ndarray) -> np.ndarray:
    """Start time (s) of every frame: frame ``i`` starts at ``sum(dt[:i])``."""
    dt = frames[:, 0]
    return np.concatenate([[0.0], np.cumsum(dt[:-1])])


def resample_times(x: np.ndarray, times: np.ndarray, where: str, dst_fps: float = float(FPS)) -> np.ndarray:
    """Linear resampling of ``x[T, ...]`` sampled at increasing ``times`` (s) to ``dst_fps``."""
    if np.any(np.diff(times) <= 0):
        f = int(np.argmax(np.diff(times) <= 0))
        raise InputError(f"{where}: frame {f}: duration dt must be > 0")
    m = int(np.floor(times[-1] * dst_fps + 1e-6)) + 1
    t = np.arange(m) / dst_fps
    i1 = np.clip(np.searchsorted(times, t, side="right"), 1, len(times) - 1)
    i0 = i1 - 1
    w = np.clip((t - times[i0]) / (times[i1] - times[i0]), 0.0, 1.0).reshape((-1,) + (1,) * (x.ndim - 1))
    return x[i0] * (1 - w) + x[i1] * w


def load_clip(
    path: str | Path,
    clip_id: str | None = None,
    source: str = "deepmimic",
    licence: str = "MIT",
    text: str | None = None,
) -> Clip:
    """Read one DeepMimic motion file into a :class:`Clip` (metres, z-up, 20 fps)."""
    where = str(path)
    frames = read_frames(path, text)
    if frames.shape[0] < 2:
        raise InputError(f"{where}: only {frames.shape[0]} frame, need at least 2")
    pos = forward_kinematics(frames, where)
    joints = np.stack([pos[n] for n in JOINT_NAMES], axis=1)  # [T, 22, 3] y-up, right = +z
    joints = to_project_frame(joints, 1.0, zup_rotation("y", "x", where))
    joints = resample_times(joints, frame_times(frames), where)
    joints = check_joints(joints, where)
    cid = clip_id or f"{source}/{Path(str(path)).stem}"
    return Clip(id=cid, source=source, licence=licence, joints=joints, file=where, derived_joints=list(DERIVED))

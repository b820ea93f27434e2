"""Kinematic constraints for controlled generation, and their file formats.

All positions are in the generated motion's world frame: metres, z up, the body starts with
its pelvis ground point at the origin facing +x at frame 0 (see ``docs/CONTRACTS.md``).
Frames are at 20 fps (``motok_robot.motion.skeleton.FPS``).

File formats (one example each in ``examples/``):

* root trajectory, CSV: a header ``frame,x,y`` or ``frame,x,y,z`` (or ``time`` in seconds
  instead of ``frame``); one row per constrained frame; sparse rows = sparse control.
  A CSV without header (or a ``.npy`` array) ``[T, 2|3]`` has one row per frame from frame 0,
  NaN = free. NPZ: ``root`` ``[T, 2|3]`` and optionally ``mask`` ``[T]`` (bool) or ``frames`` ``[K]``.
  ``z`` constrains the pelvis height.
* keyframes, JSON: ``{"keyframes": [{"frame": 40, "joint": "right_wrist", "position": [x, y, z]}, ...]}``
  (``"time"`` in seconds instead of ``"frame"`` is accepted).
* obstacles, JSON: ``{"obstacles": [{"type": "circle", "center": [x, y], "radius": r},
  {"type": "box", "center": [x, y], "size": [sx, sy], "yaw": 0.0}]}`` (yaw in radians);
  no joint and no root may enter them (a ``margin`` in metres may be given at top level).
* prefix / suffix / edit motions: ``motion.npz`` files (``joints``, ``features``).
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from motok_robot.config_utils import read_json_object
from motok_robot.errors import InputError
from motok_robot.motion.skeleton import FPS, JOINT_INDEX, JOINT_NAMES, LOWER_BODY, UPPER_BODY

#: named joint groups accepted by ``--keep``
JOINT_GROUPS: dict[str, tuple[int, ...]] = {
    "lower_body": LOWER_BODY,
    "upper_body": UPPER_BODY,
    "left_arm": tuple(JOINT_INDEX[n] for n in ("left_collar", "left_shoulder", "left_elbow", "left_wrist")),
    "right_arm": tuple(JOINT_INDEX[n] for n in ("right_collar", "right_shoulder", "right_elbow", "right_wrist")),
    "legs": tuple(i for i in LOWER_BODY if i != 0),
    "root": (0,),
}


@dataclass
class Obstacle:
    """A circle (``radius``) or an oriented box (``size`` [sx, sy], ``yaw``) on the ground plane."""

    kind: str
    center: tuple[float, float]
    radius: float = 0.0
    size: tuple[float, float] = (0.0, 0.0)
    yaw: float = 0.0


@dataclass
class Constraints:
    """Everything a controlled generation must satisfy, for one clip of ``frames`` frames.

    ``joint_targets`` ``[T, 22, 3]`` with ``joint_mask`` ``[T, 22]`` hold keyframes, the root
    trajectory (joint 0; ``root_height_mask`` says whether z counts), in-betweening frames and
    body-part editing targets, all as joint positions. ``prefix_features`` / ``suffix_features``
    ``[P, 263]`` are raw features to keep exactly at the start / end.
    """

    frames: int
    joint_targets: np.ndarray = None  # type: ignore[assignment]
    joint_mask: np.ndarray = None  # type: ignore[assignment]
    root_height_mask: np.ndarray = None  # type: ignore[assignment]
    obstacles: list[Obstacle] = field(default_factory=list)
    obstacle_margin: float = 0.05
    foot_physics: bool = False
    prefix_features: np.ndarray | None = None
    suffix_features: np.ndarray | None = None
    #: body-part editing: raw features of the source motion and the joints to keep from it
    edit_features: np.ndarray | None = None
    edit_joints: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        if self.frames < 1:
            raise InputError(f"constraints: frames must be >= 1 (got {self.frames})")
        if self.joint_targets is None:
            self.joint_targets = np.zeros((self.frames, 22, 3), np.float32)
        if self.joint_mask is None:
            self.joint_mask = np.zeros((self.frames, 22), bool)
        if self.root_height_mask is None:
            self.root_height_mask = np.zeros(self.frames, bool)

    @property
    def has_root_trajectory(self) -> bool:
        return bool(self.joint_mask[:, 0].any())

    @property
    def has_keyframes(self) -> bool:
        return bool(self.joint_mask[:, 1:].any())

    @property
    def is_empty(self) -> bool:
        return not (
            self.joint_mask.any()
            or self.obstacles
            or self.foot_physics
            or self.prefix_features is not None
            or self.suffix_features is not None
        )

    def set_joint(self, frame: int, joint: int, position, use_height: bool = True, where: str = "constraint") -> None:
        if not 0 <= frame < self.frames:
            raise InputError(f"{where}: frame {frame} is out of range 0..{self.frames - 1}")
        pos = np.asarray(position, dtype=np.float64)
        if not np.isfinite(pos).all():
            raise InputError(f"{where}: frame {frame}, joint '{JOINT_NAMES[joint]}': position is not finite")
        self.joint_targets[frame, joint, : len(pos)] = pos
        self.joint_mask[frame, joint] = True
        if joint == 0:
            self.root_height_mask[frame] = use_height and len(pos) == 3


# ----------------------------------------------------------------------------- loaders


def _frame_of(row: dict, where: str, fps: float) -> int:
    if row.get("frame") not in (None, ""):
        value = _number(row["frame"], where, "frame")
        if not math.isfinite(value) or value != int(value):
            raise InputError(f"{where}: 'frame' must be an integer, got {row['frame']!r}")
        return int(value)
    if row.get("time") not in (None, ""):
        value = _number(row["time"], where, "time")
        if not math.isfinite(value):
            raise InputError(f"{where}: 'time' is not finite")
        return int(round(value * fps))
    raise InputError(f"{where}: needs a 'frame' or a 'time' field")


def _number(value, where: str, field_name: str) -> float:
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{where}: field '{field_name}' must be a number, got {value!r}") from None
    if not math.isfinite(out):
        raise InputError(f"{where}: field '{field_name}' is NaN or infinite")
    return out


def add_trajectory(constraints: Constraints, path: str | Path, fps: float = FPS) -> Constraints:
    """Read a root trajectory (CSV or NPZ, see the module docstring) into ``constraints``."""
    path = Path(path)
    if not path.exists():
        raise InputError(f"trajectory file {path} does not exist")
    if path.suffix.lower() == ".csv":
        with open(path, newline="") as handle:
            reader = csv.DictReader(handle)
            header = [h.strip() for h in (reader.fieldnames or [])]
            if header and all(_is_number(h) for h in header):
                return _add_dense_root(constraints, _read_headerless_csv(path), str(path))
            if "x" not in header or "y" not in header or not ({"frame", "time"} & set(header)):
                raise InputError(f"{path}: CSV header must be 'frame,x,y[,z]' or 'time,x,y[,z]', got {header}")
            rows = list(reader)
        if not rows:
            raise InputError(f"{path}: no trajectory rows")
        for line, raw in enumerate(rows, start=2):
            row = {k.strip(): (v.strip() if isinstance(v, str) else v) for k, v in raw.items() if k}
            where = f"{path}: line {line}"
            frame = _frame_of(row, where, fps)
            xyz = [_number(row.get(k), where, k) for k in ("x", "y")]
            if row.get("z") not in (None, ""):
                xyz.append(_number(row["z"], where, "z"))
            constraints.set_joint(frame, 0, xyz, where=where)
        return constraints
    if path.suffix.lower() == ".npz":
        from motok_robot.npz_files import read_npz_fields

        data = read_npz_fields(path, "trajectory file")
        if True:  # (was a `with np.load(...)` block)
            if "root" not in data:
                raise InputError(f"{path}: missing array 'root' [T, 2|3] (found {sorted(data)})")
            if data["root"].dtype.kind not in "fiu":
                raise InputError(f"{path}: 'root' must be a number array [T, 2|3], got {data['root'].dtype}")
            root = np.asarray(data["root"], dtype=np.float64)
            if root.ndim != 2 or root.shape[1] not in (2, 3):
                raise InputError(f"{path}: 'root' must have shape [T, 2] or [T, 3], got {root.shape}")
            if "frames" in data:
                frames = np.asarray(data["frames"]).astype(int)
                if frames.shape != (len(root),):
                    raise InputError(f"{path}: 'frames' must have shape [{len(root)}] like 'root', got {frames.shape}")
            else:
                frames = np.arange(len(root))
            mask = np.asarray(data["mask"], bool) if "mask" in data else np.ones(len(root), bool)
            if mask.shape != (len(root),):
                raise InputError(f"{path}: 'mask' must have shape [{len(root)}], got {mask.shape}")
        for i in np.flatnonzero(mask):
            constraints.set_joint(int(frames[i]), 0, root[i], where=f"{path}: 'root' row {i}")
        return constraints
    if path.suffix.lower() == ".npy":
        try:
            root = np.load(path, allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise InputError(f"{path}: cannot be read as a .npy array ({exc})") from None
        return _add_dense_root(constraints, root, str(path))
    raise InputError(f"trajectory file {path}: expected .csv, .npz or .npy")


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _read_headerless_csv(path: Path) -> np.ndarray:
    rows = []
    with open(path, newline="") as handle:
        for line, row in enumerate(csv.reader(handle), start=1):
            if not row or not "".join(row).strip():
                continue
            try:
                rows.append([float(v) for v in row])
            except ValueError:
                raise InputError(f"{path}: line {line}: expected numbers x,y[,z], got {row}") from None
    widths = {len(r) for r in rows}
    if len(widths) != 1:
        raise InputError(f"{path}: rows have different numbers of values {sorted(widths)}")
    return np.asarray(rows, dtype=np.float64)


def _add_dense_root(constraints: Constraints, root, where: str) -> Constraints:
    """One row per frame from frame 0: ``root [T, 2|3]`` x, y (, pelvis height); NaN = free."""
    root = np.asarray(root, dtype=np.float64)
    if root.ndim != 2 or root.shape[1] not in (2, 3):
        raise InputError(f"{where}: trajectory must have shape [T, 2] or [T, 3] (x, y[, z] per frame), got {list(root.shape)}")
    if np.isinf(root).any():
        row = int(np.argwhere(np.isinf(root))[0, 0])
        raise InputError(f"{where}: row {row} is infinite (NaN marks a free frame)")
    if len(root) > constraints.frames:
        raise InputError(f"{where}: {len(root)} trajectory rows but the clip has {constraints.frames} frames")
    for f in range(len(root)):
        xy_given = np.isfinite(root[f, :2])
        if xy_given.all():
            z_given = root.shape[1] == 3 and np.isfinite(root[f, 2])
            constraints.set_joint(f, 0, root[f, :3] if z_given else root[f, :2], where=f"{where}: row {f}")
        elif xy_given.any():
            raise InputError(f"{where}: row {f}: x and y must both be given or both be NaN")
    return constraints


def _read_json(path: str | Path, what: str) -> dict:
    return read_json_object(path, f"{what} file")


def add_keyframes(constraints: Constraints, path: str | Path, fps: float = FPS) -> Constraints:
    """Read joint-position keyframes (JSON, see the module docstring)."""
    data = _read_json(path, "keyframes")
    items = data.get("keyframes")
    if not isinstance(items, list) or not items:
        raise InputError(f"{path}: field 'keyframes' must be a non-empty list")
    for i, item in enumerate(items):
        where = f"{path}: keyframes[{i}]"
        if not isinstance(item, dict):
            raise InputError(f"{where}: must be an object with 'frame', 'joint', 'position'")
        joint = item.get("joint")
        if joint not in JOINT_INDEX:
            raise InputError(f"{where}: unknown joint {joint!r} (known: {', '.join(JOINT_NAMES)})")
        position = item.get("position")
        if not isinstance(position, list) or len(position) not in (2, 3):
            raise InputError(f"{where}: 'position' must be [x, y, z] (or [x, y] for the pelvis), got {position!r}")
        pos = [_number(v, where, "position") for v in position]
        if len(pos) == 2 and joint != "pelvis":
            raise InputError(f"{where}: 'position' of joint '{joint}' needs 3 values [x, y, z]")
        constraints.set_joint(_frame_of(item, where, fps), JOINT_INDEX[joint], pos, where=where)
    return constraints


def add_obstacles(constraints: Constraints, path: str | Path) -> Constraints:
    """Read ground obstacles (JSON, see the module docstring)."""
    data = _read_json(path, "obstacles")
    items = data.get("obstacles")
    if not isinstance(items, list) or not items:
        raise InputError(f"{path}: field 'obstacles' must be a non-empty list")
    if "margin" in data:
        constraints.obstacle_margin = _number(data["margin"], str(path), "margin")
    for i, item in enumerate(items):
        where = f"{path}: obstacles[{i}]"
        kind = item.get("type") if isinstance(item, dict) else None
        center = item.get("center") if isinstance(item, dict) else None
        if not isinstance(center, list) or len(center) != 2:
            raise InputError(f"{where}: 'center' must be [x, y], got {center!r}")
        cx, cy = (_number(v, where, "center") for v in center)
        if kind == "circle":
            radius = _number(item.get("radius"), where, "radius")
            if radius <= 0:
                raise InputError(f"{where}: 'radius' must be > 0")
            constraints.obstacles.append(Obstacle("circle", (cx, cy), radius=radius))
        elif kind == "box":
            size = item.get("size")
            if not isinstance(size, list) or len(size) != 2:
                raise InputError(f"{where}: 'size' must be [sx, sy], got {size!r}")
            sx, sy = (_number(v, where, "size") for v in size)
            if sx <= 0 or sy <= 0:
                raise InputError(f"{where}: 'size' must be positive")
            yaw = _number(item.get("yaw", 0.0), where, "yaw")
            constraints.obstacles.append(Obstacle("box", (cx, cy), size=(sx, sy), yaw=yaw))
        else:
            raise InputError(f"{where}: 'type' must be 'circle' or 'box', got {kind!r}")
    return constraints


def _read_motion(path: str | Path, what: str) -> tuple[np.ndarray, np.ndarray]:
    path = Path(path)
    if not path.exists():
        raise InputError(f"{what} motion {path} does not exist")
    from motok_robot.npz_files import read_npz_fields

    data = read_npz_fields(path, f"{what} motion")
    missing = [k for k in ("joints", "features") if k not in data]
    if missing:
        raise InputError(f"{path}: missing {missing} (a motion.npz from `motok-robot generate`)")
    for key in ("joints", "features"):
        if data[key].dtype.kind not in "fiu":
            raise InputError(f"{path}: field '{key}' must be a number array, got {data[key].dtype}")
    joints, features = np.asarray(data["joints"], np.float64), np.asarray(data["features"], np.float64)
    if joints.ndim != 3 or joints.shape[1:] != (22, 3) or features.ndim != 2 or features.shape[1] != 263:
        raise InputError(f"{path}: 'joints' must be [T, 22, 3] and 'features' [T, 263]; got {joints.shape}, {features.shape}")
    if len(joints) != len(features):
        raise InputError(f"{path}: 'joints' has {len(joints)} frames but 'features' has {len(features)}")
    if not (np.isfinite(joints).all() and np.isfinite(features).all()):
        raise InputError(f"{path}: contains NaN or infinite values")
    return joints, features


def add_prefix(constraints: Constraints, path: str | Path, frames: int | None = None) -> Constraints:
    """Keep the first ``frames`` frames (default: the whole given motion) exactly."""
    joints, features = _read_motion(path, "prefix")
    n = len(joints) if frames is None else frames
    if not 1 <= n <= min(len(joints), constraints.frames - 1):
        raise InputError(f"{path}: prefix of {n} frames does not fit a clip of {constraints.frames} frames")
    constraints.prefix_features = features[:n].astype(np.float32)
    for f in range(n):
        for j in range(22):
            constraints.set_joint(f, j, joints[f, j], where=f"{path}: prefix")
    return constraints


def add_suffix(constraints: Constraints, path: str | Path, frames: int | None = None) -> Constraints:
    """Keep the last ``frames`` frames of the given motion at the end of the clip, in place.

    The suffix joints are used as they are in the file (world frame), so the clip ends where the
    suffix motion is; its features fix the pose while the root is reached by guidance.
    """
    joints, features = _read_motion(path, "suffix")
    n = len(joints) if frames is None else frames
    if not 1 <= n <= min(len(joints), constraints.frames - 1):
        raise InputError(f"{path}: suffix of {n} frames does not fit a clip of {constraints.frames} frames")
    constraints.suffix_features = features[-n:].astype(np.float32)
    start = constraints.frames - n
    for k in range(n):
        for j in range(22):
            constraints.set_joint(start + k, j, joints[len(joints) - n + k, j], where=f"{path}: suffix")
    return constraints


def add_edit(constraints: Constraints, path: str | Path, keep: str | list[str]) -> Constraints:
    """Body-part editing: keep the joints of ``keep`` (a group name or joint names) from a motion."""
    joints, features = _read_motion(path, "edit")
    names = [keep] if isinstance(keep, str) else list(keep)
    keep_idx: set[int] = set()
    for name in names:
        for part in str(name).split(","):
            part = part.strip()
            if part in JOINT_GROUPS:
                keep_idx.update(JOINT_GROUPS[part])
            elif part in JOINT_INDEX:
                keep_idx.add(JOINT_INDEX[part])
            else:
                raise InputError(f"--keep: unknown joint or group {part!r} (groups: {', '.join(JOINT_GROUPS)})")
    if len(joints) < constraints.frames:
        raise InputError(f"{path}: the motion to edit has {len(joints)} frames, the clip needs {constraints.frames}")
    for f in range(constraints.frames):
        for j in sorted(keep_idx):
            constraints.set_joint(f, j, joints[f, j], where=f"{path}: edit")
    constraints.edit_features = features[: constraints.frames].astype(np.float32)
    constraints.edit_joints = tuple(sorted(keep_idx))
    return constraints

"""The ``Clip`` every importer returns, and the helpers all importers share.

A clip holds the motion of one take already mapped onto the canonical 22-joint body
(:mod:`motok_robot.motion.skeleton`), converted to metres, to a **z-up** right-handed
world and resampled to 20 fps.  The body faces whatever direction the data faces and
stands wherever the data puts it: skeleton normalisation, floor alignment and facing
+x happen later, in :func:`motok_robot.motion.features.features_from_joints`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from motok_robot.errors import InputError
from motok_robot.motion.skeleton import FPS, JOINT_NAMES, NUM_JOINTS


@dataclass
class Clip:
    """One motion clip on the canonical body.

    Attributes:
        id: unique clip id (``source/...``, only ``[A-Za-z0-9_.-]`` and ``/`` are used; the
            prepared dataset replaces ``/`` by ``__`` in file names).
        source: importer kind (``bandai``, ``cmu``, ``deepmimic``, ``acrnn``, ``bvh``, ``asf``,
            ``humanml3d``).
        licence: licence of the data it came from (e.g. ``"CC BY-NC 4.0"``).
        joints: float32 ``[T, 22, 3]`` joint centres in metres, world frame z up, canonical
            joint order (:data:`motok_robot.motion.skeleton.JOINT_NAMES`).
        fps: frames per second of ``joints`` (20 after import).
        texts: natural-language descriptions (may be empty; prepare fills them in).
        file: origin file (path as given, or ``archive.tar.xz:member``).
        derived_joints: canonical joints that the source does not measure directly and that
            were derived (interpolated between, or offset from, measured joints).
        labels: source-specific labels used to write texts (content, style, genre, ...).
        features: optional float32 ``[T-1, 263]`` HumanML3D features to use as they are
            (only the HumanML3D reader sets it; otherwise prepare computes them).
    """

    id: str
    source: str
    licence: str
    joints: np.ndarray
    fps: float = float(FPS)
    texts: list[str] = field(default_factory=list)
    file: str = ""
    derived_joints: list[str] = field(default_factory=list)
    labels: dict = field(default_factory=dict)
    features: np.ndarray | None = None

    @property
    def frames(self) -> int:
        return int(self.joints.shape[0])

    @property
    def seconds(self) -> float:
        return self.frames / float(self.fps)

    def with_(self, **changes) -> "Clip":
        return replace(self, **changes)


def check_joints(joints: np.ndarray, where: str, min_frames: int = 2) -> np.ndarray:
    """Validate ``joints[T, 22, 3]``: finite, enough frames. Returns float32; raises InputError."""
    joints = np.asarray(joints)
    if joints.ndim != 3 or joints.shape[1:] != (NUM_JOINTS, 3):
        raise InputError(f"{where}: joints must have shape [T, {NUM_JOINTS}, 3], got {list(joints.shape)}")
    if joints.shape[0] < min_frames:
        raise InputError(f"{where}: only {joints.shape[0]} frame(s) after resampling to 20 fps, need >= {min_frames}")
    bad = ~np.isfinite(joints)
    if bad.any():
        frame, joint, _ = np.argwhere(bad)[0]
        raise InputError(f"{where}: non-finite joint position at frame {frame}, joint {JOINT_NAMES[joint]}")
    return joints.astype(np.float32)


_STATURE_CHAIN = ("left_ankle", "left_knee", "left_hip", "pelvis", "spine1", "spine2", "spine3", "neck", "head")
#: stature of the canonical rest pose (m), whose joints the skeleton module places
CANONICAL_STATURE_M = 1.72


def stature(joints: np.ndarray) -> float:
    """Body height estimate (m) of ``joints[T, 22, 3]`` (metres), independent of posture.

    The median over frames of the ankle-knee-hip-pelvis-spine-neck-head joint chain length,
    scaled by the canonical body's stature / chain length (1.72 m / 1.55 m).  A unit or
    joint-map sanity check: real adult bodies give 1.4-2.0 m.
    """
    from motok_robot.motion.skeleton import JOINT_INDEX, rest_pose

    def chain(j):
        return sum(
            np.linalg.norm(j[..., JOINT_INDEX[a], :] - j[..., JOINT_INDEX[b], :], axis=-1)
            for a, b in zip(_STATURE_CHAIN[:-1], _STATURE_CHAIN[1:])
        )

    return float(np.median(chain(np.asarray(joints, dtype=np.float64))) * CANONICAL_STATURE_M / chain(rest_pose()))


# ----------------------------------------------------------------------------- axes

_AXIS = {"x": 0, "y": 1, "z": 2}


def snap_fps(fps: float) -> float:
    """Frame rate from a rounded frame time (``1 / 0.0333333`` -> 30.0): snap to the nearest
    integer when within 0.01 %, so resampling does not lose the last frame to rounding."""
    r = round(fps)
    return float(r) if r > 0 and abs(fps - r) <= 1e-4 * fps else float(fps)


def parse_axis(text: str, what: str) -> np.ndarray:
    """``"+y"``, ``"-z"``, ``"y"`` -> unit vector; raises InputError naming ``what``."""
    t = str(text).strip().lower()
    sign = -1.0 if t.startswith("-") else 1.0
    t = t.lstrip("+-")
    if t not in _AXIS:
        raise InputError(f"{what}: axis must be one of x, y, z, -x, -y, -z; got {text!r}")
    v = np.zeros(3)
    v[_AXIS[t]] = sign
    return v


def zup_rotation(up_axis: str = "y", forward_axis: str | None = None, where: str = "map") -> np.ndarray:
    """Proper rotation ``R`` (3x3, det +1) with ``R @ up = +z`` (and ``R @ forward = +x``).

    Without a forward axis the rotation is the cyclic permutation that takes the source up
    axis to z (y-up -> z-up maps source ``(x, y, z)`` to ``(z, x, y)``, HumanML3D's
    convention), so the body keeps whatever heading it had.  With a forward axis, the
    declared forward direction becomes +x and left becomes +y.
    """
    up = parse_axis(up_axis, f"{where}: up_axis")
    if forward_axis is None:
        i = int(np.argmax(np.abs(up)))
        # cyclic permutation: source axis i goes to z, i+1 -> x, i+2 -> y
        R = np.zeros((3, 3))
        R[2, i] = 1.0
        R[0, (i + 1) % 3] = 1.0
        R[1, (i + 2) % 3] = 1.0
        if up[i] < 0:  # upside down: rotate 180 degrees about x
            R = np.diag([1.0, -1.0, -1.0]) @ R
        return R
    fwd = parse_axis(forward_axis, f"{where}: forward")
    if abs(float(fwd @ up)) > 0.5:
        raise InputError(f"{where}: forward axis {forward_axis!r} must differ from up axis {up_axis!r}")
    left = np.cross(up, fwd)
    return np.stack([fwd, left, up])  # rows: the source vectors that become x, y, z


# ----------------------------------------------------------------------------- joint maps

def load_joint_map(path: str | Path) -> dict:
    """Read a user joint-map JSON file (see docs/data.md) and validate its fields.

    Returns ``{"joints": {canonical: spec}, "units_to_m": float | None (None: BVH metres,
    ASF its own :units), "up_axis": str, "forward": str | None}`` where ``spec`` is a source joint name or
    ``{"between": [a, b], "t": float}``.
    """
    from motok_robot.config_utils import read_json_object

    path = Path(path)
    raw = read_json_object(path, "joint map")
    joints = raw.get("joints", {k: v for k, v in raw.items() if k in JOINT_NAMES})
    unknown = [k for k in joints if k not in JOINT_NAMES]
    if unknown:
        raise InputError(f"{path}: unknown canonical joint(s) {unknown}; expected names from {list(JOINT_NAMES)}")
    missing = [k for k in JOINT_NAMES if k not in joints]
    if missing:
        raise InputError(f"{path}: joint map lacks canonical joint(s) {missing}")
    for name, spec in joints.items():
        _check_spec(spec, f"{path}: joint {name!r}")
    units = raw.get("units_to_m")
    if units is not None:
        try:
            units = float(units)
        except (TypeError, ValueError):
            raise InputError(f"{path}: units_to_m must be a number, got {raw.get('units_to_m')!r}") from None
        if not units > 0:
            raise InputError(f"{path}: units_to_m must be > 0, got {units}")
    up = str(raw.get("up_axis", "y"))
    parse_axis(up, f"{path}: up_axis")
    fwd = raw.get("forward")
    if fwd is not None:
        zup_rotation(up, fwd, str(path))
    return {"joints": dict(joints), "units_to_m": units, "up_axis": up, "forward": fwd}


def _check_spec(spec, where: str) -> None:
    if isinstance(spec, str):
        return
    if isinstance(spec, dict) and "between" in spec:
        b = spec["between"]
        if not (isinstance(b, (list, tuple)) and len(b) == 2 and all(isinstance(s, str) for s in b)):
            raise InputError(f"{where}: 'between' must be a list of two source joint names, got {b!r}")
        t = spec.get("t", 0.5)
        if not isinstance(t, (int, float)):
            raise InputError(f"{where}: 't' must be a number, got {t!r}")
        return
    raise InputError(f"{where}: expected a source joint name or {{'between': [a, b], 't': 0.5}}, got {spec!r}")


def apply_joint_map(positions: dict[str, np.ndarray], joint_map: dict, where: str) -> tuple[np.ndarray, list[str]]:
    """Canonical joints from named source points.

    Args:
        positions: ``{source point name: float [T, 3]}`` world positions (source units/axes).
        joint_map: ``{canonical joint: source name | {"between": [a, b], "t": t}}``.
        where: file name for error messages.

    Returns:
        ``(joints [T, 22, 3], derived)`` where ``derived`` lists the canonical joints given
        by ``between`` specs.
    """
    T = next(iter(positions.values())).shape[0] if positions else 0
    out = np.empty((T, NUM_JOINTS, 3), dtype=np.float64)
    derived = []
    known = sorted(positions)
    shown = ", ".join(known[:30]) + (f", ... ({len(known)} in all)" if len(known) > 30 else "")

    def get(name: str, canonical: str) -> np.ndarray:
        if name not in positions:
            raise InputError(
                f"{where}: joint map names source joint {name!r} (for {canonical}) that the file does not have; "
                f"it has: {shown}"
            )
        return positions[name]

    for j, cname in enumerate(JOINT_NAMES):
        if cname not in joint_map:
            raise InputError(f"{where}: joint map lacks canonical joint {cname!r}")
        spec = joint_map[cname]
        if isinstance(spec, str):
            out[:, j] = get(spec, cname)
        else:
            a, b = spec["between"]
            t = float(spec.get("t", 0.5))
            out[:, j] = (1.0 - t) * get(a, cname) + t * get(b, cname)
            derived.append(cname)
    return out, derived


def to_project_frame(points: np.ndarray, units_to_m: float, rotation: np.ndarray) -> np.ndarray:
    """``points[..., 3]`` in source units/axes -> metres, z-up (``rotation`` from :func:`zup_rotation`)."""
    return (np.asarray(points, dtype=np.float64) * units_to_m) @ rotation.T

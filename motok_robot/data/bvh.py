# Size (403 lines): one file format: its grammar, forward kinematics and joint maps change together.
"""Biovision BVH reader, forward kinematics, and skeleton maps (Bandai Namco, acRNN, user).

Parsing follows the BVH grammar: ``HIERARCHY`` with one ``ROOT`` and nested ``JOINT`` /
``End Site`` blocks, each with an ``OFFSET`` and (joints only) a ``CHANNELS n ...`` line
naming any mix of ``Xposition Yposition Zposition Xrotation Yrotation Zrotation`` in any
order; then ``MOTION``, ``Frames: N``, ``Frame Time: dt`` and ``N`` rows of numbers, one
per channel in hierarchy order.

Forward-kinematics semantics (documented because BVH writers disagree):

* the local translation of a joint is its ``OFFSET``; a position channel *replaces* the
  matching component of the offset (so a root with ``OFFSET 0 0 0`` and position channels
  is placed at the channel values, and Bandai Namco's per-joint position channels, which
  repeat the offsets, give the same skeleton);
* rotation channels are Euler angles in degrees, composed in the order listed:
  ``Zrotation Xrotation Yrotation`` gives ``R = Rz @ Rx @ Ry`` (rotations about the
  joint's moving axes), whatever the order of other joints;
* ``world_R[j] = world_R[parent] @ R_local[j]`` and
  ``world_p[j] = world_p[parent] + world_R[parent] @ t_local[j]``;
* an ``End Site`` is a point named ``<parent joint>_end`` at ``OFFSET`` in its parent's frame.

All arrays are in the file's units and axes; :func:`load_clip` converts them to metres,
z-up, canonical joints and 20 fps.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from motok_robot.data.clip import (
    Clip,
    apply_joint_map,
    check_joints,
    load_joint_map,
    snap_fps,
    to_project_frame,
    zup_rotation,
)
from motok_robot.errors import InputError
from motok_robot.limits import check_file_size, check_frames, check_rate, check_seconds, limit
from motok_robot.limits import check_joints as check_joint_count
from motok_robot.motion.features import resample
from motok_robot.motion.rotations import rotation_about_axis

_CHANNEL_NAMES = ("Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation")


@dataclass
class BvhJoint:
    name: str
    parent: int  # index into BvhSkeleton.joints, -1 for the root
    offset: np.ndarray  # [3] file units
    channels: list[str] = field(default_factory=list)
    channel_start: int = 0  # column of its first channel in the MOTION rows
    is_end_site: bool = False


@dataclass
class BvhSkeleton:
    joints: list[BvhJoint]

    @property
    def names(self) -> list[str]:
        return [j.name for j in self.joints]

    @property
    def num_channels(self) -> int:
        return sum(len(j.channels) for j in self.joints)


@dataclass
class BvhMotion:
    """A parsed BVH file: skeleton, ``channels`` float64 ``[T, C]`` and ``frame_time`` (s)."""

    skeleton: BvhSkeleton
    channels: np.ndarray
    frame_time: float
    path: str = ""

    @property
    def fps(self) -> float:
        return 1.0 / self.frame_time


# ----------------------------------------------------------------------------- parsing

def read_bvh(source: str | Path, text: str | None = None) -> BvhMotion:
    """Parse a BVH file (or ``text`` read elsewhere, e.g. from an archive; ``source`` names it)."""
    where = str(source)
    if text is None:
        try:
            if Path(source).is_file():
                check_file_size(source, "BVH file")
            text = Path(source).read_text(encoding="utf-8", errors="replace")
        except IsADirectoryError:
            raise InputError(f"{where}: is a folder, not a BVH file") from None
    head, sep, motion = text.partition("MOTION")
    if not sep:
        raise InputError(f"{where}: no MOTION section (file truncated or not a BVH file)")
    skeleton = _parse_hierarchy(head, where)
    return BvhMotion(skeleton, *_parse_motion(motion, skeleton, where), path=where)


def _parse_hierarchy(text: str, where: str) -> BvhSkeleton:
    tokens = text.split()
    if not tokens or tokens[0].upper() != "HIERARCHY":
        raise InputError(f"{where}: does not start with HIERARCHY (not a BVH file?)")
    joints: list[BvhJoint] = []
    seen: set[str] = set()  # joint names so far (a set: parsing stays linear in the joints)
    max_joints = limit("joints")
    stack: list[int] = []  # indices of open joint blocks (-2 marks an End Site block)
    pending: tuple[str, bool] | None = None
    column = 0
    i = 1
    n = len(tokens)

    def need(k: int, what: str) -> list[str]:
        if i + k > n:
            raise InputError(f"{where}: hierarchy ends inside {what}")
        return tokens[i : i + k]

    while i < n:
        tok = tokens[i]
        up = tok.upper()
        if up in ("ROOT", "JOINT"):
            if up == "ROOT" and joints:
                raise InputError(f"{where}: more than one ROOT (only single-skeleton files are supported)")
            if up == "JOINT" and not stack:
                raise InputError(f"{where}: JOINT outside of the ROOT block")
            name = " ".join(need(2, tok)[1:])
            pending = (name, False)
            i += 2
        elif up == "END":
            (site,) = need(2, "End Site")[1:]
            if site.upper() != "SITE":
                raise InputError(f"{where}: expected 'End Site', got 'End {site}'")
            if not stack or stack[-1] < 0:
                raise InputError(f"{where}: End Site outside of a joint")
            pending = (joints[stack[-1]].name + "_end", True)
            i += 2
        elif tok == "{":
            if pending is None:
                raise InputError(f"{where}: '{{' without a ROOT/JOINT/End Site before it")
            name, is_end = pending
            parent = stack[-1] if stack else -1
            if name in seen:
                raise InputError(f"{where}: joint name {name!r} appears twice")
            seen.add(name)
            if len(joints) + 1 > max_joints:
                check_joint_count(len(joints) + 1, where, "the HIERARCHY's joints (End Sites included)")
            joints.append(BvhJoint(name, parent, np.zeros(3), is_end_site=is_end))
            stack.append(len(joints) - 1)
            pending = None
            i += 1
        elif tok == "}":
            if not stack:
                raise InputError(f"{where}: unbalanced '}}' in HIERARCHY")
            stack.pop()
            i += 1
        elif up == "OFFSET":
            vals = need(4, "OFFSET")[1:]
            if not stack:
                raise InputError(f"{where}: OFFSET outside of a joint block")
            try:
                joints[stack[-1]].offset = np.array([float(v) for v in vals])
            except ValueError:
                raise InputError(f"{where}: joint {joints[stack[-1]].name!r}: bad OFFSET {vals}") from None
            i += 4
        elif up == "CHANNELS":
            if not stack:
                raise InputError(f"{where}: CHANNELS outside of a joint block")
            joint = joints[stack[-1]]
            try:
                count = int(need(2, "CHANNELS")[1])
            except ValueError:
                raise InputError(f"{where}: joint {joint.name!r}: bad CHANNELS count {tokens[i + 1]!r}") from None
            names = tokens[i + 2 : i + 2 + count]
            bad = [c for c in names if c not in _CHANNEL_NAMES]
            if len(names) != count or bad:
                raise InputError(
                    f"{where}: joint {joint.name!r}: CHANNELS {count} lists {names} "
                    f"(expected {count} names from {', '.join(_CHANNEL_NAMES)})"
                )
            if joint.is_end_site:
                raise InputError(f"{where}: End Site of {joint.name[:-4]!r} has CHANNELS")
            joint.channels = list(names)
            joint.channel_start = column
            column += count
            i += 2 + count
        else:
            raise InputError(f"{where}: unexpected token {tok!r} in HIERARCHY")
    if stack:
        raise InputError(f"{where}: HIERARCHY ends with {len(stack)} unclosed block(s)")
    if not joints:
        raise InputError(f"{where}: HIERARCHY has no ROOT joint")
    return BvhSkeleton(joints)


_NUMBER_LINE = re.compile(r"Frames\s*:\s*(\S+)\s+Frame\s+Time\s*:\s*(\S+)", re.IGNORECASE)


def _parse_motion(text: str, skeleton: BvhSkeleton, where: str) -> tuple[np.ndarray, float]:
    m = _NUMBER_LINE.search(text[:500])
    if not m:
        raise InputError(f"{where}: MOTION section lacks 'Frames:' and 'Frame Time:' lines")
    try:
        frames = int(m.group(1))
        frame_time = float(m.group(2))
    except ValueError:
        raise InputError(f"{where}: bad 'Frames: {m.group(1)}' / 'Frame Time: {m.group(2)}'") from None
    if frames <= 0:
        raise InputError(f"{where}: MOTION has zero frames (Frames: {frames})")
    if not (frame_time > 0 and np.isfinite(frame_time)):
        raise InputError(f"{where}: Frame Time must be > 0 seconds, got {m.group(2)}")
    check_frames(frames, where, "'Frames:'")
    check_rate(1.0 / frame_time, where, f"the frame rate of 'Frame Time: {m.group(2)}'")
    check_seconds(frames * frame_time, where, "the duration ('Frames:' x 'Frame Time:')")
    body = text[m.end():]
    ncols = skeleton.num_channels
    rows = [ln for ln in body.splitlines() if ln.strip()]
    if len(rows) < frames:
        raise InputError(f"{where}: truncated motion: header says {frames} frames, file has {len(rows)}")
    rows = rows[:frames]
    lengths = [len(r.split()) for r in rows]
    for f, k in enumerate(lengths):
        if k != ncols:
            raise InputError(
                f"{where}: frame {f} has {k} values, the hierarchy declares {ncols} channels "
                f"(wrong channel count or truncated line)"
            )
    try:
        data = np.array(" ".join(rows).split(), dtype=np.float64).reshape(frames, ncols)
    except ValueError as exc:
        raise InputError(f"{where}: non-numeric value in MOTION ({exc})") from None
    bad = ~np.isfinite(data)
    if bad.any():
        f, c = np.argwhere(bad)[0]
        raise InputError(f"{where}: frame {f}: {_channel_label(skeleton, c)} is {data[f, c]} (NaN or infinite)")
    return data, frame_time


def _channel_label(skeleton: BvhSkeleton, column: int) -> str:
    for j in skeleton.joints:
        if j.channel_start <= column < j.channel_start + len(j.channels):
            return f"joint {j.name!r} channel {j.channels[column - j.channel_start]}"
    return f"column {column}"


# ----------------------------------------------------------------------------- kinematics

def forward_kinematics(motion: BvhMotion) -> dict[str, np.ndarray]:
    """World positions of every joint and End Site: ``{name: float64 [T, 3]}`` (file units/axes)."""
    skel = motion.skeleton
    data = motion.channels
    T = data.shape[0]
    eye = np.broadcast_to(np.eye(3), (T, 3, 3))
    world_R: list[np.ndarray] = []
    world_p: list[np.ndarray] = []
    out = {}
    for joint in skel.joints:
        t = np.broadcast_to(joint.offset, (T, 3)).copy()
        R = None
        for k, ch in enumerate(joint.channels):
            col = data[:, joint.channel_start + k]
            if ch.endswith("position"):
                t[:, "XYZ".index(ch[0])] = col
            else:
                Rk = rotation_about_axis(np.deg2rad(col), "XYZ".index(ch[0]))
                R = Rk if R is None else R @ Rk
        if joint.parent < 0:
            p = t
            WR = eye if R is None else R
        else:
            PR, pp = world_R[joint.parent], world_p[joint.parent]
            p = pp + np.einsum("tij,tj->ti", PR, t)
            WR = PR if R is None else PR @ R
        world_R.append(WR)
        world_p.append(p)
        out[joint.name] = p
    return out


# ----------------------------------------------------------------------------- skeleton maps

#: Bandai Namco Research Motion Dataset 1/2 (cm, y-up). Hips is the pelvis; UpperLeg the hip
#: joint, LowerLeg the knee, Foot the ankle, Toes the ball of the foot; Shoulder the collar
#: (clavicle root), UpperArm the shoulder joint. The skeleton has two spine joints (Spine,
#: Chest), so spine3 is placed 30 % of the way from Chest to Neck (derived).
BANDAI_MAP = {
    "pelvis": "Hips",
    "left_hip": "UpperLeg_L",
    "right_hip": "UpperLeg_R",
    "spine1": "Spine",
    "left_knee": "LowerLeg_L",
    "right_knee": "LowerLeg_R",
    "spine2": "Chest",
    "left_ankle": "Foot_L",
    "right_ankle": "Foot_R",
    "spine3": {"between": ["Chest", "Neck"], "t": 0.3},
    "left_foot": "Toes_L",
    "right_foot": "Toes_R",
    "neck": "Neck",
    "left_collar": "Shoulder_L",
    "right_collar": "Shoulder_R",
    "head": "Head",
    "left_shoulder": "UpperArm_L",
    "right_shoulder": "UpperArm_R",
    "left_elbow": "LowerArm_L",
    "right_elbow": "LowerArm_R",
    "left_wrist": "Hand_L",
    "right_wrist": "Hand_R",
}
BANDAI_UNITS_TO_M = 0.01
BANDAI_UP = "y"

#: acRNN (``standard.bvh``, 43 joints, cm, y-up). ``hip`` is the pelvis; ``lThigh`` the hip
#: joint (``lButtock`` is a short buttock offset above it), ``lShin`` the knee, ``lFoot`` the
#: ankle and its End Site (``lFoot_end``, ~12 cm forward) the toes. The pelvis-abdomen bone is
#: long (21 cm), so spine1 is placed 60 % of the way from hip to abdomen (derived).
ACRNN_MAP = {
    "pelvis": "hip",
    "left_hip": "lThigh",
    "right_hip": "rThigh",
    "spine1": {"between": ["hip", "abdomen"], "t": 0.6},
    "left_knee": "lShin",
    "right_knee": "rShin",
    "spine2": "abdomen",
    "left_ankle": "lFoot",
    "right_ankle": "rFoot",
    "spine3": "chest",
    "left_foot": "lFoot_end",
    "right_foot": "rFoot_end",
    "neck": "neck",
    "left_collar": "lCollar",
    "right_collar": "rCollar",
    "head": "head",
    "left_shoulder": "lShldr",
    "right_shoulder": "rShldr",
    "left_elbow": "lForeArm",
    "right_elbow": "rForeArm",
    "left_wrist": "lHand",
    "right_wrist": "rHand",
}
ACRNN_UNITS_TO_M = 0.01
ACRNN_UP = "y"

SKELETON_MAPS = {
    "bandai": (BANDAI_MAP, BANDAI_UNITS_TO_M, BANDAI_UP),
    "acrnn": (ACRNN_MAP, ACRNN_UNITS_TO_M, ACRNN_UP),
}


def bvh_to_joints(
    motion: BvhMotion,
    joint_map: dict,
    units_to_m: float,
    up_axis: str = "y",
    forward: str | None = None,
    fps: float | None = None,
) -> tuple[np.ndarray, list[str]]:
    """Canonical joints ``float32 [T20, 22, 3]`` (metres, z-up, 20 fps) and the derived joint names.

    ``fps`` overrides the file's ``Frame Time`` (for files whose header is known to be wrong).
    """
    positions = forward_kinematics(motion)
    joints, derived = apply_joint_map(positions, joint_map, motion.path)
    joints = to_project_frame(joints, units_to_m, zup_rotation(up_axis, forward, motion.path))
    joints = resample(joints, fps or snap_fps(motion.fps))
    return check_joints(joints, motion.path), derived


def load_clip(
    path: str | Path,
    skeleton: str | dict = "bandai",
    clip_id: str | None = None,
    source: str = "bvh",
    licence: str = "unknown",
    text: str | None = None,
    fps: float | None = None,
) -> Clip:
    """Read one BVH file into a :class:`Clip`.

    Args:
        path: the file (or its name inside an archive when ``text`` is given).
        skeleton: ``"bandai"``, ``"acrnn"``, a path to a joint-map JSON file, or a map dict as
            returned by :func:`motok_robot.data.clip.load_joint_map`.
        fps: override the frame rate in the file header.
    """
    if isinstance(skeleton, str) and skeleton in SKELETON_MAPS:
        jmap, units, up = SKELETON_MAPS[skeleton]
        fwd = None
    else:
        spec = skeleton if isinstance(skeleton, dict) else load_joint_map(skeleton)
        jmap, units, up, fwd = spec["joints"], spec.get("units_to_m") or 1.0, spec.get("up_axis", "y"), spec.get("forward")
    motion = read_bvh(path, text)
    joints, derived = bvh_to_joints(motion, jmap, units, up, fwd, fps)
    cid = clip_id or f"{source}/{Path(str(path)).stem}"
    return Clip(id=cid, source=source, licence=licence, joints=joints, file=str(path), derived_joints=derived)

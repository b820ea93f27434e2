# Size (410 lines): one file format pair: the ASF skeleton, the AMC motion that needs it and the CMU map.
"""Acclaim ASF (skeleton) + AMC (motion) reader, forward kinematics and the CMU joint map.

ASF fields used (any file in the format, not only CMU's):

* ``:units`` ``length L`` - file lengths are inches multiplied by ``L`` (CMU: ``length 0.45``),
  so metres = value / L * 0.0254; ``angle deg|rad``; ``mass`` is ignored.
* ``:root`` ``order`` - the AMC root channels (``TX TY TZ RX RY RZ`` in any order),
  ``axis`` - the root rotation order, ``orientation`` - the root's rest frame, ``position``
  (ignored: AMC root translations are absolute).
* ``:bonedata`` - per bone ``name``, ``direction`` (unit vector, world rest frame),
  ``length``, ``axis ax ay az ORDER`` (the bone's local frame ``C`` in world rest
  coordinates), ``dof`` (subset of ``rx ry rz tx ty tz l`` in AMC column order).
* ``:hierarchy`` - ``parent child child ...`` lines between ``begin`` and ``end``.

Forward kinematics (the Acclaim convention): Euler angles listed in order ``a1 a2 a3`` are
applied in that order about fixed axes, ``R = R(a3) @ R(a2) @ R(a1)``;
``M_bone = M_parent @ C @ R(dof) @ C^-1``; the bone starts where its parent ends and ends at
``start + M_bone @ (direction * (length + l)) + M_parent @ C @ (tx, ty, tz)``.

Named points: ``root`` (root position), ``NAME`` (start of bone NAME, i.e. the joint where
it rotates) and ``NAME_end`` (its end).  CMU data is y-up; :func:`load_clip` converts to
metres, z-up, canonical joints and 20 fps.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from motok_robot.data.clip import (
    Clip,
    apply_joint_map,
    check_joints,
    to_project_frame,
    zup_rotation,
)
from motok_robot.errors import InputError
from motok_robot.motion.features import resample
from motok_robot.motion.rotations import rotation_about_axis

INCH = 0.0254


@dataclass
class AsfBone:
    name: str
    direction: np.ndarray  # [3] unit, world rest frame
    length: float  # file units
    axis: np.ndarray  # [3] angles (file angle units)
    axis_order: str  # e.g. "XYZ"
    dof: list[str] = field(default_factory=list)
    parent: str = ""


@dataclass
class AsfSkeleton:
    """Parsed ASF. ``length_scale`` = the ``:units length`` value; ``degrees`` = angle unit."""

    bones: dict[str, AsfBone]
    root_order: list[str]
    root_axis: str
    root_orientation: np.ndarray
    length_scale: float = 1.0
    degrees: bool = True
    children: dict[str, list[str]] = field(default_factory=dict)
    path: str = ""

    @property
    def units_to_m(self) -> float:
        return INCH / self.length_scale


def _floats(vals: list[str], where: str, what: str) -> np.ndarray:
    try:
        return np.array([float(v) for v in vals], dtype=np.float64)
    except ValueError:
        raise InputError(f"{where}: bad numbers in {what}: {' '.join(vals)}") from None


def read_asf(path: str | Path, text: str | None = None) -> AsfSkeleton:
    where = str(path)
    if text is None:
        text = Path(path).read_text(encoding="utf-8", errors="replace")
    sections: dict[str, list[list[str]]] = {}
    current = None
    for raw in text.splitlines():
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        if line.startswith(":"):
            parts = line.split()
            current = parts[0][1:].lower()
            sections.setdefault(current, [])
            if len(parts) > 1:
                sections[current].append(parts[1:])
            continue
        if current is not None:
            sections[current].append(line.split())
    for need in ("root", "bonedata", "hierarchy"):
        if need not in sections:
            raise InputError(f"{where}: ASF has no :{need} section (not an ASF file, or truncated)")

    length_scale, degrees = 1.0, True
    for parts in sections.get("units", []):
        key = parts[0].lower()
        if key == "length" and len(parts) > 1:
            length_scale = float(_floats(parts[1:2], where, ":units length")[0])
            if not length_scale > 0:
                raise InputError(f"{where}: :units length must be > 0, got {parts[1]}")
        elif key == "angle" and len(parts) > 1:
            unit = parts[1].lower()
            if unit not in ("deg", "rad"):
                raise InputError(f"{where}: :units angle must be deg or rad, got {parts[1]!r}")
            degrees = unit == "deg"

    root_order = ["TX", "TY", "TZ", "RX", "RY", "RZ"]
    root_axis = "XYZ"
    root_orientation = np.zeros(3)
    for parts in sections["root"]:
        key = parts[0].lower()
        if key == "order":
            root_order = [p.upper() for p in parts[1:]]
            bad = [p for p in root_order if p not in ("TX", "TY", "TZ", "RX", "RY", "RZ")]
            if bad:
                raise InputError(f"{where}: :root order has unknown channel(s) {bad}")
        elif key == "axis":
            root_axis = parts[1].upper()
        elif key == "orientation":
            root_orientation = _floats(parts[1:4], where, ":root orientation")

    bones: dict[str, AsfBone] = {}
    cur: dict | None = None
    for parts in sections["bonedata"]:
        key = parts[0].lower()
        if key == "begin":
            cur = {}
        elif key == "end":
            if cur is None or "name" not in cur:
                raise InputError(f"{where}: a bone in :bonedata has no name")
            name = cur["name"]
            for f in ("direction", "length"):
                if f not in cur:
                    raise InputError(f"{where}: bone {name!r} has no {f}")
            d = cur["direction"]
            n = np.linalg.norm(d)
            bones[name] = AsfBone(
                name,
                d / n if n > 0 else d,
                cur["length"],
                cur.get("axis", np.zeros(3)),
                cur.get("axis_order", "XYZ"),
                cur.get("dof", []),
            )
            cur = None
        elif cur is not None:
            if key == "name":
                cur["name"] = parts[1]
            elif key == "direction":
                cur["direction"] = _floats(parts[1:4], where, f"direction of bone {cur.get('name')!r}")
            elif key == "length":
                cur["length"] = float(_floats(parts[1:2], where, f"length of bone {cur.get('name')!r}")[0])
            elif key == "axis":
                cur["axis"] = _floats(parts[1:4], where, f"axis of bone {cur.get('name')!r}")
                cur["axis_order"] = parts[4].upper() if len(parts) > 4 else "XYZ"
            elif key == "dof":
                dof = [p.lower() for p in parts[1:]]
                bad = [p for p in dof if p not in ("rx", "ry", "rz", "tx", "ty", "tz", "l")]
                if bad:
                    raise InputError(f"{where}: bone {cur.get('name')!r} has unknown dof {bad}")
                cur["dof"] = dof
    if cur is not None:
        raise InputError(f"{where}: :bonedata ends inside a bone block (missing 'end')")

    children: dict[str, list[str]] = {}
    for parts in sections["hierarchy"]:
        if parts[0].lower() in ("begin", "end"):
            continue
        parent, kids = parts[0], parts[1:]
        if parent != "root" and parent not in bones:
            raise InputError(f"{where}: :hierarchy names unknown bone {parent!r}")
        for k in kids:
            if k not in bones:
                raise InputError(f"{where}: :hierarchy names unknown bone {k!r}")
            bones[k].parent = parent
        children.setdefault(parent, []).extend(kids)
    orphans = [b for b in bones.values() if not b.parent]
    if orphans:
        raise InputError(f"{where}: bone(s) {[b.name for b in orphans]} not in :hierarchy")
    for order in [root_axis] + [b.axis_order for b in bones.values()]:
        if sorted(order) != ["X", "Y", "Z"]:
            raise InputError(f"{where}: rotation order must be a permutation of XYZ, got {order!r}")
    return AsfSkeleton(bones, root_order, root_axis, root_orientation, length_scale, degrees, children, where)


@dataclass
class AmcMotion:
    """AMC frames: ``values[name]`` float64 ``[T, n]`` in AMC column order."""

    values: dict[str, np.ndarray]
    frames: int
    path: str = ""


def read_amc(path: str | Path, skeleton: AsfSkeleton, text: str | None = None) -> AmcMotion:
    where = str(path)
    if text is None:
        text = Path(path).read_text(encoding="utf-8", errors="replace")
    expected = {"root": len(skeleton.root_order)}
    for b in skeleton.bones.values():
        expected[b.name] = len(b.dof)
    frames: list[dict[str, list[str]]] = []
    current: dict[str, list[str]] | None = None
    for lineno, raw in enumerate(text.splitlines(), 1):
        line = raw.strip()
        if not line or line.startswith("#") or line.startswith(":"):
            continue
        parts = line.split()
        if len(parts) == 1 and parts[0].isdigit():
            current = {}
            frames.append(current)
            continue
        if current is None:
            raise InputError(f"{where}: line {lineno}: data before the first frame number")
        name = parts[0]
        if name not in expected:
            raise InputError(f"{where}: frame {len(frames) - 1}: unknown bone {name!r} (not in the ASF)")
        if len(parts) - 1 != expected[name]:
            raise InputError(
                f"{where}: frame {len(frames) - 1}: bone {name!r} has {len(parts) - 1} values, "
                f"the ASF declares {expected[name]} dof"
            )
        current[name] = parts[1:]
    if not frames:
        raise InputError(f"{where}: AMC has zero frames")
    movers = [n for n, k in expected.items() if k > 0]
    values: dict[str, np.ndarray] = {}
    for name in movers:
        rows = []
        for f, fr in enumerate(frames):
            if name not in fr:
                raise InputError(f"{where}: frame {f}: bone {name!r} missing (truncated motion?)")
            rows.append(fr[name])
        try:
            arr = np.array(rows, dtype=np.float64)
        except ValueError:
            raise InputError(f"{where}: bone {name!r}: non-numeric value") from None
        bad = ~np.isfinite(arr)
        if bad.any():
            f = int(np.argwhere(bad)[0][0])
            raise InputError(f"{where}: frame {f}: bone {name!r} has a NaN or infinite value")
        values[name] = arr
    return AmcMotion(values, len(frames), where)


def euler_fixed(angles: np.ndarray, order: str) -> np.ndarray:
    """Rotation matrices ``[..., 3, 3]`` for angles (radians) ``[..., len(order)]`` applied in
    ``order`` about fixed axes: ``R = R(order[-1]) @ ... @ R(order[0])``."""
    angles = np.asarray(angles, dtype=np.float64)
    R = np.broadcast_to(np.eye(3), angles.shape[:-1] + (3, 3)).copy()
    for k, ax in enumerate(order):
        R = rotation_about_axis(angles[..., k], "XYZ".index(ax)) @ R
    return R


def forward_kinematics(skel: AsfSkeleton, motion: AmcMotion) -> dict[str, np.ndarray]:
    """World positions ``{point name: float64 [T, 3]}`` in file units/axes (see module doc)."""
    T = motion.frames
    to_rad = np.pi / 180.0 if skel.degrees else 1.0
    root_vals = motion.values["root"]
    trans = np.zeros((T, 3))
    rot = np.zeros((T, 3))
    rot_order = ""
    for k, ch in enumerate(skel.root_order):
        if ch[0] == "T":
            trans[:, "XYZ".index(ch[1])] = root_vals[:, k]
        else:
            rot[:, len(rot_order)] = root_vals[:, k] * to_rad
            rot_order += ch[1]
    # the root rotation order is the :root axis line (the order of R channels must match it)
    if rot_order and sorted(rot_order) == sorted(skel.root_axis) and rot_order != skel.root_axis:
        rot = rot[:, [rot_order.index(a) for a in skel.root_axis]]
    C0 = euler_fixed(skel.root_orientation * to_rad, skel.root_axis)
    M = {"root": C0 @ euler_fixed(rot, skel.root_axis) @ C0.T}
    end = {"root": trans}
    out = {"root": trans}
    order = []
    queue = list(skel.children.get("root", []))
    while queue:
        b = queue.pop(0)
        order.append(b)
        queue.extend(skel.children.get(b, []))
    for name in order:
        bone = skel.bones[name]
        C = euler_fixed(bone.axis * to_rad, bone.axis_order)
        vals = motion.values.get(name)
        angles, axes, t, dl = [], "", np.zeros((T, 3)), np.zeros(T)
        for k, d in enumerate(bone.dof):
            col = vals[:, k]
            if d[0] == "r":
                angles.append(col * to_rad)
                axes += d[1].upper()
            elif d[0] == "t":
                t[:, "xyz".index(d[1])] = col
            else:
                dl = col
        Mp = M[bone.parent]
        local = C @ euler_fixed(np.stack(angles, -1), axes) @ C.T if axes else np.broadcast_to(np.eye(3), (T, 3, 3))
        Mb = Mp @ local
        start = end[bone.parent]
        vec = bone.direction[None, :] * (bone.length + dl)[:, None]
        stop = start + np.einsum("tij,tj->ti", Mb, vec) + np.einsum("tij,tj->ti", Mp @ C, t)
        M[name], end[name] = Mb, stop
        out[name] = start
        out[name + "_end"] = stop
    return out


#: CMU (Vicon BodyBuilder skeleton). Bones are named by the segment; a canonical joint is the
#: START of the segment that rotates about it: lfemur starts at the hip joint, ltibia at the
#: knee, lfoot at the ankle, ltoes at the ball of the foot, lhumerus at the shoulder, lradius
#: at the elbow, lwrist at the wrist. The spine chain root-lowerback-upperback-thorax-
#: lowerneck-upperneck-head maps to spine1 (upperback start), spine2 (thorax start), spine3
#: (lowerneck start = thorax end), neck (upperneck start), head (head start). The clavicles
#: start on the spine midline, so the collars are placed 40 % along them (derived).
CMU_MAP = {
    "pelvis": "root",
    "left_hip": "lfemur",
    "right_hip": "rfemur",
    "spine1": "upperback",
    "left_knee": "ltibia",
    "right_knee": "rtibia",
    "spine2": "thorax",
    "left_ankle": "lfoot",
    "right_ankle": "rfoot",
    "spine3": "lowerneck",
    "left_foot": "ltoes",
    "right_foot": "rtoes",
    "neck": "upperneck",
    "left_collar": {"between": ["lclavicle", "lhumerus"], "t": 0.4},
    "right_collar": {"between": ["rclavicle", "rhumerus"], "t": 0.4},
    "head": "head",
    "left_shoulder": "lhumerus",
    "right_shoulder": "rhumerus",
    "left_elbow": "lradius",
    "right_elbow": "rradius",
    "left_wrist": "lwrist",
    "right_wrist": "rwrist",
}


def untracked_ends(motion: AmcMotion, min_bones: int = 3) -> tuple[int, int]:
    """``(lead, trail)``: numbers of leading / trailing frames that are not motion capture.

    A frame counts as untracked when at least ``min_bones`` bones with two or more rotation
    dof have every value exactly 0 (CMU 03_02 starts with 50 such frames: the whole upper body
    sits in its rest pose and then jumps 0.7 m in one frame). Exact zeros in all dof of several
    bones do not happen in tracked data; single-dof joints (knees) at 0 are common and ignored.
    """
    flagged = np.zeros(motion.frames, dtype=int)
    for name, vals in motion.values.items():
        if name != "root" and vals.shape[1] >= 2:
            flagged += np.all(vals == 0.0, axis=1)
    bad = flagged >= min_bones
    if bad.all() or not bad.any():
        return 0, 0
    lead = int(np.argmin(bad))
    trail = int(np.argmin(bad[::-1]))
    return lead, trail


def load_clip(
    asf_path: str | Path,
    amc_path: str | Path,
    joint_map: dict | None = None,
    fps: float = 120.0,
    up_axis: str = "y",
    forward: str | None = None,
    clip_id: str | None = None,
    source: str = "asf",
    licence: str = "unknown",
    asf_text: str | None = None,
    amc_text: str | None = None,
    units_to_m: float | None = None,
) -> Clip:
    """Read an ASF/AMC pair into a :class:`Clip` (metres, z-up, 20 fps).

    Args:
        joint_map: canonical joint -> point name (see module doc) or ``between`` spec;
            default :data:`CMU_MAP`.
        fps: AMC frame rate (AMC files do not store it; CMU is 120).
        units_to_m: override the ASF ``:units length`` conversion (default inches / length).
    """
    skel = read_asf(asf_path, asf_text)
    motion = read_amc(amc_path, skel, amc_text)
    lead, trail = untracked_ends(motion)
    if lead or trail:
        keep = slice(lead, motion.frames - trail)
        motion = AmcMotion({k: v[keep] for k, v in motion.values.items()}, motion.frames - lead - trail, motion.path)
    positions = forward_kinematics(skel, motion)
    joints, derived = apply_joint_map(positions, joint_map or CMU_MAP, str(amc_path))
    scale = units_to_m if units_to_m is not None else skel.units_to_m
    joints = to_project_frame(joints, scale, zup_rotation(up_axis, forward, str(amc_path)))
    joints = check_joints(resample(joints, fps), str(amc_path))
    cid = clip_id or f"{source}/{Path(str(amc_path)).stem}"
    labels = {"trimmed_untracked_frames": [lead, trail]} if (lead or trail) else {}
    return Clip(id=cid, source=source, licence=licence, joints=joints, file=str(amc_path), derived_joints=derived,
                labels=labels)

"""Small motion files written by the data tests themselves (no shared data needed).

Helpers only (imported by the other ``test_data_*`` modules); the single test here checks
that the generated walking BVH is what the helpers claim.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from motok_robot.motion import skeleton

# canonical joint -> Bandai Namco joint name (spine3 has no Bandai joint: it is derived)
BANDAI_NAMES = {
    "pelvis": "Hips", "left_hip": "UpperLeg_L", "right_hip": "UpperLeg_R", "spine1": "Spine",
    "left_knee": "LowerLeg_L", "right_knee": "LowerLeg_R", "spine2": "Chest", "left_ankle": "Foot_L",
    "right_ankle": "Foot_R", "left_foot": "Toes_L", "right_foot": "Toes_R", "neck": "Neck",
    "left_collar": "Shoulder_L", "right_collar": "Shoulder_R", "head": "Head", "left_shoulder": "UpperArm_L",
    "right_shoulder": "UpperArm_R", "left_elbow": "LowerArm_L", "right_elbow": "LowerArm_R",
    "left_wrist": "Hand_L", "right_wrist": "Hand_R",
}


def canonical_bvh_text(
    frames: int = 30,
    fps: float = 30.0,
    names: dict[str, str] | None = None,
    speed: float = 1.0,
    units: float = 100.0,
    skip: tuple[str, ...] = (),
) -> str:
    """A y-up BVH of the canonical body (offsets in cm) walking along +z (its forward).

    Every canonical joint becomes a BVH joint named ``names[joint]`` (default: the canonical
    name); joints in ``skip`` are left out (their children hang from the grandparent).
    The root has 6 channels, others ``Zrotation Xrotation Yrotation``; hips swing about x.
    """
    names = names or {n: n for n in skeleton.JOINT_NAMES}
    rest = skeleton.yup_from_zup(skeleton.rest_pose()) * units  # y up, facing +z, left = +x
    kids: dict[int, list[int]] = {}
    parent_of = {}
    for j in range(1, skeleton.NUM_JOINTS):
        p = skeleton.PARENTS[j]
        while skeleton.JOINT_NAMES[p] in skip:
            p = skeleton.PARENTS[p]
        if skeleton.JOINT_NAMES[j] in skip:
            continue
        kids.setdefault(p, []).append(j)
        parent_of[j] = p
    order: list[int] = []
    lines = ["HIERARCHY"]

    def emit(j: int, depth: int) -> None:
        pad = "  " * depth
        off = rest[j] - (rest[parent_of[j]] if j else 0.0)
        if j == 0:
            lines.append(f"ROOT {names[skeleton.JOINT_NAMES[j]]}")
        else:
            lines.append(f"{pad}JOINT {names[skeleton.JOINT_NAMES[j]]}")
        lines.append(pad + "{")
        lines.append(f"{pad}  OFFSET {off[0]:.6f} {off[1]:.6f} {off[2]:.6f}" if j else f"{pad}  OFFSET 0 0 0")
        if j == 0:
            lines.append(f"{pad}  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation")
        else:
            lines.append(f"{pad}  CHANNELS 3 Zrotation Xrotation Yrotation")
        order.append(j)
        for k in kids.get(j, []):
            emit(k, depth + 1)
        if not kids.get(j):
            lines.append(f"{pad}  End Site")
            lines.append(pad + "  {")
            lines.append(f"{pad}    OFFSET 0 {0.05 * units:.6f} 0")
            lines.append(pad + "  }")
        lines.append(pad + "}")

    emit(0, 0)
    lines += ["MOTION", f"Frames: {frames}", f"Frame Time: {1.0 / fps:.8f}"]
    t = np.arange(frames) / fps
    for f in range(frames):
        row = []
        for j in order:
            if j == 0:
                row += [rest[0, 0], rest[0, 1], rest[0, 2] + speed * units * t[f], 0.0, 0.0, 0.0]
                continue
            name = skeleton.JOINT_NAMES[j]
            ax = 0.0
            if name in ("left_hip", "right_hip"):
                ax = 25.0 * np.sin(2 * np.pi * t[f]) * (1 if name == "left_hip" else -1)
            row += [0.0, ax, 0.0]
        lines.append(" ".join(f"{v:.6f}" for v in row))
    return "\n".join(lines) + "\n"


def identity_map(path: Path, units_to_m: float = 0.01, up_axis: str = "y", **extra) -> Path:
    spec = {"joints": {n: n for n in skeleton.JOINT_NAMES}, "units_to_m": units_to_m, "up_axis": up_axis, **extra}
    path.write_text(json.dumps(spec))
    return path


# ----------------------------------------------------------------------------- ASF / AMC

# CMU bone -> (start joint, end joint) on the canonical rest pose, or (joint, direction offset)
_CMU_BONES = [
    ("lhipjoint", "root", "pelvis", "left_hip"), ("lfemur", "lhipjoint", "left_hip", "left_knee"),
    ("ltibia", "lfemur", "left_knee", "left_ankle"), ("lfoot", "ltibia", "left_ankle", "left_foot"),
    ("ltoes", "lfoot", "left_foot", None),
    ("rhipjoint", "root", "pelvis", "right_hip"), ("rfemur", "rhipjoint", "right_hip", "right_knee"),
    ("rtibia", "rfemur", "right_knee", "right_ankle"), ("rfoot", "rtibia", "right_ankle", "right_foot"),
    ("rtoes", "rfoot", "right_foot", None),
    ("lowerback", "root", "pelvis", "spine1"), ("upperback", "lowerback", "spine1", "spine2"),
    ("thorax", "upperback", "spine2", "spine3"), ("lowerneck", "thorax", "spine3", "neck"),
    ("upperneck", "lowerneck", "neck", "head"), ("head", "upperneck", "head", None),
    ("lclavicle", "thorax", "spine3", "left_shoulder"), ("lhumerus", "lclavicle", "left_shoulder", "left_elbow"),
    ("lradius", "lhumerus", "left_elbow", "left_wrist"), ("lwrist", "lradius", "left_wrist", None),
    ("rclavicle", "thorax", "spine3", "right_shoulder"), ("rhumerus", "rclavicle", "right_shoulder", "right_elbow"),
    ("rradius", "rhumerus", "right_elbow", "right_wrist"), ("rwrist", "rradius", "right_wrist", None),
]


def cmu_like_asf(length_scale: float = 0.45) -> str:
    """An ASF with CMU bone names on the canonical rest pose (y up, facing +z), inch-based units."""
    rest = skeleton.yup_from_zup(skeleton.rest_pose())
    J = skeleton.JOINT_INDEX
    out = [":version 1.10", ":name TEST", ":units", "  mass 1.0", f"  length {length_scale}", "  angle deg",
           ":root", "   order TX TY TZ RX RY RZ", "   axis XYZ", "   position 0 0 0", "   orientation 0 0 0",
           ":bonedata"]
    for i, (name, _parent, a, b) in enumerate(_CMU_BONES, 1):
        vec = rest[J[b]] - rest[J[a]] if b else np.array([0.0, 0.03, 0.03])
        length_m = float(np.linalg.norm(vec))
        d = vec / length_m
        out += ["  begin", f"     id {i}", f"     name {name}", f"     direction {d[0]:.6f} {d[1]:.6f} {d[2]:.6f}",
                f"     length {length_m / 0.0254 * length_scale:.6f}", "     axis 0 0 0  XYZ"]
        if name in ("lfemur", "rfemur", "lhumerus", "rhumerus"):
            out += ["    dof rx ry rz", "    limits (-180 180)", "           (-180 180)", "           (-180 180)"]
        elif name in ("ltibia", "rtibia"):
            out += ["    dof rx", "    limits (-10 170)"]
        out += ["  end"]
    out += [":hierarchy", "  begin"]
    kids: dict[str, list[str]] = {}
    for name, parent, _a, _b in _CMU_BONES:
        kids.setdefault(parent, []).append(name)
    out += [f"    {p} {' '.join(k)}" for p, k in kids.items()]
    out += ["  end"]
    return "\n".join(out) + "\n"


def cmu_like_amc(frames: int = 24, knee_deg: float = 30.0, speed: float = 1.0, fps: float = 120.0,
                 untracked_lead: int = 0) -> str:
    """AMC frames for :func:`cmu_like_asf`: root walking along +z (inches*0.45 units), knees bent.

    The first ``untracked_lead`` frames have femurs and humeri exactly 0 (untracked data)."""
    pelvis = skeleton.yup_from_zup(skeleton.rest_pose()[0]) / 0.0254 * 0.45  # y up, forward +z
    out = [":FULLY-SPECIFIED", ":DEGREES"]
    for f in range(frames):
        z = pelvis[2] + speed * f / fps / 0.0254 * 0.45
        out.append(str(f + 1))
        out.append(f"root {pelvis[0]:.6f} {pelvis[1]:.6f} {z:.6f} 0 0 0")
        for side in "lr":
            lost = f < untracked_lead
            out.append(f"{side}femur 0 0 0" if lost else f"{side}femur {-10.0 * np.sin(f / 10):.4f} 0 0")
            out.append(f"{side}tibia {knee_deg:.4f}")
            out.append(f"{side}humerus 0 0 0" if lost else f"{side}humerus 0.0001 0 0")
    return "\n".join(out) + "\n"


# ----------------------------------------------------------------------------- DeepMimic

def deepmimic_json(frames: int = 10, dt: float = 1 / 30, speed: float = 1.0, knee: float = -0.3) -> str:
    """DeepMimic motion walking along +x (y up) with identity rotations and bent knees."""
    rows = []
    ident = [1.0, 0.0, 0.0, 0.0]
    for f in range(frames):
        row = [dt if f < frames - 1 else 0.0, speed * f * dt, 0.85, 0.0] + ident + ident + ident
        row += ident + [knee] + ident + ident + [0.2]  # right hip, knee, ankle, shoulder, elbow
        row += ident + [knee] + ident + ident + [0.2]  # left
        rows.append(row)
    return json.dumps({"Loop": "none", "Frames": rows})


def test_canonical_bvh_parses_to_rest_pose(tmp_path):
    from motok_robot.data import bvh

    f = tmp_path / "c.bvh"
    f.write_text(canonical_bvh_text(frames=3, speed=0.0))
    m = bvh.read_bvh(f)
    assert len(m.skeleton.joints) == 22 + 5  # 22 joints + 5 End Sites (feet, head, wrists)
    spec = {"joints": {n: n for n in skeleton.JOINT_NAMES}}
    joints, derived = bvh.bvh_to_joints(m, spec["joints"], 0.01, "y", fps=20.0)
    # frame 0: zero rotations except hips (sin 0 = 0) -> exactly the rest pose (z up)
    np.testing.assert_allclose(joints[0], skeleton.rest_pose(), atol=1e-5)
    assert derived == []

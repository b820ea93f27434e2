"""The human motion of a ``motion.npz`` as a Biovision BVH file (numpy only).

Units and axes: **centimetres, y up**, the body facing **+z** at frame 0 when the motion faces
+x (BVH has no unit or axis field, so this is fixed here and in docs/export.md).  The project
frame (x forward, y left, z up, metres) maps to the BVH frame by the cyclic permutation of
:func:`motok_robot.motion.skeleton.yup_from_zup` (BVH x = project y, y = project z, z = project
x) and a factor 100; the project's BVH reader (:mod:`motok_robot.data.bvh`) undoes both for a
file that says ``up_axis: y``, ``units_to_m: 0.01``.

Skeleton: the 22 canonical joints under their canonical names (``pelvis``, ``left_hip``, ...),
the tree of :data:`motok_robot.motion.skeleton.PARENTS`, children in joint order, an ``End Site``
after each leaf (head, wrists, toes).  The root has ``Xposition Yposition Zposition Zrotation
Xrotation Yrotation`` channels, every other joint ``Zrotation Xrotation Yrotation`` (the
rotation matrix is ``Rz @ Rx @ Ry``, the reader's convention, degrees).

Offsets: the canonical rest directions (T-pose, :data:`~motok_robot.motion.skeleton.REST_OFFSETS`)
scaled to each bone's median length in the clip; the children of the pelvis (hips, spine1) and
of spine3 (neck, collars) keep their mean arrangement in the clip, since they hang rigidly
from one joint.

Rotations, solved from the joint positions (:func:`solve_rotations`): the pelvis and spine3
by the best rotation of their children's offsets onto the clip's (Kabsch); every joint with one
child by the shortest arc from its parent's frame that points the bone at the child
(:func:`motok_robot.motion.rotations.quat_between`), so no bone twists about its own axis
(positions do not determine twist); leaves keep their parent's frame.  Bone directions are
reproduced exactly; positions differ from the input only where the clip's bone lengths vary
(BVH offsets are fixed) or its pelvis / spine3 children are not rigid.  :class:`BvhExport`
reports both.  ``bone_positions=True`` gives every joint position channels as well (as the
Bandai Namco files do: ``Xposition Yposition Zposition Zrotation Xrotation Yrotation``, the
joint's place in its parent's frame per frame), which reproduces the positions exactly; some
viewers ignore position channels below the root.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from motok_robot.export.progress import write_rows
from motok_robot.motion import skeleton
from motok_robot.motion.rotations import quat_between, quat_to_matrix

#: centimetres per metre: the BVH file's unit
CM_PER_M = 100.0
ROOT_CHANNELS = ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")
JOINT_CHANNELS = ("Zrotation", "Xrotation", "Yrotation")

#: the joint map that reads an exported file back with :func:`motok_robot.data.bvh.load_clip`
#: (``skeleton=JOINT_MAP``; the same fields as a joint-map JSON file, docs/data.md)
JOINT_MAP = {"joints": {name: name for name in skeleton.JOINT_NAMES}, "units_to_m": 1.0 / CM_PER_M,
             "up_axis": "y", "forward": None}

_CHILDREN = [[c for c in range(skeleton.NUM_JOINTS) if skeleton.PARENTS[c] == j] for j in range(skeleton.NUM_JOINTS)]
#: length of the End Site beyond each leaf, as a fraction of the leaf's own bone (at least END_SITE_MIN_CM)
END_SITE_FRACTION = 0.5
END_SITE_MIN_CM = 5.0


@dataclass
class BvhExport:
    """What :func:`write_bvh` wrote and how faithful it is.

    ``offsets_cm`` [22, 3] (BVH frame, row 0 zero), ``max_position_error_m`` (largest distance of
    a joint, reconstructed from offsets and rotations, from the input), ``max_bone_length_change_m``
    (largest deviation of a bone from its median length in the input), ``bone_positions``
    (position channels on every joint: then the positions are exact).
    """

    path: Path
    frames: int
    fps: float
    offsets_cm: np.ndarray
    max_position_error_m: float
    max_bone_length_change_m: float
    bone_positions: bool = False

    def line(self) -> str:
        text = (f"wrote {self.path}: {self.frames} frames at {self.fps:g} fps, 22 joints, centimetres, y up"
                + (", position channels on every joint" if self.bone_positions else ""))
        if self.bone_positions or self.max_position_error_m < 1e-4:
            return text
        return (text + f"; joints move up to {self.max_position_error_m * 1000:.1f} mm from the input because its "
                f"bone lengths vary by up to {self.max_bone_length_change_m * 1000:.1f} mm (BVH offsets are fixed; "
                "--bone-positions keeps them exactly)")


def _normalise(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.maximum(n, 1e-12)


def _kabsch(offsets: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """Rotations ``[T, 3, 3]`` that best take ``offsets[k, 3]`` onto ``targets[T, k, 3]``."""
    h = np.einsum("ki,tkj->tij", offsets, targets)  # sum_k o_k d_k^T
    u, _, vt = np.linalg.svd(h)
    v = np.swapaxes(vt, -1, -2)
    ut = np.swapaxes(u, -1, -2)
    d = np.sign(np.linalg.det(v @ ut))
    d = np.where(d == 0, 1.0, d)
    fix = np.broadcast_to(np.eye(3), h.shape).copy()
    fix[:, 2, 2] = d
    return v @ fix @ ut


def skeleton_offsets(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Rest offsets ``[22, 3]`` (points' units and axes, BVH frame) for ``points[T, 22, 3]``, and
    the largest deviation of a bone from its median length."""
    rest = skeleton.yup_from_zup(skeleton.REST_OFFSETS)
    parents = np.array(skeleton.PARENTS[1:])
    bones = points[:, 1:] - points[:, parents]  # [T, 21, 3]
    lengths = np.linalg.norm(bones, axis=-1)
    median = np.median(lengths, axis=0)
    canonical = np.linalg.norm(rest[1:], axis=-1) * (np.median(median) / np.median(np.linalg.norm(rest[1:], axis=-1)))
    median = np.where(median > 1e-9, median, canonical)  # a bone of zero length keeps a canonical one
    offsets = np.zeros((skeleton.NUM_JOINTS, 3))
    offsets[1:] = _normalise(rest[1:]) * median[:, None]
    for j, children in enumerate(_CHILDREN):
        if len(children) < 2:
            continue
        targets = points[:, children] - points[:, j : j + 1]
        frame = _kabsch(offsets[children], targets)  # the joint's frame with the rest arrangement
        local = np.einsum("tji,tkj->tki", frame, targets).mean(axis=0)  # children seen from that frame
        offsets[children] = _normalise(local) * median[np.array(children) - 1, None]
    return offsets, float(np.abs(lengths - median).max())


def solve_rotations(points: np.ndarray, offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Local rotations ``[T, 22, 3, 3]`` (each joint relative to its parent; row 0 the root's
    world rotation) that point every bone of ``offsets`` along the bones of ``points[T, 22, 3]``
    (see the module docstring), and the world rotations of the joints' frames."""
    T = points.shape[0]
    world = np.zeros((T, skeleton.NUM_JOINTS, 3, 3))
    local = np.zeros_like(world)
    for j in range(skeleton.NUM_JOINTS):
        parent = skeleton.PARENTS[j]
        above = np.broadcast_to(np.eye(3), (T, 3, 3)) if parent < 0 else world[:, parent]
        children = _CHILDREN[j]
        if len(children) >= 2:
            world[:, j] = _kabsch(offsets[children], points[:, children] - points[:, j : j + 1])
        elif len(children) == 1:
            c = children[0]
            swing = quat_to_matrix(quat_between(above @ offsets[c], points[:, c] - points[:, j]))
            world[:, j] = swing @ above
        else:
            world[:, j] = above
        local[:, j] = np.swapaxes(above, -1, -2) @ world[:, j]
    return local, world


def forward_positions(root: np.ndarray, local: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Joint positions ``[T, 22, 3]`` from the root position ``[T, 3]``, local rotations and offsets."""
    T = root.shape[0]
    world = np.zeros((T, skeleton.NUM_JOINTS, 3, 3))
    out = np.zeros((T, skeleton.NUM_JOINTS, 3))
    for j in range(skeleton.NUM_JOINTS):
        parent = skeleton.PARENTS[j]
        if parent < 0:
            world[:, j], out[:, j] = local[:, j], root
        else:
            world[:, j] = world[:, parent] @ local[:, j]
            out[:, j] = out[:, parent] + world[:, parent] @ offsets[j]
    return out


def euler_zxy_degrees(matrices: np.ndarray) -> np.ndarray:
    """``[..., 3, 3]`` -> ``[..., 3]`` angles (z, x, y) in degrees with ``R = Rz @ Rx @ Ry``.

    ``x`` lies in [-90, 90]; at x = +-90 (gimbal lock) y is set to 0."""
    m = np.asarray(matrices, dtype=np.float64)
    sx = np.clip(m[..., 2, 1], -1.0, 1.0)
    x = np.arcsin(sx)
    locked = np.abs(sx) > 1.0 - 1e-9
    z = np.where(locked, np.arctan2(m[..., 1, 0], m[..., 0, 0]), np.arctan2(-m[..., 0, 1], m[..., 1, 1]))
    y = np.where(locked, 0.0, np.arctan2(-m[..., 2, 0], m[..., 2, 2]))
    return np.degrees(np.stack([z, x, y], axis=-1))


def _hierarchy(offsets_cm: np.ndarray, bone_positions: bool) -> list[str]:
    rest = skeleton.yup_from_zup(skeleton.REST_OFFSETS)
    lines = ["HIERARCHY"]

    def block(j: int, depth: int) -> None:
        pad = "  " * depth
        channels = ROOT_CHANNELS if j == 0 or bone_positions else JOINT_CHANNELS
        lines.append(f"{pad}{'ROOT' if j == 0 else 'JOINT'} {skeleton.JOINT_NAMES[j]}")
        lines.append(f"{pad}{{")
        lines.append(f"{pad}  OFFSET " + " ".join(f"{v:.6f}" for v in offsets_cm[j]))
        lines.append(f"{pad}  CHANNELS {len(channels)} " + " ".join(channels))
        for c in _CHILDREN[j]:
            block(c, depth + 1)
        if not _CHILDREN[j]:
            length = max(END_SITE_FRACTION * float(np.linalg.norm(offsets_cm[j])), END_SITE_MIN_CM)
            end = _normalise(rest[j]) * length
            lines.extend([f"{pad}  End Site", f"{pad}  {{", f"{pad}    OFFSET " + " ".join(f"{v:.6f}" for v in end),
                          f"{pad}  }}"])
        lines.append(f"{pad}}}")

    block(0, 0)
    return lines


def _depth_first() -> list[int]:
    order: list[int] = []

    def visit(j: int) -> None:
        order.append(j)
        for c in _CHILDREN[j]:
            visit(c)

    visit(0)
    return order


def write_bvh(joints: np.ndarray, fps: float, path: str | Path, *, bone_positions: bool = False,
              progress=None) -> BvhExport:
    """Write ``joints[T, 22, 3]`` (metres, z up, project frame) at ``fps`` as a BVH file.

    ``bone_positions``: position channels on every joint (exact positions, see the module
    docstring).  ``progress(done, total)`` (optional) is called as the frame rows are written."""
    path = Path(path)
    joints = np.asarray(joints, dtype=np.float64)
    points = skeleton.yup_from_zup(joints) * CM_PER_M  # BVH frame, centimetres
    T = len(points)
    if progress is not None:
        progress(0, T)  # solving comes first (about 0.1 ms a frame)
    offsets, bone_change = skeleton_offsets(points)
    local, world = solve_rotations(points, offsets)
    if bone_positions:  # each joint's place in its parent's frame, frame by frame
        parents = list(skeleton.PARENTS[1:])
        places = np.zeros_like(points)
        places[:, 0] = points[:, 0]
        places[:, 1:] = np.einsum("tkji,tkj->tki", world[:, parents], points[:, 1:] - points[:, parents])
        error_m = 0.0
    else:
        places = np.broadcast_to(offsets, points.shape).copy()
        places[:, 0] = points[:, 0]
        rebuilt = forward_positions(points[:, 0], local, offsets)
        error_m = float(np.linalg.norm(rebuilt - points, axis=-1).max()) / CM_PER_M
    angles = np.degrees(np.unwrap(np.radians(euler_zxy_degrees(local)), axis=0))  # continuous over time
    order = _depth_first()
    if bone_positions:
        rows = np.concatenate([places[:, order], angles[:, order]], axis=2).reshape(T, -1)
    else:
        rows = np.concatenate([points[:, 0], angles[:, order].reshape(T, -1)], axis=1)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", encoding="utf-8", newline="\n") as handle:
        handle.write("\n".join(_hierarchy(offsets, bone_positions)) + "\n")
        handle.write(f"MOTION\nFrames: {T}\nFrame Time: {1.0 / fps:.8f}\n")
        write_rows(handle, rows, " ", ".6f", progress)
    return BvhExport(path=path, frames=T, fps=float(fps), offsets_cm=offsets, max_position_error_m=error_m,
                     max_bone_length_change_m=bone_change / CM_PER_M, bone_positions=bone_positions)

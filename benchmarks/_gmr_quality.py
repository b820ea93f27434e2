"""Quality measures of a retargeted robot trajectory, the same code for every method (bench_gmr.py).

Pure functions of a MuJoCo model, a ``qpos[T, nq]`` sequence, its frame rate and (for the
keypoint error) the human joints at the same frames; no project or GMR imports, so
``tests/test_bench_gmr.py`` checks them on a tiny model without ../shared or GMR. The leading
underscore keeps ``bench_all.py`` from taking this helper for a benchmark.

Definitions (floor at world ``z = floor``, default 0; every geom test uses MuJoCo geometry):

* **robot geoms**: geoms of bodies other than the world body that collide (``contype`` or
  ``conaffinity`` non-zero) and are not planes; a model without any such geom uses all its
  non-world, non-plane geoms. A geom's **lowest point** is exact for spheres, capsules,
  cylinders, boxes and ellipsoids and the lowest vertex for meshes.
* **below floor**: frames where any robot geom's lowest point is more than ``below_tol``
  (1 cm) below the floor; also the lowest point over the clip.
* **foot contact and slip**: a foot is the robot geoms of the subtree of its foot body (ankle
  link, toe links under it). It is in contact in a frame when its lowest point is within
  ``contact_height`` (1 cm) of the floor (above or below). Slip is the horizontal distance the
  foot body's origin moves between two consecutive frames that are both in contact; summed
  over the clip for both feet (metres), its worst single frame (metres) and the summed slip
  divided by the seconds of contact (m/s).
* **joint limits**: frames where any limited hinge or slide joint is outside its range by more
  than ``limit_tol`` (0.001 rad / m), and the largest excess.
* **self-collision**: frames where ``mj_collision`` finds a contact between two robot geoms
  (not the floor, not a world geom) that penetrate deeper than ``penetration_tol`` (2 mm, the
  depth the project's validator tolerates). MuJoCo's own filters apply: ``contype`` /
  ``conaffinity``, ``<exclude>`` pairs and parent-child pairs. Pairs that already penetrate in
  the model's reference pose (``qpos0``, base lifted clear of the floor) are counted apart
  (``designed`` pairs, e.g. overlapping gear meshes) and do not make a frame count.
* **keypoint error**: for keypoints ``(human joint index, robot point)`` (a site, a body origin
  or a joint anchor), with the robot and human hip midpoints as origins:
  ``| (p_robot - hipmid_robot) - s * (p_human - hipmid_human) |`` in metres, averaged over
  keypoints and frames, where ``s`` = robot leg length (hip-knee + knee-ankle of the keypoint
  points at the reference pose) / human leg length (median over the clip): one factor for a
  clip and robot, whichever method produced the trajectory. World axes, no rotation alignment.
  With one factor the robot's own proportions (wider hips, shorter arms) leave a constant
  offset per keypoint whatever the method does; ``keypoint_error_centred_m`` removes it: the
  same error vectors expressed in the human's heading frame (from its hips), each keypoint's
  mean over the clip subtracted, then the mean length (how well the keypoints follow the
  human's motion).
* **stance** (when the human's foot contacts are given, ``stance[T, 2]``): the foot body's
  horizontal travel between consecutive frames in which the human foot is planted (summed,
  worst frame), and the median height of the robot foot's lowest point in those frames (a
  foot that hovers during stance shows here, not in the floor-based slip).
* **base turn**: the rotation angle of the free joint's quaternion between consecutive frames;
  the largest over the clip in degrees, and that divided by the frame time (deg/s).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

PLANE = 0  # mjtGeom.mjGEOM_PLANE
SPHERE, CAPSULE, ELLIPSOID, CYLINDER, BOX, MESH = 2, 3, 4, 5, 6, 7


# -- geometry -----------------------------------------------------------------------------------------
def robot_geoms(model) -> np.ndarray:
    """Ids of the robot's colliding geoms (see the module doc)."""
    ids = np.arange(model.ngeom)
    own = (model.geom_bodyid != 0) & (model.geom_type != PLANE)
    colliding = own & ((model.geom_contype != 0) | (model.geom_conaffinity != 0))
    return ids[colliding] if colliding.any() else ids[own]


def subtree_bodies(model, body: int) -> list[int]:
    """``body`` and every body below it."""
    out = [body]
    for b in range(body + 1, model.nbody):
        if int(model.body_parentid[b]) in out:
            out.append(b)
    return out


def subtree_geoms(model, body_name: str, geoms: np.ndarray | None = None) -> np.ndarray:
    """Robot geoms (or ``geoms``) of the subtree of ``body_name``."""
    import mujoco

    b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body_name)
    if b < 0:
        raise KeyError(f"no body {body_name!r} in the model")
    bodies = set(subtree_bodies(model, b))
    geoms = robot_geoms(model) if geoms is None else np.asarray(geoms)
    return np.array([g for g in geoms if int(model.geom_bodyid[g]) in bodies], dtype=int)


class LowestPoint:
    """Lowest world z of each of a set of geoms, from ``data.geom_xpos`` / ``geom_xmat``."""

    def __init__(self, model, geoms):
        self.geoms = np.asarray(geoms, dtype=int)
        self.types = model.geom_type[self.geoms].copy()
        self.size = model.geom_size[self.geoms].copy()
        self.verts = {}
        for k, g in enumerate(self.geoms):
            if self.types[k] == MESH:
                m = int(model.geom_dataid[g])
                a, n = int(model.mesh_vertadr[m]), int(model.mesh_vertnum[m])
                self.verts[k] = np.asarray(model.mesh_vert[a : a + n], dtype=np.float64)

    def __call__(self, data) -> np.ndarray:
        pos = data.geom_xpos[self.geoms]
        mat = data.geom_xmat[self.geoms].reshape(-1, 3, 3)
        z = np.empty(len(self.geoms))
        for k in range(len(self.geoms)):
            r = mat[k, 2]  # world z of the geom's local x, y, z axes
            s = self.size[k]
            t = self.types[k]
            if t == SPHERE:
                d = s[0]
            elif t == CAPSULE:
                d = s[0] + s[1] * abs(r[2])
            elif t == CYLINDER:
                d = s[1] * abs(r[2]) + s[0] * np.sqrt(max(0.0, 1.0 - r[2] ** 2))
            elif t == BOX:
                d = float(np.abs(r) @ s)
            elif t == ELLIPSOID:
                d = float(np.sqrt(((r * s) ** 2).sum()))
            elif t == MESH:
                z[k] = pos[k, 2] + float((self.verts[k] @ r).min())
                continue
            else:  # hfield, sdf, ...: bounding sphere
                d = float(np.max(s))
            z[k] = pos[k, 2] - d
        return z


# -- one trajectory -------------------------------------------------------------------------------------
@dataclass
class Keypoint:
    human: int  # index into the human joint array
    kind: str  # "site", "body" or "joint" (joint anchor)
    name: str


@dataclass
class MeasureSpec:
    """What to measure on a model: the two foot bodies and the keypoints (``Keypoint``)."""

    feet: dict  # {"left": body name, "right": body name}
    keypoints: list = field(default_factory=list)
    hips: tuple = ()  # (left, right) indices into keypoints: the robot origin; the human one too
    legs: tuple = ()  # ((hip, knee, ankle) keypoint indices per leg) for the scale factor
    floor: float = 0.0
    below_tol: float = 0.01
    contact_height: float = 0.01
    limit_tol: float = 1e-3
    penetration_tol: float = 0.002


def _point_ids(model, keypoints):
    import mujoco

    obj = {"site": mujoco.mjtObj.mjOBJ_SITE, "body": mujoco.mjtObj.mjOBJ_BODY, "joint": mujoco.mjtObj.mjOBJ_JOINT}
    out = []
    for kp in keypoints:
        i = mujoco.mj_name2id(model, obj[kp.kind], kp.name)
        if i < 0:
            raise KeyError(f"no {kp.kind} {kp.name!r} in the model")
        out.append(i)
    return out


def _points(data, keypoints, ids) -> np.ndarray:
    out = np.empty((len(ids), 3))
    for k, (kp, i) in enumerate(zip(keypoints, ids)):
        out[k] = data.site_xpos[i] if kp.kind == "site" else data.xpos[i] if kp.kind == "body" else data.xanchor[i]
    return out


def reference_qpos(model) -> np.ndarray:
    """``qpos0`` with a free base lifted so the robot is clear of the floor (for designed contacts)."""
    q = np.array(model.qpos0, dtype=np.float64)
    if model.njnt and model.jnt_type[0] == 0:
        q[2] = 10.0
    return q


def designed_pairs(model, geoms: np.ndarray, tol: float) -> set:
    """Robot geom pairs that penetrate deeper than ``tol`` in the reference pose."""
    import mujoco

    data = mujoco.MjData(model)
    data.qpos[:] = reference_qpos(model)
    mujoco.mj_kinematics(model, data)
    mujoco.mj_collision(model, data)
    own = set(int(g) for g in geoms)
    return {tuple(sorted((int(c.geom1), int(c.geom2)))) for c in data.contact[: data.ncon]
            if c.geom1 in own and c.geom2 in own and c.dist < -tol}


def leg_scale(model, spec: MeasureSpec, human: np.ndarray) -> float:
    """Robot leg length at the reference pose / median human leg length (see the module doc)."""
    import mujoco

    data = mujoco.MjData(model)
    data.qpos[:] = reference_qpos(model)
    mujoco.mj_kinematics(model, data)
    p = _points(data, spec.keypoints, _point_ids(model, spec.keypoints))
    robot = np.mean([np.linalg.norm(p[k] - p[h]) + np.linalg.norm(p[a] - p[k]) for h, k, a in spec.legs])
    hk = [spec.keypoints[i].human for leg in spec.legs for i in leg]
    hj = np.asarray(human)[:, hk].reshape(len(human), len(spec.legs), 3, 3)
    lengths = (np.linalg.norm(hj[:, :, 1] - hj[:, :, 0], axis=-1) + np.linalg.norm(hj[:, :, 2] - hj[:, :, 1], axis=-1)).mean(axis=1)
    return float(robot / np.median(lengths))


def quat_angles_deg(quats: np.ndarray) -> np.ndarray:
    """Rotation angle (degrees) between consecutive unit quaternions ``[T, 4]`` -> ``[T-1]``."""
    q = np.asarray(quats, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    dot = np.clip(np.abs(np.sum(q[1:] * q[:-1], axis=1)), 0.0, 1.0)
    return np.degrees(2.0 * np.arccos(dot))


def measure(model, qpos: np.ndarray, fps: float, spec: MeasureSpec, human: np.ndarray | None = None,
            scale: float | None = None, stance: np.ndarray | None = None) -> dict:
    """All measures of the module doc for ``qpos[T, nq]`` at ``fps``; ``human[T, J, 3]`` at the same
    frames for the keypoint error (``scale``: the factor ``s``, default :func:`leg_scale`);
    ``stance[T, 2]`` (left, right; the order of ``spec.feet``): the human's foot contacts, for the
    stance slip."""
    import mujoco

    qpos = np.asarray(qpos, dtype=np.float64)
    T = len(qpos)
    if qpos.ndim != 2 or qpos.shape[1] != model.nq:
        raise ValueError(f"qpos must be [T, {model.nq}], got {list(qpos.shape)}")
    data = mujoco.MjData(model)
    geoms = robot_geoms(model)
    lowest = LowestPoint(model, geoms)
    feet = {side: subtree_geoms(model, body, geoms) for side, body in spec.feet.items()}
    foot_cols = {side: np.searchsorted(geoms, g) for side, g in feet.items()}
    foot_body = {side: mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body) for side, body in spec.feet.items()}
    own = set(int(g) for g in geoms)
    designed = designed_pairs(model, geoms, spec.penetration_tol)
    limited = [j for j in range(model.njnt) if model.jnt_type[j] in (2, 3) and model.jnt_limited[j]]
    adr = np.array([model.jnt_qposadr[j] for j in limited], dtype=int)
    rng = np.array([model.jnt_range[j] for j in limited]).reshape(-1, 2)
    ids = _point_ids(model, spec.keypoints) if human is not None and spec.keypoints else []

    min_z = np.empty(T)
    foot_z = {side: np.empty(T) for side in feet}
    foot_xy = {side: np.empty((T, 2)) for side in feet}
    self_frames, pairs_seen, designed_seen = 0, set(), set()
    deepest = 0.0
    kp = np.empty((T, len(ids), 3)) if ids else None
    for t in range(T):
        data.qpos[:] = qpos[t]
        mujoco.mj_kinematics(model, data)
        z = lowest(data)
        min_z[t] = z.min()
        for side in feet:
            foot_z[side][t] = z[foot_cols[side]].min()
            foot_xy[side][t] = data.xpos[foot_body[side], :2]
        mujoco.mj_collision(model, data)
        hit = False
        for c in data.contact[: data.ncon]:
            g1, g2 = int(c.geom1), int(c.geom2)
            if g1 in own and g2 in own and c.dist < -spec.penetration_tol:
                pair = tuple(sorted((g1, g2)))
                if pair in designed:
                    designed_seen.add(pair)
                    continue
                hit = True
                pairs_seen.add(pair)
                deepest = max(deepest, -float(c.dist))
        self_frames += hit
        if ids:
            kp[t] = _points(data, spec.keypoints, ids)

    out: dict = {"frames": T, "fps": float(fps), "seconds": T / float(fps)}
    below = min_z < spec.floor - spec.below_tol
    out["below_floor_frames"] = int(below.sum())
    out["lowest_point_m"] = float(min_z.min()) - spec.floor
    # feet
    total, worst, contact_pairs, contact_frames = 0.0, 0.0, 0, 0
    for side in feet:
        c = np.abs(foot_z[side] - spec.floor) <= spec.contact_height
        contact_frames += int(c.sum())
        both = c[1:] & c[:-1]
        step = np.linalg.norm(np.diff(foot_xy[side], axis=0), axis=1)[both]
        contact_pairs += int(both.sum())
        if step.size:
            total += float(step.sum())
            worst = max(worst, float(step.max()))
    out["foot_contact_fraction"] = contact_frames / max(1, T * len(feet))
    out["foot_slip_total_m"] = total
    out["foot_slip_worst_frame_m"] = worst
    out["foot_slip_speed_m_s"] = total / (contact_pairs / float(fps)) if contact_pairs else 0.0
    # joints
    if len(adr):
        q = qpos[:, adr]
        excess = np.maximum(rng[:, 0] - q, q - rng[:, 1])
        out["joint_limit_frames"] = int((excess > spec.limit_tol).any(axis=1).sum())
        out["joint_limit_excess_max"] = float(max(0.0, excess.max()))
    else:
        out["joint_limit_frames"], out["joint_limit_excess_max"] = 0, 0.0
    out["self_collision_frames"] = self_frames
    out["self_collision_deepest_m"] = deepest
    out["self_collision_pairs"] = sorted(f"{_geom_name(model, a)}|{_geom_name(model, b)}" for a, b in pairs_seen)
    out["designed_pairs_ignored"] = len(designed)
    # base
    if model.njnt and model.jnt_type[0] == 0 and T > 1:
        turn = quat_angles_deg(qpos[:, 3:7])
        out["base_turn_max_deg"] = float(turn.max())
        out["base_turn_max_deg_s"] = float(turn.max() * fps)
        out["base_turn_max_at_frame"] = int(np.argmax(turn)) + 1
    else:
        out["base_turn_max_deg"], out["base_turn_max_deg_s"], out["base_turn_max_at_frame"] = 0.0, 0.0, 0
    # keypoints
    if ids:
        human = np.asarray(human, dtype=np.float64)
        if len(human) != T:
            raise ValueError(f"human has {len(human)} frames, qpos {T}")
        s = leg_scale(model, spec, human) if scale is None else float(scale)
        hl, hr = spec.hips
        r_origin = 0.5 * (kp[:, hl] + kp[:, hr])
        hidx = [k.human for k in spec.keypoints]
        h = human[:, hidx]
        h_origin = 0.5 * (h[:, hl] + h[:, hr])
        diff = (kp - r_origin[:, None]) - s * (h - h_origin[:, None])
        err = np.linalg.norm(diff, axis=-1)
        out["keypoint_error_mean_m"] = float(err.mean())
        out["keypoint_error_p95_frame_m"] = float(np.percentile(err.mean(axis=1), 95))
        # the same with each keypoint's mean offset in the human's heading frame removed
        across = h[:, hl] - h[:, hr]
        yaw = np.arctan2(across[:, 1], across[:, 0]) - np.pi / 2  # heading: left hip -> right hip turned -90 deg
        c, sn = np.cos(-yaw)[:, None], np.sin(-yaw)[:, None]
        local = np.stack([c * diff[..., 0] - sn * diff[..., 1], sn * diff[..., 0] + c * diff[..., 1], diff[..., 2]], axis=-1)
        out["keypoint_error_centred_m"] = float(np.linalg.norm(local - local.mean(axis=0), axis=-1).mean())
        out["keypoint_scale"] = s
    if stance is not None:
        stance = np.asarray(stance, dtype=bool)
        if stance.shape != (T, len(feet)):
            raise ValueError(f"stance must be [{T}, {len(feet)}], got {list(stance.shape)}")
        total, worst, heights = 0.0, 0.0, []
        for k, side in enumerate(feet):
            c = stance[:, k]
            both = c[1:] & c[:-1]
            step = np.linalg.norm(np.diff(foot_xy[side], axis=0), axis=1)[both]
            if step.size:
                total += float(step.sum())
                worst = max(worst, float(step.max()))
            heights.append(foot_z[side][c] - spec.floor)
        heights = np.concatenate(heights) if heights else np.zeros(0)
        out["stance_fraction"] = float(stance.mean())
        out["stance_slip_total_m"] = total
        out["stance_slip_worst_frame_m"] = worst
        out["stance_foot_height_median_m"] = float(np.median(heights)) if heights.size else None
    return out


def _geom_name(model, g: int) -> str:
    import mujoco

    return mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) or f"geom {g}"


# -- mapping ---------------------------------------------------------------------------------------------
def map_qpos(src_qpos: np.ndarray, src_joints: list[str], dst_model, rename: dict | None = None,
             flip: set | None = None, fill: np.ndarray | None = None) -> tuple[np.ndarray, list[str]]:
    """Copy a trajectory onto ``dst_model`` by joint name.

    ``src_qpos[T, 7 + n]``: free base then one value per joint of ``src_joints`` (hinge/slide);
    ``rename``: source -> destination name; ``flip``: destination joints whose sign is reversed.
    Destination joints without a source keep ``fill`` (default ``dst_model.qpos0``). Returns the
    ``[T, dst nq]`` trajectory and the destination joints left at ``fill``.
    """
    import mujoco

    src = np.asarray(src_qpos, dtype=np.float64)
    rename, flip = rename or {}, flip or set()
    base = np.array(dst_model.qpos0 if fill is None else fill, dtype=np.float64)
    out = np.tile(base, (len(src), 1))
    out[:, :7] = src[:, :7]
    placed = set()
    for k, name in enumerate(src_joints):
        dst = rename.get(name, name)
        j = mujoco.mj_name2id(dst_model, mujoco.mjtObj.mjOBJ_JOINT, dst)
        if j < 0:
            raise KeyError(f"joint {name!r} (as {dst!r}) is not in the destination model")
        out[:, dst_model.jnt_qposadr[j]] = -src[:, 7 + k] if dst in flip else src[:, 7 + k]
        placed.add(j)
    missing = [mujoco.mj_id2name(dst_model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(dst_model.njnt)
               if dst_model.jnt_type[j] != 0 and j not in placed]
    return out, missing

"""Symbolic forward kinematics in CasADi, built from a compiled ``mujoco.MjModel``.

The expressions follow MuJoCo's own ``mj_kinematics`` step by step, so that for the same
``qpos`` they give the same numbers (to rounding, ~1e-15):

* a body with a **free** joint takes its world position and orientation straight from
  ``qpos`` (position, unit quaternion w x y z, normalised);
* any other body starts from its parent frame composed with ``body_pos`` / ``body_quat``,
  then applies its joints in order: a **slide** joint moves the body along the joint axis
  (world-rotated) by ``qpos - qpos0``; a **hinge** joint rotates the body about the joint
  axis through the joint anchor ``jnt_pos`` by ``qpos - qpos0``;
* sites are fixed in their body: ``site_xpos = xpos + xmat @ site_pos``,
  ``site_xmat = xmat @ mat(site_quat)``.

Ball joints are not supported (:class:`UnsupportedJointError`); mocap bodies are treated as
fixed bodies at their model pose.

Orientations are carried as 3x3 rotation matrices (columns = body axes in world
coordinates), which keeps the expression graph small; :func:`quat_to_matrix` builds them
from MuJoCo's w, x, y, z quaternions.

Units: metres and radians (slide joints in metres).  All functions work on numeric
``numpy`` arrays as well as on ``casadi.SX`` / ``MX`` symbols.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from motok_robot.errors import InputError


class UnsupportedJointError(InputError):
    """The model has a joint type that the symbolic kinematics does not implement."""


def quat_to_matrix(q) -> ca.SX:
    """Rotation matrix ``[3, 3]`` from a quaternion ``q = (w, x, y, z)``, normalised first."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    n2 = w * w + x * x + y * y + z * z
    s = 2.0 / n2
    return ca.vertcat(
        ca.horzcat(1 - s * (y * y + z * z), s * (x * y - z * w), s * (x * z + y * w)),
        ca.horzcat(s * (x * y + z * w), 1 - s * (x * x + z * z), s * (y * z - x * w)),
        ca.horzcat(s * (x * z - y * w), s * (y * z + x * w), 1 - s * (x * x + y * y)),
    )


def quat_to_matrix_np(q: np.ndarray) -> np.ndarray:
    """Numeric version of :func:`quat_to_matrix` for a constant quaternion (w, x, y, z)."""
    out = np.zeros(9)
    import mujoco

    q = np.asarray(q, dtype=np.float64)
    mujoco.mju_quat2Mat(out, q / np.linalg.norm(q))
    return out.reshape(3, 3)


def axis_angle_matrix(axis: np.ndarray, angle) -> ca.SX:
    """Rotation by ``angle`` (rad) about the constant unit ``axis`` (3,), Rodrigues' formula.

    Zero components of the axis are folded in by CasADi, so coordinate axes give the
    usual 4-entry rotation matrices.
    """
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    c = ca.cos(angle)
    s = ca.sin(angle)
    t = 1 - c
    x, y, z = (float(v) for v in a)

    def term(v):
        # keep exact zeros out of the graph
        return 0.0 if v == 0.0 else v

    rows = [
        [c + term(x * x) * t, term(x * y) * t - term(z) * s, term(x * z) * t + term(y) * s],
        [term(x * y) * t + term(z) * s, c + term(y * y) * t, term(y * z) * t - term(x) * s],
        [term(x * z) * t - term(y) * s, term(y * z) * t + term(x) * s, c + term(z * z) * t],
    ]
    return ca.vertcat(*[ca.horzcat(*r) for r in rows])


def _const_mat(m: np.ndarray) -> ca.DM:
    return ca.DM(np.asarray(m, dtype=np.float64))


def _rot_const(R, m: np.ndarray):
    """``R @ m`` for a constant matrix ``m``; skips the product for the identity."""
    if np.array_equal(m, np.eye(3)):
        return R
    return ca.mtimes(R, _const_mat(m))


def _apply_const(R, v: np.ndarray):
    """``R @ v`` for a constant vector ``v``; zero vectors give exact zeros."""
    if not np.any(v):
        return ca.DM.zeros(3, 1)
    return ca.mtimes(R, _const_mat(np.asarray(v).reshape(3, 1)))


@dataclass(frozen=True)
class KinematicTree:
    """The parts of a compiled ``MjModel`` that forward kinematics needs (plain numpy copies).

    Arrays are indexed by MuJoCo body / joint / site id; positions in metres, quaternions
    w, x, y, z.
    """

    nq: int
    body_names: tuple[str, ...]
    site_names: tuple[str, ...]
    body_parent: np.ndarray  # [nbody] int
    body_pos: np.ndarray  # [nbody, 3]
    body_quat: np.ndarray  # [nbody, 4]
    body_joints: tuple[tuple[int, ...], ...]  # joint ids of each body, in order
    jnt_type: np.ndarray  # [njnt] int (mjtJoint)
    jnt_qposadr: np.ndarray  # [njnt] int
    jnt_axis: np.ndarray  # [njnt, 3]
    jnt_pos: np.ndarray  # [njnt, 3]
    jnt_names: tuple[str, ...]
    qpos0: np.ndarray  # [nq]
    site_body: np.ndarray  # [nsite] int
    site_pos: np.ndarray  # [nsite, 3]
    site_quat: np.ndarray  # [nsite, 4]
    body_mass: np.ndarray  # [nbody] kg
    body_ipos: np.ndarray  # [nbody, 3] centre of mass in the body frame

    @classmethod
    def from_model(cls, model) -> "KinematicTree":
        import mujoco

        def name(obj, i):
            return mujoco.mj_id2name(model, obj, i) or f"#{i}"

        body_joints = []
        for b in range(model.nbody):
            start, num = int(model.body_jntadr[b]), int(model.body_jntnum[b])
            body_joints.append(tuple(range(start, start + num)) if start >= 0 else ())
        for j in range(model.njnt):
            if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_BALL:
                raise UnsupportedJointError(
                    f"joint {name(mujoco.mjtObj.mjOBJ_JOINT, j)!r} is a ball joint; the CasADi kinematics "
                    "supports free, hinge and slide joints only"
                )
            if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE and body_joints[model.jnt_bodyid[j]] != (j,):
                raise UnsupportedJointError(
                    f"free joint {name(mujoco.mjtObj.mjOBJ_JOINT, j)!r} shares its body with other joints"
                )
        return cls(
            nq=int(model.nq),
            body_names=tuple(name(mujoco.mjtObj.mjOBJ_BODY, b) for b in range(model.nbody)),
            site_names=tuple(name(mujoco.mjtObj.mjOBJ_SITE, s) for s in range(model.nsite)),
            body_parent=np.array(model.body_parentid, dtype=int),
            body_pos=np.array(model.body_pos, dtype=np.float64),
            body_quat=np.array(model.body_quat, dtype=np.float64),
            body_joints=tuple(body_joints),
            jnt_type=np.array(model.jnt_type, dtype=int),
            jnt_qposadr=np.array(model.jnt_qposadr, dtype=int),
            jnt_axis=np.array(model.jnt_axis, dtype=np.float64),
            jnt_pos=np.array(model.jnt_pos, dtype=np.float64),
            jnt_names=tuple(name(mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(model.njnt)),
            qpos0=np.array(model.qpos0, dtype=np.float64),
            site_body=np.array(model.site_bodyid, dtype=int),
            site_pos=np.array(model.site_pos, dtype=np.float64),
            site_quat=np.array(model.site_quat, dtype=np.float64),
            body_mass=np.array(model.body_mass, dtype=np.float64),
            body_ipos=np.array(model.body_ipos, dtype=np.float64),
        )

    def site_id(self, name: str) -> int:
        try:
            return self.site_names.index(name)
        except ValueError:
            raise InputError(f"site {name!r} is not in the model (sites: {', '.join(self.site_names)})") from None

    def body_id(self, name: str) -> int:
        try:
            return self.body_names.index(name)
        except ValueError:
            raise InputError(f"body {name!r} is not in the model") from None


@dataclass
class Frames:
    """World frames of every body: ``pos[b]`` (3x1) and ``rot[b]`` (3x3), symbolic or numeric."""

    pos: list
    rot: list


def forward_kinematics(tree: KinematicTree, qpos, root_rotation=None) -> Frames:
    """World position and rotation of every body for ``qpos`` (length ``nq``).

    ``root_rotation``: optional 3x3 rotation to use for the free-joint body instead of the
    quaternion in ``qpos`` (the optimiser parametrises the base with Euler angles); the
    quaternion entries of ``qpos`` are then ignored.
    """
    import mujoco

    nb = len(tree.body_names)
    pos: list = [ca.DM.zeros(3, 1)] * nb
    rot: list = [ca.DM.eye(3)] * nb
    for b in range(1, nb):
        joints = tree.body_joints[b]
        if len(joints) == 1 and tree.jnt_type[joints[0]] == mujoco.mjtJoint.mjJNT_FREE:
            a = tree.jnt_qposadr[joints[0]]
            pos[b] = ca.vertcat(qpos[a], qpos[a + 1], qpos[a + 2])
            rot[b] = root_rotation if root_rotation is not None else quat_to_matrix(qpos[a + 3 : a + 7])
            continue
        p = tree.body_parent[b]
        xpos = pos[p] + _apply_const(rot[p], tree.body_pos[b])
        xrot = _rot_const(rot[p], quat_to_matrix_np(tree.body_quat[b]))
        for j in joints:
            a = tree.jnt_qposadr[j]
            angle = qpos[a] - tree.qpos0[a] if tree.qpos0[a] != 0.0 else qpos[a]
            if tree.jnt_type[j] == mujoco.mjtJoint.mjJNT_SLIDE:
                axis = tree.jnt_axis[j] / np.linalg.norm(tree.jnt_axis[j])
                xpos = xpos + _apply_const(xrot, axis) * angle
            elif tree.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE:
                anchor = xpos + _apply_const(xrot, tree.jnt_pos[j])
                xrot = ca.mtimes(xrot, axis_angle_matrix(tree.jnt_axis[j], angle))
                xpos = anchor - _apply_const(xrot, tree.jnt_pos[j])
            else:  # pragma: no cover - rejected in from_model
                raise UnsupportedJointError(f"joint {tree.jnt_names[j]!r}: unsupported type {tree.jnt_type[j]}")
        pos[b] = xpos
        rot[b] = xrot
    return Frames(pos=pos, rot=rot)


def site_position(tree: KinematicTree, frames: Frames, site: int):
    """World position (3x1) of site id ``site``."""
    b = tree.site_body[site]
    return frames.pos[b] + _apply_const(frames.rot[b], tree.site_pos[site])


def site_rotation(tree: KinematicTree, frames: Frames, site: int):
    """World rotation matrix (3x3) of site id ``site`` (columns = site axes)."""
    b = tree.site_body[site]
    return _rot_const(frames.rot[b], quat_to_matrix_np(tree.site_quat[site]))


def center_of_mass(tree: KinematicTree, frames: Frames, root_body: int = 1):
    """Mass-weighted centre of mass (3x1, world) of the subtree rooted at ``root_body``."""
    total = 0.0
    acc = ca.DM.zeros(3, 1)
    for b in range(1, len(tree.body_names)):
        a = b
        while a > 0 and a != root_body:
            a = tree.body_parent[a]
        if a != root_body or tree.body_mass[b] <= 0:
            continue
        acc = acc + tree.body_mass[b] * (frames.pos[b] + _apply_const(frames.rot[b], tree.body_ipos[b]))
        total += tree.body_mass[b]
    return acc / total


def kinematics_function(model, sites: list[str] | None = None, bodies: list[str] | None = None) -> ca.Function:
    """A ``casadi.Function`` ``qpos[nq] -> (site_pos[3, ns], site_rot[3, 3*ns], body_pos[3, nb], body_rot[3, 3*nb], com[3])``.

    ``sites`` / ``bodies`` default to all sites / all bodies except the world.  ``site_rot``
    holds the 3x3 rotation matrices side by side (``[:, 3*i:3*i+3]`` for the i-th site);
    ``com`` is the centre of mass of the subtree of body 1.  Built with ``SX`` symbols.
    """
    tree = KinematicTree.from_model(model)
    site_ids = [tree.site_id(s) for s in sites] if sites is not None else list(range(len(tree.site_names)))
    body_ids = [tree.body_id(b) for b in bodies] if bodies is not None else list(range(1, len(tree.body_names)))
    q = ca.SX.sym("qpos", tree.nq)
    frames = forward_kinematics(tree, q)
    sp = [site_position(tree, frames, s) for s in site_ids]
    sr = [site_rotation(tree, frames, s) for s in site_ids]
    bp = [frames.pos[b] for b in body_ids]
    br = [frames.rot[b] for b in body_ids]
    com = center_of_mass(tree, frames) if len(tree.body_names) > 1 else ca.DM.zeros(3, 1)

    def cat(xs, rows):
        return ca.horzcat(*xs) if xs else ca.SX.zeros(rows, 0)

    return ca.Function(
        "forward_kinematics",
        [q],
        [cat(sp, 3), cat(sr, 3), cat(bp, 3), cat(br, 3), com],
        ["qpos"],
        ["site_pos", "site_rot", "body_pos", "body_rot", "com"],
    )

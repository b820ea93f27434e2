"""Kinematic replay of a trajectory: per-frame measurements, no physics stepping.

:func:`replay` sets ``qpos`` frame by frame on a constraint-free copy of the model
(``mj_inverse`` runs the position and velocity stages itself) and measures:

* feet: lowest sole-corner height, contact (height < ``contact_height_m``), sole-centre
  horizontal speed, skating (speed > ``skate_speed_mps`` while in contact);
* ground: penetration of the lowest sole corner, floating of the robot's lowest sole point;
* self-collision between non-adjacent bodies (``motok_robot.robots.index.body_pairs_in_collision``);
* joints: position, velocity, acceleration (finite differences) against limits;
* required joint torques from inverse dynamics with the ground reaction distributed over
  the sole corners in contact (:mod:`motok_robot.feasibility.dynamics`);
* balance: centre of mass, support polygon (convex hull of the corners in contact), signed
  CoM margin, ZMP and its margin;
* continuity: the angle of the base rotation between consecutive frames (a flipped solution).

Every array in :class:`KinematicResult` has the frame as its first axis (T frames at
``fps``); foot arrays are ordered (left, right).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

from motok_robot.sim.config import ValidationConfig
from motok_robot.feasibility.dynamics import (ContactDistributor, finite_difference, moving_average, qvel_qacc,
                                      zmp_from_centroidal)
from motok_robot.feasibility.geometry import convex_hull, signed_distance
from motok_robot.robots.index import RobotIndex, body_pairs_in_collision


@dataclass
class KinematicResult:
    """Per-frame measurements of a kinematic replay (T frames; feet ordered left, right)."""

    fps: float
    time: np.ndarray              # [T] s
    sole_height: np.ndarray       # [T, 2] m, lowest sole corner above the floor
    sole_pos: np.ndarray          # [T, 2, 3] m, sole-centre site position
    corners: np.ndarray           # [T, 2, 4, 3] m, sole corner positions
    sole_speed: np.ndarray        # [T, 2] m/s, horizontal sole-centre speed
    contact: np.ndarray           # bool [T, 2]
    skating: np.ndarray           # bool [T, 2]
    skate_distance: np.ndarray    # [2] m, horizontal travel while in contact
    com: np.ndarray               # [T, 3] m, whole-robot centre of mass
    com_speed: np.ndarray         # [T] m/s, horizontal
    support: list                 # T hulls, each [H, 2] m (empty where no foot is in contact)
    balance_margin: np.ndarray    # [T] m, signed CoM margin (+ inside), NaN without contact
    quasi_static: np.ndarray      # bool [T] CoM slower than static_com_speed_mps
    zmp: np.ndarray               # [T, 2] m (NaN in free fall)
    zmp_margin: np.ndarray        # [T] m, signed ZMP margin, NaN without contact or ZMP
    joint_pos: np.ndarray         # [T, nj] rad
    joint_vel: np.ndarray         # [T, nj] rad/s
    joint_acc: np.ndarray         # [T, nj] rad/s^2
    torque: np.ndarray            # [T, nj] N m, required actuator torques
    contact_force: np.ndarray     # [T, 2, 3] N, ground reaction per foot (sum over corners)
    unsupported_force: np.ndarray  # [T] N, norm of the base force the feet cannot supply
    self_collisions: list = field(default_factory=list)  # [(frame, body1, body2, depth m)]
    base_rotation_step: np.ndarray = field(default_factory=lambda: np.zeros(0))  # [T-1] deg, base turn frame to frame

    @property
    def num_frames(self) -> int:
        return int(self.time.shape[0])


def replay(index: RobotIndex, qpos: np.ndarray, fps: float, config: ValidationConfig) -> KinematicResult:
    """Measure ``qpos`` [T, nq] (frames at ``fps``) on ``index``'s robot."""
    m = index.kin_model
    d = mujoco.MjData(m)
    dc = mujoco.MjData(index.collision_model)
    T = qpos.shape[0]
    qvel, qacc = qvel_qacc(m, qpos, fps)
    distributor = ContactDistributor(m, index.base_dof, config.friction_coefficient)

    corners = np.zeros((T, 2, 4, 3))
    sole_pos = np.zeros((T, 2, 3))
    com = np.zeros((T, 3))
    angmom = np.zeros((T, 3))
    torque = np.zeros((T, index.nj))
    contact_force = np.zeros((T, 2, 3))
    unsupported = np.zeros(T)
    collisions = []
    body_names = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b) or f"body{b}" for b in range(m.nbody)]
    corner_bodies = index.sole_body[:, None].repeat(4, axis=1)

    # one pass: positions, contacts, inverse dynamics, self-collisions
    for t in range(T):
        d.qpos[:] = qpos[t]
        d.qvel[:] = qvel[t]
        d.qacc[:] = qacc[t]
        mujoco.mj_inverse(m, d)
        corners[t] = d.site_xpos[index.corner_sites]
        sole_pos[t] = d.site_xpos[index.sole_site]
        com[t] = d.subtree_com[index.root_body]
        mujoco.mj_subtreeVel(m, d)
        angmom[t] = d.subtree_angmom[index.root_body]
        sole_height_t = corners[t, :, :, 2].min(axis=1)
        in_contact = sole_height_t < config.contact_height_m
        points = corners[t][in_contact].reshape(-1, 3)
        bodies = corner_bodies[in_contact].reshape(-1)
        qfrc_contact, forces, residual = distributor.solve(d, d.qfrc_inverse, points, bodies)
        torque[t] = (d.qfrc_inverse - qfrc_contact)[index.dof_adr]
        unsupported[t] = float(np.linalg.norm(residual[:3]))
        k = 0
        for side in range(2):
            if in_contact[side]:
                contact_force[t, side] = forces[k:k + 4].sum(0)
                k += 4
        dc.qpos[:] = qpos[t]
        for b1, b2, depth in body_pairs_in_collision(index, dc, config.self_collision_depth_m):
            collisions.append((t, body_names[b1], body_names[b2], depth))

    sole_height = corners[:, :, :, 2].min(axis=2)
    contact = sole_height < config.contact_height_m
    sole_speed = np.linalg.norm(finite_difference(sole_pos[:, :, :2], fps), axis=2)
    skating, skate_distance = contact_skating(sole_pos[:, :, :2], contact, fps, config.skate_speed_mps)

    com_vel = finite_difference(com, fps)
    com_speed = np.linalg.norm(com_vel[:, :2], axis=1)
    support, margin, zmp_margin = [], np.full(T, np.nan), np.full(T, np.nan)
    smooth_com = moving_average(com, config.zmp_smoothing_frames)
    com_acc = finite_difference(finite_difference(smooth_com, fps), fps)
    rate = None
    if config.zmp_model == "multibody":
        rate = finite_difference(moving_average(angmom, config.zmp_smoothing_frames), fps)
    zmp = zmp_from_centroidal(com, com_acc, rate, index.total_mass)
    for t in range(T):
        pts = corners[t][contact[t]].reshape(-1, 3)[:, :2]
        hull = convex_hull(pts) if len(pts) else np.zeros((0, 2))
        support.append(hull)
        if len(hull):
            margin[t] = signed_distance(com[t, :2], hull)
            if np.all(np.isfinite(zmp[t])):
                zmp_margin[t] = signed_distance(zmp[t], hull)

    joint_pos = qpos[:, index.qpos_adr]
    joint_vel = qvel[:, index.dof_adr]
    joint_acc = qacc[:, index.dof_adr]
    return KinematicResult(
        fps=fps, time=np.arange(T) / fps, sole_height=sole_height, sole_pos=sole_pos, corners=corners,
        sole_speed=sole_speed, contact=contact, skating=skating, skate_distance=skate_distance, com=com,
        com_speed=com_speed, support=support, balance_margin=margin,
        quasi_static=com_speed < config.static_com_speed_mps, zmp=zmp, zmp_margin=zmp_margin,
        joint_pos=joint_pos, joint_vel=joint_vel, joint_acc=joint_acc, torque=torque,
        contact_force=contact_force, unsupported_force=unsupported, self_collisions=collisions,
        base_rotation_step=base_rotation_steps(qpos[:, 3:7]))


def base_rotation_steps(quat: np.ndarray) -> np.ndarray:
    """Angle (degrees) of the rotation between consecutive base quaternions ``quat[T, 4]`` (w x y z)."""
    q = np.asarray(quat, dtype=np.float64)
    if len(q) < 2:
        return np.zeros(0)
    q = q / np.maximum(np.linalg.norm(q, axis=1, keepdims=True), 1e-12)
    dot = np.abs(np.sum(q[1:] * q[:-1], axis=1))  # q and -q are the same rotation
    return np.degrees(2.0 * np.arccos(np.clip(dot, 0.0, 1.0)))


def contact_skating(sole_xy: np.ndarray, contact: np.ndarray, fps: float, speed_threshold: float) -> tuple[np.ndarray, np.ndarray]:
    """Skating frames and distance of the soles while in contact.

    Args:
        sole_xy: ``[T, 2, 2]`` horizontal sole positions (m) of the left and right foot.
        contact: ``[T, 2]`` bool, sole in contact with the ground.
        fps: frames per second.
        speed_threshold: m/s above which a foot in contact skates.

    Returns:
        ``(skating [T, 2] bool, distance [2] m)``. Speeds come only from steps whose two frames
        are both in contact: a central difference at the first or last frame of a contact phase
        would include the swing frame next to it and flag a planted foot.
    """
    step = np.linalg.norm(np.diff(sole_xy, axis=0), axis=-1)  # [T-1, 2] m
    both = contact[1:] & contact[:-1]
    distance = (step * both).sum(axis=0)
    step_speed = np.where(both, step * fps, 0.0)
    speed = np.zeros(contact.shape)
    speed[1:] = step_speed
    speed[:-1] = np.maximum(speed[:-1], step_speed)
    return contact & (speed > speed_threshold), distance

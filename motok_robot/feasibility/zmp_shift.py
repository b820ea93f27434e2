"""A centre-of-mass path whose ZMP stays on the feet, applied by moving the base over planted feet.

A human walk retargeted kinematically keeps the human's sway, which does not put a small
robot's centre of mass over its stance foot: on op3_like the cart-table ZMP of a retargeted
Bandai walk lies outside the support polygon in 64-67 % of frames, also played slower.  This
module replaces the horizontal CoM path by the closest one whose cart-table ZMP
(``p = c - (c_z / g) c''``, the linear inverted pendulum the ROBOTIS OP3 walk's preview control
uses) stays inside the support polygon of the planned contacts shrunk by ``margin_m``:

1. the reference ZMP of each frame is moved to the nearest point of its shrunk support polygon
   (frames without contact keep it);
2. per horizontal axis, the CoM path ``x`` minimises
   ``sum (x_t - (h_t/g) xdd_t - p_t)^2 + reg sum (x_t - c_t)^2`` (a banded least-squares
   problem; the end frames are held at the reference);
3. the base is moved by the CoM change and each leg is re-solved (damped least squares on the
   leg's joints) to keep its sole where the reference has it; two passes absorb the legs' own
   mass moving with the base.

The motion keeps its footsteps, its timing and its upper body; only the pelvis sways more.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from scipy import sparse
from scipy.sparse.linalg import spsolve

from motok_robot.feasibility.geometry import convex_hull, heading, nearest_point, signed_distance

GRAVITY = 9.81


@dataclass
class ZmpShiftResult:
    qpos: np.ndarray          # [T, nq] the shifted trajectory
    com_shift: np.ndarray     # [T, 2] m, horizontal CoM change
    zmp_outside_before: float  # fraction of support frames with the cart-table ZMP outside (> tolerance)
    zmp_outside_after: float
    foot_error_m: float       # largest sole position error of the leg re-solve (m)

    def record(self) -> dict:
        shift = np.linalg.norm(self.com_shift, axis=1)
        return {"method": "cart-table ZMP CoM path", "com_shift_m_mean": float(shift.mean()),
                "com_shift_m_max": float(shift.max()), "zmp_outside_before": self.zmp_outside_before,
                "zmp_outside_after": self.zmp_outside_after, "foot_error_m": self.foot_error_m}


def _shrink(hull: np.ndarray, margin: float) -> np.ndarray:
    """The hull pulled toward its centroid by ``margin`` (m), never past the centroid."""
    centre = hull.mean(axis=0)
    d = hull - centre
    r = np.linalg.norm(d, axis=1, keepdims=True)
    return centre + d * np.clip((r - margin) / np.maximum(r, 1e-9), 0.0, 1.0)


def _kinematics(index, qpos: np.ndarray):
    """CoM [T, 3], sole corners [T, 2, 4, 3], sole body poses (pos [T, 2, 3], quat [T, 2, 4])."""
    model = index.kin_model
    data = mujoco.MjData(model)
    T = qpos.shape[0]
    com = np.zeros((T, 3))
    corners = np.zeros((T, 2, 4, 3))
    foot_pos = np.zeros((T, 2, 3))
    foot_quat = np.zeros((T, 2, 4))
    for t in range(T):
        data.qpos[:] = qpos[t]
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        com[t] = data.subtree_com[index.root_body]
        corners[t] = data.site_xpos[index.corner_sites]
        foot_pos[t] = data.xpos[index.sole_body]
        foot_quat[t] = data.xquat[index.sole_body]
    return com, corners, foot_pos, foot_quat


def cart_table_zmp(com: np.ndarray, fps: float, ground: float = 0.0) -> np.ndarray:
    """ZMP [T, 2] of the cart-table model for the CoM path ``com`` [T, 3]."""
    acc = np.zeros_like(com[:, :2])
    if com.shape[0] > 2:
        acc[1:-1] = (com[2:, :2] - 2 * com[1:-1, :2] + com[:-2, :2]) * fps * fps
        acc[0], acc[-1] = acc[1], acc[-2]
    return com[:, :2] - ((com[:, 2] - ground) / GRAVITY)[:, None] * acc


def _support(corners: np.ndarray, contacts: np.ndarray) -> list:
    return [convex_hull(corners[t][contacts[t]].reshape(-1, 3)[:, :2]) if contacts[t].any() else np.zeros((0, 2))
            for t in range(corners.shape[0])]


def _outside_fraction(zmp, hulls, tolerance) -> float:
    margins = [signed_distance(p, h) for p, h in zip(zmp, hulls) if len(h) >= 3]
    return float(np.mean(np.asarray(margins) < -tolerance)) if margins else 0.0


def _com_path(com: np.ndarray, target_zmp: np.ndarray, fps: float, regularisation: float) -> np.ndarray:
    """Least-squares horizontal CoM path [T, 2] (see the module docstring, step 2)."""
    T = com.shape[0]
    if T < 3:
        return com[:, :2].copy()
    k = com[:, 2] / GRAVITY * fps * fps
    rows = np.arange(1, T - 1)
    # x_t - k_t (x_{t+1} - 2 x_t + x_{t-1}) for interior frames
    A = sparse.diags([np.r_[0.0, -k[1:-1], 0.0][1:], np.r_[1.0, 1 + 2 * k[1:-1], 1.0], np.r_[0.0, -k[1:-1], 0.0][:-1]],
                     [-1, 0, 1], shape=(T, T), format="csr")
    A = A[rows]
    R = sparse.identity(T, format="csr") * np.sqrt(regularisation)
    # the first and last frames held at the reference (weight 1e3)
    E = sparse.csr_matrix((np.full(2, 1e3), ([0, 1], [0, T - 1])), shape=(2, T))
    M = sparse.vstack([A, R, E]).tocsr()
    out = np.zeros((T, 2))
    for axis in range(2):
        b = np.r_[target_zmp[rows, axis], np.sqrt(regularisation) * com[:, axis],
                  1e3 * com[0, axis], 1e3 * com[-1, axis]]
        out[:, axis] = spsolve((M.T @ M).tocsc(), M.T @ b)
    return out


def leg_dofs(index) -> list:
    """Per leg: (qpos addresses, dof addresses) of the hinges from the sole body up to the base."""
    model = index.kin_model
    legs = []
    for body in index.sole_body:
        qadr, dadr = [], []
        b = int(body)
        while b > 0 and b != index.root_body:
            for jid in range(model.body_jntadr[b], model.body_jntadr[b] + model.body_jntnum[b]):
                if model.jnt_type[jid] == mujoco.mjtJoint.mjJNT_HINGE:
                    qadr.append(int(model.jnt_qposadr[jid]))
                    dadr.append(int(model.jnt_dofadr[jid]))
            b = int(model.body_parentid[b])
        legs.append((np.array(qadr), np.array(dadr)))
    return legs


def solve_legs(index, qpos_t: np.ndarray, foot_pos: np.ndarray, foot_quat: np.ndarray, legs, data,
                iterations: int = 20, damping: float = 1e-4, previous: np.ndarray | None = None,
                max_step: np.ndarray | None = None) -> float:
    """Re-solve the legs in place so each sole body reaches its pose; returns the position error (m).

    With ``previous`` (qpos [nq] of the frame before) and ``max_step`` ([nq] rad per frame, for
    the leg joints), each joint stays within ``max_step`` of its previous value: a velocity limit.
    A joint that reaches its bound (velocity or range) is held there and the step is solved again
    for the others (an active set), so the leg's remaining joints keep the foot's pose as well as
    they can: clipping each joint of a free step on its own would break the coordination, e.g.
    hip, knee and ankle pitch each at their speed limit tip the sole by the ankle's whole step."""
    model = index.kin_model
    jacp = np.zeros((3, model.nv))
    jacr = np.zeros((3, model.nv))
    err = np.zeros(6)
    q_err = np.zeros(3)
    worst = 0.0
    lower = np.full(model.nq, -np.inf)
    upper = np.full(model.nq, np.inf)
    for j in range(model.njnt):
        if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE and model.jnt_limited[j]:
            lower[model.jnt_qposadr[j]], upper[model.jnt_qposadr[j]] = model.jnt_range[j]
    for side, (qadr, dadr) in enumerate(legs):
        body = int(index.sole_body[side])
        lo, hi = lower[qadr], upper[qadr]
        if previous is not None:
            lo = np.maximum(lo, previous[qadr] - max_step[qadr])
            hi = np.minimum(hi, previous[qadr] + max_step[qadr])
            hi = np.maximum(hi, lo)  # a previous frame outside the range: the range wins
        qpos_t[qadr] = np.clip(qpos_t[qadr], lo, hi)
        for _ in range(iterations):
            data.qpos[:] = qpos_t
            mujoco.mj_kinematics(model, data)
            err[:3] = foot_pos[side] - data.xpos[body]
            mujoco.mju_subQuat(q_err, foot_quat[side], data.xquat[body])
            # mju_subQuat gives the body-frame rotation; the Jacobian is world-frame
            err[3:] = data.xmat[body].reshape(3, 3) @ q_err
            if np.linalg.norm(err[:3]) < 1e-5 and np.linalg.norm(err[3:]) < 1e-4:
                break
            mujoco.mj_comPos(model, data)
            mujoco.mj_jacBody(model, data, jacp, jacr, body)
            J = np.vstack([jacp[:, dadr], jacr[:, dadr]])
            q = qpos_t[qadr]
            free = np.ones(len(qadr), dtype=bool)
            target = q.copy()
            for _ in range(len(qadr)):
                Jf = J[:, free]
                step = np.zeros(len(qadr))
                held = J[:, ~free] @ (target - q)[~free]  # what the held joints already move
                step[free] = Jf.T @ np.linalg.solve(Jf @ Jf.T + damping * np.eye(6), err - held)
                step[free] = np.clip(step[free], -0.05, 0.05)  # small steps: stay on the reference's IK branch
                target[free] = q[free] + step[free]
                out = free & ((target < lo) | (target > hi))
                if not out.any():
                    break
                target[out] = np.clip(target[out], lo[out], hi[out])  # held at the bound it reached
                free &= ~out
            qpos_t[qadr] = np.clip(target, lo, hi)
        data.qpos[:] = qpos_t
        mujoco.mj_kinematics(model, data)
        worst = max(worst, float(np.linalg.norm(foot_pos[side] - data.xpos[body])))
    return worst


def shift_com(index, qpos: np.ndarray, fps: float, contacts: np.ndarray, margin_m: float = 0.01,
              regularisation: float = 1e-3, tolerance_m: float = 0.005, passes: int = 2,
              axes: str = "lateral") -> ZmpShiftResult:
    """The trajectory ``qpos`` [T, nq] with its CoM moved so the cart-table ZMP stays on the
    planned contacts ``contacts`` [T, 2] (see the module docstring)."""
    qpos = np.asarray(qpos, dtype=np.float64).copy()
    contacts = np.asarray(contacts, dtype=bool)
    com, corners, foot_pos, foot_quat = _kinematics(index, qpos)
    hulls = _support(corners, contacts)
    zmp = cart_table_zmp(com, fps)
    before = _outside_fraction(zmp, hulls, tolerance_m)
    target = np.array([nearest_point(p, _shrink(h, margin_m)) if len(h) >= 3 else p for p, h in zip(zmp, hulls)])
    path = _com_path(com, target, fps, regularisation)
    if axes == "lateral":  # only across the walking direction (the heading of each frame)
        yaw = heading(qpos)
        side = np.stack([-np.sin(yaw), np.cos(yaw)], axis=1)
        change = ((path - com[:, :2]) * side).sum(axis=1, keepdims=True)
        path = com[:, :2] + change * side
    legs = leg_dofs(index)
    data = mujoco.MjData(index.kin_model)
    worst = 0.0
    current = com
    reference = qpos.copy()
    leg_q = np.concatenate([q for q, _ in legs])
    for k in range(passes):
        delta = path - current[:, :2]
        correction = np.zeros(leg_q.size)  # warm start: the previous frame's change of the leg joints
        worst = 0.0
        for t in range(qpos.shape[0]):
            qpos[t, :2] += delta[t]
            if k == 0:
                qpos[t, leg_q] = reference[t, leg_q] + correction
            worst = max(worst, solve_legs(index, qpos[t], foot_pos[t], foot_quat[t], legs, data))
            correction = qpos[t, leg_q] - reference[t, leg_q]
        current = _kinematics(index, qpos)[0]
    after = _outside_fraction(cart_table_zmp(current, fps), hulls, tolerance_m)
    return ZmpShiftResult(qpos=qpos, com_shift=current[:, :2] - com[:, :2], zmp_outside_before=before,
                          zmp_outside_after=after, foot_error_m=worst)

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


def _half_planes(hull: np.ndarray, margin: float) -> tuple[np.ndarray, np.ndarray]:
    """Inward unit normals [H, 2] and offsets [H] of a CCW polygon shrunk by ``margin``:
    ``normals @ p >= offsets`` holds for the points at least ``margin`` inside it."""
    edges = np.roll(hull, -1, axis=0) - hull
    lengths = np.maximum(np.linalg.norm(edges, axis=1, keepdims=True), 1e-12)
    normals = np.stack([-edges[:, 1], edges[:, 0]], axis=1) / lengths
    return normals, (normals * hull).sum(axis=1) + margin


def _com_path(com: np.ndarray, hulls: list, fps: float, margin: float, basis: np.ndarray,
              smoothness: float, slack_weight: float) -> np.ndarray:
    """Horizontal CoM path [T, 2] closest to the reference ``com`` whose cart-table ZMP lies in
    each frame's support polygon shrunk by ``margin`` (see the module docstring, step 2).

    The change of frame ``t`` is ``basis[t] @ u_t`` (``basis`` [T, 2, r]: r = 1 moves the CoM
    across the heading only, r = 2 in both directions).  A quadratic programme (OSQP through
    CasADi): minimise ``sum |u_t|^2 + smoothness sum |second difference of the change|^2 +
    slack_weight sum s_t^2`` subject to ``n . p_t >= offset - s_t`` for every edge of the
    polygon of every interior support frame, ``s_t >= 0``, no change at the first and last frame.
    The slack ``s_t`` (m) is how far frame ``t``'s ZMP stays outside where no path can do better.
    """
    import casadi as ca

    T, r = com.shape[0], basis.shape[2]
    if T < 3:
        return com[:, :2].copy()
    k = com[:, 2] / GRAVITY * fps * fps
    n_u = T * r
    n = n_u + T  # u, then one slack per frame
    # the change of the CoM: x = X @ u  (X: [2T, n_u], rows 2t, 2t+1)
    rows = np.repeat(np.arange(2 * T), r)
    cols = (np.arange(T)[:, None, None] * r + np.arange(r)[None, None, :]).repeat(2, axis=1).reshape(-1)
    X = sparse.csr_matrix((basis.reshape(-1), (rows, cols)), shape=(2 * T, n_u))
    # second difference of the change, and the ZMP change p = x - k (second difference)
    D = sparse.diags([np.ones(T - 2), -2 * np.ones(T - 2), np.ones(T - 2)], [0, 1, 2], shape=(T - 2, T))
    D2 = sparse.kron(D, sparse.identity(2)).tocsr()  # acts on the interleaved (x, y) vector
    K = sparse.kron(sparse.diags(k[1:-1]), sparse.identity(2))
    Sel = sparse.kron(sparse.eye(T - 2, T, k=1), sparse.identity(2))
    P = ((Sel - K @ D2) @ X).tocsr()  # [2(T-2), n_u]: ZMP change of the interior frames
    acc = D2 @ X
    H = sparse.block_diag([sparse.identity(n_u) + smoothness * (acc.T @ acc),
                           slack_weight * sparse.identity(T)]).tocsc()
    zmp_ref = cart_table_zmp(com, fps)
    A_rows, lower = [], []
    for t in range(1, T - 1):
        hull = hulls[t]
        if len(hull) < 3:
            continue
        normals, offsets = _half_planes(hull, margin)
        block = sparse.csr_matrix(normals) @ P[2 * (t - 1):2 * t]
        slack = sparse.csr_matrix((np.ones(len(normals)), (np.arange(len(normals)), np.full(len(normals), n_u + t))),
                                  shape=(len(normals), n))
        A_rows.append(sparse.hstack([block, sparse.csr_matrix((len(normals), T))]) + slack)
        lower.append(offsets - normals @ zmp_ref[t])
    if not A_rows:
        return com[:, :2].copy()
    A = sparse.vstack(A_rows).tocsc()
    lba = np.concatenate(lower)
    lbx = np.r_[np.full(n_u, -np.inf), np.zeros(T)]
    ubx = np.full(n, np.inf)
    lbx[:r], ubx[:r] = 0.0, 0.0  # the first and last frames keep the reference CoM
    lbx[n_u - r:n_u], ubx[n_u - r:n_u] = 0.0, 0.0

    def dm(m):
        m = m.tocsc()
        return ca.DM(ca.Sparsity(m.shape[0], m.shape[1], m.indptr.tolist(), m.indices.tolist()), m.data.tolist())

    Hd, Ad = dm(H), dm(A)
    solver = ca.conic("com_path", "osqp", {"h": Hd.sparsity(), "a": Ad.sparsity()},
                      {"osqp": {"verbose": False, "eps_abs": 1e-7, "eps_rel": 1e-7, "max_iter": 20000,
                                "polish": True}, "error_on_fail": False})
    sol = solver(h=Hd, g=np.zeros(n), a=Ad, lba=lba, uba=np.full(len(lba), np.inf), lbx=lbx, ubx=ubx)
    u = np.asarray(sol["x"]).reshape(-1)[:n_u]
    change = (X @ u).reshape(T, 2)
    return com[:, :2] + change


def _leg_dofs(index) -> list:
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


def _solve_legs(index, qpos_t: np.ndarray, foot_pos: np.ndarray, foot_quat: np.ndarray, legs, data,
                iterations: int = 20, damping: float = 1e-4) -> float:
    """Re-solve the legs in place so each sole body reaches its pose; returns the position error (m)."""
    model = index.kin_model
    jacp = np.zeros((3, model.nv))
    jacr = np.zeros((3, model.nv))
    err = np.zeros(6)
    q_err = np.zeros(3)
    worst = 0.0
    limits = {}
    for j in range(model.njnt):
        if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE and model.jnt_limited[j]:
            limits[int(model.jnt_qposadr[j])] = model.jnt_range[j]
    for side, (qadr, dadr) in enumerate(legs):
        body = int(index.sole_body[side])
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
            step = J.T @ np.linalg.solve(J @ J.T + damping * np.eye(6), err)
            qpos_t[qadr] += np.clip(step, -0.05, 0.05)  # small steps: stay on the reference's IK branch
            for a in qadr:
                if a in limits:
                    qpos_t[a] = np.clip(qpos_t[a], limits[a][0], limits[a][1])
        data.qpos[:] = qpos_t
        mujoco.mj_kinematics(model, data)
        worst = max(worst, float(np.linalg.norm(foot_pos[side] - data.xpos[body])))
    return worst


def shift_com(index, qpos: np.ndarray, fps: float, contacts: np.ndarray, margin_m: float = 0.01,
              tolerance_m: float = 0.005, passes: int = 2, axes: str = "lateral", smoothness: float = 1.0,
              slack_weight: float = 1e4) -> ZmpShiftResult:
    """The trajectory ``qpos`` [T, nq] with its CoM moved so the cart-table ZMP stays on the
    planned contacts ``contacts`` [T, 2] (see the module docstring)."""
    qpos = np.asarray(qpos, dtype=np.float64).copy()
    contacts = np.asarray(contacts, dtype=bool)
    com, corners, foot_pos, foot_quat = _kinematics(index, qpos)
    hulls = _support(corners, contacts)
    zmp = cart_table_zmp(com, fps)
    before = _outside_fraction(zmp, hulls, tolerance_m)
    T = qpos.shape[0]
    if axes == "lateral":  # only across the walking direction (the heading of each frame)
        yaw = heading(qpos)
        basis = np.stack([-np.sin(yaw), np.cos(yaw)], axis=1)[:, :, None]
    else:
        basis = np.repeat(np.eye(2)[None], T, axis=0)
    path = _com_path(com, hulls, fps, margin_m, basis, smoothness, slack_weight)
    legs = _leg_dofs(index)
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
            worst = max(worst, _solve_legs(index, qpos[t], foot_pos[t], foot_quat[t], legs, data))
            correction = qpos[t, leg_q] - reference[t, leg_q]
        current = _kinematics(index, qpos)[0]
    after = _outside_fraction(cart_table_zmp(current, fps), hulls, tolerance_m)
    return ZmpShiftResult(qpos=qpos, com_shift=current[:, :2] - com[:, :2], zmp_outside_before=before,
                          zmp_outside_after=after, foot_error_m=worst)

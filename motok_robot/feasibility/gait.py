"""The whole-body walking motion for a footstep schedule: a CoM path planned from the ZMP.

Given the robot's footsteps (:mod:`.footsteps`) and a reference motion (the upper body, the
base height, roll and pitch to keep; the heading may be given smoothed), this builds what the
robot's balance depends on, as a biped walking pattern generator does:

1. **A ZMP reference that walks from foothold to foothold**: on the stance foot's sole centre in
   single support, moving linearly across over the first ``zmp_transfer_share`` of each double
   support (half: with one frame of double support it is on the landed foot at touchdown, where
   physics puts the load), between the feet before the first step and after the last.
2. **A CoM path for it**: the horizontal CoM minimising the cart-table ZMP error plus its jerk,
   a banded least-squares problem over the whole clip at ``rate_hz`` (the non-causal form of
   ZMP preview control), starting and ending at rest (:func:`com_path`).
3. **The whole body**: the base keeps the reference's height (smoothed over about a human step:
   the pelvis bobs with the human's own steps) and tilt and is moved
   horizontally until the robot's CoM is on that path, lowered where a leg could not reach its
   foot; each leg is solved for its foot pose within the servos' velocity limits (damped least
   squares, :func:`~motok_robot.feasibility.zmp_shift.solve_legs`); arms, head and torso joints
   are the reference's.

The result is the feasibility stage's task trajectory: the feedforward goals and the balance
plan are built from it; validation judges the executed motion against the reference.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from scipy import sparse
from scipy.sparse.linalg import spsolve

from motok_robot.feasibility.footsteps import StepSchedule
from motok_robot.feasibility.geometry import heading
from motok_robot.feasibility.zmp_shift import GRAVITY, leg_dofs, solve_legs


@dataclass
class GaitResult:
    qpos: np.ndarray         # [T, nq] the generated task trajectory
    contacts: np.ndarray     # [T, 2] bool, the planned support phases
    com: np.ndarray          # [T, 2] planned horizontal CoM path
    zmp: np.ndarray          # [T, 2] ZMP reference
    foot_errors: np.ndarray  # [T] sole position error of the leg solve (m)
    com_error_m: float       # largest horizontal distance of the achieved CoM from the plan
    base_drop_m: float       # largest lowering of the base below the reference (for the legs' reach)

    def record(self) -> dict:
        return {"foot_error_m_max": float(self.foot_errors.max()), "foot_error_m_mean": float(self.foot_errors.mean()),
                "com_error_m": self.com_error_m, "base_drop_m": self.base_drop_m}


def _com(index, qpos: np.ndarray) -> np.ndarray:
    """The whole robot's centre of mass [T, 3] along ``qpos`` [T, nq]."""
    data = mujoco.MjData(index.kin_model)
    com = np.zeros((qpos.shape[0], 3))
    for t in range(qpos.shape[0]):
        data.qpos[:] = qpos[t]
        mujoco.mj_kinematics(index.kin_model, data)
        mujoco.mj_comPos(index.kin_model, data)
        com[t] = data.subtree_com[index.root_body]
    return com


def _hips_and_reach(index, legs, margin: float = 0.97):
    """Per leg: the hinge whose anchor is farthest from the sole with the leg straight (the hip),
    and the largest hip-to-sole-body distance the leg reaches (``margin`` x that distance)."""
    model = index.kin_model
    data = mujoco.MjData(model)
    data.qpos[:] = index.nominal_qpos
    data.qpos[np.concatenate([a for a, _ in legs])] = 0.0
    mujoco.mj_kinematics(model, data)
    hips, reach = [], []
    for k, (qadr, _) in enumerate(legs):
        joints = [j for j in range(model.njnt) if model.jnt_qposadr[j] in set(qadr.tolist())]
        hip = max(joints, key=lambda j: np.linalg.norm(data.xanchor[j] - data.xpos[index.sole_body[k]]))
        hips.append(hip)
        reach.append(margin * float(np.linalg.norm(data.xanchor[hip] - data.xpos[index.sole_body[k]])))
    return hips, reach


def smoothed(values: np.ndarray, width: int) -> np.ndarray:
    """[T] ``values`` smoothed by a Hann window ``width`` frames wide (edges held)."""
    if width < 3:
        return np.asarray(values, dtype=np.float64).copy()
    kernel = np.hanning(width + 2)[1:-1]
    kernel /= kernel.sum()
    half = width // 2
    padded = np.pad(np.asarray(values, dtype=np.float64), (half, width - 1 - half), mode="edge")
    return np.convolve(padded, kernel, mode="valid")


def com_path(zmp: np.ndarray, height: float, dt: float, start: np.ndarray, end: np.ndarray,
             jerk_weight: float) -> np.ndarray:
    """Horizontal CoM [N, 2] minimising the cart-table ZMP error to ``zmp`` [N, 2] plus jerk,
    at rest at ``start`` and ``end`` (the first and last two samples are pinned)."""
    N = zmp.shape[0]
    k = height / GRAVITY / dt ** 2
    rows = np.arange(1, N - 1)
    A = sparse.diags([np.full(N - 1, -k), np.full(N, 1 + 2 * k), np.full(N - 1, -k)], [-1, 0, 1],
                     shape=(N, N), format="csr")[rows]
    J = sparse.diags([np.full(N - 3, -1.0), np.full(N - 3, 3.0), np.full(N - 3, -3.0), np.full(N - 3, 1.0)],
                     [0, 1, 2, 3], shape=(N - 3, N), format="csr") * (np.sqrt(jerk_weight) / dt ** 3)
    pin = [0, 1, N - 2, N - 1]
    E = sparse.csr_matrix((np.full(4, 1e4), (np.arange(4), pin)), shape=(4, N))
    M = sparse.vstack([A, J, E]).tocsr()
    MtM = (M.T @ M).tocsc()
    out = np.zeros((N, 2))
    for axis in range(2):
        b = np.r_[zmp[rows, axis], np.zeros(N - 3),
                  1e4 * np.array([start[axis], start[axis], end[axis], end[axis]])]
        out[:, axis] = spsolve(MtM, M.T @ b)
    return out


def with_yaw(quat: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """Base orientations ``quat`` [T, 4] (wxyz) turned about the vertical so their heading is ``yaw`` [T]."""
    now = heading(np.c_[np.zeros((len(quat), 3)), quat])
    out = np.zeros_like(quat)
    for t in range(len(quat)):
        turn = 0.5 * (yaw[t] - now[t])
        mujoco.mju_mulQuat(out[t], np.array([np.cos(turn), 0.0, 0.0, np.sin(turn)]), quat[t])
    return out


def zmp_reference(schedule: StepSchedule, transfer_share: float = 1.0) -> np.ndarray:
    """[T, 2] the ZMP reference of ``schedule`` (see the module docstring, step 1): in each
    double support it reaches the next support after ``transfer_share`` of it (1: at its end)."""
    contacts = schedule.contacts
    T = contacts.shape[0]
    centre = np.zeros((T, 2, 2))
    for f in schedule.footholds:
        centre[f.start:f.end + 1, f.foot] = f.centre
    zmp = np.zeros((T, 2))
    t = 0
    while t < T:
        if not contacts[t].all():
            zmp[t] = centre[t, 0 if contacts[t, 0] else 1]
            t += 1
            continue
        u = t
        while u + 1 < T and contacts[u + 1].all():
            u += 1
        before = None if t == 0 else (0 if contacts[t - 1, 0] else 1)
        after = None if u == T - 1 else (0 if contacts[u + 1, 0] else 1)
        for v in range(t, u + 1):
            w = min(1.0, (v - t + 1) / ((u - t + 2) * transfer_share))
            mid = centre[v].mean(axis=0)
            start = mid if before is None else centre[v, before]
            end = mid if after is None else centre[v, after]
            zmp[v] = (1 - w) * start + w * end
        t = u + 1
    return zmp


def generate_gait(index, qpos: np.ndarray, fps: float, schedule: StepSchedule, *, rate_hz: float = 100.0,
                  jerk_weight: float = 1e-7, passes: int = 6, reach_window_s: float = 0.1,
                  max_drop_fraction: float = 0.2, velocity_fraction: float = 0.9,
                  speed_limit: np.ndarray | None = None,
                  base_yaw: np.ndarray | None = None, zmp_transfer_share: float = 1.0,
                  height_window_s: float = 0.0, zmp: np.ndarray | None = None) -> GaitResult:
    """The task trajectory [T, nq] walking ``schedule`` with the upper body, base height and
    orientation of reference ``qpos`` [T, nq] at ``fps`` (see the module docstring); with
    ``base_yaw`` [T] (rad) the base turns with it instead of the reference's (a human's pelvis
    swings its heading with every step; on a robot's stance foot that swing is a twist); with
    ``height_window_s`` > 0 the base height is the reference's smoothed over that window (a
    human's pelvis also bobs with every one of its steps, which the robot's steps do not share);
    ``zmp_transfer_share``: see :func:`zmp_reference`; ``zmp`` [T, 2]: the ZMP reference to
    use instead of :func:`zmp_reference`'s (a motion on the spot, :mod:`.spot_steps`)."""
    qpos = np.asarray(qpos, dtype=np.float64).copy()
    if base_yaw is not None:
        qpos[:, 3:7] = with_yaw(qpos[:, 3:7], base_yaw)
    if height_window_s > 0:
        qpos[:, 2] = smoothed(qpos[:, 2], int(round(height_window_s * fps)))
    T = qpos.shape[0]
    foot_pos, foot_quat = schedule.foot_pos, schedule.foot_quat
    com = _com(index, qpos)
    zmp = zmp_reference(schedule, zmp_transfer_share) if zmp is None else np.asarray(zmp, dtype=np.float64)
    # CoM path at rate_hz over the clip, sampled back at the frames
    n = max(4, int(round((T - 1) / fps * rate_hz)) + 1)
    times = np.linspace(0, (T - 1) / fps, n)
    frame_x = np.arange(T) / fps
    zmp_hi = np.stack([np.interp(times, frame_x, zmp[:, a]) for a in range(2)], axis=1)
    height = float(np.mean(com[:, 2]))
    path_hi = com_path(zmp_hi, height, times[1] - times[0], zmp[0], zmp[-1], jerk_weight)
    path = np.stack([np.interp(frame_x, times, path_hi[:, a]) for a in range(2)], axis=1)
    # whole body: base moved until the CoM is on the path, lowered where a leg cannot reach its
    # foot, legs solved for the feet
    out = qpos.copy()
    legs = leg_dofs(index)
    model = index.kin_model
    data = mujoco.MjData(model)
    hips, reach = _hips_and_reach(index, legs)
    current = com[:, :2].copy()
    drop = np.zeros(T)
    window = max(1, int(round(reach_window_s * fps)))
    kernel = np.ones(2 * window + 1) / (2 * window + 1)
    leg_q = np.concatenate([a for a, _ in legs])
    max_step = np.full(model.nq, np.inf)
    joint_speed = velocity_fraction * np.asarray(index.velocity_limit, dtype=np.float64)
    if speed_limit is not None:
        joint_speed = np.minimum(joint_speed, np.asarray(speed_limit, dtype=np.float64))
    max_step[index.qpos_adr] = joint_speed / fps
    for _ in range(passes):
        out[:, leg_q] = qpos[:, leg_q]  # each pass starts from the reference's legs (a straight
        # knee is a singular point the leg solve cannot bend back out of)
        errors = np.zeros(T)
        need = np.zeros(T)
        for t in range(T):
            out[t, :2] += path[t] - current[t]
            out[t, 2] = qpos[t, 2] - drop[t]
            data.qpos[:] = out[t]
            mujoco.mj_kinematics(model, data)
            for k in range(2):  # how much lower the hip must be for this leg to reach its foot
                d = data.xanchor[hips[k]] - foot_pos[t, k]
                flat = min(float(np.hypot(d[0], d[1])), reach[k])
                need[t] = max(need[t], float(d[2]) - np.sqrt(reach[k] ** 2 - flat ** 2))
            if t and velocity_fraction > 0:  # the servos' velocity limits, as retargeting keeps them
                last = out[t - 1, leg_q]
                out[t, leg_q] = np.clip(out[t, leg_q], last - max_step[leg_q], last + max_step[leg_q])
                errors[t] = solve_legs(index, out[t], foot_pos[t], foot_quat[t], legs, data,
                                       previous=out[t - 1], max_step=max_step)
            else:
                errors[t] = solve_legs(index, out[t], foot_pos[t], foot_quat[t], legs, data)
                if t == 0 and errors[t] > 1e-3:  # e.g. a straight knee, where the solve cannot bend
                    # it (a singular point): start again from the robot's own stance
                    again = out[t].copy()
                    again[leg_q] = index.nominal_qpos[leg_q]
                    error = solve_legs(index, again, foot_pos[t], foot_quat[t], legs, data)
                    if error < errors[t]:
                        out[t], errors[t] = again, error
        current = _com(index, out)[:, :2]
        if need.max() <= 0:
            break
        spread = np.array([need[max(0, t - window):t + window + 1].max() for t in range(T)])
        smooth = np.convolve(np.pad(spread, window, mode="edge"), kernel, mode="valid")
        drop = np.clip(drop + np.maximum(smooth, need), 0.0, max_drop_fraction * qpos[:, 2])
    com_error = float(np.linalg.norm(current - path, axis=1).max())
    return GaitResult(qpos=out, contacts=schedule.contacts.copy(), com=path, zmp=zmp, foot_errors=errors,
                      com_error_m=com_error, base_drop_m=float(drop.max()))

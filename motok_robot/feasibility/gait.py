"""A walking pattern generated from the reference's footsteps, instead of the reference's own CoM.

A retargeted human walk hands a 0.5 m robot the human's timing: support passes from one foot
to the other within one 20 fps frame, and the centre of mass sways as the human's did, 1-4 cm
outside the small robot's stance foot (docs/experiments/2026-12-01-feasibility-variants.md).
Tracking that more closely did not make it stand.  This module keeps what the motion is made of
and regenerates what the robot's balance depends on, as a biped walking pattern generator does:

1. **Footsteps from the reference.**  Each stance of each foot (frames where its sole is down)
   becomes a foothold: the sole pose at the middle of that stance.  Short contact blips and gaps
   are cleaned first.
2. **Double support by construction.**  Every swing is shortened at both ends so that both feet
   are down for at least ``min_double_support_s`` around each transfer of support; the swing
   keeps the reference's own foot path (a kick stays a kick), resampled into the shorter time and
   bent so it leaves and lands exactly on the footholds, never below the floor.
3. **A CoM path whose ZMP walks from foothold to foothold.**  The ZMP reference sits on the
   stance foot in single support and moves linearly across in double support; the horizontal
   CoM path minimises the cart-table ZMP error plus its jerk (a banded least-squares problem over
   the whole clip at ``rate_hz``, the non-causal form of ZMP preview control), starting and
   ending at rest over the reference's CoM.
4. **Whole body.**  The base keeps the reference's height and orientation and is moved
   horizontally until the robot's CoM is on that path; each leg is solved for its foot pose
   (damped least squares, :func:`~motok_robot.feasibility.zmp_shift.solve_legs`); arms, head and
   torso joints are the reference's.

The result is the stage's task trajectory: the feedforward goals and the balance plan are built
from it, and validation still judges the executed motion against the unmodified reference.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from scipy import sparse
from scipy.sparse.linalg import spsolve

from motok_robot.feasibility.zmp_shift import GRAVITY, leg_dofs, solve_legs


@dataclass
class Stance:
    foot: int        # 0 left, 1 right
    start: int       # first frame down (in the generated timing)
    end: int         # last frame down
    pos: np.ndarray  # [3] sole body position of the foothold
    quat: np.ndarray  # [4] sole body orientation
    centre: np.ndarray  # [2] sole centre (ZMP target in single support)


@dataclass
class GaitResult:
    qpos: np.ndarray         # [T, nq] the generated task trajectory
    contacts: np.ndarray     # [T, 2] bool, the generated support phases
    stances: list            # [Stance]
    com: np.ndarray          # [T, 2] planned horizontal CoM path
    zmp: np.ndarray          # [T, 2] ZMP reference
    foot_error_m: float      # largest sole position error of the leg solve
    foot_errors: np.ndarray  # [T] per frame
    com_error_m: float       # largest horizontal distance of the achieved CoM from the plan
    base_drop_m: float       # largest lowering of the base below the reference (for the legs' reach)

    def record(self) -> dict:
        return {"method": "generated gait (reference footsteps, ZMP-planned CoM)",
                "footsteps": [{"foot": "left" if s.foot == 0 else "right", "start_frame": s.start,
                               "end_frame": s.end, "x": float(s.pos[0]), "y": float(s.pos[1])} for s in self.stances],
                "double_support_fraction": float(np.mean(self.contacts.all(axis=1))),
                "foot_error_m": self.foot_error_m, "com_error_m": self.com_error_m,
                "base_drop_m": self.base_drop_m}


def clean_contacts(contacts: np.ndarray, min_frames: int) -> np.ndarray:
    """``contacts`` [T, 2] with gaps and blips shorter than ``min_frames`` removed (gaps first)."""
    out = np.asarray(contacts, dtype=bool).copy()
    for value in (False, True):  # fill short gaps, then drop short contacts
        for k in range(out.shape[1]):
            col = out[:, k]
            t = 0
            while t < len(col):
                if col[t] == value:
                    u = t
                    while u < len(col) and col[u] == value:
                        u += 1
                    if u - t < min_frames and t > 0 and u < len(col):
                        col[t:u] = not value
                    t = u
                else:
                    t += 1
    return out


def _runs(col: np.ndarray) -> list:
    """(start, end) inclusive of each run of True in ``col``."""
    runs, t = [], 0
    while t < len(col):
        if col[t]:
            u = t
            while u + 1 < len(col) and col[u + 1]:
                u += 1
            runs.append((t, u))
            t = u + 1
        else:
            t += 1
    return runs


def _foot_poses(index, qpos: np.ndarray):
    model = index.kin_model
    data = mujoco.MjData(model)
    T = qpos.shape[0]
    pos, quat, centre, com = np.zeros((T, 2, 3)), np.zeros((T, 2, 4)), np.zeros((T, 2, 3)), np.zeros((T, 3))
    for t in range(T):
        data.qpos[:] = qpos[t]
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        pos[t] = data.xpos[index.sole_body]
        quat[t] = data.xquat[index.sole_body]
        centre[t] = data.site_xpos[index.sole_site]
        com[t] = data.subtree_com[index.root_body]
    return pos, quat, centre, com


def _slerp(q0: np.ndarray, q1: np.ndarray, s: float) -> np.ndarray:
    if np.dot(q0, q1) < 0:
        q1 = -q1
    dot = float(np.clip(np.dot(q0, q1), -1.0, 1.0))
    if dot > 0.9995:
        q = q0 + s * (q1 - q0)
    else:
        theta = np.arccos(dot)
        q = (np.sin((1 - s) * theta) * q0 + np.sin(s * theta) * q1) / np.sin(theta)
    return q / np.linalg.norm(q)


def _resample(values: np.ndarray, a: int, b: int, a2: int, b2: int, t: int) -> np.ndarray:
    """``values`` between frames a..b, played over a2..b2 instead: the value at frame ``t``."""
    x = a + (t - a2) * (b - a) / max(b2 - a2, 1)
    i = int(np.clip(np.floor(x), a, b))
    j = min(i + 1, b)
    f = x - i
    return (1 - f) * values[i] + f * values[j]


def _hips_and_reach(index, legs, margin: float = 0.97):
    """Per leg: the joint id of the hip joint nearest the base whose anchor is the hip centre
    (the first hinge above the knee, from the base down), and the largest hip-to-sole-body
    distance the leg reaches (``margin`` x its length with the knee straight)."""
    model = index.kin_model
    data = mujoco.MjData(model)
    data.qpos[:] = index.nominal_qpos
    data.qpos[np.concatenate([a for a, _ in legs])] = 0.0
    mujoco.mj_kinematics(model, data)
    hips, reach = [], []
    for k, (qadr, _) in enumerate(legs):
        joints = [j for j in range(model.njnt) if model.jnt_qposadr[j] in set(qadr.tolist())]
        hip = joints[0]  # leg_dofs lists sole -> base; the last is the hip joint at the base
        hip = max(joints, key=lambda j: np.linalg.norm(data.xanchor[j] - data.xpos[index.sole_body[k]]))
        hips.append(hip)
        reach.append(margin * float(np.linalg.norm(data.xanchor[hip] - data.xpos[index.sole_body[k]])))
    return hips, reach


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


def generate_gait(index, qpos: np.ndarray, fps: float, contacts: np.ndarray, *, lead_in_frames: int = 0,
                  min_double_support_s: float = 0.1, min_phase_s: float = 0.1, rate_hz: float = 100.0,
                  jerk_weight: float = 1e-7, clearance_m: float = 0.02, passes: int = 6,
                  reach_tolerance_m: float = 0.002, reach_window_s: float = 0.1,
                  max_drop_fraction: float = 0.2, step_height_limit_m: float = 0.08,
                  velocity_fraction: float = 0.9) -> GaitResult | None:
    """The generated task trajectory for reference ``qpos`` [T, nq] at ``fps`` with sole
    contacts ``contacts`` [T, 2]; None when the reference does not step (fewer than one swing
    from foothold to foothold)."""
    qpos = np.asarray(qpos, dtype=np.float64)
    T = qpos.shape[0]
    import os  # EXPERIMENT knobs
    clearance_m = float(os.environ.get("G_CLEAR", clearance_m))
    velocity_fraction = float(os.environ.get("G_VEL", velocity_fraction))
    contacts = clean_contacts(contacts, max(1, int(round(min_phase_s * fps))))
    measured = contacts.copy()
    contacts[:lead_in_frames] = True  # the lead-in: both feet planted
    pos, quat, centre, com = _foot_poses(index, qpos)
    runs = [_runs(contacts[:, k]) for k in range(2)]
    if sum(max(0, len(r) - 1) for r in runs) < 1:
        return None
    half = max(0, int(round(min_double_support_s * fps / 2)))
    foot_pos = pos.copy()
    foot_quat = quat.copy()
    gen_contacts = np.zeros_like(contacts)
    stances = []
    for k in range(2):
        holds = []
        for a, b in runs[k]:
            down = a + np.nonzero(measured[a:b + 1, k])[0]  # the foothold: the middle of the
            m = int(down[len(down) // 2]) if down.size else (a + b) // 2  # frames really down
            holds.append((a, b, pos[m, k].copy(), quat[m, k].copy(), centre[m, k, :2].copy()))
        for i, (a, b, p, q, c) in enumerate(holds):
            # the generated stance: longer by ``half`` frames at each end that borders a swing
            a2 = a if i == 0 else a - half
            b2 = b if i == len(holds) - 1 else b + half
            a2, b2 = max(0, a2), min(T - 1, b2)
            foot_pos[a2:b2 + 1, k] = p
            foot_quat[a2:b2 + 1, k] = q
            gen_contacts[a2:b2 + 1, k] = True
            # before the first and after the last stance (the clip starts or ends with this foot
            # in the air): the reference's foot path, moved with the foothold
            ends = ([range(0, a2)] if i == 0 else []) + ([range(b2 + 1, T)] if i == len(holds) - 1 else [])
            for frames in ends:
                anchor = a if frames.start == 0 else b
                for t in frames:
                    foot_pos[t, k] = pos[t, k] + (p - pos[anchor, k])
                    foot_pos[t, k, 2] = max(foot_pos[t, k, 2], p[2])
                    foot_quat[t, k] = quat[t, k]
            stances.append(Stance(foot=k, start=a2, end=b2, pos=p, quat=q, centre=c))
        for i in range(len(holds) - 1):  # swings: the reference's foot path, compressed and bent
            _, b, p0, q0, _ = holds[i]
            a, _, p1, q1, _ = holds[i + 1]
            s0, s1 = b + half + 1, a - half - 1
            if s1 - s0 < 2:  # too short to shorten: the swing keeps its reference timing
                s0, s1 = b + 1, a - 1
                if s1 < s0:
                    continue
            ref0, ref1 = pos[b, k], pos[a, k]
            raised = float(pos[b:a + 1, k, 2].max() - max(ref0[2], ref1[2]))
            generated = os.environ.get("G_SWING", "gen") == "gen" and raised < step_height_limit_m
            for t in range(s0, s1 + 1):
                s = (t - s0 + 1) / (s1 - s0 + 2)
                ease = 10 * s ** 3 - 15 * s ** 4 + 6 * s ** 5
                if generated:  # an ordinary step: a smooth arc (min-jerk across, a bump up)
                    target = p0 + ease * (p1 - p0)
                    target[2] = (1 - ease) * p0[2] + ease * p1[2] + clearance_m * 16 * s * s * (1 - s) * (1 - s)
                else:  # a foot raised higher than a step (a kick): the reference's path
                    raw = _resample(pos[:, k], b, a, s0 - 1, s1 + 1, t)
                    target = raw + (1 - s) * (p0 - ref0) + s * (p1 - ref1)
                    target[2] = max(target[2], min(p0[2], p1[2]) + clearance_m * np.sin(np.pi * s))
                foot_pos[t, k] = target
                foot_quat[t, k] = _slerp(q0, q1, ease)
            gen_contacts[s0:s1 + 1, k] = False
    stances.sort(key=lambda s: (s.start, s.foot))
    if not gen_contacts.any(axis=1).all():
        return None
    # ZMP reference per frame: on the single support foot, linear across double support
    zmp = np.zeros((T, 2))
    stance_centre = np.zeros((T, 2, 2))
    for s in stances:
        stance_centre[s.start:s.end + 1, s.foot] = s.centre
    t = 0
    while t < T:
        both = gen_contacts[t].all()
        if not both:
            k = 0 if gen_contacts[t, 0] else 1
            zmp[t] = stance_centre[t, k]
            t += 1
            continue
        u = t
        while u + 1 < T and gen_contacts[u + 1].all():
            u += 1
        before = None if t == 0 else (0 if gen_contacts[t - 1, 0] else 1)
        after = None if u == T - 1 else (0 if gen_contacts[u + 1, 0] else 1)
        mid = stance_centre[t:u + 1].mean(axis=1)
        for v in range(t, u + 1):
            w = (v - t + 1) / (u - t + 2)
            p_from = mid[v - t] if before is None else stance_centre[v, before]
            p_to = mid[v - t] if after is None else stance_centre[v, after]
            zmp[v] = (1 - w) * p_from + w * p_to
        t = u + 1
    # CoM path at rate_hz over the clip, sampled back at the frames
    n = max(4, int(round((T - 1) / fps * rate_hz)) + 1)
    times = np.linspace(0, (T - 1) / fps, n)
    frame_x = np.arange(T) / fps
    zmp_hi = np.stack([np.interp(times, frame_x, zmp[:, a]) for a in range(2)], axis=1)
    height = float(np.mean(com[:, 2]))
    path_hi = com_path(zmp_hi, height, times[1] - times[0], zmp[0], zmp[-1], jerk_weight)
    path = np.stack([np.interp(frame_x, times, path_hi[:, a]) for a in range(2)], axis=1)
    # whole body: base moved until the CoM is on the path, lowered where a leg cannot reach its
    # foot (the compressed swings start and end farther from the hip than the reference's), legs
    # solved for the feet
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
    max_step[index.qpos_adr] = velocity_fraction * np.asarray(index.velocity_limit, dtype=np.float64) / fps
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
                out[t, leg_q] = np.clip(out[t, leg_q], out[t - 1, leg_q] - max_step[leg_q], out[t - 1, leg_q] + max_step[leg_q])
                errors[t] = solve_legs(index, out[t], foot_pos[t], foot_quat[t], legs, data,
                                       previous=out[t - 1], max_step=max_step)
            else:
                errors[t] = solve_legs(index, out[t], foot_pos[t], foot_quat[t], legs, data)
        current = _foot_poses(index, out)[3][:, :2]
        if need.max() <= 0:
            break
        spread = np.array([need[max(0, t - window):t + window + 1].max() for t in range(T)])
        smooth = np.convolve(np.pad(spread, window, mode="edge"), kernel, mode="valid")
        drop = np.clip(drop + np.maximum(smooth, need), 0.0, max_drop_fraction * qpos[:, 2])
    foot_error = float(errors.max())
    com_error = float(np.linalg.norm(current - path, axis=1).max())
    return GaitResult(qpos=out, contacts=gen_contacts, stances=stances, com=path, zmp=zmp,
                      foot_error_m=foot_error, foot_errors=errors, com_error_m=com_error, base_drop_m=float(drop.max()))

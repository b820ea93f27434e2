"""Synthetic trajectories of any robot: clean motions and the faults each check must catch.

All generators take a :class:`~motok_robot.robots.index.RobotIndex` and return
``qpos`` float64 [T, nq] at ``fps`` frames per second, built from the robot's nominal pose.
Feet are placed by damped least-squares inverse kinematics on the leg joints (the joints
that move a sole), with the free base prescribed, so the soles are where they are meant
to be to ~1e-6 m.

Clean: :func:`standing`, :func:`walk` (a slow quasi-static walk: weight shift over the
stance foot in double support, foot lift and swing in single support), :func:`squat`.
Faults: :func:`sliding_foot` (a loaded foot slides half a foot length),
:func:`sunk_feet` (2 cm into the floor), :func:`leaning` (CoM pushed past the toes and held),
:func:`over_limit` (an arm joint driven past its range), :func:`too_fast` (an arm joint
oscillating at twice its servo velocity limit), :func:`lift_foot_without_shift` (one foot
lifted with the weight still between the feet: the robot falls in physics).
"""

from __future__ import annotations

import mujoco
import numpy as np

from motok_robot.robots.index import RobotIndex


class LegIK:
    """Sole-pose inverse kinematics with a prescribed free base."""

    def __init__(self, index: RobotIndex):
        self.index = index
        self.model = index.kin_model
        self.data = mujoco.MjData(self.model)
        self.data.qpos[:] = index.nominal_qpos
        mujoco.mj_kinematics(self.model, self.data)
        mujoco.mj_comPos(self.model, self.data)
        jac = np.zeros((3, self.model.nv))
        moved = np.zeros(self.model.nv, dtype=bool)
        for site in index.sole_site:
            mujoco.mj_jacSite(self.model, self.data, jac, None, int(site))
            moved |= np.abs(jac).sum(0) > 1e-9
        self.leg = np.array([j for j in range(index.nj) if moved[index.dof_adr[j]]])
        self.sole_pos0 = self.data.site_xpos[index.sole_site].copy()
        self.sole_quat0 = np.array([self._body_quat(b) for b in index.sole_body])

    def _body_quat(self, body: int) -> np.ndarray:
        return self.data.xquat[body].copy()

    def solve(self, qpos: np.ndarray, targets: np.ndarray, iterations: int = 100) -> np.ndarray:
        """Move the leg joints of ``qpos`` [nq] so the soles reach ``targets`` [2, 3] (flat feet)."""
        m, d, idx = self.model, self.data, self.index
        q = qpos.copy()
        qadr, dadr = idx.qpos_adr[self.leg], idx.dof_adr[self.leg]
        jacp, jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
        low, high = idx.joint_range[self.leg, 0], idx.joint_range[self.leg, 1]
        for _ in range(iterations):
            d.qpos[:] = q
            mujoco.mj_kinematics(m, d)
            mujoco.mj_comPos(m, d)
            rows, errs = [], []
            for side in range(2):
                site, body = int(idx.sole_site[side]), int(idx.sole_body[side])
                mujoco.mj_jacSite(m, d, jacp, jacr, site)
                rot = np.zeros(3)
                mujoco.mju_subQuat(rot, self.sole_quat0[side], d.xquat[body])
                rot = d.xmat[body].reshape(3, 3) @ rot
                errs += [targets[side] - d.site_xpos[site], rot]
                rows += [jacp[:, dadr].copy(), jacr[:, dadr].copy()]
            err = np.concatenate(errs)
            if np.abs(err).max() < 1e-7:
                break
            jac = np.vstack(rows)
            step = np.linalg.solve(jac.T @ jac + 1e-6 * np.eye(len(dadr)), jac.T @ err)
            q[qadr] = np.clip(q[qadr] + step, low, high)
        return q


def _smoothstep(x):
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3 - 2 * x)


def _frames(seconds: float, fps: float) -> np.ndarray:
    return np.arange(int(round(seconds * fps)) + 1) / fps


def standing(index: RobotIndex, seconds: float = 2.0, fps: float = 20.0) -> np.ndarray:
    """The nominal pose held still."""
    return np.tile(index.nominal_qpos, (len(_frames(seconds, fps)), 1))


def _foot_length(index: RobotIndex, ik: LegIK) -> float:
    d = ik.data
    d.qpos[:] = index.nominal_qpos
    mujoco.mj_kinematics(ik.model, d)
    c = d.site_xpos[index.corner_sites[0]]
    return float(np.ptp(c[:, 0]))


def _with_base_and_feet(index, ik, base_xyz, feet) -> np.ndarray:
    """qpos [T, nq]: nominal pose with base position [T, 3] and soles at feet [T, 2, 3]."""
    out = np.zeros((len(base_xyz), index.model.nq))
    q = index.nominal_qpos.copy()
    for t in range(len(base_xyz)):
        q[:3] = base_xyz[t]
        q = ik.solve(q, feet[t])
        error = np.abs(ik.data.site_xpos[index.sole_site] - feet[t]).max()
        if error > 2e-3:  # above this the clip would show faults nobody asked for
            raise ValueError(f"{index.name}: the legs cannot place the soles at frame {t} "
                             f"(error {error * 1000:.1f} mm): the synthetic motion is beyond this robot")
        out[t] = q
    return out


def walk(index: RobotIndex, steps: int = 4, step_period_s: float = 3.2, fps: float = 20.0,
         double_support: float = 0.5) -> np.ndarray:
    """A slow forward walk of ``steps`` steps with the feet planted while loaded.

    Each step: double support (``double_support`` of the period) shifting the pelvis over the
    next stance foot, then single support with the other foot lifted by 8 % of the leg length
    and moved forward (horizontal motion only in the middle 70 % of the swing, so the foot
    leaves and meets the floor vertically).  Foot displacements: the first step is half a foot length, the others a
    whole one (each foot lands half a foot length ahead of the other).  One extra period at
    the end brings the pelvis back between the feet.
    """
    ik = LegIK(index)
    step_len = _foot_length(index, ik)
    base0 = index.nominal_qpos[:3].copy()
    feet0 = ik.sole_pos0.copy()
    sway = 0.5 * abs(feet0[0, 1] - feet0[1, 1])
    lift = 0.08 * base0[2]
    ds = double_support * step_period_s
    time = _frames((steps + 1) * step_period_s, fps)
    # pelvis x: waypoints over the stance foot during single support, eased with a moving average
    wp_t, wp_x = [0.0], [0.0]
    for k in range(steps):
        stance = k * step_len / 2
        wp_t += [k * step_period_s + ds, (k + 1) * step_period_s]
        wp_x += [stance - step_len / 8, stance + step_len / 8]
    wp_t.append((steps + 1) * step_period_s)
    wp_x.append((2 * steps - 1) * step_len / 4)
    x = np.interp(time, wp_t, wp_x)
    window = max(1, int(0.25 * step_period_s * fps)) | 1
    x = np.convolve(np.pad(x, window // 2, mode="edge"), np.ones(window) / window, mode="valid")
    # pelvis y: over the stance foot (left, +y, for even steps), shifted during double support
    y = np.zeros_like(time)
    for i, t in enumerate(time):
        k = min(int(t // step_period_s), steps)
        now = 0.0 if k >= steps else (1.0 if k % 2 == 0 else -1.0)
        prev = 0.0 if k == 0 else (1.0 if (k - 1) % 2 == 0 else -1.0)
        y[i] = prev + (now - prev) * _smoothstep((t - k * step_period_s) / ds)
    base = np.tile(base0, (len(time), 1))
    base[:, 0] += x
    base[:, 1] += sway * y
    feet = np.tile(feet0, (len(time), 1, 1))
    for k in range(steps):
        swing = 1 if k % 2 == 0 else 0
        start, goal = (k - 1) * step_len / 2 if k else 0.0, (k + 1) * step_len / 2
        t0, t1 = k * step_period_s + ds, (k + 1) * step_period_s
        s = _smoothstep(((time - t0) / (t1 - t0) - 0.15) / 0.7)  # lift first, then move
        moving = time >= t0
        feet[moving, swing, 0] = feet0[swing, 0] + start + (goal - start) * s[moving]
        swinging = (time >= t0) & (time <= t1)
        feet[swinging, swing, 2] += lift * np.sin(np.pi * (time[swinging] - t0) / (t1 - t0))
    return _with_base_and_feet(index, ik, base, feet)


def squat(index: RobotIndex, seconds: float = 3.0, fps: float = 20.0, depth: float = 0.2) -> np.ndarray:
    """Feet planted, the pelvis goes down by ``depth`` x its standing height and back up
    (a deliberate low root: no fall)."""
    ik = LegIK(index)
    time = _frames(seconds, fps)
    base = np.tile(index.nominal_qpos[:3], (len(time), 1))
    base[:, 2] -= depth * index.nominal_qpos[2] * np.sin(np.pi * time / seconds) ** 2
    feet = np.tile(ik.sole_pos0, (len(time), 1, 1))
    return _with_base_and_feet(index, ik, base, feet)


def sliding_foot(index: RobotIndex, seconds: float = 2.0, fps: float = 20.0, side: int = 1) -> np.ndarray:
    """Standing, then the ``side`` foot (0 left, 1 right) slides forward half a foot length
    during the middle half of the clip while still on the floor."""
    ik = LegIK(index)
    time = _frames(seconds, fps)
    base = np.tile(index.nominal_qpos[:3], (len(time), 1))
    feet = np.tile(ik.sole_pos0, (len(time), 1, 1))
    slide = 0.5 * _foot_length(index, ik)
    feet[:, side, 0] += slide * _smoothstep((time - seconds / 4) / (seconds / 2))
    return _with_base_and_feet(index, ik, base, feet)


def sunk_feet(index: RobotIndex, seconds: float = 2.0, fps: float = 20.0, depth_m: float = 0.02) -> np.ndarray:
    """Standing with the whole robot ``depth_m`` lower: both soles below the floor."""
    qpos = standing(index, seconds, fps)
    qpos[:, 2] -= depth_m
    return qpos


def leaning(index: RobotIndex, seconds: float = 2.0, fps: float = 20.0, past_toes_m: float = 0.03) -> np.ndarray:
    """Feet planted, pelvis pushed forward until the CoM is ``past_toes_m`` beyond the front sole
    edge (over the first third of the clip), then held there."""
    ik = LegIK(index)
    time = _frames(seconds, fps)
    data = ik.data
    data.qpos[:] = index.nominal_qpos
    mujoco.mj_kinematics(ik.model, data)
    mujoco.mj_comPos(ik.model, data)
    com_x = data.subtree_com[index.root_body, 0]
    toe_x = data.site_xpos[index.corner_sites.reshape(-1), 0].max()
    shift = (toe_x - com_x + past_toes_m) * 1.15  # legs tilting moves the CoM a little less than the pelvis
    base = np.tile(index.nominal_qpos[:3], (len(time), 1))
    base[:, 0] += shift * _smoothstep(time / (seconds / 3))
    base[:, 2] -= 0.25 * shift * _smoothstep(time / (seconds / 3))
    feet = np.tile(ik.sole_pos0, (len(time), 1, 1))
    return _with_base_and_feet(index, ik, base, feet)


def _non_leg_joints(index: RobotIndex) -> np.ndarray:
    leg = set(LegIK(index).leg.tolist())
    return np.array([j for j in range(index.nj) if j not in leg])


def over_limit(index: RobotIndex, seconds: float = 2.0, fps: float = 20.0, beyond_rad: float = 0.15,
               joint: int | None = None) -> tuple[np.ndarray, int]:
    """Standing while one arm joint goes ``beyond_rad`` past its upper limit in the middle of the
    clip (slowly).  Returns (qpos, joint index)."""
    if joint is None:
        candidates = _non_leg_joints(index)
        joint = int(candidates[-1])
    qpos = standing(index, seconds, fps)
    time = _frames(seconds, fps)
    adr = index.qpos_adr[joint]
    start = qpos[0, adr]
    goal = index.joint_range[joint, 1] + beyond_rad
    bump = np.sin(np.pi * np.clip((time - seconds * 0.1) / (seconds * 0.8), 0, 1)) ** 2
    qpos[:, adr] = start + (goal - start) * bump
    return qpos, joint


def too_fast(index: RobotIndex, seconds: float = 2.0, fps: float = 20.0, speed_ratio: float = 2.0,
             joint: int | None = None) -> tuple[np.ndarray, int]:
    """Standing while the arm joint with the widest range oscillates (inside its range) with a
    peak speed of ``speed_ratio`` x its servo velocity limit.  Returns (qpos, joint index)."""
    if joint is None:
        candidates = _non_leg_joints(index)
        widths = np.ptp(index.joint_range[candidates], axis=1)
        joint = int(candidates[np.argmax(widths)])
    qpos = standing(index, seconds, fps)
    time = _frames(seconds, fps)
    adr = index.qpos_adr[joint]
    low, high = index.joint_range[joint]
    centre = float(np.clip(qpos[0, adr], low + 0.4 * (high - low), high - 0.4 * (high - low)))
    amplitude = 0.35 * (high - low)
    omega = speed_ratio * index.velocity_limit[joint] / amplitude
    omega = min(omega, 0.4 * np.pi * fps)  # stay well below Nyquist
    envelope = _smoothstep(time / (seconds / 4)) * _smoothstep((seconds - time) / (seconds / 4))
    base_value = qpos[0, adr] + (centre - qpos[0, adr]) * _smoothstep(time / (seconds / 4))
    qpos[:, adr] = base_value + amplitude * envelope * np.sin(omega * time)
    return qpos, joint


def lift_foot_without_shift(index: RobotIndex, seconds: float = 2.0, fps: float = 20.0, side: int = 1) -> np.ndarray:
    """Standing, then the ``side`` foot lifts 15 % of the leg length with no weight shift:
    the CoM stays between the feet, outside the stance foot, and the robot topples sideways."""
    ik = LegIK(index)
    time = _frames(seconds, fps)
    base = np.tile(index.nominal_qpos[:3], (len(time), 1))
    feet = np.tile(ik.sole_pos0, (len(time), 1, 1))
    feet[:, side, 2] += 0.15 * index.nominal_qpos[2] * _smoothstep((time - 0.2 * seconds) / (0.2 * seconds))
    return _with_base_and_feet(index, ik, base, feet)

"""Closed-loop balance from what a rig measures: the torso IMU (gyro, accelerometer).

The controller runs at the servo bus rate (125 Hz on the OP3-class robots).  Each tick it gets
the servo goals the trajectory asks for (feedforward goals, rad), the gyro (rad/s) and the
accelerometer (m/s^2, specific force: +g up at rest) in the IMU frame, and returns corrected
goals.  The same :class:`BalanceController` object runs in the validation rollout
(:mod:`motok_robot.feasibility.physics`), on the simulated rig and on a real bus in ``play``
(:mod:`motok_robot.servo.streamer`), so what passed in simulation is what is played.

Estimator: a complementary filter on the gravity direction in the IMU frame, ``d``: each tick
the gyro rotates it (``d -= dt (w x d)``) and it is pulled toward the accelerometer's down
direction with weight ``accel_weight``.

Control law: the tilt error is the small rotation ``e = d x d_ref`` (IMU frame) that takes the
reference torso attitude to the estimated one, the rate error ``w_f - w_ref`` (filtered gyro
minus the reference torso rate).  For a leg whose sole is on the floor, turning one of its
joints by ``q`` about its world axis ``a`` turns the body above by ``-q a``; so the correction

    goal_j += s_j(t) (kp_role(j) a_j . e + kd_role(j) a_j . (w_f - w_ref))

turns the torso back toward its reference attitude (the ankle strategy when the ankles carry
it, the hip strategy with the hips), ``a_j`` with its vertical part removed, except for the hip
yaw joints, which keep only their vertical part (yaw damping: the tilt error has no yaw part,
and the IMU cannot observe heading), ``s_j`` = 1 while the leg's foot is in contact in the reference and
``swing_share`` otherwise.  Everything that depends on the reference (attitude, rate, axes,
support) is precomputed per frame into a :class:`BalancePlan`; at run time the controller is a
time-varying linear feedback plus the filter, cheap enough for a Python loop at 125 Hz and
vectorised over a batch of rollouts (the physics refinement).

Walks with the robot's own steps add foothold tracking from leg odometry
(:mod:`.stepping`): at each lift-off the servo present positions measure the last step, and the
next steps carry the feet back to their planned footholds.

The plan travels with the servo goals (``servo_goals.npz``, fields ``balance_*`` and, for a
walk, ``step_*``), so playback needs neither the reference trajectory nor MuJoCo to run the
controller.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from motok_robot.errors import InputError
from motok_robot.feasibility.config import ROLES, BalanceConfig
from motok_robot.feasibility.stepping import FootholdTracker, SteppingPlan

#: file fields of a plan in servo_goals.npz (docs/CONTRACTS.md)
PLAN_FIELDS = ("balance_fps", "balance_down", "balance_rate", "balance_tilt_matrix", "balance_rate_matrix",
               "balance_config")


@dataclass
class BalancePlan:
    """Per-frame reference quantities of the controller (frames at ``fps``)."""

    fps: float
    down: np.ndarray         # [T, 3] reference gravity direction in the IMU frame (unit)
    rate: np.ndarray         # [T, 3] reference IMU angular velocity (rad/s, IMU frame)
    tilt_matrix: np.ndarray  # [T, nj, 3] goal offset (rad) per rad of tilt error (IMU frame)
    rate_matrix: np.ndarray  # [T, nj, 3] goal offset (rad) per rad/s of rate error (IMU frame)
    config: BalanceConfig
    stepping: SteppingPlan | None = None  # foothold tracking (walks with the robot's own steps)

    @property
    def num_frames(self) -> int:
        return int(self.down.shape[0])

    def fields(self) -> dict:
        """The plan as ``balance_*`` arrays for servo_goals.npz."""
        import json

        return {"balance_fps": np.float64(self.fps), "balance_down": self.down, "balance_rate": self.rate,
                "balance_tilt_matrix": self.tilt_matrix, "balance_rate_matrix": self.rate_matrix,
                "balance_config": np.asarray(json.dumps(self.config.to_dict())),
                **(self.stepping.fields() if self.stepping is not None else {})}

    @classmethod
    def from_fields(cls, fields: dict, nj: int, where: str) -> "BalancePlan | None":
        """The plan stored in a servo_goals file (None when it has none); errors name the field."""
        import json

        if "balance_down" not in fields:
            return None
        missing = [k for k in PLAN_FIELDS if k not in fields]
        if missing:
            raise InputError(f"{where}: field(s) {', '.join(missing)} missing (a balance plan needs all of {', '.join(PLAN_FIELDS)})")
        down = np.asarray(fields["balance_down"], dtype=np.float64)
        T = down.shape[0] if down.ndim == 2 else -1
        shapes = {"balance_down": (T, 3), "balance_rate": (T, 3), "balance_tilt_matrix": (T, nj, 3),
                  "balance_rate_matrix": (T, nj, 3)}
        arrays = {}
        for key, shape in shapes.items():
            value = np.asarray(fields[key])
            if value.dtype.kind not in "fi" or value.shape != shape or T < 1:
                raise InputError(f"{where}: field '{key}' must be a float array of shape {shape}, got {value.dtype} {value.shape}")
            value = value.astype(np.float64)
            if not np.isfinite(value).all():
                raise InputError(f"{where}: field '{key}' is not finite at frame {int(np.argwhere(~np.isfinite(value))[0, 0])}")
            arrays[key] = value
        fps = float(np.asarray(fields["balance_fps"]).reshape(-1)[0]) if np.asarray(fields["balance_fps"]).size == 1 else -1.0
        if not 1.0 <= fps <= 1000.0:
            raise InputError(f"{where}: field 'balance_fps' must be one number in [1, 1000], got {fields['balance_fps']!r}")
        try:
            config = BalanceConfig.from_dict(json.loads(str(fields["balance_config"])))
        except (ValueError, TypeError) as exc:
            raise InputError(f"{where}: field 'balance_config' is not a balance configuration: {exc}") from None
        return cls(fps=fps, down=arrays["balance_down"], rate=arrays["balance_rate"],
                   tilt_matrix=arrays["balance_tilt_matrix"], rate_matrix=arrays["balance_rate_matrix"], config=config,
                   stepping=SteppingPlan.from_fields(fields, T, nj, where))


def imu_frame(model: mujoco.MjModel, root_body: int) -> tuple[int, int]:
    """(object type, id) of the IMU: the site named ``imu`` when the model has one, else the
    base body's frame."""
    site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, "imu")
    if site >= 0:
        return int(mujoco.mjtObj.mjOBJ_SITE), site
    return int(mujoco.mjtObj.mjOBJ_BODY), int(root_body)


def leg_roles(index) -> tuple[np.ndarray, np.ndarray]:
    """Role (index into :data:`ROLES`, -1: none) and leg (0 left, 1 right, -1: none) of each
    actuated joint [nj], from the chain of hinges from each sole body up to the base."""
    model = index.kin_model
    data = mujoco.MjData(model)
    data.qpos[:] = index.nominal_qpos
    mujoco.mj_kinematics(model, data)
    joint_of = {int(mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n)): j for j, n in enumerate(index.joint_names)}
    role = np.full(index.nj, -1, dtype=int)
    side = np.full(index.nj, -1, dtype=int)
    for leg, body in enumerate(index.sole_body):
        pitch, roll = [], []
        b = int(body)
        while b > 0 and b != index.root_body:
            for jid in range(model.body_jntadr[b], model.body_jntadr[b] + model.body_jntnum[b]):
                if jid not in joint_of:
                    continue
                axis = np.abs(data.xaxis[jid])
                kind = int(np.argmax(axis))  # 0: roll (x), 1: pitch (y), 2: yaw (z)
                if kind == 2:
                    role[joint_of[jid]] = ROLES.index("hip_yaw")
                    side[joint_of[jid]] = leg
                (roll if kind == 0 else pitch if kind == 1 else []).append(joint_of[jid])
            b = int(model.body_parentid[b])
        for k, j in enumerate(pitch):  # pitch joints from the sole upward
            role[j] = ROLES.index("ankle_pitch" if k == 0 else "hip_pitch" if k == len(pitch) - 1 else "knee")
            side[j] = leg
        for k, j in enumerate(roll):
            role[j] = ROLES.index("ankle_roll" if k == 0 else "hip_roll")
            side[j] = leg
    return role, side


def support_weights(contacts: np.ndarray, fps: float, swing_share: float) -> np.ndarray:
    """[T, 2] weight of each leg's correction from the reference contacts [T, 2] (bool):
    1 in contact, ``swing_share`` in the air, smoothed over 0.1 s so touchdowns do not step the goals."""
    w = np.where(np.asarray(contacts, dtype=bool), 1.0, float(swing_share))
    half = max(0, int(round(0.05 * fps)))
    if half:
        kernel = np.ones(2 * half + 1) / (2 * half + 1)
        padded = np.pad(w, ((half, half), (0, 0)), mode="edge")
        w = np.stack([np.convolve(padded[:, k], kernel, mode="valid") for k in range(2)], axis=1)
    return w


def build_plan(index, qpos: np.ndarray, fps: float, contacts: np.ndarray,
               config: BalanceConfig | None = None, stepping: SteppingPlan | None = None) -> BalancePlan:
    """The controller's plan for the reference ``qpos`` [T, nq] at ``fps`` with foot contacts
    ``contacts`` [T, 2] (left, right; bool) on robot ``index`` (a RobotIndex); ``stepping``:
    the foothold tracking of a walk (:func:`.stepping.build_stepping` of the same frames)."""
    config = config or BalanceConfig()
    qpos = np.asarray(qpos, dtype=np.float64)
    T = qpos.shape[0]
    model = index.kin_model
    data = mujoco.MjData(model)
    kind, obj = imu_frame(model, index.root_body)
    joint_ids = [int(mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n)) for n in index.joint_names]
    rot = np.zeros((T, 3, 3))
    axes = np.zeros((T, index.nj, 3))
    for t in range(T):
        data.qpos[:] = qpos[t]
        mujoco.mj_kinematics(model, data)
        frame = data.site_xmat[obj] if kind == mujoco.mjtObj.mjOBJ_SITE else data.xmat[obj]
        rot[t] = frame.reshape(3, 3)
        axes[t] = data.xaxis[joint_ids]
    down = -rot[:, 2, :]  # R^T (0, 0, -1): the world's down in the IMU frame
    # IMU angular velocity (IMU frame) from central differences of the attitude
    rate = np.zeros((T, 3))
    if T > 1:
        nxt = np.concatenate([rot[1:], rot[-1:]])
        prv = np.concatenate([rot[:1], rot[:-1]])
        span = np.full(T, 2.0 / fps)
        span[0] = span[-1] = 1.0 / fps
        dR = np.einsum("tji,tjk->tik", rot, nxt - prv) / span[:, None, None]  # R^T dR/dt (skew)
        rate = 0.5 * np.stack([dR[:, 2, 1] - dR[:, 1, 2], dR[:, 0, 2] - dR[:, 2, 0], dR[:, 1, 0] - dR[:, 0, 1]], axis=1)
    role, side = leg_roles(index)
    weight = support_weights(contacts, fps, config.swing_share)  # [T, 2]
    kp = np.array([config.tilt_gain.get(r, 0.0) for r in ROLES] + [0.0])[role]
    kd = np.array([config.rate_gain.get(r, 0.0) for r in ROLES] + [0.0])[role]
    s = np.where(side[None, :] >= 0, weight[:, np.maximum(side, 0)], 0.0)  # [T, nj]
    # tilt acts through each joint's horizontal axis part, yaw through a hip yaw's vertical part
    used = axes.copy()
    yaw = role == ROLES.index("hip_yaw")
    used[:, ~yaw, 2] = 0.0
    used[:, yaw, :2] = 0.0
    in_imu = np.einsum("tkn,tjk->tjn", rot, used)  # R^T a_j per joint: [T, nj, 3]
    tilt_matrix = (s * kp)[:, :, None] * in_imu
    rate_matrix = (s * kd)[:, :, None] * in_imu
    return BalancePlan(fps=float(fps), down=down, rate=rate, tilt_matrix=tilt_matrix, rate_matrix=rate_matrix,
                       config=config, stepping=stepping)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross product of ``a`` [B, 3] and ``b`` [B, 3] or [3]: the arithmetic of
    ``np.cross`` without its per-call axis handling (this runs every tick)."""
    a0, a1, a2 = a[:, 0], a[:, 1], a[:, 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out = np.empty((a.shape[0], 3))
    out[:, 0] = a1 * b2 - a2 * b1
    out[:, 1] = a2 * b0 - a0 * b2
    out[:, 2] = a0 * b1 - a1 * b0
    return out


class BalanceController:
    """The balance feedback of the module docstring, for a batch of ``batch`` robots.

    ``step`` is called once per tick, in time order, from ``reset`` on.  Goals and joint
    ranges are in the robot's joint order (rad)."""

    def __init__(self, plan: BalancePlan, joint_range: np.ndarray, batch: int = 1):
        self.plan = plan
        self.config = plan.config
        self.low = np.asarray(joint_range, dtype=np.float64)[:, 0]
        self.high = np.asarray(joint_range, dtype=np.float64)[:, 1]
        self.batch = int(batch)
        self.dt = 1.0 / float(self.config.rate_hz)
        self.tracker = FootholdTracker(plan.stepping, plan.fps, self.batch) if plan.stepping is not None else None
        self.reset()

    def reset(self, down: np.ndarray | None = None) -> None:
        """Start: the attitude estimate is the reference's at frame 0 (or ``down`` [B, 3])."""
        start = self.plan.down[0] if down is None else np.asarray(down, dtype=np.float64)
        self.down = np.broadcast_to(start, (self.batch, 3)).copy()
        self.gyro = np.broadcast_to(self.plan.rate[0], (self.batch, 3)).copy()
        self.last_offset = np.zeros((self.batch, self.low.size))
        if self.tracker is not None:
            self.tracker.reset()

    def clone(self, batch: int) -> "BalanceController":
        """A controller for ``batch`` robots starting from this one's estimator state (robot 0's)."""
        other = BalanceController(self.plan, np.stack([self.low, self.high], axis=1), batch)
        other.down[:] = self.down[0]
        other.gyro[:] = self.gyro[0]
        other.last_offset[:] = self.last_offset[0]
        if self.tracker is not None:
            other.tracker.copy_state(self.tracker)
        return other

    def _at(self, t: float):
        """Plan quantities at time ``t`` (linear between frames, held past the ends)."""
        x = min(max(float(t) * self.plan.fps, 0.0), float(self.plan.num_frames - 1))
        i = int(math.floor(x))
        k = min(i + 1, self.plan.num_frames - 1)
        f = x - i
        down = (1 - f) * self.plan.down[i] + f * self.plan.down[k]
        down /= max(math.sqrt(float(down @ down)), 1e-9)
        rate = (1 - f) * self.plan.rate[i] + f * self.plan.rate[k]
        tilt = (1 - f) * self.plan.tilt_matrix[i] + f * self.plan.tilt_matrix[k]
        damp = (1 - f) * self.plan.rate_matrix[i] + f * self.plan.rate_matrix[k]
        return down, rate, tilt, damp

    def step(self, t: float, goals: np.ndarray, gyro: np.ndarray, accel: np.ndarray,
             present: np.ndarray | None = None) -> np.ndarray:
        """Corrected goals [B, nj] for tick time ``t`` (s) from the trajectory's ``goals``
        [B, nj] and the IMU: ``gyro`` [B, 3] rad/s and ``accel`` [B, 3] m/s^2 (IMU frame).
        ``present`` [B, nj] (servo present positions, rad; None when not read this tick) feeds
        the foothold tracking of a walk.  Non-finite sensor values hold the last correction (a
        glitch is not acted on)."""
        goals = np.atleast_2d(np.asarray(goals, dtype=np.float64))
        gyro = np.atleast_2d(np.asarray(gyro, dtype=np.float64))
        accel = np.atleast_2d(np.asarray(accel, dtype=np.float64))
        ok = np.isfinite(gyro).all(axis=1) & np.isfinite(accel).all(axis=1)
        all_ok = bool(ok.all())  # the usual tick: no glitch to mask out
        cfg = self.config
        down_ref, rate_ref, tilt_m, rate_m = self._at(t)
        g = gyro if all_ok else np.where(ok[:, None], gyro, self.gyro)
        self.gyro = self.gyro + cfg.gyro_filter * (g - self.gyro)
        pred = self.down - self.dt * _cross(self.gyro, self.down)
        norm = np.sqrt((accel * accel).sum(axis=1, keepdims=True))
        use = norm > 1e-6 if all_ok else ok[:, None] & (norm > 1e-6)
        measured = np.where(use, -accel / np.maximum(norm, 1e-9), pred)
        down = (1 - cfg.accel_weight) * pred + cfg.accel_weight * measured
        self.down = down / np.maximum(np.sqrt((down * down).sum(axis=1, keepdims=True)), 1e-9)
        tilt_err = _cross(self.down, down_ref)            # [B, 3]
        rate_err = self.gyro - rate_ref                   # [B, 3]
        offset = tilt_err @ tilt_m.T + rate_err @ rate_m.T  # [B, nj]
        offset = np.minimum(np.maximum(offset, -cfg.max_offset_rad), cfg.max_offset_rad)
        if not all_ok:
            offset = np.where(ok[:, None], offset, self.last_offset)
        self.last_offset = offset
        if self.tracker is not None:
            if present is not None:
                present = np.atleast_2d(np.asarray(present, dtype=np.float64))
            step = self.tracker.offsets(t, present)
            offset = offset + np.minimum(np.maximum(step, -cfg.max_offset_rad), cfg.max_offset_rad)
        return np.minimum(np.maximum(goals + offset, self.low), self.high)

"""The robot in MuJoCo with its servos and torso IMU, stepped at the servo bus rate.

:func:`servo_model` copies the robot model for tracking (validation's open-loop rollout uses it
too).  :class:`ServoPhysics` steps a batch of robots tick by tick: at each controller tick
(``rate_hz``, 125 Hz by default) it reads each robot's IMU and joint positions as a rig reads
its IMU and servo present positions, lets the
:class:`~motok_robot.feasibility.balance.BalanceController` correct the goals (or passes them
through when there is none), writes them to the position actuators and advances the physics by
the tick's steps (2 steps of 4 ms at 125 Hz).  Goals are held over a tick, as a servo holds the
last goal it was sent.

IMU readings (:func:`read_imu`) are what MuJoCo's gyro and accelerometer sensors give at the
IMU frame (the ``imu`` site, else the base body): angular velocity in the IMU frame and linear
acceleration including gravity (+9.81 m/s^2 up at rest), both for the state at the start of
the last physics step (a one-step sensor delay).
"""

from __future__ import annotations

import copy
import time

import mujoco
import numpy as np

from motok_robot.feasibility.balance import BalanceController, BalancePlan, imu_frame


def servo_model(index, timestep_s: float = 0.0, motor_kp_per_nm: float = 10.0,
                motor_kd_ratio: float = 0.05) -> tuple[mujoco.MjModel, np.ndarray]:
    """Copy of the robot model ready for tracking, and each actuator's gear [nu].

    ``timestep_s`` > 0 replaces the model's own step (0 keeps it).  Position actuators are kept; plain
    motors get a PD servo law ``kp = motor_kp_per_nm x force limit`` (N m/rad),
    ``kd = motor_kd_ratio x kp``, their force limits kept."""
    model = copy.deepcopy(index.model)
    if timestep_s > 0:
        model.opt.timestep = timestep_s
    gear = model.actuator_gear[:, 0].copy()
    gear[gear == 0] = 1.0
    for a in range(model.nu):
        if index.actuator_is_position[a] or index.actuator_joint[a] < 0:
            continue
        limit = float(np.max(np.abs(model.actuator_forcerange[a]))) if model.actuator_forcelimited[a] else 0.0
        if limit <= 0:
            limit = float(index.torque_limit[index.actuator_joint[a]])
        kp = motor_kp_per_nm * limit
        kd = motor_kd_ratio * kp
        model.actuator_gaintype[a] = mujoco.mjtGain.mjGAIN_FIXED
        model.actuator_gainprm[a, :3] = [kp / gear[a] ** 2, 0, 0]
        model.actuator_biastype[a] = mujoco.mjtBias.mjBIAS_AFFINE
        model.actuator_biasprm[a, :3] = [0.0, -kp / gear[a] ** 2, -kd / gear[a] ** 2]
        model.actuator_ctrllimited[a] = 0
    return model, gear


def read_imu(model: mujoco.MjModel, data: mujoco.MjData, imu: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """(gyro [3] rad/s, accelerometer [3] m/s^2) in the IMU frame ``imu`` = (object type, id)."""
    mujoco.mj_rnePostConstraint(model, data)
    res = np.zeros(6)
    mujoco.mj_objectVelocity(model, data, imu[0], imu[1], res, 1)
    gyro = res[:3].copy()
    mujoco.mj_objectAcceleration(model, data, imu[0], imu[1], res, 1)
    return gyro, res[3:].copy()


class ServoPhysics:
    """Tick-by-tick physics of a batch of robots (see the module docstring)."""

    def __init__(self, index, timestep_s: float = 0.0, rate_hz: float = 125.0, motor_kp_per_nm: float = 10.0,
                 motor_kd_ratio: float = 0.05, model: mujoco.MjModel | None = None):
        self.index = index
        if model is None:
            model, gear = servo_model(index, timestep_s, motor_kp_per_nm, motor_kd_ratio)
        else:
            gear = model.actuator_gear[:, 0].copy()
            gear[gear == 0] = 1.0
        self.model, self.gear = model, gear
        self.dt = float(model.opt.timestep)
        self.rate_hz = float(rate_hz)
        self.steps_per_tick = max(1, int(round(1.0 / (self.rate_hz * self.dt))))
        self.tick_s = self.steps_per_tick * self.dt
        self.imu = imu_frame(model, index.root_body)
        self.actuator_of_joint = np.full(index.nj, -1, dtype=int)
        for a in range(model.nu):
            if index.actuator_joint[a] >= 0:
                self.actuator_of_joint[index.actuator_joint[a]] = a
        self.spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        self.nstate = mujoco.mj_stateSize(model, self.spec)

    def initial_state(self, qpos0: np.ndarray, qvel0: np.ndarray, goals0: np.ndarray) -> np.ndarray:
        """Full physics state [nstate] at ``qpos0``, ``qvel0`` with the actuators at ``goals0``."""
        data = mujoco.MjData(self.model)
        data.qpos[:] = qpos0
        data.qvel[:] = qvel0
        self._write_goals(data, goals0)
        mujoco.mj_forward(self.model, data)
        state = np.zeros(self.nstate)
        mujoco.mj_getState(self.model, data, state, self.spec)
        return state

    def _write_goals(self, data: mujoco.MjData, goals: np.ndarray) -> None:
        active = self.actuator_of_joint >= 0
        data.ctrl[self.actuator_of_joint[active]] = self.gear[self.actuator_of_joint[active]] * goals[active]

    def new_datas(self, states: np.ndarray) -> list:
        """One MjData per row of ``states`` [B, nstate], set to it (derived quantities computed)."""
        datas = [mujoco.MjData(self.model) for _ in range(states.shape[0])]
        self.set_states(datas, states)
        return datas

    def set_states(self, datas: list, states: np.ndarray) -> None:
        for data, state in zip(datas, states):
            mujoco.mj_setState(self.model, data, state, self.spec)
            mujoco.mj_forward(self.model, data)

    def get_states(self, datas: list) -> np.ndarray:
        out = np.zeros((len(datas), self.nstate))
        for b, data in enumerate(datas):
            mujoco.mj_getState(self.model, data, out[b], self.spec)
        return out

    def tick_goals(self, goals: np.ndarray, fps: float, tick0: int, nticks: int) -> np.ndarray:
        """Goals [B, nticks, nj] of ticks ``tick0 .. tick0 + nticks - 1`` from goal frames
        ``goals`` [B, T, nj] at ``fps``: linear between frames at each tick's start time, as
        playback sends them (:mod:`motok_robot.servo.streamer`)."""
        T = goals.shape[1]
        tick_start = (tick0 + np.arange(nticks)) * self.tick_s
        x = np.clip(tick_start * fps, 0, T - 1)
        i0 = np.floor(x).astype(int)
        i1 = np.minimum(i0 + 1, T - 1)
        f = (x - i0)[None, :, None]
        return (1 - f) * goals[:, i0] + f * goals[:, i1]

    def advance(self, datas: list, goals: np.ndarray, fps: float, tick0: int, nticks: int,
                controller: BalanceController | None = None, on_tick=None, states: np.ndarray | None = None,
                perturb=None, previous: np.ndarray | None = None) -> np.ndarray:
        """Advance ``datas`` (B robots) by ``nticks`` ticks from tick ``tick0`` tracking goal
        frames ``goals`` [B, T, nj] (or [T, nj]) at ``fps``.  ``on_tick(k, datas)`` is called
        after each tick (k counted from ``tick0``), ``states`` [B, nticks x steps_per_tick,
        nstate] receives the state after each step, ``perturb(step, b, data)`` may apply forces
        before a step.  Every command then goes through playback's limits: the joint range and a
        per-tick change of at most ``velocity_limit x tick`` from ``previous`` [B, nj] (default:
        the first planned goal, where playback's ramp-in ends).  Returns the goals sent
        [B, nticks, nj]."""
        B = len(datas)
        goals = np.asarray(goals, dtype=np.float64)
        if goals.ndim == 2:
            goals = np.broadcast_to(goals, (B,) + goals.shape)
        planned = self.tick_goals(goals, fps, tick0, nticks)
        commands = np.zeros_like(planned)
        low, high = self.index.joint_range[:, 0], self.index.joint_range[:, 1]
        max_step = np.asarray(self.index.velocity_limit, dtype=np.float64) * self.tick_s
        last = planned[:, 0].copy() if previous is None else np.broadcast_to(previous, planned[:, 0].shape).copy()
        gyro = np.zeros((B, 3))
        accel = np.zeros((B, 3))
        present = np.zeros((B, self.index.nj))
        joint_qpos = np.asarray(self.index.qpos_adr, dtype=int)
        step = 0
        for k in range(nticks):
            command = planned[:, k]
            if controller is not None:
                for b, data in enumerate(datas):
                    gyro[b], accel[b] = read_imu(self.model, data, self.imu)
                    present[b] = data.qpos[joint_qpos]
                command = controller.step((tick0 + k) * self.tick_s, command, gyro, accel, present)
            command = np.clip(np.clip(command, last - max_step, last + max_step), low, high)
            last = command
            commands[:, k] = command
            for b, data in enumerate(datas):
                self._write_goals(data, command[b])
            for _ in range(self.steps_per_tick):
                for b, data in enumerate(datas):
                    if perturb is not None:
                        perturb((tick0 + k) * self.steps_per_tick + step % self.steps_per_tick, b, data)
                    mujoco.mj_step(self.model, data)
                    if states is not None:
                        mujoco.mj_getState(self.model, data, states[b, step], self.spec)
                step += 1
            if on_tick is not None:
                on_tick(tick0 + k, datas)
        return commands

    def run(self, initial: np.ndarray, goals: np.ndarray, fps: float, duration_s: float,
            controller: BalanceController | None = None, perturb=None) -> dict:
        """Roll ``B`` robots out for ``duration_s`` from ``initial`` [B, nstate] tracking goal
        frames ``goals`` [B, T, nj] (or [T, nj] for all) at ``fps`` (see :meth:`advance`).
        Returns ``{"states": [B, nstep, nstate] after each step, "step_time": [nstep] s,
        "commands": [B, nticks, nj] goals sent, "wall_s"}``."""
        start = time.perf_counter()
        initial = np.atleast_2d(initial)
        nticks = max(1, int(round(duration_s / self.tick_s)))
        nstep = nticks * self.steps_per_tick
        datas = self.new_datas(initial)
        states = np.zeros((len(datas), nstep, self.nstate))
        commands = self.advance(datas, goals, fps, 0, nticks, controller, states=states, perturb=perturb)
        return {"states": states, "step_time": (np.arange(nstep) + 1) * self.dt, "commands": commands,
                "wall_s": time.perf_counter() - start}


def execute(index, qpos0: np.ndarray, goals: np.ndarray, fps: float, plan: BalancePlan | None,
            timestep_s: float = 0.0, initial_qvel: np.ndarray | None = None,
            fall_tilt_rad: float = 1.0) -> tuple[np.ndarray, int | None]:
    """The rollout of ``goals`` [T, nj] from ``qpos0`` (at rest unless ``initial_qvel``) with the
    plan's controller: qpos [T, nq] at the frame times, and the first frame whose torso is tilted
    more than ``fall_tilt_rad`` from vertical (validation's ``fall_tilt_rad``), None if none is."""
    physics = ServoPhysics(index, timestep_s=timestep_s, rate_hz=plan.config.rate_hz if plan else 125.0)
    T = goals.shape[0]
    qvel0 = np.zeros(index.model.nv) if initial_qvel is None else initial_qvel
    initial = physics.initial_state(qpos0, qvel0, goals[0])
    nticks = max(1, int(round((T - 1) / fps / physics.tick_s)))
    datas = physics.new_datas(initial[None])
    states = np.zeros((1, nticks * physics.steps_per_tick, physics.nstate))
    controller = BalanceController(plan, index.joint_range) if plan is not None else None
    physics.advance(datas, goals[None], fps, 0, nticks, controller, states=states)
    nq = physics.model.nq
    all_qpos = np.vstack([initial[None, 1:1 + nq], states[0, :, 1:1 + nq]])
    step = np.clip(np.round(np.arange(T) / fps / physics.dt).astype(int), 0, all_qpos.shape[0] - 1)
    qpos = all_qpos[step]
    quat = qpos[:, 3:7] / np.linalg.norm(qpos[:, 3:7], axis=1, keepdims=True)
    up_z = 1 - 2 * (quat[:, 1] ** 2 + quat[:, 2] ** 2)
    tilted = np.nonzero(up_z < np.cos(fall_tilt_rad))[0]
    return qpos, int(tilted[0]) if tilted.size else None

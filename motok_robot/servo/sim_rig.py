"""A simulated rig: the servo bus is the MuJoCo model's position actuators, stepped in real time.

:class:`SimRig` implements :class:`~motok_robot.servo.bus.ServoBus`, so the same
:class:`~motok_robot.servo.streamer.Streamer` (report gate, pre-flight, ramp, limiter, log)
plays a trajectory on the simulated robot.  Goal ticks are converted back to joint angles with
the servo map and written to the actuators' ``ctrl``; present positions are the joint ``qpos``
in ticks.  Physics is advanced to the clock's time (seconds since the rig was built) on every
bus call, so with :class:`~motok_robot.servo.timing.RealClock` the robot moves in real time and
with :class:`~motok_robot.servo.timing.FakeClock` it moves in the streamer's time.  The robot
starts free-standing at ``robot.nominal_qpos()``.

The rig has the torso IMU too (:meth:`SimRig.read_imu`): gyro and accelerometer at the MJCF's
``imu`` site (else the base body) from the MuJoCo state, computed by
:func:`motok_robot.feasibility.physics.read_imu`, the function validation's closed-loop rollout
reads its IMU with.  It answers at the ID of the description's ``[bus.imu]`` (200 when none).

``render_path`` (MP4/GIF): the state is sampled at ``render_fps`` while playing and the frames
are drawn from the model's ``track`` camera when the rig is closed (rendering stays off the
real-time path).
:attr:`SimRig.fell` tells whether the base (pelvis) dropped below ``fall_fraction`` of its
start height at any time; :attr:`min_base_height` is the lowest base height (m).
"""

from __future__ import annotations

import copy
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from motok_robot.errors import InputError
from motok_robot.servo import control_table as ct
from motok_robot.servo.bus import ServoBus, ServoCommError
from motok_robot.servo.convert import ServoMap
from motok_robot.servo.timing import RealClock


class SimRig(ServoBus):
    """Servo bus backed by a MuJoCo simulation of ``robot`` (see the module docstring)."""

    def __init__(self, robot, *, clock=None, initial_qpos: np.ndarray | None = None,
                 render_path: str | Path | None = None, render_fps: float = 30.0, width: int = 640,
                 height: int = 480, camera: str = "track", fall_fraction: float = 0.6,
                 max_lag_s: float = 0.25):
        if render_path is not None:
            os.environ.setdefault("MUJOCO_GL", "egl")
        import mujoco

        self._mj = mujoco
        self.port_name = f"sim:{robot.name}"
        self.robot = robot
        self.model = copy.deepcopy(robot.model)  # torque-off edits actuator gains on our copy only
        self.data = mujoco.MjData(self.model)
        self.map = ServoMap.from_specs(robot.servos)
        self.clock = clock or RealClock()
        index = {name: i for i, name in enumerate(robot.joint_names)}
        missing = [j for j in self.map.joints if j not in index]
        if missing:
            raise InputError(f"robot {robot.name}: servo joint(s) {', '.join(missing)} not in the model")
        joint_of_actuator = np.asarray(robot.actuator_joint)
        self._qpos_adr: dict[int, int] = {}
        self._actuator: dict[int, int] = {}
        self._column: dict[int, int] = {}
        for k, (servo_id, joint) in enumerate(zip(self.map.ids, self.map.joints)):
            j = index[joint]
            actuators = np.nonzero(joint_of_actuator == j)[0]
            if len(actuators) != 1:
                raise InputError(f"robot {robot.name}: joint {joint} needs exactly one actuator")
            self._qpos_adr[int(servo_id)] = int(robot.qpos_adr[j])
            self._actuator[int(servo_id)] = int(actuators[0])
            self._column[int(servo_id)] = k
        self._gains = {a: (self.model.actuator_gainprm[a].copy(), self.model.actuator_biasprm[a].copy())
                       for a in self._actuator.values()}
        qpos0 = robot.nominal_qpos() if initial_qpos is None else np.asarray(initial_qpos, dtype=np.float64)
        self.data.qpos[:] = qpos0
        mujoco.mj_forward(self.model, self.data)
        for servo_id, a in self._actuator.items():
            self.data.ctrl[a] = self.data.qpos[self._qpos_adr[servo_id]]
        self.start_base_height = float(self.data.qpos[2])
        self.min_base_height = self.start_base_height
        self.fall_fraction = fall_fraction
        self.max_lag_s = max_lag_s
        from motok_robot.feasibility.balance import imu_frame

        self._imu = imu_frame(self.model, int(self.model.jnt_bodyid[0]))  # the free joint's body
        spec = getattr(robot.bus, "imu", None) if robot.bus is not None else None
        self.imu_id = int(spec.id) if spec is not None else 200
        self._t0 = self.clock.now()
        self.steps = 0
        self.render_path = Path(render_path) if render_path is not None else None
        self.render_fps = render_fps
        self.snapshots: list[np.ndarray] = []  # qpos [nq] sampled at render_fps
        self._size = (height, width)
        self._camera = camera
        if self.render_path is not None:
            self._capture()
        self.closed = False

    # ---------------------------------------------------------------- physics
    @property
    def fell(self) -> bool:
        return self.min_base_height < self.fall_fraction * self.start_base_height

    def _capture(self) -> None:
        self.snapshots.append(self.data.qpos.copy())

    def advance(self) -> None:
        """Step physics up to the clock's time (at most ``max_lag_s`` behind: no runaway catch-up)."""
        if self.closed:
            raise ServoCommError(None, "the simulated rig is closed", self.port_name)
        target = self.clock.now() - self._t0
        dt = self.model.opt.timestep
        if target - self.data.time > self.max_lag_s:  # the host stalled: do not replay the stall
            self._t0 += target - self.data.time - self.max_lag_s
            target = self.data.time + self.max_lag_s
        while self.data.time + 0.5 * dt < target:
            self._mj.mj_step(self.model, self.data)
            self.steps += 1
            self.min_base_height = min(self.min_base_height, float(self.data.qpos[2]))
            if self.render_path is not None and self.data.time >= len(self.snapshots) / self.render_fps:
                self._capture()

    def joint_angles(self, ids: Sequence[int]) -> np.ndarray:
        """Joint angles (rad) of the servos ``ids``, float64 [len(ids)]."""
        return np.array([self.data.qpos[self._qpos_adr[int(i)]] for i in ids])

    def _check_ids(self, ids: Sequence[int]) -> None:
        unknown = [int(i) for i in ids if int(i) not in self._actuator]
        if unknown:
            raise ServoCommError(unknown[0], "no such servo in the simulated rig (no reply)", self.port_name)

    # ---------------------------------------------------------------- ServoBus
    def ping(self, servo_id: int) -> int:
        self._check_ids([servo_id])
        return ct.MODEL_NUMBERS.get(self.map.models[self._column[int(servo_id)]].upper(), 0)

    def scan(self) -> dict[int, int]:
        return {int(i): self.ping(int(i)) for i in self.map.ids}

    def read_present_positions(self, ids, *, allow_alert=False):
        self._check_ids(ids)
        self.advance()
        cols = [self._column[int(i)] for i in ids]
        sub = self.map.select(cols)
        return np.rint(sub.ticks_float(self.joint_angles(ids))).astype(np.int64)

    def write_goal_positions(self, ids, ticks):
        self._check_ids(ids)
        self.advance()
        cols = [self._column[int(i)] for i in ids]
        angles = self.map.select(cols).to_rad(np.asarray(ticks))
        for servo_id, angle in zip(ids, angles):
            self.data.ctrl[self._actuator[int(servo_id)]] = angle

    def set_torque(self, ids, enabled):
        self._check_ids(ids)
        for servo_id in ids:
            a = self._actuator[int(servo_id)]
            gain, bias = self._gains[a]
            self.model.actuator_gainprm[a] = gain if enabled else 0.0
            self.model.actuator_biasprm[a] = bias if enabled else 0.0
            if enabled:
                self.data.ctrl[a] = self.data.qpos[self._qpos_adr[int(servo_id)]]

    def set_profile_velocity(self, ids, units):
        self._check_ids(ids)  # the actuator model has no profile generator; the streamer's limiter applies

    def read_hardware_errors(self, ids):
        self._check_ids(ids)
        return {int(i): 0 for i in ids}

    def set_bus_watchdog(self, ids, units):
        self._check_ids(ids)

    def read_bus_watchdog(self, ids):
        self._check_ids(ids)
        return {int(i): 0 for i in ids}  # no watchdog in simulation

    def set_return_delay_time(self, ids, units):
        self._check_ids(ids)

    #: the simulated robot is released at its nominal pose and has not settled on the floor yet
    imu_at_rest_in_preflight = False

    def ping_imu(self) -> int:
        if self.closed:
            raise ServoCommError(self.imu_id, "the simulated rig is closed", self.port_name)
        return 0

    def read_imu(self):
        """(gyro [3] rad/s, accelerometer [3] m/s^2) in the IMU frame, after stepping to the clock."""
        from motok_robot.feasibility.physics import read_imu

        self.advance()
        return read_imu(self.model, self.data, self._imu)

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        if self.render_path is not None and self.snapshots:
            self.render(self.render_path)

    def render(self, path: str | Path) -> Path:
        """Draw the sampled states to a video (MP4/GIF) at ``render_fps``; returns its path."""
        import imageio.v2 as imageio
        from tqdm import tqdm

        mujoco = self._mj
        height, width = self._size
        cam = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_CAMERA, self._camera)
        data = mujoco.MjData(self.model)
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        with mujoco.Renderer(self.model, height=height, width=width) as renderer, \
                imageio.get_writer(path, fps=self.render_fps) as writer:
            for qpos in tqdm(self.snapshots, desc="rendering", unit="frame", disable=None):
                data.qpos[:] = qpos
                mujoco.mj_forward(self.model, data)
                renderer.update_scene(data, camera=cam if cam >= 0 else -1)
                writer.append_data(renderer.render())
        return path

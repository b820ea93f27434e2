"""Servo goals with inverse-dynamics feedforward, and the ``servo_goals.npz`` file.

A position servo (a Dynamixel in position mode, MuJoCo's ``<position>`` actuator) produces

    tau = k (goal - q) - k_d qdot          (k: stiffness, k_d: velocity damping of the servo)

so a goal equal to the reference angle only produces torque once the joint *lags* the
reference.  On a compliant servo (op3_like's XM430: k = 19 N m/rad) the stance leg sags
and the swing leg trails by 10-30 degrees in a walk, and an open-loop replay falls although
the motion itself needs no more torque than the servo has (docs/validation.md).

Feedforward moves each goal by the torque the motion needs:

    goal = q_ref + (tau_ref + k_d qdot_ref) / k

where ``tau_ref`` is the required joint torque of the validator's inverse dynamics
(:mod:`motok_robot.feasibility.dynamics`: ``mj_inverse`` with the ground reaction distributed over
the soles in contact; it includes the joints' passive damping and armature) clipped to the
actuator's force limit.  The goals are then clamped to the joint range and rate-limited to
a fraction of the servo velocity limit per frame (``ValidationConfig.servo_goal_velocity_fraction``,
0.95, clear of playback's whole-tick step), so that the playback
streamer's own clamps (position limits, ``velocity_limit / rate`` per tick on the frames
linearly interpolated to its rate) never change them: what the physics rollout tracked is
exactly what the servos receive.  It is still open loop: no sensor is read, and a servo
whose real stiffness differs from the robot description gets a proportionally wrong offset
(calibrate ``kp`` in the MJCF to the servo's P gain).

``servo_goals.npz`` (written by validation next to ``report.json``; docs/CONTRACTS.md)::

    goals         float64 [T, nj]  servo goal angles (rad), robot joint order
    joint_names   str [nj]
    fps           float
    robot         str
    mode          str              "feedforward" (or "reference": goals = the joint angles;
                                   "feasibility": refined by the feasibility stage)
    source_sha256 str              sha256 of the robot.npz the goals were computed from
    balance_*                      the balance controller's plan when validation ran closed loop
                                   (:class:`motok_robot.feasibility.balance.BalancePlan`)
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from motok_robot.errors import InputError
from motok_robot.npz_files import read_npz_fields

GOALS_FILE = "servo_goals.npz"
MODES = ("feedforward", "reference", "feasibility")


def servo_gains(model, index) -> tuple[np.ndarray, np.ndarray]:
    """Effective stiffness ``k`` (N m/rad) and damping ``k_d`` (N m s/rad) per joint [nj] of the
    servo model the rollout uses (``model`` from :func:`motok_robot.feasibility.physics.servo_model`).

    For an actuator with gear ``g``, control ``g x goal`` and an affine bias, the joint torque
    is ``g^2 (gain ctrl/g + bias1 q + bias2 qdot)``, so ``k = g^2 gain`` and ``k_d = -g^2 bias2``.
    A joint without a position-type actuator gets ``k = 0`` (no feedforward is possible).
    """
    k = np.zeros(index.nj)
    kd = np.zeros(index.nj)
    for a in range(model.nu):
        j = int(index.actuator_joint[a])
        if j < 0:
            continue
        gear = float(model.actuator_gear[a, 0]) or 1.0
        gain = float(model.actuator_gainprm[a, 0])
        if gain <= 0 or abs(float(model.actuator_biasprm[a, 1]) + gain) > 1e-9 * max(gain, 1.0):
            continue  # not a position servo (bias -gain x length)
        k[j] = gear * gear * gain
        kd[j] = -gear * gear * float(model.actuator_biasprm[a, 2])
    return k, kd


def feedforward_goals(index, joint_pos: np.ndarray, joint_vel: np.ndarray, torque: np.ndarray,
                      fps: float, stiffness: np.ndarray, damping: np.ndarray,
                      velocity_fraction: float = 1.0) -> np.ndarray:
    """Servo goals [T, nj] (rad) for reference joint angles ``joint_pos`` [T, nj], velocities
    ``joint_vel`` [T, nj] and required torques ``torque`` [T, nj] (see the module docstring).

    Joints with zero ``stiffness`` keep the reference angle (pass zero stiffness everywhere
    for plain reference goals).  The result lies in the joint range and changes by at most
    ``velocity_fraction x velocity_limit / fps`` per frame.
    """
    limit = np.asarray(index.torque_limit, dtype=np.float64)
    tau = np.clip(torque, -limit, limit)
    active = stiffness > 0
    offset = np.zeros_like(joint_pos)
    offset[:, active] = (tau[:, active] + damping[active] * joint_vel[:, active]) / stiffness[active]
    low, high = index.joint_range[:, 0], index.joint_range[:, 1]
    goals = np.clip(joint_pos + offset, low, high)
    step = velocity_fraction * np.asarray(index.velocity_limit, dtype=np.float64) / float(fps)
    for t in range(1, goals.shape[0]):  # sequential: each frame moves at most one step
        goals[t] = np.clip(goals[t], goals[t - 1] - step, goals[t - 1] + step)
    return np.clip(goals, low, high)


def goals_digest(goals: np.ndarray) -> str:
    """SHA-256 of the goal array (float64, C order): what report.json records."""
    return hashlib.sha256(np.ascontiguousarray(goals, dtype=np.float64).tobytes()).hexdigest()


def save_servo_goals(path: str | Path, goals: np.ndarray, joint_names, fps: float, robot: str, mode: str,
                     source_sha256: str | None, plan=None) -> Path:
    """Write ``servo_goals.npz`` (schema in the module docstring), with the balance
    controller's ``plan`` (:class:`~motok_robot.feasibility.balance.BalancePlan`) when given."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    extra = plan.fields() if plan is not None else {}
    np.savez(path, goals=np.asarray(goals, dtype=np.float64), joint_names=np.asarray(list(joint_names)),
             fps=np.float64(fps), robot=np.asarray(robot), mode=np.asarray(mode),
             source_sha256=np.asarray(source_sha256 or ""), **extra)
    return path


def load_servo_goals(path: str | Path, *, expected_sha256: str | None = None) -> dict:
    """Read ``servo_goals.npz``; with ``expected_sha256`` (from report.json) the goal array must
    match it.  Returns ``{"goals", "joint_names", "fps", "robot", "mode", "source_sha256", "plan"}`` ("plan": the balance plan or None).
    Raises :class:`InputError` naming the file and the field."""
    path = Path(path)
    fields = read_npz_fields(path, "servo goals file")  # validation writes it next to report.json
    for key in ("goals", "joint_names", "fps", "mode"):
        if key not in fields:
            raise InputError(f"{path}: field '{key}' missing (servo_goals.npz needs goals, joint_names, fps, mode)")
    goals = np.asarray(fields["goals"], dtype=np.float64)
    names = [str(n) for n in fields["joint_names"]]
    if goals.ndim != 2 or goals.shape[1] != len(names):
        raise InputError(f"{path}: field 'goals' must be [T, {len(names)}] (one column per joint name), got {goals.shape}")
    if not np.isfinite(goals).all():
        frame = int(np.argwhere(~np.isfinite(goals))[0, 0])
        raise InputError(f"{path}: field 'goals' is not finite at frame {frame}")
    mode = str(fields["mode"])
    if mode not in MODES:
        raise InputError(f"{path}: field 'mode' is {mode!r}, expected one of {', '.join(MODES)}")
    if expected_sha256 and goals_digest(goals) != expected_sha256:
        raise InputError(f"{path}: goals differ from the validated ones (sha256 {expected_sha256[:12]}... in the report)")
    from motok_robot.feasibility.balance import BalancePlan

    plan = BalancePlan.from_fields(fields, len(names), str(path))
    if plan is not None and plan.num_frames != goals.shape[0]:
        raise InputError(f"{path}: field 'balance_down' has {plan.num_frames} frames, 'goals' {goals.shape[0]}")
    return {"goals": goals, "joint_names": names, "fps": float(fields["fps"]),
            "robot": str(fields.get("robot", "")), "mode": mode, "source_sha256": str(fields.get("source_sha256", "")),
            "plan": plan}


def goals_for_joints(goals: dict, joints, frames: int, fps: float, where, of) -> np.ndarray:
    """The goal array of ``goals`` (as :func:`load_servo_goals` returns it) as ``[frames,
    len(joints)]`` in the order of ``joints``; InputError naming ``where`` (the goals file) when its
    frames, fps or joint names do not fit ``of`` (the trajectory they are played with)."""
    array = goals["goals"]
    if array.shape[0] != frames or abs(goals["fps"] - fps) > 1e-9:
        raise InputError(f"{where}: field 'goals' has {array.shape[0]} frames at {goals['fps']:g} fps, "
                         f"{of} has {frames} at {fps:g}")
    index = {n: i for i, n in enumerate(goals["joint_names"])}
    lacking = [n for n in joints if n not in index]
    if lacking:
        raise InputError(f"{where}: field 'joint_names' lacks {', '.join(lacking[:5])} of {of}")
    return array[:, [index[n] for n in joints]]

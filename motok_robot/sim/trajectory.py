"""Reading a ``robot.npz`` (see docs/CONTRACTS.md) and checking it against a robot.

:func:`load_robot_npz` returns a :class:`RobotTrajectory`; every mismatch with the robot
(wrong ``nq``, joint names or order, robot name, non-finite values, bad fps, too few frames)
raises :class:`~motok_robot.errors.InputError` naming the file and the field.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from motok_robot.errors import InputError
from motok_robot.limits import check_frames, check_joints, check_rate, check_seconds
from motok_robot.npz_files import read_npz_fields, scalar_field
from retarget.io import check_retime_factor  # light: numpy only


@dataclass
class RobotTrajectory:
    """A joint-space trajectory of one robot.

    qpos:        float64 [T, nq] MuJoCo qpos per frame (free base position m, quaternion wxyz,
                 then hinge angles rad), in the robot model's qpos order.
    fps:         frames per second.
    joint_names: actuated joint names [nj], in qpos order (as in the file).
    robot:       robot name recorded in the file ("" when absent).
    contacts:    bool [T, 2] (left, right) foot contacts planned by retargeting, or None.
    source:      where it came from (a path or a description).
    reference_qpos: float64 [T, nq] the kinematic trajectory the robot was asked to perform, when
                 ``qpos`` is what it executed in physics (the feasibility stage's output), or None.
    initial_qvel: float64 [nv] the start velocity of that execution, or None.
    task_qpos:   float64 [T, nq] what the servos were commanded to follow in that execution (the
                 reference with the feasibility stage's changes), or None.
    retime_factor: how many times slower than its source motion the trajectory plays (1.0 when
                 the file has no such field); validation's ``time_warp`` check judges it.
    """

    qpos: np.ndarray
    fps: float
    joint_names: list[str]
    robot: str = ""
    contacts: np.ndarray | None = None
    source: str = ""
    reference_qpos: np.ndarray | None = None
    initial_qvel: np.ndarray | None = None
    task_qpos: np.ndarray | None = None
    retime_factor: float = 1.0

    @property
    def num_frames(self) -> int:
        return int(self.qpos.shape[0])

    @property
    def duration_s(self) -> float:
        return (self.num_frames - 1) / self.fps


def load_robot_npz(path: str | Path, robot=None) -> RobotTrajectory:
    """Read ``path`` (robot.npz) and, when ``robot`` is given, check it matches that robot."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such file")
    fields = read_npz_fields(path, "trajectory file")
    for key in ("qpos", "fps"):
        if key not in fields:
            raise InputError(f"{path}: field '{key}' is missing (robot.npz needs qpos, fps, joint_names)")
    qpos = np.asarray(fields["qpos"])
    if qpos.ndim != 2 or not np.issubdtype(qpos.dtype, np.number):
        raise InputError(f"{path}: field 'qpos' must be a number array [T, nq], got shape {qpos.shape} {qpos.dtype}")
    fps = scalar_field(fields, "fps", path)
    check_rate(fps, str(path), "field 'fps'")
    check_frames(qpos.shape[0], str(path), "field 'qpos' frames")
    check_joints(qpos.shape[1], str(path), "field 'qpos' columns")
    check_seconds((qpos.shape[0] - 1) / fps, str(path), "the duration (qpos frames / fps)")
    qpos = qpos.astype(np.float64)
    raw_names = np.asarray(fields.get("joint_names", np.array([], dtype=str)))
    if raw_names.ndim > 1 or (raw_names.size and raw_names.dtype.kind not in "US"):
        raise InputError(f"{path}: field 'joint_names' must be a list of strings, got shape {raw_names.shape} "
                         f"({raw_names.dtype})")
    names = [str(n) for n in raw_names.reshape(-1)]
    robot_name = ""
    if "robot" in fields:
        raw_robot = np.asarray(fields["robot"])
        if raw_robot.size != 1 or raw_robot.dtype.kind not in "US":
            raise InputError(f"{path}: field 'robot' must be one string, got shape {raw_robot.shape} ({raw_robot.dtype})")
        robot_name = str(raw_robot.reshape(()))
    contacts = None
    if "contacts" in fields:
        contacts = np.asarray(fields["contacts"]).astype(bool)
        if contacts.shape != (qpos.shape[0], 2):
            raise InputError(f"{path}: field 'contacts' has shape {contacts.shape}, expected ({qpos.shape[0]}, 2)")
    initial_qvel = None
    like_qpos = {}
    for name in ("reference_qpos", "task_qpos"):
        if name in fields:
            value = np.asarray(fields[name])
            if value.shape != qpos.shape or value.dtype.kind not in "fi" or not np.isfinite(value).all():
                raise InputError(f"{path}: field '{name}' must be a finite number array of the shape of 'qpos' "
                                 f"{qpos.shape}, got {value.dtype} {value.shape}")
            like_qpos[name] = value.astype(np.float64)
    if "initial_qvel" in fields:
        initial_qvel = np.asarray(fields["initial_qvel"])
        if initial_qvel.ndim != 1 or initial_qvel.dtype.kind not in "fi" or not np.isfinite(initial_qvel).all():
            raise InputError(f"{path}: field 'initial_qvel' must be a finite number vector [nv], got {initial_qvel.dtype} {initial_qvel.shape}")
        initial_qvel = initial_qvel.astype(np.float64)
    retime_factor = check_retime_factor(scalar_field(fields, "retime_factor", path), path) \
        if "retime_factor" in fields else 1.0
    trajectory = RobotTrajectory(qpos=qpos, fps=fps, joint_names=names, robot=robot_name,
                                 contacts=contacts, source=str(path), reference_qpos=like_qpos.get("reference_qpos"),
                                 initial_qvel=initial_qvel, task_qpos=like_qpos.get("task_qpos"),
                                 retime_factor=retime_factor)
    if robot is not None:
        check_matches_robot(trajectory, robot, where=str(path))
    return trajectory


def check_matches_robot(trajectory: RobotTrajectory, robot, where: str = "trajectory") -> None:
    """Raise :class:`InputError` naming the field when ``trajectory`` does not fit ``robot``."""
    qpos = trajectory.qpos
    nq = robot.model.nq
    if qpos.ndim != 2 or qpos.shape[1] != nq:
        raise InputError(
            f"{where}: field 'qpos' has {qpos.shape[-1] if qpos.ndim else 0} columns but robot "
            f"'{robot.name}' has nq={nq} (free base 7 + {nq - 7} joints)")
    if qpos.shape[0] < 3:
        raise InputError(f"{where}: field 'qpos' has {qpos.shape[0]} frames; validation needs at least 3")
    bad = ~np.isfinite(qpos)
    if bad.any():
        frame, col = np.argwhere(bad)[0]
        raise InputError(f"{where}: field 'qpos' is not finite at frame {frame}, column {col}")
    if not (np.isfinite(trajectory.fps) and trajectory.fps > 0):
        raise InputError(f"{where}: field 'fps' must be a positive number, got {trajectory.fps}")
    if trajectory.joint_names:
        expected = list(robot.joint_names)
        got = list(trajectory.joint_names)
        if got != expected:
            missing = [n for n in expected if n not in got]
            extra = [n for n in got if n not in expected]
            if missing or extra:
                detail = f"missing {missing[:5]}" if missing else ""
                detail += ("; " if detail and extra else "") + (f"unknown {extra[:5]}" if extra else "")
            else:
                first = next(i for i, (a, b) in enumerate(zip(got, expected)) if a != b)
                detail = f"order differs at index {first}: '{got[first]}' where robot has '{expected[first]}'"
            raise InputError(f"{where}: field 'joint_names' does not match robot '{robot.name}': {detail}")
    if trajectory.initial_qvel is not None and trajectory.initial_qvel.shape != (robot.model.nv,):
        raise InputError(f"{where}: field 'initial_qvel' has {trajectory.initial_qvel.size} values but robot "
                         f"'{robot.name}' has nv={robot.model.nv}")
    if trajectory.robot and trajectory.robot != robot.name:
        raise InputError(
            f"{where}: field 'robot' is '{trajectory.robot}' but validating against robot '{robot.name}' "
            f"(pass --robot {trajectory.robot})")
    quat = qpos[:, 3:7]
    norms = np.linalg.norm(quat, axis=1)
    if np.any(np.abs(norms - 1.0) > 1e-3):
        frame = int(np.argmax(np.abs(norms - 1.0)))
        raise InputError(f"{where}: field 'qpos' base quaternion (columns 3:7) is not unit length at frame {frame} "
                         f"(norm {norms[frame]:.4f})")


def save_robot_npz(path: str | Path, trajectory: RobotTrajectory) -> None:
    """Write the fields validation reads (used by tests and the synthetic examples)."""
    data = {"qpos": trajectory.qpos.astype(np.float64), "fps": np.float64(trajectory.fps),
            "joint_names": np.array(trajectory.joint_names, dtype=str), "robot": np.array(trajectory.robot)}
    if trajectory.contacts is not None:
        data["contacts"] = trajectory.contacts.astype(bool)
    if trajectory.retime_factor != 1.0:
        data["retime_factor"] = np.float64(trajectory.retime_factor)
    np.savez(path, **data)

"""A robot trajectory (``robot.npz``) or its validated servo goals as a CSV table (numpy only).

One row per frame, every column name carrying its unit::

    time_s, root_x_m, root_y_m, root_z_m, root_qw, root_qx, root_qy, root_qz, <joint>_rad, ...

``time_s`` is ``frame / fps``; the root is the free base of ``qpos`` (position in metres, world
frame z up; orientation as a unit quaternion w, x, y, z, MuJoCo's order); then one column per
actuated joint, named by its MJCF joint name, in ``joint_names`` order (the robot's qpos order),
radians.  With servo goals (``servo_goals.npz``: what validation's physics rollout tracked and
playback streams) the joint columns are the goals, named ``<joint>_goal_rad``, and the root
columns stay those of the trajectory.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from motok_robot.errors import InputError
from motok_robot.export.progress import write_rows
from motok_robot.servo.trajectory import FREE_BASE  # qpos columns of the free base (position, quaternion wxyz)

ROOT_COLUMNS = ("root_x_m", "root_y_m", "root_z_m", "root_qw", "root_qx", "root_qy", "root_qz")


@dataclass
class RobotTable:
    """A robot trajectory ready to export: ``qpos`` [T, 7 + nj], ``joint_names`` [nj], ``fps``,
    ``robot`` name, ``sha256`` of the file, ``path``."""

    qpos: np.ndarray
    joint_names: list[str]
    fps: float
    robot: str
    sha256: str
    path: Path

    @property
    def joints(self) -> np.ndarray:
        return self.qpos[:, FREE_BASE:]


def file_sha256(path: str | Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def read_robot_table(path: str | Path) -> RobotTable:
    """Read ``robot.npz`` (docs/CONTRACTS.md) for export; InputError naming the file and field."""
    from motok_robot.sim.trajectory import load_robot_npz

    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: robot trajectory not found")
    trajectory = load_robot_npz(path)
    names = list(trajectory.joint_names)
    if not names:
        raise InputError(f"{path}: field 'joint_names' is missing or empty (robot.npz needs qpos, joint_names, fps)")
    if len(set(names)) != len(names):
        raise InputError(f"{path}: field 'joint_names' lists {sorted({n for n in names if names.count(n) > 1})} "
                         "more than once")
    qpos = trajectory.qpos
    if qpos.shape[1] != FREE_BASE + len(names) or qpos.shape[0] < 1:
        raise InputError(f"{path}: field 'qpos' has shape {qpos.shape}; the free base ({FREE_BASE}) and the "
                         f"{len(names)} joints of joint_names need [T >= 1, {FREE_BASE + len(names)}]")
    bad = ~np.isfinite(qpos)
    if bad.any():
        frame, column = (int(v) for v in np.argwhere(bad)[0])
        what = ROOT_COLUMNS[column] if column < FREE_BASE else f"joint {names[column - FREE_BASE]}"
        raise InputError(f"{path}: field 'qpos' is not finite at frame {frame} ({what})")
    return RobotTable(qpos=qpos, joint_names=names, fps=trajectory.fps, robot=trajectory.robot,
                      sha256=file_sha256(path), path=path)


def read_goals_for(table: RobotTable, goals_path: str | Path, expected_sha256: str | None = None) -> np.ndarray:
    """The servo goals of ``goals_path`` (servo_goals.npz) as ``[T, nj]`` in ``table``'s joint
    order; they must have been computed from this very robot.npz (``source_sha256``), with its
    frames and fps, and (``expected_sha256``, from report.json) be the validated ones."""
    from motok_robot.feasibility.feedforward import goals_for_joints, load_servo_goals

    goals_path = Path(goals_path)
    if not goals_path.is_file():
        raise InputError(f"{goals_path}: servo goals file not found")
    goals = load_servo_goals(goals_path, expected_sha256=expected_sha256)
    if goals["source_sha256"] and goals["source_sha256"] != table.sha256:
        raise InputError(f"{goals_path}: field 'source_sha256' says the goals were computed from other content "
                         f"than {table.path} (sha256 {goals['source_sha256'][:12]}..., the file is "
                         f"{table.sha256[:12]}...)")
    return goals_for_joints(goals, table.joint_names, table.qpos.shape[0], table.fps, goals_path, table.path)


def csv_columns(joint_names: list[str], goals: bool = False) -> list[str]:
    suffix = "_goal_rad" if goals else "_rad"
    return ["time_s", *ROOT_COLUMNS, *(f"{n}{suffix}" for n in joint_names)]


def write_robot_csv(table: RobotTable, path: str | Path, goals: np.ndarray | None = None, progress=None) -> Path:
    """Write ``table`` (joint columns: ``goals`` [T, nj] when given) to ``path``; returns it.

    ``progress(done, total)`` (optional) is called as the rows are written."""
    path = Path(path)
    joints = table.joints if goals is None else np.asarray(goals, dtype=np.float64)
    T = table.qpos.shape[0]
    values = np.concatenate([(np.arange(T) / table.fps)[:, None], table.qpos[:, :FREE_BASE], joints], axis=1)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", encoding="utf-8", newline="\n") as handle:
        handle.write(",".join(csv_columns(table.joint_names, goals is not None)) + "\n")
        write_rows(handle, values, ",", ".9g", progress)
    return path


def read_robot_csv(path: str | Path) -> dict[str, np.ndarray]:
    """Read an exported table back: ``{column: float64 [T]}`` (tests and scripts)."""
    lines = Path(path).read_text(encoding="utf-8").splitlines()
    header = lines[0].split(",")
    data = np.array([[float(v) for v in line.split(",")] for line in lines[1:] if line], dtype=np.float64)
    data = data.reshape(-1, len(header))
    return {name: data[:, k] for k, name in enumerate(header)}

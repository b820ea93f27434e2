"""Checks measured on a retargeted trajectory (never assumed from the solver's status).

All functions take the robot's :class:`retarget.problem.RobotKinematics` and the solver
variables ``x[T, nx]`` (or MuJoCo ``qpos`` converted with ``kin.x_from_qpos``).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from retarget.contacts import contact_phases


@dataclass
class TrajectoryMetrics:
    """Numbers of one retargeted clip.

    ``keypoint_error_mean`` m (mean over frames and keypoints); ``sole_drift_max`` m: the
    largest horizontal distance any sole point (site and 4 corners) moves from where it was at
    the start of its contact phase; ``sole_min_height`` m: lowest sole corner over all frames
    (relative to the ground); ``joint_range_excess`` rad: largest amount a joint leaves its range
    (0 = never); ``velocity_ratio_max``: largest |joint velocity| / velocity limit;
    ``joint_acceleration_mean`` rad/s^2: mean |finite-difference joint acceleration|.
    """

    frames: int
    keypoint_error_mean: float
    sole_drift_max: float
    sole_min_height: float
    contact_phases: int
    joint_range_excess: float
    velocity_ratio_max: float
    joint_acceleration_mean: float

    def as_dict(self) -> dict:
        return asdict(self)


def sole_points(kin, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(sole_site[T, 2, 3], corners[T, 2, 4, 3])`` world positions (m) for ``x[T, nx]``."""
    T = len(x)
    out = kin.frame.map(T)(np.asarray(x).T)
    site = np.array(out[1]).reshape(3, 2, T, order="F").transpose(2, 1, 0)
    corners = np.array(out[3]).reshape(3, 8, T, order="F").transpose(2, 1, 0).reshape(T, 2, 4, 3)
    return site, corners


def sole_drift(kin, x: np.ndarray, contacts: np.ndarray) -> tuple[float, int]:
    """Largest horizontal drift (m) of any sole point within any contact phase, and the phase count."""
    site, corners = sole_points(kin, x)
    pts = np.concatenate([site[:, :, None, :], corners], axis=2)  # [T, 2, 5, 3]
    worst, count = 0.0, 0
    for s in range(2):
        for a, b in contact_phases(contacts[:, s]):
            count += 1
            d = np.linalg.norm(pts[a:b, s, :, :2] - pts[a, s, :, :2], axis=-1)
            worst = max(worst, float(d.max()))
    return worst, count


def measure(kin, x: np.ndarray, contacts: np.ndarray, keypoint_error: np.ndarray, fps: float, ground: float = 0.0) -> TrajectoryMetrics:
    robot = kin.robot
    x = np.asarray(x, dtype=np.float64)
    q = x[:, 6:]
    _, corners = sole_points(kin, x)
    drift, phases = sole_drift(kin, x, contacts)
    lo, hi = robot.joint_range[:, 0], robot.joint_range[:, 1]
    excess = float(np.maximum(np.maximum(lo - q, q - hi), 0.0).max()) if len(q) else 0.0
    vel = np.abs(np.diff(q, axis=0)) * fps
    ratio = float((vel / robot.velocity_limit).max()) if len(vel) else 0.0
    acc = np.abs(np.diff(q, n=2, axis=0)) * fps**2
    return TrajectoryMetrics(
        frames=len(x),
        keypoint_error_mean=float(np.mean(keypoint_error)) if keypoint_error.size else 0.0,
        sole_drift_max=drift,
        sole_min_height=float(corners[..., 2].min() - ground),
        contact_phases=phases,
        joint_range_excess=excess,
        velocity_ratio_max=ratio,
        joint_acceleration_mean=float(acc.mean()) if acc.size else 0.0,
    )

"""One call that validates a trajectory: checks, verdict, report, plots, video.

>>> from motok_robot.robots import load
>>> from motok_robot.sim.validate import validate_file
>>> result = validate_file("robot.npz", load("op3_like"), out_dir="val/")
>>> result.report["passed"], result.report["failed_checks"]
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from motok_robot import __version__
from motok_robot.sim.config import ValidationConfig
from motok_robot.sim.kinematic import KinematicResult, replay
from motok_robot.sim.model_index import RobotIndex, index_robot
from motok_robot.sim.report import SCHEMA, build_checks, summary_text, write_report
from motok_robot.sim.rollout import RolloutResult, simulate
from motok_robot.sim.trajectory import RobotTrajectory, check_matches_robot, load_robot_npz


@dataclass
class ValidationResult:
    """The report dict (report.json) with the per-frame measurements behind it."""

    report: dict
    kinematic: KinematicResult
    rollout: RolloutResult | None
    index: RobotIndex

    @property
    def passed(self) -> bool:
        return bool(self.report["passed"])

    def summary(self) -> str:
        return summary_text(self.report)


def validate_trajectory(trajectory: RobotTrajectory, robot, config: ValidationConfig | None = None,
                        out_dir: str | Path | None = None, physics: bool = True, plots: bool = True,
                        render: bool = False, input_sha256: str | None = None) -> ValidationResult:
    """Validate ``trajectory`` on ``robot`` (a ``Robot`` or a prebuilt :class:`RobotIndex`).

    With ``out_dir``, writes ``report.json``, the PNG plots (``plots``) and ``validation.mp4``
    (``render``) there.  ``input_sha256`` (the file's digest) is recorded in ``input`` so a
    later stage can check that the file it plays is the one validated.  Raises :class:`~motok_robot.errors.InputError` when the trajectory does
    not fit the robot.
    """
    config = config or ValidationConfig()
    index = robot if isinstance(robot, RobotIndex) else index_robot(robot)
    check_matches_robot(trajectory, _RobotView(index), where=trajectory.source or "trajectory")
    timing = {}
    roll = None
    if physics:
        # the rollout runs in C without the GIL (mujoco.rollout): overlap it with the replay
        from concurrent.futures import ThreadPoolExecutor

        def timed_simulate():
            begin = time.perf_counter()
            out = simulate(index, trajectory.qpos, trajectory.fps, config)
            timing["physics"] = time.perf_counter() - begin
            return out

        with ThreadPoolExecutor(max_workers=1) as pool:
            pending = pool.submit(timed_simulate)
            start = time.perf_counter()
            kin = replay(index, trajectory.qpos, trajectory.fps, config)
            timing["kinematic"] = time.perf_counter() - start
            roll = pending.result()
    else:
        start = time.perf_counter()
        kin = replay(index, trajectory.qpos, trajectory.fps, config)
        timing["kinematic"] = time.perf_counter() - start
    checks, metrics, per_foot, per_joint = build_checks(index, kin, roll, config, trajectory.contacts)
    report = {
        "schema": SCHEMA, "version": __version__, "passed": metrics["passed"],
        "failed_checks": [c.name for c in checks if not c.passed], "robot": index.name,
        "input": {"path": trajectory.source, "frames": trajectory.num_frames, "fps": trajectory.fps,
                  "duration_s": trajectory.duration_s, "sha256": input_sha256},
        "physics": physics, "metrics": metrics, "checks": {c.name: c.to_dict() for c in checks},
        "per_foot": per_foot, "per_joint": per_joint, "config": config.to_dict(), "timing_s": timing,
        "outputs": {"report": None, "plots": [], "video": None},
    }
    result = ValidationResult(report=report, kinematic=kin, rollout=roll, index=index)
    if out_dir is not None:
        out_dir = Path(out_dir)
        out_dir.mkdir(parents=True, exist_ok=True)
        if plots:
            from motok_robot.sim.plots import save_plots

            start = time.perf_counter()
            report["outputs"]["plots"] = [str(p) for p in save_plots(result, out_dir)]
            timing["plots"] = time.perf_counter() - start
        if render:
            from motok_robot.sim.render import render_video

            start = time.perf_counter()
            report["outputs"]["video"] = str(render_video(result, trajectory, out_dir / "validation.mp4", config))
            timing["render"] = time.perf_counter() - start
        report["outputs"]["report"] = str(out_dir / "report.json")
        write_report(report, out_dir / "report.json")
    return result


def validate_file(path: str | Path, robot, config: ValidationConfig | None = None, out_dir: str | Path | None = None,
                  physics: bool = True, plots: bool = True, render: bool = False) -> ValidationResult:
    """Read ``path`` (robot.npz), check it fits ``robot`` and validate it (see :func:`validate_trajectory`)."""
    import hashlib

    index = robot if isinstance(robot, RobotIndex) else index_robot(robot)
    trajectory = load_robot_npz(path, _RobotView(index))
    digest = hashlib.sha256(Path(path).read_bytes()).hexdigest()
    return validate_trajectory(trajectory, index, config, out_dir, physics, plots, render, input_sha256=digest)


class _RobotView:
    """The attributes ``check_matches_robot`` reads, from a RobotIndex."""

    def __init__(self, index: RobotIndex):
        self.name = index.name
        self.model = index.model
        self.joint_names = index.joint_names

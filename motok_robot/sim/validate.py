"""One call that validates a trajectory: checks, verdict, report, plots, video.

>>> from motok_robot.robots import load
>>> from motok_robot.sim.validate import validate_file
>>> result = validate_file("robot.npz", load("op3_like"), out_dir="val/")
>>> result.report["passed"], result.report["failed_checks"]
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from motok_robot import __version__
from motok_robot.errors import InputError
from motok_robot.feasibility import BalanceConfig, BalancePlan, build_plan
from motok_robot.feasibility.feedforward import (GOALS_FILE, feedforward_goals, goals_digest, load_servo_goals,
                                                 save_servo_goals, servo_gains)
from motok_robot.robots.index import RobotIndex, index_robot
from motok_robot.sim.config import ValidationConfig
from motok_robot.sim.fidelity import fidelity_measures
from motok_robot.sim.kinematic import KinematicResult, replay
from motok_robot.sim.notes import joint_limit_notes
from motok_robot.sim.report import SCHEMA, build_checks, robot_description_record, summary_text, write_report
from motok_robot.sim.rollout import Push, RolloutResult, servo_model, simulate
from motok_robot.sim.trajectory import RobotTrajectory, check_matches_robot, load_robot_npz


@dataclass
class ValidationResult:
    """The report dict (report.json) with the per-frame measurements behind it."""

    report: dict
    kinematic: KinematicResult
    rollout: RolloutResult | None
    index: RobotIndex
    goals: np.ndarray | None = None  # [T, nj] servo goals of the rollout (None without physics)
    plan: BalancePlan | None = None  # the balance controller's plan (None: open loop)

    @property
    def passed(self) -> bool:
        return bool(self.report["passed"])

    def summary(self) -> str:
        return summary_text(self.report)


def validate_trajectory(trajectory: RobotTrajectory, robot, config: ValidationConfig | None = None,
                        out_dir: str | Path | None = None, physics: bool = True, plots: bool = True,
                        render: bool = False, input_sha256: str | None = None,
                        balance: BalanceConfig | None = None, servo_goals: dict | None = None,
                        physics_model=None, pushes: Sequence[Push] = ()) -> ValidationResult:
    """Validate ``trajectory`` on ``robot`` (a ``Robot`` or a prebuilt :class:`RobotIndex`).

    With ``out_dir``, writes ``report.json``, the PNG plots (``plots``) and ``validation.mp4``
    (``render``) there.  With physics, the servo goals of the rollout (feedforward by default,
    see :mod:`motok_robot.feasibility.feedforward`) are recorded in ``report["servo_goals"]`` and, with
    ``out_dir``, written to ``servo_goals.npz``, which playback streams.  ``input_sha256`` (the
    file's digest) is recorded in ``input`` so a later stage can check that the file it plays
    is the one validated.  Raises :class:`~motok_robot.errors.InputError` when the trajectory
    does not fit the robot.

    ``balance`` (a :class:`~motok_robot.feasibility.config.BalanceConfig`, default: the robot's
    defaults) runs the rollout closed loop with the balance controller, whose plan is built from
    this trajectory and stored with the servo goals, so playback runs the same controller;
    ``BalanceConfig(enabled=False)`` plays the goals open loop.  ``servo_goals`` (a dict as
    :func:`~motok_robot.feasibility.feedforward.load_servo_goals` returns) replaces both: the
    rollout plays those goals with that plan, as the feasibility stage made them.  A trajectory
    with ``reference_qpos`` (the feasibility stage's executed trajectory) is judged against that
    reference: falls, drift and fidelity; ``tracking`` against its ``task_qpos`` when present
    (what the servos were commanded to follow), else against the reference too.

    ``physics_model`` and ``pushes`` change the physics only, for robustness tests (see
    :func:`~motok_robot.sim.rollout.simulate`): the goals and the plan stay those of the nominal robot.
    """
    config = config or ValidationConfig()
    index = robot if isinstance(robot, RobotIndex) else index_robot(robot)
    check_matches_robot(trajectory, _RobotView(index), where=trajectory.source or "trajectory")
    timing = {}
    roll = goals = plan = fidelity = None
    start = time.perf_counter()
    kin = replay(index, trajectory.qpos, trajectory.fps, config)
    timing["kinematic"] = time.perf_counter() - start
    if physics:
        start = time.perf_counter()
        if servo_goals is not None:  # the goals and controller plan the feasibility stage made
            expected = (trajectory.num_frames, index.nj)
            if servo_goals["goals"].shape != expected:
                raise InputError(f"{trajectory.source or 'trajectory'}: the servo goals have shape "
                                 f"{servo_goals['goals'].shape}, the trajectory needs {expected}")
            goals, plan = servo_goals["goals"], servo_goals.get("plan")
        else:
            stiffness, damping = servo_gains(servo_model(index, config)[0], index)
            if not config.servo_feedforward:
                stiffness = np.zeros_like(stiffness)  # the reference angles (still within the servo's limits)
            goals = feedforward_goals(index, kin.joint_pos, kin.joint_vel, kin.torque, trajectory.fps, stiffness,
                                      damping, config.servo_goal_velocity_fraction)
            balance = balance if balance is not None else BalanceConfig()
            if balance.enabled:
                plan = build_plan(index, trajectory.qpos, trajectory.fps, kin.contact, balance)
        judge = trajectory.reference_qpos if trajectory.reference_qpos is not None else trajectory.qpos
        roll = simulate(index, trajectory.qpos, trajectory.fps, config, goals=goals, plan=plan,
                        initial_qvel=trajectory.initial_qvel, judge_qpos=judge, model=physics_model, pushes=pushes,
                        track_qpos=trajectory.task_qpos)
        fidelity = fidelity_measures(index, roll.qpos, judge, roll.valid_frames)
        timing["physics"] = time.perf_counter() - start
    checks, metrics, per_foot, per_joint = build_checks(index, kin, roll, config, trajectory.contacts, fidelity,
                                                         getattr(trajectory, "retime_factor", 1.0))
    report = {
        "schema": SCHEMA, "version": __version__, "passed": metrics["passed"],
        "failed_checks": [c.name for c in checks if not c.passed], "robot": index.name,
        "input": {"path": trajectory.source, "frames": trajectory.num_frames, "fps": trajectory.fps,
                  "duration_s": trajectory.duration_s, "sha256": input_sha256},
        "physics": physics, "metrics": metrics, "checks": {c.name: c.to_dict() for c in checks},
        "per_foot": per_foot, "per_joint": per_joint,
        "notes": joint_limit_notes(per_joint, config.joint_limit_tolerance_rad),
        "config": config.to_dict(), "timing_s": timing,
        "outputs": {"report": None, "plots": [], "video": None},
        "servo_goals": None if goals is None else {
            "mode": servo_goals["mode"] if servo_goals is not None else
            "feedforward" if config.servo_feedforward else "reference", "file": None,
            "sha256": goals_digest(goals)},
    }
    report["robot_description"] = robot_description_record(index)
    if plan is not None:
        report["servo_goals"]["balance"] = plan.config.to_dict()
    result = ValidationResult(report=report, kinematic=kin, rollout=roll, index=index, goals=goals, plan=plan)
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
        write_servo_goals(result, out_dir)
        report["outputs"]["report"] = str(out_dir / "report.json")
        write_report(report, out_dir / "report.json")
    return result


def validate_file(path: str | Path, robot, config: ValidationConfig | None = None, out_dir: str | Path | None = None,
                  physics: bool = True, plots: bool = True, render: bool = False) -> ValidationResult:
    """Read ``path`` (robot.npz), check it fits ``robot`` and validate it (see :func:`validate_trajectory`).

    When ``servo_goals.npz`` lies beside ``path`` and was made from this very file (its
    ``source_sha256``), as the feasibility stage leaves them, the rollout plays those goals."""
    import hashlib

    index = robot if isinstance(robot, RobotIndex) else index_robot(robot)
    trajectory = load_robot_npz(path, _RobotView(index))
    digest = hashlib.sha256(Path(path).read_bytes()).hexdigest()
    servo_goals = stage_goals_beside(path, digest) if physics else None
    return validate_trajectory(trajectory, index, config, out_dir, physics, plots, render, input_sha256=digest,
                               servo_goals=servo_goals)


def stage_goals_beside(path: str | Path, digest: str | None = None) -> dict | None:
    """The feasibility stage's ``servo_goals.npz`` beside ``path`` (robot.npz) when it was made from
    this very file (its ``source_sha256``; ``digest``: the file's sha256 when already known), else None."""
    import hashlib

    beside = Path(path).with_name(GOALS_FILE)
    if not beside.is_file():
        return None
    digest = digest or hashlib.sha256(Path(path).read_bytes()).hexdigest()
    goals = load_servo_goals(beside)
    return goals if goals["source_sha256"] == digest and goals["mode"] == "feasibility" else None


def write_servo_goals(result: ValidationResult, out_dir: str | Path) -> Path | None:
    """Write the rollout's servo goals to ``out_dir/servo_goals.npz`` and name the file in
    ``result.report["servo_goals"]`` (playback streams it); None without physics."""
    if result.goals is None:
        return None
    report = result.report
    path = save_servo_goals(Path(out_dir) / GOALS_FILE, result.goals, result.index.joint_names, report["input"]["fps"],
                            result.index.name, report["servo_goals"]["mode"], report["input"]["sha256"],
                            plan=result.plan)
    report["servo_goals"]["file"] = GOALS_FILE
    return path


class _RobotView:
    """The attributes ``check_matches_robot`` reads, from a RobotIndex."""

    def __init__(self, index: RobotIndex):
        self.name = index.name
        self.model = index.model
        self.joint_names = index.joint_names

"""What playback plays: a ``robot.npz`` and the servo goals its validation report recorded.

* the **report gate** (:func:`check_validation_report`): a ``report.json`` with ``"passed": true``
  for this file (its sha256), this robot and this robot description; ``force=True`` plays anyway
  and warns (:class:`PlaybackWarning`);
* **loading** (:func:`load_trajectory`): the validated servo goals (``servo_goals.npz``, digest
  checked) with the balance plan they carry, or the joint columns of ``qpos``, in servo-map
  order, every size bounded before it is allocated;
* :func:`plan_targets`: the per-tick targets of a trajectory at the control rate.

The fixed-rate loop that streams them is :mod:`motok_robot.servo.streamer`.
"""

from __future__ import annotations

import json
import math
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from motok_robot.errors import InputError
from motok_robot.limits import check_frames, check_joints, check_rate, check_seconds
from motok_robot.npz_files import read_npz_fields, scalar_field
from motok_robot.servo.convert import ServoMap
from retarget.cache import file_sha256  # the digest a report's input.sha256 records

#: qpos columns before the joints in robot.npz: free base position (3) + quaternion wxyz (4)
FREE_BASE = 7


class PlaybackWarning(UserWarning):
    """Something playback went on despite (no passing report with force, clamped targets ...)."""


# ----------------------------------------------------------------------------- inputs
@dataclass
class Trajectory:
    """Joint targets for the servos.

    Attributes:
        q: float64 [T, n_servos] joint angles (rad), servo-map order (may hold NaN).
        fps: frames per second of ``q``.
        joints: joint name of each column.
        source: the file it came from.
        goals: what ``q`` holds: ``"reference"`` (the joint angles of ``qpos``) or
            ``"feedforward"`` (the validated servo goals of ``servo_goals.npz``).
        plan: the balance controller's plan validated with those goals
            (:class:`~motok_robot.feasibility.balance.BalancePlan`, from ``servo_goals.npz``),
            None when validation ran open loop.
        plan_joints: the joint order of ``plan`` (the robot's, ``servo_goals.npz``'s joint_names).
    """

    q: np.ndarray
    fps: float
    joints: tuple[str, ...]
    source: Path | None = None
    goals: str = "reference"
    plan: object | None = None
    plan_joints: tuple[str, ...] = ()

    @property
    def duration_s(self) -> float:
        return (len(self.q) - 1) / self.fps


def load_trajectory(path: str | Path, servo_map: ServoMap, robot_name: str | None = None,
                    report_path: str | Path | None = None, robot_sha256: str | None = None) -> Trajectory:
    """Read ``robot.npz`` (CONTRACTS.md) and pick the servo joints' columns of ``qpos``.

    ``qpos`` is [T, nq] with the free base (7 values) first; the joint columns are the last
    ``len(joint_names)``.  When the validation report (``report_path``, default ``report.json``
    next to the file) validated this very file and records servo goals (``servo_goals``, the
    feedforward goals its physics rollout tracked), those goals are played instead, read from
    the ``servo_goals.npz`` it names and checked against its sha256: the servos get exactly
    what was validated.  Raises InputError naming the file and field.
    """
    path = Path(path)
    fields = read_npz_fields(path, "trajectory file")
    for key in ("qpos", "joint_names", "fps"):
        if key not in fields:
            raise InputError(f"{path}: field '{key}' missing (robot.npz needs qpos, joint_names, robot, fps)")
    qpos = np.asarray(fields["qpos"])
    if qpos.ndim != 2 or qpos.shape[0] < 1 or not (np.issubdtype(qpos.dtype, np.number) and qpos.dtype.kind != "c"):
        raise InputError(f"{path}: field 'qpos' must be a number array [T, nq] with T >= 1, got shape {qpos.shape} "
                         f"({qpos.dtype})")
    qpos = qpos.astype(np.float64)
    raw_names = np.asarray(fields["joint_names"])
    if raw_names.ndim > 1 or raw_names.dtype.kind not in "US":
        raise InputError(f"{path}: field 'joint_names' must be a list of strings, got shape {raw_names.shape} "
                         f"({raw_names.dtype})")
    names = [str(n) for n in np.atleast_1d(raw_names)]
    fps = scalar_field(fields, "fps", path)
    check_rate(fps, str(path), "field 'fps'")
    check_frames(qpos.shape[0], str(path), "field 'qpos' frames")
    check_joints(len(names), str(path), "field 'joint_names' length")
    check_seconds((qpos.shape[0] - 1) / fps, str(path), "the duration (qpos frames / fps)")
    if len(set(names)) != len(names):
        twice = sorted({n for n in names if names.count(n) > 1})
        raise InputError(f"{path}: field 'joint_names' lists {', '.join(twice)} more than once")
    if qpos.shape[1] != FREE_BASE + len(names):
        raise InputError(f"{path}: field 'qpos' has {qpos.shape[1]} columns, but the free base ({FREE_BASE}) and "
                         f"the {len(names)} joints of joint_names need {FREE_BASE + len(names)}: the joint columns "
                         "cannot be matched to their names")
    if robot_name is not None and "robot" in fields:
        saved = str(fields["robot"])
        if saved and saved != robot_name and Path(saved).stem != robot_name:
            raise InputError(f"{path}: trajectory was made for robot '{saved}', not '{robot_name}'")
    offset = FREE_BASE
    index = {n: i for i, n in enumerate(names)}
    missing = [j for j in servo_map.joints if j not in index]
    if missing:
        raise InputError(f"{path}: joint_names lacks the servo joint(s) {', '.join(missing)}")
    columns = [offset + index[j] for j in servo_map.joints]
    trajectory = Trajectory(q=qpos[:, columns].copy(), fps=fps, joints=servo_map.joints, source=path)
    report_path = Path(report_path) if report_path is not None else path.with_name("report.json")
    goals = _validated_goals(path, report_path, robot_sha256)
    if goals is not None:
        from motok_robot.feasibility.feedforward import goals_for_joints

        trajectory.q = goals_for_joints(goals, servo_map.joints, qpos.shape[0], fps, goals["path"], path).copy()
        trajectory.goals = goals["mode"]
        trajectory.plan = goals.get("plan")  # the balance plan validated with these goals
        trajectory.plan_joints = tuple(goals["joint_names"])
    return trajectory


def _validated_goals(path: Path, report_path: Path, robot_sha256: str | None = None) -> dict | None:
    """The servo goals a validation report recorded for ``path``, or None when there is no
    readable report, it validated other content or (with ``robot_sha256``) another robot
    description (the report gate deals with those), or it records no goals file.  A recorded
    file that is missing or altered is an InputError."""
    from motok_robot.feasibility.feedforward import load_servo_goals

    try:
        report = json.loads(report_path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    record = report.get("servo_goals") if isinstance(report, dict) else None
    validated = report.get("input") if isinstance(report, dict) else None
    digest = validated.get("sha256") if isinstance(validated, dict) else None
    if not isinstance(record, dict) or not record.get("file") or not isinstance(digest, str):
        return None
    if file_sha256(path) != digest.lower():
        return None
    if robot_sha256 is not None and _description_problem(report, report_path, robot_sha256) is not None:
        return None
    goals_path = report_path.parent / str(record["file"])
    goals = load_servo_goals(goals_path, expected_sha256=record.get("sha256"))
    if goals["source_sha256"] and goals["source_sha256"] != digest.lower():
        raise InputError(f"{goals_path}: computed for other content than {path} (source sha256 differs)")
    goals["path"] = goals_path
    return goals


def check_validation_report(trajectory_path: str | Path, report_path: str | Path | None = None, *,
                            force: bool = False, robot_name: str | None = None,
                            robot_sha256: str | None = None) -> dict | None:
    """Require a passing validation report for ``trajectory_path``; returns the report (or None).

    The report is ``report_path`` or ``report.json`` next to the trajectory.  It must parse,
    have ``"passed": true``, name the same robot, and match the file: by ``input.sha256`` (the
    digest of the validated robot.npz) when the report has it, else by file name.  With
    ``robot_sha256`` (``Robot.description_sha256`` of the robot about to be played) the report
    must also record that digest in ``robot_description.sha256``: limits validated on another
    description (a widened copy, an edited TOML or MJCF) do not count.  Otherwise InputError,
    unless ``force`` (then a :class:`PlaybackWarning`).
    """
    trajectory_path = Path(trajectory_path)
    path = Path(report_path) if report_path is not None else trajectory_path.with_name("report.json")
    report = None
    problem = None
    if not path.is_file():
        problem = f"no validation report at {path}"
    else:
        try:
            report = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            problem = f"validation report {path} is unreadable ({exc})"
        else:
            validated = report.get("input") if isinstance(report, dict) else None
            digest = None
            if isinstance(validated, dict):  # {"path": ..., "frames": ..., "sha256": ...}
                digest = validated.get("sha256") if isinstance(validated.get("sha256"), str) else None
                validated = validated.get("path")
            validated = validated if isinstance(validated, str) and validated else None
            if not isinstance(report, dict) or "passed" not in report:
                problem = f"validation report {path} has no top-level 'passed' field"
            elif report["passed"] is not True:
                failed = [name for name, check in (report.get("checks") or {}).items()
                          if isinstance(check, dict) and check.get("passed") is False]
                problem = f"validation report {path} did not pass" + (f" (failed: {', '.join(failed)})" if failed else "")
            elif robot_name and report.get("robot") and str(report["robot"]) != robot_name:
                problem = f"validation report {path} is for robot '{report['robot']}', not '{robot_name}'"
            elif digest is not None:  # the content decides, whatever the file is called now
                if not trajectory_path.is_file() or file_sha256(trajectory_path) != digest.lower():
                    problem = (f"validation report {path} is for different content (sha256 {digest[:12]}...): "
                               f"{trajectory_path.name} changed after it was validated")
            elif validated is not None and Path(validated).name != trajectory_path.name:
                problem = f"validation report {path} validated {validated}, not {trajectory_path.name}"
            if problem is None and robot_sha256 is not None:
                problem = _description_problem(report, path, robot_sha256)
    if problem is None:
        return report
    if not force:
        raise InputError(f"{trajectory_path}: refusing to play: {problem}. Validate it first "
                         "(motok-robot validate) or pass --force to play an unvalidated trajectory")
    warnings.warn(f"{trajectory_path}: playing WITHOUT a passing validation report ({problem}) because of --force",
                  PlaybackWarning, stacklevel=2)
    return report


def _description_problem(report: dict, path: Path, robot_sha256: str) -> str | None:
    """Why ``report`` does not bind the robot description with digest ``robot_sha256``, or None."""
    record = report.get("robot_description")
    recorded = record.get("sha256") if isinstance(record, dict) else None
    if not isinstance(recorded, str) or not recorded:
        return (f"validation report {path} records no robot description digest (robot_description.sha256); "
                "it was written before reports bound the description: validate again")
    if recorded.lower() != robot_sha256.lower():
        return (f"validation report {path} was made with another robot description (sha256 {recorded[:12]}..., "
                f"this robot's TOML + MJCF is {robot_sha256[:12]}...)")
    return None


def plan_targets(trajectory: Trajectory, start_ticks: np.ndarray, servo_map: ServoMap, rate_hz: float,
                 ramp_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Wanted servo positions for every control tick, before the safety limiter.

    Returns ``(targets float64 [N, n] ticks, is_ramp bool [N])``: ``round(ramp_s * rate)``
    ramp ticks (smoothstep from ``start_ticks`` [n] to frame 0), then one tick per ``1/rate`` s
    of the trajectory, linearly interpolated between frames, up to and including the last frame.
    """
    q = trajectory.q
    where = str(trajectory.source or "trajectory")
    check_rate(rate_hz, where, "the control rate")
    check_rate(trajectory.fps, where, "the frame rate")
    check_seconds(trajectory.duration_s, where, "the duration")
    check_seconds(ramp_s, where, "the ramp time")
    n_ramp = int(round(ramp_s * rate_hz))
    n_play = int(math.floor(trajectory.duration_s * rate_hz + 1e-9)) + 1
    with np.errstate(invalid="ignore", over="ignore"):
        frames = np.arange(n_play) / rate_hz * trajectory.fps
        i0 = np.minimum(np.floor(frames).astype(np.int64), max(len(q) - 2, 0))
        w = np.clip(frames - i0, 0.0, 1.0)[:, None]
        i1 = np.minimum(i0 + 1, len(q) - 1)
        exact = w[:, 0] == 0.0
        play_q = np.where(exact[:, None], q[i0], q[i0] * (1.0 - w) + q[i1] * w)
        play = servo_map.ticks_float(play_q)
        s = np.arange(1, n_ramp + 1) / max(n_ramp, 1)
        s = (s * s * (3.0 - 2.0 * s))[:, None]
        first = play[0]
        start = np.asarray(start_ticks, dtype=np.float64)
        ramp = start + (first - start) * s
    targets = np.concatenate([ramp, play], axis=0)
    is_ramp = np.zeros(len(targets), dtype=bool)
    is_ramp[:n_ramp] = True
    return targets, is_ramp

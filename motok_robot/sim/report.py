# Size (414 lines): the report schema (in the docstring) and every check that fills it, kept side by side.
"""The validation verdict and ``report.json``.

Schema (``"schema": "motok-robot/validation-report/1"``)::

    {
      "schema":  "motok-robot/validation-report/1",
      "version": "<motok-robot version>",
      "passed":  bool,                       # every check passed
      "failed_checks": [str, ...],           # names of the failing checks, in check order
      "robot":   str,                        # robot name
      "input":   {"path": str, "frames": int, "fps": float, "duration_s": float,
                  "sha256": str|null},           # digest of the validated robot.npz file
      "physics": bool,                       # whether the physics rollout ran
      "metrics": {                           # one number per question (null when not measured)
        "foot_skate_ratio": float,           # worst foot: skating frames / contact frames
        "foot_skate_distance_m": float,      # worst foot: horizontal travel while in contact (m)
        "max_penetration_m": float,          # deepest sole corner below the floor (m, >= 0)
        "max_float_m": float,                # highest "lowest sole point" of the robot (m)
        "self_collision_frames": int,        # frames with a self-collision
        "joint_limit_violations": int,       # (frame, joint) pairs beyond the joint range
        "max_velocity_ratio": float,         # max |qdot| / servo velocity limit
        "max_joint_acceleration_radps2": float,
        "max_base_rotation_step_deg": float,  # largest base rotation between consecutive frames (deg)
        "max_torque_ratio": float,           # max |required torque| / actuator force limit
        "balance_margin_min_m": float|null,  # min signed CoM margin over quasi-static contact frames
        "balance_margin_min_all_m": float|null,  # the same over all contact frames
        "zmp_outside_ratio": float,          # support frames with the ZMP outside / support frames
        "zmp_max_excursion_m": float,        # farthest ZMP outside the support polygon (m, >= 0)
        "unsupported_force_max_n": float,    # largest base force the feet cannot supply (N)
        "time_warp": float,                  # times slower than the source motion (retime_factor)
        "fell": bool|null, "fall_time_s": float|null,
        "tracking_rmse_rad": float|null,     # RMS joint tracking error before any fall
        "base_drift_m": float|null,          # max horizontal root distance sim vs reference
        "cop_outside_ratio": float|null,     # CoP samples outside the simulated sole polygon
        "passed": bool
      },
      "checks": {                            # one entry per check, in this order
        NAME: {"passed": bool, "value": number|bool|null, "threshold": number|bool,
               "comparison": "<=" | ">=" | "==",   # value <comparison> threshold passes
               "unit": str, "description": str,
               "frames": [int, ...],         # failing frame indices (reference frames at fps)
               "details": {...}}             # check-specific (worst joint, foot, pairs ...)
      },
      "per_foot":  {"left": {...}, "right": {...}},  # contact_frames, skate_ratio, skate_distance_m, ...
      "per_joint": {JOINT: {...}},           # range, max_velocity_ratio, max_torque_ratio, at_limit_ratio ...
      "notes":   [str, ...],                 # joints parked at a limit (motok_robot.sim.notes); not a failure
      "config":  {...},                      # the ValidationConfig used (all thresholds)
      "timing_s": {"kinematic": s, "physics": s, "plots": s, "render": s},
      "outputs": {"report": path, "plots": [path, ...], "video": path|null},
      "servo_goals": {"mode": "feedforward"|"reference",   # what the rollout's servos tracked
                      "file": "servo_goals.npz"|null,     # written next to report.json
                      "sha256": str}|null,                # of the goal array; null without physics
      "robot_description": {"name": str,                  # the robot description validated against
                            "sha256": str|null}           # Robot.description_sha256 (TOML + MJCF bytes)
    }

Check names: ``foot_skate_ratio``, ``foot_skate_distance``, ``penetration``, ``floating``,
``self_collision``, ``joint_limits``, ``joint_velocity``, ``joint_acceleration``, ``base_continuity``, ``torque``,
``static_balance``, ``zmp``, ``time_warp``, and with physics ``fall``, ``tracking``, ``base_drift``,
``center_of_pressure``, ``fidelity_pose``, ``fidelity_heading``, ``fidelity_foot_lift``.  A check whose value cannot be measured (e.g. no quasi-static
contact frame for static balance) passes with ``value: null`` and says why in ``details``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from motok_robot.sim.config import ValidationConfig
from motok_robot.sim.kinematic import KinematicResult
from motok_robot.sim.notes import at_limit_fields
from motok_robot.robots.index import SIDES, RobotIndex
from motok_robot.sim.rollout import RolloutResult

SCHEMA = "motok-robot/validation-report/1"
METRIC_KEYS = (
    "foot_skate_ratio", "foot_skate_distance_m", "max_penetration_m", "max_float_m",
    "self_collision_frames", "joint_limit_violations", "max_velocity_ratio",
    "max_joint_acceleration_radps2", "max_torque_ratio", "balance_margin_min_m",
    "balance_margin_min_all_m", "zmp_outside_ratio", "zmp_max_excursion_m", "unsupported_force_max_n",
    "fell", "fall_time_s", "tracking_rmse_rad", "base_drift_m", "cop_outside_ratio", "passed",
)


@dataclass
class Check:
    name: str
    passed: bool
    value: object
    threshold: object
    comparison: str
    unit: str
    description: str
    frames: list = field(default_factory=list)
    details: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {"passed": bool(self.passed), "value": _clean(self.value), "threshold": _clean(self.threshold),
                "comparison": self.comparison, "unit": self.unit, "description": self.description,
                "frames": [int(f) for f in self.frames], "details": _clean(self.details)}


def _clean(value):
    """JSON-safe copy: numpy scalars to Python, NaN/inf to None."""
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_clean(v) for v in value]
    if isinstance(value, np.ndarray):
        return _clean(value.tolist())
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        value = float(value)
        return value if math.isfinite(value) else None
    return value


def _upper(name, value, threshold, unit, description, frames=(), details=None) -> Check:
    ok = value is None or (isinstance(value, float) and math.isnan(value)) or value <= threshold
    return Check(name, bool(ok), value, threshold, "<=", unit, description, list(frames), details or {})


def _frames(mask: np.ndarray) -> list[int]:
    return np.flatnonzero(mask).tolist()


def build_checks(index: RobotIndex, kin: KinematicResult, roll: RolloutResult | None,
                 config: ValidationConfig, planned_contacts: np.ndarray | None = None,
                 fidelity: dict | None = None, time_warp: float = 1.0) -> tuple[list[Check], dict, dict, dict]:
    """All checks, the metrics dict, the per-foot and the per-joint summaries.

    ``time_warp``: how many times slower than its source the trajectory plays (robot.npz
    ``retime_factor``), judged by the ``time_warp`` check.

    ``fidelity`` (:func:`motok_robot.sim.fidelity.fidelity_measures` of the rollout) adds the
    ``fidelity_pose``, ``fidelity_heading`` and ``fidelity_foot_lift`` checks.

    ``planned_contacts`` (bool [T, 2], the ``contacts`` field of robot.npz) only adds a
    diagnosis to the skating details: skating inside planned contact phases (the foot slides)
    versus outside them (the swing foot skims the floor: too little clearance).
    """
    c = config
    checks: list[Check] = []
    contact_frames = kin.contact.sum(axis=0)
    skate_ratio = np.where(contact_frames > 0, kin.skating.sum(axis=0) / np.maximum(contact_frames, 1), 0.0)
    worst_ratio_foot = int(np.argmax(skate_ratio))
    worst_dist_foot = int(np.argmax(kin.skate_distance))
    skate_details = {"foot": SIDES[worst_ratio_foot]}
    if planned_contacts is not None and planned_contacts.shape == kin.skating.shape:
        inside = kin.skating & planned_contacts
        outside_plan = kin.skating & ~planned_contacts
        skate_details.update(skate_frames_in_planned_contact=inside.sum(axis=0).tolist(),
                             skate_frames_outside_planned_contact=outside_plan.sum(axis=0).tolist())
        if outside_plan.sum() > inside.sum():
            skate_details["diagnosis"] = ("most skating frames are planned swing frames: the swing foot moves within "
                                          f"{config.contact_height_m} m of the floor (too little foot clearance)")
    checks.append(_upper(
        "foot_skate_ratio", float(skate_ratio.max()), c.max_foot_skate_ratio, "ratio",
        f"fraction of a foot's contact frames (sole < {c.contact_height_m} m) moving faster than "
        f"{c.skate_speed_mps} m/s horizontally", _frames(kin.skating.any(axis=1)), skate_details))
    checks.append(_upper(
        "foot_skate_distance", float(kin.skate_distance.max()), c.max_foot_skate_distance_m, "m",
        "horizontal distance a foot travels while in contact, summed over the clip",
        _frames(kin.skating.any(axis=1)), {"foot": SIDES[worst_dist_foot]}))

    lowest = kin.corners[:, :, :, 2].min(axis=(1, 2))  # [T] lowest sole corner of the robot
    penetration = float(max(0.0, -lowest.min()))
    checks.append(_upper("penetration", penetration, c.max_penetration_m, "m",
                         "depth of the lowest sole corner below the floor", _frames(-lowest > c.max_penetration_m),
                         {"foot": SIDES[int(np.argmin(kin.sole_height.min(axis=0)))]}))
    max_float = float(lowest.max())
    checks.append(_upper("floating", max_float, c.max_float_m, "m",
                         "height of the robot's lowest sole point above the floor (both feet in the air)",
                         _frames(lowest > c.max_float_m)))

    collision_frames = sorted({f for f, *_ in kin.self_collisions})
    pairs: dict = {}
    for frame, b1, b2, depth in kin.self_collisions:
        key = f"{b1}|{b2}"
        pairs[key] = max(pairs.get(key, 0.0), depth)
    checks.append(_upper("self_collision", len(collision_frames), c.max_self_collision_frames, "frames",
                         f"frames where bodies that are not parent and child overlap deeper than "
                         f"{c.self_collision_depth_m} m", collision_frames,
                         {"pairs_max_depth_m": pairs, "ignored_pairs_at_nominal": len(index.ignored_body_pairs)}))

    low, high = index.joint_range[:, 0], index.joint_range[:, 1]
    beyond = np.maximum(low - kin.joint_pos, kin.joint_pos - high)  # [T, nj] rad beyond the range
    violating = beyond > c.joint_limit_tolerance_rad
    worst_joint = int(np.argmax(beyond.max(axis=0)))
    checks.append(_upper("joint_limits", int(violating.sum()), c.max_joint_limit_violations, "count",
                         f"(frame, joint) pairs outside the joint range by more than {c.joint_limit_tolerance_rad} rad",
                         _frames(violating.any(axis=1)),
                         {"worst_joint": index.joint_names[worst_joint],
                          "worst_excess_rad": float(max(0.0, beyond.max()))}))

    vel_ratio = np.abs(kin.joint_vel) / np.maximum(index.velocity_limit, 1e-9)
    worst = int(np.argmax(vel_ratio.max(axis=0)))
    checks.append(_upper("joint_velocity", float(vel_ratio.max()), c.max_velocity_ratio, "ratio",
                         "|joint velocity| / servo velocity limit", _frames((vel_ratio > c.max_velocity_ratio).any(1)),
                         {"worst_joint": index.joint_names[worst]}))
    acc = np.abs(kin.joint_acc)
    worst = int(np.argmax(acc.max(axis=0)))
    checks.append(_upper("joint_acceleration", float(acc.max()), c.max_joint_acceleration_radps2, "rad/s^2",
                         "|joint acceleration| (finite differences)",
                         _frames((acc > c.max_joint_acceleration_radps2).any(1)),
                         {"worst_joint": index.joint_names[worst]}))
    steps = np.asarray(kin.base_rotation_step, dtype=np.float64)
    max_step = float(steps.max()) if len(steps) else 0.0
    checks.append(_upper("base_continuity", max_step, c.max_base_rotation_step_deg, "deg",
                         "largest rotation of the base between two consecutive frames (a flip of the solution)",
                         [int(t) + 1 for t in np.flatnonzero(steps > c.max_base_rotation_step_deg)],
                         {"worst_frame": int(np.argmax(steps)) + 1 if len(steps) else None}))
    torque_ratio = np.abs(kin.torque) / np.maximum(index.torque_limit, 1e-9)
    worst = int(np.argmax(torque_ratio.max(axis=0)))
    checks.append(_upper("torque", float(torque_ratio.max()), c.max_torque_ratio, "ratio",
                         "|required joint torque| (inverse dynamics, ground reaction on the soles in contact) / "
                         "actuator force limit", _frames((torque_ratio > c.max_torque_ratio).any(1)),
                         {"worst_joint": index.joint_names[worst],
                          "worst_torque_nm": float(np.abs(kin.torque[:, worst]).max())}))

    has_contact = kin.contact.any(axis=1)
    judged = has_contact & kin.quasi_static & np.isfinite(kin.balance_margin)
    margin_qs = float(np.min(kin.balance_margin[judged])) if judged.any() else None
    margin_all = float(np.nanmin(kin.balance_margin)) if np.isfinite(kin.balance_margin).any() else None
    static_fail = judged & (kin.balance_margin < c.min_balance_margin_m)
    checks.append(Check(
        "static_balance", margin_qs is None or margin_qs >= c.min_balance_margin_m, margin_qs,
        c.min_balance_margin_m, ">=", "m",
        f"signed distance of the CoM ground projection to the support polygon (+ inside), over frames "
        f"where the CoM moves slower than {c.static_com_speed_mps} m/s", _frames(static_fail),
        {"judged_frames": int(judged.sum()), "min_margin_all_contact_frames_m": margin_all,
         **({} if judged.any() else {"note": "no quasi-static contact frame"})}))

    support = has_contact & np.isfinite(kin.zmp_margin)
    outside = support & (kin.zmp_margin < -c.zmp_tolerance_m)
    zmp_ratio = float(outside.sum() / support.sum()) if support.any() else 0.0
    excursion = float(max(0.0, -np.nanmin(kin.zmp_margin))) if support.any() else 0.0
    checks.append(_upper("zmp", zmp_ratio, c.max_zmp_outside_ratio, "ratio",
                         f"fraction of support frames with the ZMP ({c.zmp_model}) outside the support polygon by more "
                         f"than {c.zmp_tolerance_m} m", _frames(outside),
                         {"max_excursion_m": excursion, "support_frames": int(support.sum()), "model": c.zmp_model}))

    warp = float(time_warp)
    checks.append(_upper("time_warp", warp, c.max_time_warp, "x",
                         "how many times slower than the source motion the robot plays it (robot.npz retime_factor; "
                         "a property of the whole clip, so no frames are listed)", []))

    metrics = {
        "foot_skate_ratio": float(skate_ratio.max()), "foot_skate_distance_m": float(kin.skate_distance.max()),
        "max_penetration_m": penetration, "max_float_m": max_float,
        "self_collision_frames": len(collision_frames), "joint_limit_violations": int(violating.sum()),
        "max_velocity_ratio": float(vel_ratio.max()), "max_joint_acceleration_radps2": float(acc.max()),
        "max_base_rotation_step_deg": max_step,
        "max_torque_ratio": float(torque_ratio.max()), "balance_margin_min_m": margin_qs,
        "balance_margin_min_all_m": margin_all, "zmp_outside_ratio": zmp_ratio, "zmp_max_excursion_m": excursion,
        "unsupported_force_max_n": float(kin.unsupported_force.max()), "time_warp": warp,
        "fell": None, "fall_time_s": None, "tracking_rmse_rad": None, "base_drift_m": None, "cop_outside_ratio": None,
    }

    if roll is not None:
        fall_frames = _frames(~roll.valid_frames)
        checks.append(Check("fall", not roll.fell, roll.fell, False, "==", "bool",
                            f"the root body drops below {c.fall_height_ratio} x the reference height or tilts more "
                            f"than {c.fall_tilt_rad} rad from the reference in the physics rollout", fall_frames,
                            {"fall_time_s": roll.fall_time_s, "reason": roll.fall_reason}))
        valid = roll.valid_frames
        worst = int(np.argmax(roll.tracking_rmse_per_joint))
        per_frame_err = np.sqrt((roll.tracking_error ** 2).mean(axis=1))
        checks.append(_upper("tracking", roll.tracking_rmse, c.max_tracking_rmse_rad, "rad",
                             "RMS joint tracking error of the physics rollout (frames before any fall)",
                             _frames(valid & (per_frame_err > c.max_tracking_rmse_rad)),
                             {"worst_joint": index.joint_names[worst],
                              "worst_joint_rmse_rad": float(roll.tracking_rmse_per_joint[worst])}))
        drift_limit = c.max_base_drift_per_height * index.height_m
        drift = float(roll.base_drift[valid].max())
        checks.append(_upper("base_drift", drift, drift_limit, "m",
                             f"largest horizontal distance between the simulated and the reference root before any fall "
                             f"(threshold {c.max_base_drift_per_height} x robot height {index.height_m:.2f} m)",
                             _frames(valid & (roll.base_drift > drift_limit)),
                             {"final_drift_m": float(roll.base_drift[-1])}))
        cop_valid = np.isfinite(roll.cop_margin)
        if roll.fell:
            cop_valid &= roll.cop_time < roll.fall_time_s
        cop_out = cop_valid & (roll.cop_margin < -c.zmp_tolerance_m)
        cop_ratio = float(cop_out.sum() / cop_valid.sum()) if cop_valid.any() else 0.0
        cop_frames = sorted({int(round(t * kin.fps)) for t in roll.cop_time[cop_out]})
        checks.append(_upper("center_of_pressure", cop_ratio, c.max_cop_outside_ratio, "ratio",
                             "fraction of rollout samples (before any fall) whose centre of pressure lies outside the "
                             "simulated sole polygon", cop_frames,
                             {"min_margin_m": float(np.min(roll.cop_margin[cop_valid])) if cop_valid.any() else None,
                              "samples": int(cop_valid.sum())}))
        metrics.update(fell=roll.fell, fall_time_s=roll.fall_time_s, tracking_rmse_rad=roll.tracking_rmse,
                       base_drift_m=drift, cop_outside_ratio=cop_ratio)
        if fidelity is not None:
            pose_limit = c.max_pose_error_per_height * index.height_m
            checks.append(_upper("fidelity_pose", fidelity["pose_error_mean_m"], pose_limit, "m",
                                 f"mean distance of the rollout's bodies from the reference's, each relative to its root's "
                                 f"heading frame (threshold {c.max_pose_error_per_height} x robot height)",
                                 _frames(valid & (fidelity["pose_error_m"] > pose_limit))))
            checks.append(_upper("fidelity_heading", fidelity["heading_error_max_rad"], c.max_heading_error_rad, "rad",
                                 "largest root heading difference between the rollout and the reference",
                                 _frames(valid & (fidelity["heading_error_rad"] > c.max_heading_error_rad))))
            lift_limit = c.max_foot_lift_shortfall_per_height * index.height_m
            lifts = {}
            if fidelity["reference_lift_m"] is not None:
                short = fidelity["reference_lift_m"] - fidelity["executed_lift_m"]
                lifts = {f"{side}_reference_m": round(float(fidelity["reference_lift_m"][s]), 4) for s, side in
                         enumerate(SIDES)} | {f"{side}_executed_m": round(float(fidelity["executed_lift_m"][s]), 4)
                                              for s, side in enumerate(SIDES)}
                lift_frames = sorted(int(fidelity["reference_lift_frame"][s]) for s in range(2) if short[s] > lift_limit)
            else:
                lift_frames = []
            checks.append(_upper("fidelity_foot_lift", fidelity["foot_lift_shortfall_m"], lift_limit, "m",
                                 f"how much lower a foot's highest lift (lowest sole corner above its lowest point) "
                                 f"stayed in the rollout than in the reference, the larger of the two feet (threshold "
                                 f"{c.max_foot_lift_shortfall_per_height} x robot height; frames: the reference's "
                                 f"highest lift of a foot that fell short)", lift_frames, lifts))
            metrics.update(pose_error_mean_m=fidelity["pose_error_mean_m"],
                           heading_error_max_rad=fidelity["heading_error_max_rad"],
                           foot_lift_shortfall_m=fidelity["foot_lift_shortfall_m"])

    metrics["passed"] = all(ch.passed for ch in checks)

    per_foot = {}
    for s, side in enumerate(SIDES):
        per_foot[side] = {"contact_frames": int(contact_frames[s]), "skate_frames": int(kin.skating[:, s].sum()),
                          "skate_ratio": float(skate_ratio[s]), "skate_distance_m": float(kin.skate_distance[s]),
                          "min_sole_height_m": float(kin.sole_height[:, s].min())}
    per_joint = {}
    for j, name in enumerate(index.joint_names):
        entry = {"range_rad": index.joint_range[j].tolist(), "velocity_limit_radps": float(index.velocity_limit[j]),
                 "torque_limit_nm": float(index.torque_limit[j]), "limit_violations": int(violating[:, j].sum()),
                 "max_velocity_ratio": float(vel_ratio[:, j].max()), "max_torque_ratio": float(torque_ratio[:, j].max()),
                 "max_acceleration_radps2": float(acc[:, j].max()),
                 **at_limit_fields(kin.joint_pos[:, j], low[j], high[j], c.joint_limit_tolerance_rad)}
        if roll is not None:
            entry["tracking_rmse_rad"] = float(roll.tracking_rmse_per_joint[j])
        per_joint[name] = entry
    return checks, metrics, per_foot, per_joint


def frame_ranges(frames: list[int], limit: int = 4) -> str:
    """'3-7, 12, 20-25' (at most ``limit`` ranges, then '...')."""
    if not frames:
        return ""
    ranges, start, prev = [], frames[0], frames[0]
    for f in frames[1:]:
        if f != prev + 1:
            ranges.append((start, prev))
            start = f
        prev = f
    ranges.append((start, prev))
    text = ", ".join(f"{a}" if a == b else f"{a}-{b}" for a, b in ranges[:limit])
    return text + (", ..." if len(ranges) > limit else "")


def _format_value(check: dict, key: str = "value") -> str:
    value = check[key]
    if isinstance(value, bool) or value is None:
        return str(value)
    if isinstance(value, int):
        return str(value)
    return f"{value:.3g}"


def summary_text(report: dict) -> str:
    """Short human-readable summary naming the failing checks."""
    name = Path(report["input"]["path"]).name
    checks = report["checks"]
    failed = report["failed_checks"]
    head = (f"{'PASS' if report['passed'] else 'FAIL'} {name} on {report['robot']} "
            f"({report['input']['duration_s']:.1f} s, {report['input']['frames']} frames): "
            f"{len(checks) - len(failed)}/{len(checks)} checks passed")
    lines = [head]
    for key in failed:
        ch = checks[key]
        extra = ""
        if ch["details"].get("diagnosis"):
            extra = f", {ch['details']['foot']} foot: {ch['details']['diagnosis']}"
        elif ch["details"].get("worst_joint"):
            extra = f", joint {ch['details']['worst_joint']}"
        elif ch["details"].get("foot"):
            extra = f", {ch['details']['foot']} foot"
        if key == "fall" and ch["details"].get("fall_time_s") is not None:
            extra = f" at {ch['details']['fall_time_s']:.2f} s ({ch['details']['reason']})"
        frames = frame_ranges(ch["frames"])
        lines.append(f"  FAILED {key}: {_format_value(ch)} (must be {ch['comparison']} {_format_value(ch, 'threshold')}){extra}"
                     + (f"; frames {frames}" if frames else ""))
    lines += [f"  note: {note}" for note in report.get("notes") or []]
    return "\n".join(lines)


def robot_description_record(index: RobotIndex) -> dict:
    """``report["robot_description"]``: the digest of the description (TOML + MJCF bytes) the
    report's limits came from; playback refuses a report whose digest differs from the robot it
    loads (:func:`motok_robot.servo.streamer.check_validation_report`)."""
    return {"name": index.name, "sha256": getattr(index, "description_sha256", None)}


def write_report(report: dict, path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(_clean(report), indent=2) + "\n")
    return path


def validate_report_dict(report: dict) -> None:
    """Raise ValueError when ``report`` does not follow the schema above (used by tests and batch)."""
    for key in ("schema", "passed", "failed_checks", "robot", "input", "metrics", "checks", "config"):
        if key not in report:
            raise ValueError(f"report: key '{key}' missing")
    if report["schema"] != SCHEMA:
        raise ValueError(f"report: schema {report['schema']!r} is not {SCHEMA!r}")
    missing = [k for k in METRIC_KEYS if k not in report["metrics"]]
    if missing:
        raise ValueError(f"report: metrics missing {missing}")
    for name, check in report["checks"].items():
        for key in ("passed", "value", "threshold", "comparison", "frames", "unit", "description", "details"):
            if key not in check:
                raise ValueError(f"report: check '{name}' has no '{key}'")
    if report["passed"] != all(ch["passed"] for ch in report["checks"].values()):
        raise ValueError("report: 'passed' disagrees with the checks")

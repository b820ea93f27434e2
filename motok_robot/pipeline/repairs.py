"""The two repairs tried after a failed validation, each kept only when it trades no passing check
for a failing one (thresholds are never changed):

* the balance repair (:func:`rebalance`): when the robot loses its footing or balance
  (:data:`BALANCE_CHECKS`) after retargeting without the ZMP term, the motion is retargeted again
  with the ZMP term and a foot planted in every frame (``PipelineConfig.balance_zmp_weight``);
* the slow-down (:func:`slow_down`): when the motion asks more than the servos have
  (:data:`SPEED_CHECKS`), the robot plays it slower (``PipelineConfig.max_retime``).

Neither is tried when the feasibility stage ran (it owns timing and balance).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from motok_robot.pipeline.config import PipelineConfig

#: validation checks that a slower playback of the same motion can fix
SPEED_CHECKS = frozenset({"torque", "joint_velocity", "joint_acceleration"})
#: validation checks of the robot's footing and balance, which retargeting with the ZMP term and a
#: foot planted in every frame can fix (``PipelineConfig.balance_zmp_weight``)
BALANCE_CHECKS = frozenset({"floating", "zmp", "static_balance", "center_of_pressure", "fall", "base_drift"})
#: slow-down factors the pipeline tries, in order, up to ``PipelineConfig.max_retime``
RETIME_STEPS = (1.25, 1.5, 2.0, 3.0)


def balance_retargeter(entry: dict, weight: float,
                       acceleration: float = PipelineConfig.balance_acceleration_weight):
    """The retargeter of the balance repair for a
    :func:`~motok_robot.pipeline.run.load_robot_stages` ``entry``: its plain retargeter's
    settings with the ZMP term at ``weight``, the joint-acceleration weight at ``acceleration``
    and a foot planted in every frame (contact support ``"always"``).  Built once per robot
    entry and weights; its compiled window problems are kept like the plain retargeter's."""
    from dataclasses import replace

    from retarget.solve import Retargeter

    key = (float(weight), float(acceleration))
    cache = entry.setdefault("balance_retargeters", {})
    if key not in cache:
        base = entry["retargeter"]
        weights = replace(base.config.weights, zmp=key[0], acceleration=key[1])
        cache[key] = Retargeter(base.robot, replace(base.config, weights=weights,
                                                    contacts=replace(base.config.contacts, support="always")))
    return cache[key]


def violated_windows(windows) -> int:
    """How many solver windows ended with a hard constraint violated: ``windows`` are a retarget
    result's windows (``.violated``) or robot.npz ``solver_status`` entries (``"violated"``)."""
    return sum((w.get("violated") if isinstance(w, dict) else w.violated) is not None for w in windows)


def rebalance(retargeter, config: PipelineConfig, motion, robot_path: Path, first_violated: int, unbalanced: set,
              validation, validate_robot_file, notes: list[str]):
    """Retarget ``motion`` (``.joints``, ``.fps``) again with ``retargeter``
    (:func:`balance_retargeter`: the ZMP term at ``config.balance_zmp_weight``, a foot planted in
    every frame) and validate it.  Keeps the new trajectory in ``robot_path`` and returns
    ``(retarget result, trajectory, validation)`` when the checks it fails, speed checks aside,
    are a strict subset of those that failed before and no more of its solver windows end with a
    hard constraint violated than ``first_violated`` (the first retargeting's count,
    :func:`violated_windows`; a window that stopped short of optimality with every constraint
    holding counts as feasible: validation judges it); otherwise restores the first trajectory
    and returns None."""
    from retarget.io import write_robot_npz

    weights = (f"weight {config.balance_zmp_weight:g}, "
               f"acceleration weight {config.balance_acceleration_weight:g}")
    original_bytes = robot_path.read_bytes()
    before = set(validation.report["failed_checks"])
    rt = retargeter.run(motion.joints, float(motion.fps), progress=False, source="motion.npz")
    write_robot_npz(robot_path, rt)
    trajectory, balanced = validate_robot_file()
    after = set(balanced.report["failed_checks"])
    listed = ", ".join(sorted(unbalanced))
    infeasible = violated_windows(rt.windows) - int(first_violated)
    if infeasible > 0:
        robot_path.write_bytes(original_bytes)
        notes.append(f"balance: {listed} failed; retargeting again with the ZMP term ({weights}) left "
                     f"{infeasible} more solver window(s) with a constraint violated, so the first trajectory is kept")
        return None
    if after - SPEED_CHECKS < before - SPEED_CHECKS:
        now = "every check passes" if not after else f"fails {', '.join(sorted(after))}"
        notes.append(f"balance: {listed} failed; retargeted again with the ZMP term ({weights}) and a "
                     f"foot planted in every frame, the trajectory kept: {now}")
        return rt, trajectory, balanced
    robot_path.write_bytes(original_bytes)
    notes.append(f"balance: {listed} failed; retargeting again with the ZMP term ({weights}) and a foot "
                 f"planted in every frame failed "
                 f"{', '.join(sorted(after)) or 'nothing'} instead, not fewer checks, so the first trajectory is kept")
    return None


def slow_down(limit: float, robot_path: Path, too_fast: set, validation, trajectory, validate_robot_file, notes):
    """Play ``robot_path`` slower (:data:`RETIME_STEPS` up to ``limit``, the config's
    ``max_retime``) until no speed check fails and no check fails that passed before; keep the
    original file and verdict when no factor does.  Returns ``(trajectory, validation, factor)``
    of the timing kept (``robot_path`` holds it)."""
    from retarget.io import read_robot_npz, write_robot_npz
    from retarget.retime import retime

    original_bytes = robot_path.read_bytes()
    original = read_robot_npz(robot_path)
    before = ", ".join(f"{name} {validation.report['checks'][name]['value']:.2f}" for name in sorted(too_fast))
    factors = [f for f in RETIME_STEPS if f < limit - 1e-9] + [limit]
    failed_before = set(validation.report["failed_checks"])
    for factor in factors:
        write_robot_npz(robot_path, retime(original, factor))
        slowed_trajectory, slowed = validate_robot_file()
        failed_now = set(slowed.report["failed_checks"])
        if not SPEED_CHECKS.intersection(failed_now) and failed_now <= failed_before:
            after = ", ".join(f"{name} {slowed.report['checks'][name]['value']:.2f}" for name in sorted(too_fast))
            notes.append(f"retime: the motion asked more than the servos have ({before}); the robot plays it "
                         f"{factor:g}x slower ({after}; {slowed_trajectory.duration_s:.1f} s instead of "
                         f"{trajectory.duration_s:.1f} s)")
            return slowed_trajectory, slowed, factor
    robot_path.write_bytes(original_bytes)
    notes.append(f"retime: {before} fail; playing up to {limit:g}x slower did not bring "
                 f"{', '.join(sorted(too_fast))} within the servo limits without failing another check, "
                 "so the original timing is kept")
    return trajectory, validation, 1.0


@dataclass
class Repaired:
    """What :func:`apply_repairs` kept."""

    trajectory: object          # the validated trajectory (motok_robot.sim.trajectory.RobotTrajectory)
    validation: object          # its ValidationResult
    retime_factor: float        # 1.0 unless the slow-down was kept
    zmp_weight: float           # retargeting's ZMP weight of the trajectory kept
    acceleration_weight: float  # and its joint-acceleration weight
    retarget: object | None     # the balance repair's retarget result when it was kept, else None


def apply_repairs(config: PipelineConfig, retargeter_for_balance, motion, robot_path: Path, zmp_weight: float,
                  acceleration_weight: float, first_violated: int, trajectory, validation, validate_robot_file,
                  notes: list[str], stage=None, timings: dict | None = None) -> Repaired:
    """The repairs ``run`` tries after validating ``robot_path`` (the same code serves
    ``motok-robot repair``, so the stages run one by one give what ``run`` gives): the balance
    repair when a footing or balance check failed and the trajectory was retargeted without the
    ZMP term (``zmp_weight`` 0), then the slow-down when a speed check fails.
    ``retargeter_for_balance()`` builds the balance repair's retargeter when needed
    (:func:`balance_retargeter`); ``stage(name)`` names the running repair and ``timings``
    receives ``balance`` / ``retime`` seconds.  ``robot_path`` holds the trajectory kept."""
    import time

    timings = timings if timings is not None else {}
    retarget = None
    unbalanced = BALANCE_CHECKS.intersection(validation.report["failed_checks"])
    if unbalanced and config.balance_zmp_weight > 0 and zmp_weight == 0:
        if stage is not None:
            stage("balance")
        t = time.perf_counter()
        rebalanced = rebalance(retargeter_for_balance(), config, motion, robot_path, first_violated, unbalanced,
                               validation, validate_robot_file, notes)
        if rebalanced is not None:
            retarget, trajectory, validation = rebalanced
            zmp_weight = config.balance_zmp_weight
            acceleration_weight = config.balance_acceleration_weight
        timings["balance"] = time.perf_counter() - t
    retime_factor = 1.0
    too_fast = SPEED_CHECKS.intersection(validation.report["failed_checks"])
    if too_fast and config.max_retime > 1.0:
        if stage is not None:
            stage("retime")
        t = time.perf_counter()
        trajectory, validation, retime_factor = slow_down(config.max_retime, robot_path, too_fast, validation,
                                                           trajectory, validate_robot_file, notes)
        timings["retime"] = time.perf_counter() - t
    return Repaired(trajectory=trajectory, validation=validation, retime_factor=float(retime_factor),
                    zmp_weight=float(zmp_weight), acceleration_weight=float(acceleration_weight), retarget=retarget)

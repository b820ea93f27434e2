"""Robustness benchmark helpers: the physics perturbations change what they claim, and a
validation with changed physics (servo model, torso push) runs on a tiny synthetic clip."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import robustness as R  # noqa: E402

from motok_robot.feasibility import BalanceConfig  # noqa: E402
from motok_robot.robots.index import index_robot  # noqa: E402
from motok_robot.sim import synthetic as S  # noqa: E402
from motok_robot.sim.config import ValidationConfig  # noqa: E402
from motok_robot.sim.rollout import Push, push_wrench, servo_model  # noqa: E402
from motok_robot.sim.testing import tiny_humanoid  # noqa: E402
from motok_robot.sim.trajectory import RobotTrajectory  # noqa: E402
from motok_robot.sim.validate import validate_trajectory  # noqa: E402

FPS = 20.0


@pytest.fixture(scope="module")
def tiny():
    return index_robot(tiny_humanoid())


def test_varied_model_scales_servo_stiffness_and_link_masses(tiny):
    nominal, _ = servo_model(tiny, ValidationConfig())
    stiff = R.varied_model(tiny, 1.2, 1.0)
    heavy = R.varied_model(tiny, 1.0, 0.9)
    assert np.allclose(stiff.actuator_gainprm[:, 0], 1.2 * nominal.actuator_gainprm[:, 0])
    assert np.allclose(stiff.actuator_biasprm[:, 1], 1.2 * nominal.actuator_biasprm[:, 1])  # -kp of the bias
    assert np.allclose(stiff.actuator_biasprm[:, 2], nominal.actuator_biasprm[:, 2])  # damping kept
    assert np.allclose(stiff.body_mass, nominal.body_mass)
    assert np.allclose(heavy.body_mass, 0.9 * nominal.body_mass) and heavy.body_mass.sum() > 0
    assert np.allclose(heavy.body_inertia, 0.9 * nominal.body_inertia)
    assert np.allclose(heavy.actuator_gainprm, nominal.actuator_gainprm)
    assert np.allclose(tiny.model.body_mass.sum(), nominal.body_mass.sum())  # the robot's own model untouched


def test_perturbations_list_the_model_changes_and_one_push_per_direction_and_size():
    variants = R.perturbations([0.2, 0.4])
    assert variants[0] == {"name": "nominal", "stiffness": 1.0, "mass": 1.0, "push": None}
    assert {(v["stiffness"], v["mass"]) for v in variants if v["push"] is None} == \
        {(1.0, 1.0), (0.8, 1.0), (1.2, 1.0), (1.0, 0.9), (1.0, 1.1)}
    pushes = [(v["push"]["direction"], v["push"]["fraction"]) for v in variants if v["push"]]
    assert sorted(pushes) == sorted((d, f) for d in ("forward", "backward", "left") for f in (0.2, 0.4))


def test_push_wrench_is_on_the_body_only_while_the_push_lasts():
    push = Push(body=2, force=(3.0, -1.0, 0.0), start_s=0.5, duration_s=0.1)
    assert np.all(push_wrench([push], 4, 0.496) == 0)
    on = push_wrench([push], 4, 0.5)
    assert np.allclose(on[2], [3.0, -1.0, 0.0, 0.0, 0.0, 0.0]) and np.all(np.delete(on, 2, axis=0) == 0)
    assert np.allclose(push_wrench([push], 4, 0.596)[2, :3], (3.0, -1.0, 0.0))
    assert np.all(push_wrench([push], 4, 0.6) == 0)
    assert np.allclose(push_wrench([push, push], 4, 0.55)[2, :3], (6.0, -2.0, 0.0))  # pushes add


def test_torso_push_is_a_weight_fraction_relative_to_the_heading_at_mid_clip(tiny):
    qpos = S.standing(tiny, 2.0, FPS)
    yaw = math.pi / 2  # the robot faces +y
    qpos[:, 3:7] = [math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]
    weight = tiny.total_mass * 9.81
    forward = R.torso_push(tiny, qpos, FPS, "forward", 0.3)
    assert forward.body == tiny.root_body and forward.start_s == pytest.approx(1.0) and forward.duration_s == 0.1
    assert np.allclose(forward.force, (0.0, 0.3 * weight, 0.0), atol=1e-9)
    assert np.allclose(R.torso_push(tiny, qpos, FPS, "backward", 0.3).force, (0.0, -0.3 * weight, 0.0), atol=1e-9)
    assert np.allclose(R.torso_push(tiny, qpos, FPS, "left", 0.3).force, (-0.3 * weight, 0.0, 0.0), atol=1e-9)


@pytest.mark.parametrize("plan_mode", ["open", "closed"])
def test_a_zero_push_changes_nothing_and_a_model_change_only_the_physics(tiny, plan_mode):
    qpos = S.standing(tiny, 1.0, FPS)
    trajectory = RobotTrajectory(qpos, FPS, tiny.joint_names, tiny.name)
    balance = BalanceConfig() if plan_mode == "closed" else BalanceConfig(enabled=False)
    nominal = validate_trajectory(trajectory, tiny, plots=False, balance=balance)
    zero = validate_trajectory(trajectory, tiny, plots=False, balance=balance,
                               pushes=[Push(tiny.root_body, (0.0, 0.0, 0.0), 0.5)])
    assert np.allclose(zero.rollout.qpos, nominal.rollout.qpos)  # the xfrc path is the plain one at zero force
    soft = validate_trajectory(trajectory, tiny, plots=False, balance=balance,
                               physics_model=R.varied_model(tiny, 0.5, 1.0))
    assert np.array_equal(soft.goals, nominal.goals)  # goals made for the nominal robot
    assert np.abs(soft.rollout.qpos - nominal.rollout.qpos).max() > 1e-3  # the rollout used the softer servos


def test_a_hard_torso_push_makes_the_standing_robot_fall_in_both_modes(tiny):
    qpos = S.standing(tiny, 2.0, FPS)
    trajectory = RobotTrajectory(qpos, FPS, tiny.joint_names, tiny.name)
    hard = {"name": "push", "stiffness": 1.0, "mass": 1.0, "push": {"direction": "forward", "fraction": 1.5}}
    nominal = R.perturbations([])[0]
    for mode in R.MODES:
        assert R.validate_perturbed(trajectory, tiny, nominal, mode, {}).passed
        pushed = R.validate_perturbed(trajectory, tiny, hard, mode, {})
        assert pushed.report["metrics"]["fell"] and "fall" in pushed.report["failed_checks"]
        assert pushed.rollout.qpos[-1, 0] > qpos[-1, 0] + 0.05  # it went forward, the way it was pushed


def test_the_stage_outputs_are_played_with_their_own_goals_closed_and_open_loop(tiny, tmp_path, retargeted):
    """``--stage``: a feasibility stage output found under WORK/runs/ROBOT/CLIP/D/feasible is played
    with the stage's servo goals, closed loop with its balance plan and open loop without it."""
    from motok_robot.feasibility.config import FeasibilityConfig
    from motok_robot.feasibility.feedforward import load_servo_goals
    from motok_robot.feasibility.stage import make_feasible, write_feasible
    from motok_robot.sim.trajectory import load_robot_npz
    from motok_robot.sim.validate import stage_goals_beside

    qpos = S.standing(tiny, 1.5, FPS)
    result = make_feasible(retargeted(tiny, qpos), tiny, FeasibilityConfig())
    folder = tmp_path / "runs" / tiny.name / "stand" / "D" / "feasible"
    npz = write_feasible(result, folder, tiny.name)
    clips = R.stage_clips(tiny.name, tmp_path, tmp_path / "no-datasets")
    assert [(c["clip"], c["group"], c["npz"]) for c in clips] == [("stand", "stage", npz)]
    goals = stage_goals_beside(npz)
    assert goals is not None and goals["plan"] is not None
    assert np.array_equal(goals["goals"], load_servo_goals(folder / "servo_goals.npz")["goals"])
    other = tmp_path / "other" / "robot.npz"  # the same goals beside another file are not its goals
    other.parent.mkdir()
    (other.parent / "servo_goals.npz").write_bytes((folder / "servo_goals.npz").read_bytes())
    other.write_bytes(npz.read_bytes() + b"\0")
    assert stage_goals_beside(other) is None
    trajectory = load_robot_npz(npz, tiny)
    nominal = R.perturbations([])[0]
    closed = R.validate_perturbed(trajectory, tiny, nominal, "closed", {}, goals)
    opened = R.validate_perturbed(trajectory, tiny, nominal, "open", {}, goals)
    assert closed.report["servo_goals"]["mode"] == "feasibility" and closed.passed
    assert np.array_equal(closed.goals, opened.goals)  # the stage's goals both times
    assert np.abs(closed.rollout.qpos - opened.rollout.qpos).max() > 0  # only the controller differs

"""Playback on the simulated rig (MuJoCo actuators as the servo bus)."""

import json

import numpy as np
import pytest

from motok_robot.robots import load
from motok_robot.servo.config import PlaybackConfig
from motok_robot.servo.sim_rig import SimRig
from motok_robot.servo.streamer import Streamer, Trajectory, play_file
from motok_robot.servo.timing import FakeClock


@pytest.fixture(scope="module")
def robot():
    return load("op3_like")


@pytest.fixture(scope="module")
def index(robot):
    from motok_robot.robots.index import index_robot

    return index_robot(robot)


def save(path, robot, qpos):
    np.savez(path, qpos=qpos, joint_names=np.array(robot.joint_names), robot=robot.name, fps=20.0)
    return path


def test_sim_rig_tracks_commands_and_converts_ticks(robot):
    clock = FakeClock()
    rig = SimRig(robot, clock=clock)
    ids = [int(i) for i in rig.map.ids]
    present = rig.read_present_positions(ids)
    assert np.allclose(rig.map.to_rad(present), rig.joint_angles(ids), atol=2 * np.pi / 4096)
    head = ids[rig.map.joints.index("head_pan")]
    goal = present.copy()
    goal[ids.index(head)] += 300  # about 0.46 rad
    rig.write_goal_positions(ids, goal)
    for _ in range(10):
        clock.advance(0.1)
        after = rig.read_present_positions(ids)
    assert abs(after[ids.index(head)] - goal[ids.index(head)]) < 30
    assert rig.steps == pytest.approx(1.0 / robot.model.opt.timestep, abs=2)
    clock.advance(5.0)  # a stalled host: physics catches up at most max_lag_s, not 5 s at once
    rig.read_present_positions(ids)
    assert rig.data.time == pytest.approx(1.0 + rig.max_lag_s, abs=0.01)
    assert not rig.fell


def test_stand_and_wave_stays_upright(robot):
    clock = FakeClock()
    rig = SimRig(robot, clock=clock)
    nominal = robot.nominal_qpos()
    q = np.array([nominal[robot.qpos_adr[robot.joint_names.index(j)]] for j in rig.map.joints])
    t = np.arange(41) / 20
    traj = np.repeat(q[None], len(t), axis=0)
    traj[:, rig.map.joints.index("head_pan")] += 0.4 * np.sin(2 * np.pi * 0.5 * t)
    traj[:, rig.map.joints.index("l_sho_roll")] += 0.3 * np.sin(2 * np.pi * 0.5 * t)
    result = Streamer(rig, rig.map, PlaybackConfig(ramp_s=0.5), clock=clock).play(
        Trajectory(traj, 20.0, rig.map.joints))
    assert result.completed and not rig.fell
    assert rig.min_base_height > 0.9 * rig.start_base_height


def test_sim_rig_detects_a_fall(robot, index):
    from motok_robot.sim import synthetic

    qpos = synthetic.lift_foot_without_shift(index, seconds=3.0)
    clock = FakeClock()
    rig = SimRig(robot, clock=clock)
    q = qpos[:, [7 + robot.joint_names.index(j) for j in rig.map.joints]]
    Streamer(rig, rig.map, PlaybackConfig(ramp_s=0.2), clock=clock).play(Trajectory(q, 20.0, rig.map.joints))
    assert rig.fell


def test_validated_walk_plays_upright_on_the_sim_rig(robot, index, tmp_path):
    from motok_robot.sim import synthetic
    from motok_robot.sim.validate import validate_file

    path = save(tmp_path / "walk.npz", robot, synthetic.walk(index, steps=2))
    validate_file(path, robot, out_dir=tmp_path / "val", plots=False, render=False)
    report = json.loads((tmp_path / "val" / "report.json").read_text())
    if not report["passed"]:
        failed = [k for k, c in report["checks"].items() if not c["passed"]]
        pytest.skip(f"the synthetic walk does not pass validation yet ({', '.join(failed)}): nothing validated to play")
    clock = FakeClock()
    rig = SimRig(robot, clock=clock)
    result = play_file(path, robot, rig, config=PlaybackConfig(ramp_s=0.5), report_path=tmp_path / "val" / "report.json",
                       clock=clock, log_path=tmp_path / "walk.csv")
    assert result.completed and not rig.fell

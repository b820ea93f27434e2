"""Retiming a robot trajectory (retarget.retime) and the pipeline's slow-down when a motion is too
fast for the servos."""

from __future__ import annotations

import json

import numpy as np
import pytest

from motok_robot.errors import InputError
from retarget.io import RobotTrajectory, read_robot_npz, write_robot_npz
from retarget.retime import retime


def _trajectory(T=21, nj=3, fps=20.0) -> RobotTrajectory:
    t = np.arange(T) / fps
    qpos = np.zeros((T, 7 + nj))
    qpos[:, 0] = 0.1 * t                       # base walks forward
    yaw = 0.5 * t                              # and turns
    qpos[:, 3], qpos[:, 6] = np.cos(yaw / 2), np.sin(yaw / 2)
    qpos[:, 7:] = np.sin(2 * np.pi * t)[:, None] * np.arange(1, nj + 1)
    contacts = np.zeros((T, 2), dtype=bool)
    contacts[: T // 2, 0] = True
    contacts[T // 2:, 1] = True
    return RobotTrajectory(qpos=qpos, joint_names=[f"j{i}" for i in range(nj)], robot="toy", fps=fps, contacts=contacts,
                           keypoint_error=np.full((T, 4), 0.01), keypoint_names=["a", "b", "c", "d"],
                           source=np.random.default_rng(0).normal(size=(T, 22, 3)).astype(np.float32),
                           solver_status=[{"start": 0, "stop": T, "status": "Solve_Succeeded"}])


def test_retime_plays_the_same_path_slower():
    tr = _trajectory()
    slow = retime(tr, 2.0)
    T = tr.qpos.shape[0]
    assert slow.qpos.shape == (2 * (T - 1) + 1, tr.qpos.shape[1]) and slow.fps == tr.fps
    assert np.allclose(slow.qpos[::2, 7:], tr.qpos[:, 7:])         # original frames at every other frame
    assert np.allclose(slow.qpos[0], tr.qpos[0]) and np.allclose(slow.qpos[-1], tr.qpos[-1])
    assert np.allclose(np.linalg.norm(slow.qpos[:, 3:7], axis=1), 1.0)
    # joint speed halves
    speed = np.abs(np.diff(tr.qpos[:, 7:], axis=0)).max() * tr.fps
    slow_speed = np.abs(np.diff(slow.qpos[:, 7:], axis=0)).max() * slow.fps
    assert slow_speed == pytest.approx(speed / 2, rel=1e-9)
    assert slow.contacts.shape == (slow.qpos.shape[0], 2) and slow.contacts[0, 0] and slow.contacts[-1, 1]
    assert slow.keypoint_error.shape[0] == slow.source.shape[0] == slow.qpos.shape[0]
    assert slow.retime_factor == 2.0 and retime(slow, 1.5).retime_factor == pytest.approx(3.0)
    assert retime(tr, 1.0).qpos.shape == tr.qpos.shape


def test_retime_rejects_speeding_up():
    for factor in (0.5, float("nan"), -1.0):
        with pytest.raises(InputError, match="factor must be a number >= 1"):
            retime(_trajectory(), factor)


def test_retime_factor_round_trips_through_robot_npz(tmp_path):
    slow = retime(_trajectory(), 1.25)
    path = write_robot_npz(tmp_path / "robot.npz", slow)
    back = read_robot_npz(path)
    assert back.retime_factor == 1.25 and np.allclose(back.qpos, slow.qpos)
    assert back.solver_status == slow.solver_status
    # files written before the field existed read as 1.0
    data = dict(np.load(path))
    del data["retime_factor"]
    np.savez(tmp_path / "old.npz", **data)
    assert read_robot_npz(tmp_path / "old.npz").retime_factor == 1.0
    # a factor that is not a positive number is named, not carried on
    for bad in (0.0, -1.0, float("nan")):
        data["retime_factor"] = np.float64(bad)
        np.savez(tmp_path / "bad.npz", **data)
        with pytest.raises(InputError, match="field 'retime_factor' must be a positive number"):
            read_robot_npz(tmp_path / "bad.npz")


@pytest.fixture(scope="module")
def fast_wave(tmp_path_factory):
    """The shipped demo wave played 3x faster: the shoulder then needs more than the XM430's 4.1 N m."""
    demo = np.load("examples/wave_demo.npz")
    path = tmp_path_factory.mktemp("fast") / "fast_wave.npz"
    np.savez(path, joints=demo["joints"][::3], fps=20, text="fast wave")
    return path


def test_pipeline_slows_a_motion_that_is_too_fast(fast_wave, tmp_path):
    from motok_robot.pipeline import SPEED_CHECKS, Pipeline, PipelineConfig

    strict = Pipeline(PipelineConfig(plots=False, max_retime=1.0)).run(
        None, motion=fast_wave, robot="op3_like", out_dir=tmp_path / "strict", render=False)
    too_fast = SPEED_CHECKS.intersection(strict.failed_checks)
    assert too_fast, f"the 3x wave should be too fast for op3_like (failed: {strict.failed_checks})"
    assert strict.retime_factor == 1.0

    result = Pipeline(PipelineConfig(plots=False)).run(None, motion=fast_wave, robot="op3_like",
                                                       out_dir=tmp_path / "slowed", render=False)
    assert result.retime_factor > 1.0
    assert not SPEED_CHECKS.intersection(result.failed_checks)
    assert any(n.startswith("retime:") for n in result.notes)
    robot = read_robot_npz(result.files["robot"])
    assert robot.retime_factor == result.retime_factor
    assert robot.qpos.shape[0] == round((read_robot_npz(strict.files["robot"]).qpos.shape[0] - 1) * result.retime_factor) + 1
    # the report validated the slowed file, and playback streamed it
    report = json.loads(result.files["report"].read_text())
    import hashlib

    assert report["input"]["sha256"] == hashlib.sha256(result.files["robot"].read_bytes()).hexdigest()
    assert result.playback.status == "completed"
    # the streamed goals are the validated ones: the playback limiter never had to clamp them
    assert json.loads(result.files["playback_stats"].read_text())["limited"] == 0
    assert "slower" in result.files["summary"].read_text()


def test_hold_ends_stands_before_and_after_and_keeps_every_per_frame_field():
    from retarget.retime import hold_ends

    trajectory = _trajectory(T=10)
    held = hold_ends(trajectory, 3, 2)
    assert held.qpos.shape[0] == 15
    assert np.array_equal(held.qpos[:4], np.repeat(trajectory.qpos[:1], 4, axis=0))
    assert np.array_equal(held.qpos[3:13], trajectory.qpos)
    assert np.array_equal(held.qpos[-3:], np.repeat(trajectory.qpos[-1:], 3, axis=0))
    for name in ("contacts", "keypoint_error", "source"):
        assert getattr(held, name).shape[0] == 15
    assert held.retime_factor == trajectory.retime_factor  # standing still is not a slow-down
    assert hold_ends(trajectory, 0, 0).qpos.shape == trajectory.qpos.shape


def test_task_qpos_round_trips_through_robot_npz_and_a_wrong_shape_is_named(tmp_path):
    import dataclasses

    trajectory = _trajectory()
    task = trajectory.qpos + 0.1
    path = write_robot_npz(tmp_path / "robot.npz", dataclasses.replace(trajectory, task_qpos=task))
    assert np.array_equal(read_robot_npz(path).task_qpos, task)
    assert read_robot_npz(write_robot_npz(tmp_path / "plain.npz", trajectory)).task_qpos is None
    data = dict(np.load(path))
    data["task_qpos"] = task[:-1]
    np.savez(tmp_path / "bad.npz", **data)
    with pytest.raises(InputError, match="task_qpos"):
        read_robot_npz(tmp_path / "bad.npz")


def test_the_stages_one_by_one_give_what_run_gives_for_a_motion_too_fast(fast_wave, tmp_path):
    """retarget, then repair (run's slow-down as a stage of its own), on run's motion.npz: the same
    robot.npz, verdict and servo goals as run."""
    from motok_robot.cli import main
    from motok_robot.pipeline import SPEED_CHECKS, Pipeline, PipelineConfig

    ran = Pipeline(PipelineConfig(plots=False)).run(None, motion=fast_wave, robot="op3_like", out_dir=tmp_path / "run",
                                                    render=False)
    assert ran.retime_factor > 1.0  # run slowed it down
    motion, robot = ran.files["motion"], tmp_path / "robot.npz"
    assert main(["retarget", str(motion), "--robot", "op3_like", "--out", str(robot)]) == 0
    rc = main(["repair", str(robot), "--motion", str(motion), "--out", str(tmp_path / "repaired")])
    repaired = read_robot_npz(tmp_path / "repaired" / "robot.npz")
    ran_robot = read_robot_npz(ran.files["robot"])
    assert repaired.retime_factor == ran.retime_factor
    assert np.array_equal(repaired.qpos, ran_robot.qpos)
    report = json.loads((tmp_path / "repaired" / "report.json").read_text())
    assert report["passed"] == ran.passed and report["failed_checks"] == ran.failed_checks
    assert not SPEED_CHECKS.intersection(report["failed_checks"])
    assert report["servo_goals"]["sha256"] == json.loads(ran.files["report"].read_text())["servo_goals"]["sha256"]
    assert rc == (0 if ran.passed else 1)


def test_repair_refuses_bad_input_with_one_line(tmp_path, capsys):
    from motok_robot.cli import main

    robot = tmp_path / "robot.npz"
    write_robot_npz(robot, _trajectory())
    cases = [(["--motion", str(tmp_path / "missing.npz")], "missing.npz"),
             (["--motion", str(robot), "--max-retime", "0.5"], "--max-retime"),
             (["--motion", str(robot), "--balance-zmp-weight", "nan"], "--balance-zmp-weight")]
    for extra, named in cases:
        assert main(["repair", str(robot), "--out", str(tmp_path / "out"), *extra]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and named in err[0], err
    data = dict(np.load(robot))
    data["solver_status"] = np.array(json.dumps([1, 2]))
    np.savez(tmp_path / "odd.npz", **data)
    assert main(["repair", str(tmp_path / "odd.npz"), "--motion", str(robot), "--out", str(tmp_path / "out")]) == 2
    assert "field 'solver_status'" in capsys.readouterr().err

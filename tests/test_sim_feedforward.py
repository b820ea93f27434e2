"""Servo goals with inverse-dynamics feedforward: computed by validation, tracked by its physics
rollout, written to servo_goals.npz, and streamed by playback exactly as validated."""

from __future__ import annotations

import json

import numpy as np
import pytest

from motok_robot.feasibility import BalanceConfig
from motok_robot.errors import InputError
from motok_robot.sim import synthetic as S
from motok_robot.sim.config import ValidationConfig
from motok_robot.feasibility.feedforward import GOALS_FILE, feedforward_goals, goals_digest, load_servo_goals, servo_gains
from motok_robot.robots.index import index_robot
from motok_robot.sim.rollout import servo_model, simulate
from motok_robot.sim.testing import tiny_humanoid
from motok_robot.sim.trajectory import RobotTrajectory
from motok_robot.sim.validate import validate_file, validate_trajectory

FPS = 20.0


@pytest.fixture(scope="module")
def tiny():
    return index_robot(tiny_humanoid())


def _validate(index, qpos, **kw):
    trajectory = RobotTrajectory(qpos, FPS, index.joint_names, index.name, source="clip.npz")
    return validate_trajectory(trajectory, index, **kw)


def test_servo_gains_read_the_position_servo_law(tiny):
    model, _ = servo_model(tiny, ValidationConfig())
    k, kd = servo_gains(model, tiny)
    assert np.allclose(k, 60.0) and np.allclose(kd, 1.0)  # tiny humanoid: <position kp="60" kv="1.0">


def test_servo_gains_of_motors_are_the_rollout_pd(tiny):
    index = index_robot(tiny_humanoid(actuator="motor"))
    config = ValidationConfig()
    model, _ = servo_model(index, config)
    k, kd = servo_gains(model, index)
    expected = config.motor_kp_per_nm * 3.0  # 3 N m force limit
    assert np.allclose(k, expected) and np.allclose(kd, config.motor_kd_ratio * expected)


def test_goals_add_torque_and_damping_over_stiffness(tiny):
    T, nj = 5, tiny.nj
    pos = np.tile(tiny.nominal_qpos[tiny.qpos_adr], (T, 1))
    vel = np.full((T, nj), 0.1)
    torque = np.full((T, nj), 0.6)
    k, kd = np.full(nj, 60.0), np.full(nj, 1.0)
    goals = feedforward_goals(tiny, pos, vel, torque, FPS, k, kd)
    expected = np.clip(pos + (0.6 + 1.0 * 0.1) / 60.0, tiny.joint_range[:, 0], tiny.joint_range[:, 1])
    assert np.allclose(goals, expected)
    # a joint without a servo (k = 0) keeps the reference angle
    k[3] = 0.0
    assert np.allclose(feedforward_goals(tiny, pos, vel, torque, FPS, k, kd)[:, 3], pos[:, 3])


def test_goals_clip_torque_and_respect_range_and_velocity(tiny):
    T, nj = 40, tiny.nj
    rng = np.random.default_rng(0)
    low, high = tiny.joint_range[:, 0], tiny.joint_range[:, 1]
    pos = rng.uniform(low, high, size=(T, nj))  # jumps far beyond the velocity limit
    torque = rng.normal(0.0, 50.0, size=(T, nj))  # far beyond the 3 N m force limit
    goals = feedforward_goals(tiny, pos, np.zeros((T, nj)), torque, FPS, np.full(nj, 60.0), np.zeros(nj))
    assert (goals >= low - 1e-12).all() and (goals <= high + 1e-12).all()
    assert (np.abs(np.diff(goals, axis=0)) <= tiny.velocity_limit / FPS + 1e-12).all()
    # at most force limit / stiffness away from the reference in the first frame (no rate limit yet)
    assert (np.abs(goals[0] - np.clip(pos[0], low, high)) <= 3.0 / 60.0 + 1e-12).all()


def test_feedforward_tracks_a_squat_better_than_reference_goals(tiny):
    qpos = S.squat(tiny, seconds=3.0, fps=FPS, depth=0.25)
    open_loop = BalanceConfig(enabled=False)  # the feedforward's own effect, without the balance controller
    kin_goals = _validate(tiny, qpos, physics=True, balance=open_loop)
    plain = _validate(tiny, qpos, physics=True, config=ValidationConfig(servo_feedforward=False), balance=open_loop)
    assert kin_goals.report["servo_goals"]["mode"] == "feedforward"
    assert plain.report["servo_goals"]["mode"] == "reference"
    assert np.allclose(plain.goals, qpos[:, tiny.qpos_adr])
    ff_rmse = kin_goals.report["metrics"]["tracking_rmse_rad"]
    plain_rmse = plain.report["metrics"]["tracking_rmse_rad"]
    assert ff_rmse < 0.5 * plain_rmse, (ff_rmse, plain_rmse)


def test_rollout_controls_follow_the_goals(tiny):
    qpos = S.standing(tiny, seconds=1.0, fps=FPS)
    shifted = qpos[:, tiny.qpos_adr] + 0.2  # bend every joint 0.2 rad away from the reference
    shifted = np.clip(shifted, tiny.joint_range[:, 0], tiny.joint_range[:, 1])
    roll = simulate(tiny, qpos, FPS, ValidationConfig(), goals=shifted)
    plain = simulate(tiny, qpos, FPS, ValidationConfig())
    assert roll.tracking_rmse > plain.tracking_rmse + 0.05


def test_report_records_and_writes_the_goals(tiny, tmp_path):
    from motok_robot.sim.trajectory import save_robot_npz

    qpos = S.standing(tiny, seconds=1.0, fps=FPS)
    path = tmp_path / "robot.npz"
    save_robot_npz(path, RobotTrajectory(qpos, FPS, tiny.joint_names, tiny.name))
    result = validate_file(path, tiny, out_dir=tmp_path / "val", plots=False)
    record = json.loads((tmp_path / "val" / "report.json").read_text())["servo_goals"]
    assert record["mode"] == "feedforward" and record["file"] == GOALS_FILE
    saved = load_servo_goals(tmp_path / "val" / GOALS_FILE, expected_sha256=record["sha256"])
    assert np.array_equal(saved["goals"], result.goals)
    assert saved["joint_names"] == list(tiny.joint_names) and saved["fps"] == FPS
    import hashlib

    assert saved["source_sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()
    # standing still: the goals hold the knees against gravity, so they differ from the reference
    assert np.abs(result.goals - qpos[:, tiny.qpos_adr]).max() > 1e-3
    # without physics there is no rollout and no goals
    assert validate_file(path, tiny, physics=False).report["servo_goals"] is None


def test_goals_file_errors_name_the_problem(tmp_path):
    with pytest.raises(InputError, match="missing.npz: servo goals file not found"):
        load_servo_goals(tmp_path / "missing.npz")
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(InputError, match="junk.npz: not a readable .npz file"):
        load_servo_goals(tmp_path / "junk.npz")
    bad = tmp_path / "bad.npz"
    np.savez(bad, goals=np.zeros((3, 2)), joint_names=np.array(["a"]), fps=20.0, mode="feedforward")
    with pytest.raises(InputError, match="'goals' must be"):
        load_servo_goals(bad)
    nan = tmp_path / "nan.npz"
    goals = np.zeros((3, 1))
    goals[2, 0] = np.nan
    np.savez(nan, goals=goals, joint_names=np.array(["a"]), fps=20.0, mode="feedforward")
    with pytest.raises(InputError, match="frame 2"):
        load_servo_goals(nan)
    ok = tmp_path / "ok.npz"
    np.savez(ok, goals=np.zeros((3, 1)), joint_names=np.array(["a"]), fps=20.0, mode="feedforward")
    with pytest.raises(InputError, match="differ from the validated"):
        load_servo_goals(ok, expected_sha256=goals_digest(np.ones((3, 1))))


# ---- playback streams exactly the validated goals (op3_like: it has a servo map) -----------

@pytest.fixture(scope="module")
def op3():
    from motok_robot.robots import load

    return load("op3_like")


def _validated_stand(op3, tmp_path):
    index = index_robot(op3)
    qpos = S.standing(index, seconds=1.0, fps=FPS)
    path = tmp_path / "robot.npz"
    np.savez(path, qpos=qpos, joint_names=np.array(op3.joint_names), robot=op3.name, fps=FPS)
    result = validate_file(path, op3, out_dir=tmp_path, plots=False)
    return path, result, index


def test_playback_loads_the_validated_goals(op3, tmp_path):
    from motok_robot.servo.convert import ServoMap
    from motok_robot.servo.streamer import load_trajectory

    path, result, index = _validated_stand(op3, tmp_path)
    servo_map = ServoMap.from_specs(op3.servos)
    trajectory = load_trajectory(path, servo_map, op3.name)
    assert trajectory.goals == "feedforward"
    columns = [list(index.joint_names).index(j) for j in servo_map.joints]
    assert np.array_equal(trajectory.q, result.goals[:, columns])

    # a goals file changed after validation is refused, naming the file
    saved = np.load(tmp_path / GOALS_FILE)
    fields = {k: saved[k] for k in saved.files}
    fields["goals"] = fields["goals"] + 0.01
    np.savez(tmp_path / GOALS_FILE, **fields)
    with pytest.raises(InputError, match="servo_goals.npz: goals differ"):
        load_trajectory(path, servo_map, op3.name)
    (tmp_path / GOALS_FILE).unlink()
    with pytest.raises(InputError, match="servo goals file not found"):
        load_trajectory(path, servo_map, op3.name)


def test_playback_of_other_content_uses_the_reference(op3, tmp_path):
    from motok_robot.servo.convert import ServoMap
    from motok_robot.servo.streamer import load_trajectory

    path, _, _ = _validated_stand(op3, tmp_path)
    data = dict(np.load(path))
    data["qpos"] = data["qpos"].copy()
    data["qpos"][:, -1] += 0.05  # not the validated content: the report gate refuses it unless --force
    np.savez(path, **data)
    servo_map = ServoMap.from_specs(op3.servos)
    trajectory = load_trajectory(path, servo_map, op3.name)
    assert trajectory.goals == "reference"

"""`motok-robot play` / `servo scan` / `servo calibrate` on emulated hardware, and their errors."""

import hashlib
import json

import numpy as np
import pytest

from motok_robot.cli import main
from motok_robot.feasibility.feedforward import GOALS_FILE, goals_digest, save_servo_goals
from motok_robot.robots import load
from motok_robot.servo.calibrate import calibrated_description, prepare, read_zero_pose
from motok_robot.servo.convert import ServoMap
from motok_robot.servo.playback_log import read_log
from motok_robot.servo.testing import emulated_bus


@pytest.fixture(scope="module")
def robot():
    return load("op3_like")


def write_clip(folder, robot, seconds=0.4, passed=True, report=True, goals=True, report_folder=None):
    """A short head-and-arm motion of op3_like at 20 fps, with a validation report (in
    ``report_folder``, default beside it) that records servo goals (the joint angles, in
    ``reference`` mode) unless ``goals=False``."""
    nominal = robot.nominal_qpos()
    t = np.arange(int(seconds * 20) + 1) / 20
    qpos = np.repeat(nominal[None], len(t), axis=0)
    for joint, amp in (("head_pan", 0.3), ("l_sho_roll", 0.2)):
        qpos[:, robot.qpos_adr[robot.joint_names.index(joint)]] += amp * np.sin(2 * np.pi * t)
    path = folder / "robot.npz"
    np.savez(path, qpos=qpos, joint_names=np.array(robot.joint_names), robot=robot.name, fps=20.0)
    if report:
        where = report_folder or folder
        where.mkdir(parents=True, exist_ok=True)
        digest = hashlib.sha256(path.read_bytes()).hexdigest()
        record = None
        if goals:
            joint_goals = qpos[:, 7:]
            save_servo_goals(where / GOALS_FILE, joint_goals, robot.joint_names, 20.0, robot.name, "reference", digest)
            record = {"mode": "reference", "file": GOALS_FILE, "sha256": goals_digest(joint_goals)}
        (where / "report.json").write_text(json.dumps({
            "passed": passed, "robot": robot.name, "input": {"path": str(path), "sha256": digest},
            "servo_goals": record, "robot_description": {"sha256": robot.description_sha256}}))
    return path


def one_line_error(capsys):
    err = capsys.readouterr().err.strip()
    assert err.startswith("motok-robot: error: ") and "\n" not in err and "Traceback" not in err
    return err


def test_play_dry_run_streams_and_writes_log_and_stats(tmp_path, robot, capsys):
    clip = write_clip(tmp_path, robot)
    log = tmp_path / "out" / "play.csv"
    rc = main(["play", str(clip), "--robot", "op3_like", "--dry-run", "--ramp", "0.2", "--log", str(log)])
    out = capsys.readouterr().out
    assert rc == 0, out
    assert "played 0.40 s" in out and "jitter p50" in out and "overruns" in out
    rows = read_log(log)
    assert len(rows["tick"]) == 25 + 51
    assert np.all(rows["cmd_head_pan_ticks"] <= 3072) and np.all(rows["cmd_head_pan_ticks"] >= 1024)
    assert json.loads((tmp_path / "out" / "play.stats.json").read_text())["completed"] is True


def test_play_refuses_unvalidated_and_failed_trajectories(tmp_path, robot, capsys):
    clip = write_clip(tmp_path, robot, report=False)
    assert main(["play", str(clip), "--dry-run"]) == 2
    assert "refusing to play: no validation report" in one_line_error(capsys)
    (tmp_path / "report.json").write_text(json.dumps({"passed": False}))
    assert main(["play", str(clip), "--dry-run"]) == 2
    assert "did not pass" in one_line_error(capsys)


def test_play_force_without_goals_refuses_unless_told_to_stream_joint_angles(tmp_path, robot, capsys):
    clip = write_clip(tmp_path, robot, seconds=0.1, report=False)
    assert main(["play", str(clip), "--dry-run", "--force", "--ramp", "0.1"]) == 2
    warning, err = capsys.readouterr().err.strip().splitlines()  # the --force warning, then the error
    assert warning.startswith("motok-robot: warning:") and "WITHOUT a passing validation report" in warning
    assert err.startswith("motok-robot: error: ") and "no validated servo goals for it (no validation report)" in err
    assert "--joint-angles" in err and not (tmp_path / "robot.playback.csv").exists()
    rc = main(["play", str(clip), "--dry-run", "--force", "--joint-angles", "--ramp", "0.1"])
    captured = capsys.readouterr()
    assert rc == 0
    assert "WITHOUT a passing validation report" in captured.err and "RAW JOINT ANGLES" in captured.err
    assert (tmp_path / "robot.playback.csv").is_file()


def test_play_force_with_a_failed_report_streams_its_goals(tmp_path, robot, capsys):
    clip = write_clip(tmp_path, robot, seconds=0.2, passed=False)
    saved = np.load(tmp_path / GOALS_FILE)["goals"].copy()
    changed = saved.copy()
    changed[:, 0] += 0.05  # goals that differ from the joint angles, as feedforward goals do
    save_servo_goals(tmp_path / GOALS_FILE, changed, robot.joint_names, 20.0, robot.name, "feedforward",
                     hashlib.sha256(clip.read_bytes()).hexdigest())
    report = json.loads((tmp_path / "report.json").read_text())
    report["servo_goals"] = {"mode": "feedforward", "file": GOALS_FILE, "sha256": goals_digest(changed)}
    (tmp_path / "report.json").write_text(json.dumps(report))
    log = tmp_path / "p.csv"
    assert main(["play", str(clip), "--dry-run", "--force", "--ramp", "0.1", "--log", str(log)]) == 0
    captured = capsys.readouterr()
    assert "did not pass" in captured.err and "streaming the validated feedforward servo goals" in captured.out
    joint = robot.joint_names[0]
    rows = read_log(log)
    played = rows[f"cmd_{joint}_rad"][rows["phase"] == "play"]
    assert np.allclose(played[-1], changed[-1, 0], atol=2e-3)  # one tick is 1.5e-3 rad
    assert not np.allclose(played[-1], saved[-1, 0], atol=0.02)


def test_play_with_a_report_without_goals_refuses(tmp_path, robot, capsys):
    clip = write_clip(tmp_path, robot, seconds=0.1, goals=False)
    assert main(["play", str(clip), "--dry-run", "--ramp", "0.1"]) == 2
    assert "records no servo goals (validated without physics)" in one_line_error(capsys)


def test_play_finds_the_report_validate_wrote_elsewhere(tmp_path, robot, capsys, monkeypatch):
    clip = write_clip(tmp_path, robot, seconds=0.1, report_folder=tmp_path / "val")
    other = tmp_path / "other"  # a report for other content is not taken
    other.mkdir()
    write_clip(other, robot, seconds=0.2)
    monkeypatch.chdir(tmp_path / "other")
    assert main(["play", str(clip), "--dry-run", "--ramp", "0.1"]) == 0
    out = capsys.readouterr().out
    assert f"validation report: {tmp_path / 'val' / 'report.json'}" in out
    assert "streaming the validated servo goals" in out
    (tmp_path / "val" / "report.json").rename(tmp_path / "val" / "r.json")
    assert main(["play", str(clip), "--dry-run", "--ramp", "0.1"]) == 2
    err = one_line_error(capsys)
    assert "refusing to play: no validation report" in err and "--report" in err
    assert main(["play", str(clip), "--dry-run", "--ramp", "0.1", "--report", str(tmp_path / "val" / "r.json")]) == 0


def test_missing_port_is_a_one_line_error(tmp_path, robot, capsys):
    clip = write_clip(tmp_path, robot)
    rc = main(["play", str(clip), "--robot", "op3_like", "--port", str(tmp_path / "ttyUSB9")])
    assert rc == 2
    assert "does not exist" in one_line_error(capsys)
    assert main(["play", str(clip)]) == 2
    assert "--port DEV is required" in one_line_error(capsys)
    assert main(["servo", "scan", "--port", "/dev/does-not-exist-42"]) == 2
    assert "does not exist" in one_line_error(capsys)


def test_busy_port_is_a_one_line_error(tmp_path, robot, capsys):
    serial = pytest.importorskip("serial")
    import os

    if not hasattr(os, "openpty"):
        pytest.skip("no pseudo-terminals")
    clip = write_clip(tmp_path, robot)
    master, slave = os.openpty()
    holder = serial.Serial(os.ttyname(slave), 2_000_000, timeout=0, exclusive=True)
    try:
        assert main(["play", str(clip), "--port", os.ttyname(slave)]) == 2
        assert "is busy" in one_line_error(capsys)
    finally:
        holder.close()
        os.close(master)
        os.close(slave)


def test_scan_lists_ids_models_and_positions(capsys):
    assert main(["servo", "scan", "--emulate", "op3_like"]) == 0
    out = capsys.readouterr().out
    assert "20 servo(s)" in out
    lines = [line.split() for line in out.splitlines()[2:]]
    assert [int(f[0]) for f in lines] == list(range(1, 21))
    assert all(f[1] == "XM430-W350" and f[2] == "1020" and f[3] == "2048" for f in lines)


def test_calibrate_records_zero_offsets_in_a_loadable_copy(tmp_path, robot):
    smap = ServoMap.from_specs(robot.servos)
    shift = np.array([(-1) ** k * (5 + k) for k in range(smap.n)])
    bus, chain = emulated_bus(smap, positions=smap.zero_offset + shift)
    prepare(bus, smap)
    assert not any(servo.torque_enabled for servo in chain.servos.values())
    zero = read_zero_pose(bus, smap)
    out = calibrated_description(robot, zero, tmp_path / "cal" / "op3_like.toml")
    calibrated = load(out)
    for old, new, d in zip(robot.servos, calibrated.servos, shift):
        assert new.zero_offset_ticks == old.zero_offset_ticks + d
        assert (new.min_ticks, new.max_ticks) == (old.min_ticks + d, old.max_ticks + d)
        assert (new.id, new.sign, new.joint) == (old.id, old.sign, old.joint)
    assert calibrated.name == robot.name


def test_calibrate_names_a_servo_whose_range_would_leave_the_tick_range(tmp_path, robot):
    from motok_robot.errors import InputError

    zero = {s.joint: s.zero_offset_ticks for s in robot.servos}
    zero["r_sho_pitch"] = 2048 + 300  # its range already spans 92..4004
    with pytest.raises(InputError, match=r"servo 1 \(r_sho_pitch\).*re-seat the servo horn"):
        calibrated_description(robot, zero, tmp_path / "x.toml")


def test_calibrate_cli_on_emulated_chain(tmp_path, capsys):
    out = tmp_path / "op3_like.toml"
    assert main(["servo", "calibrate", "--robot", "op3_like", "--emulate", "--yes", "--out", str(out)]) == 0
    assert "zero offsets of 20 servos" in capsys.readouterr().out
    assert load(out).servos[0].zero_offset_ticks == 2048


def test_play_ctrl_c_exits_130_with_one_line_after_holding(tmp_path, robot, capsys, monkeypatch):
    import motok_robot.servo.streamer as streamer_module

    real = streamer_module.limit_command
    calls = {"n": 0}

    def interrupt_at_tick_20(*args):
        calls["n"] += 1
        if calls["n"] == 20:
            raise KeyboardInterrupt
        return real(*args)

    monkeypatch.setattr(streamer_module, "limit_command", interrupt_at_tick_20)
    clip = write_clip(tmp_path, robot)
    rc = main(["play", str(clip), "--dry-run", "--ramp", "0.2", "--no-realtime"])
    err = capsys.readouterr().err.strip()
    assert rc == 130 and "\n" not in err
    assert err.startswith("motok-robot: interrupted (Ctrl-C)") and "holding their present position" in err
    rows = read_log(tmp_path / "robot.playback.csv")
    assert len(rows["tick"]) == 20 and rows["phase"][-1] == "hold"


def test_play_fault_in_preflight_names_the_joint(tmp_path, robot, capsys, monkeypatch):
    import motok_robot.servo.emulator as emulator_module

    real = emulator_module.emulated_chain

    def overloaded_knee(*args, **kwargs):
        chain = real(*args, **kwargs)
        chain.set_hardware_error(13, 0x20)
        return chain

    monkeypatch.setattr(emulator_module, "emulated_chain", overloaded_knee)
    clip = write_clip(tmp_path, robot)
    assert main(["play", str(clip), "--dry-run"]) == 2
    err = one_line_error(capsys)
    assert "servo 13 (r_knee)" in err and "overload" in err


def test_validate_then_play_streams_the_goals_validate_wrote(tmp_path, robot, capsys, monkeypatch):
    """The stage-by-stage path of a new user: `validate robot.npz --out val/`, then `play robot.npz`."""
    from motok_robot.robots.index import index_robot
    from motok_robot.sim import synthetic

    qpos = synthetic.standing(index_robot(robot), seconds=0.5)
    qpos[:, robot.qpos_adr[robot.joint_names.index("head_pan")]] += 0.2 * np.sin(np.linspace(0, np.pi, len(qpos)))
    clip = tmp_path / "robot.npz"
    np.savez(clip, qpos=qpos, joint_names=np.array(robot.joint_names), robot=robot.name, fps=20.0)
    monkeypatch.chdir(tmp_path)
    assert main(["validate", "robot.npz", "--out", "val", "--no-render", "--no-plots"]) == 0, capsys.readouterr()
    capsys.readouterr()
    log = tmp_path / "play.csv"
    assert main(["play", "robot.npz", "--dry-run", "--ramp", "0.1", "--log", str(log)]) == 0
    out = capsys.readouterr().out
    assert "validation report: val/report.json" in out or f"validation report: {tmp_path / 'val'}" in out, out
    assert "streaming the validated feedforward servo goals" in out
    goals = np.load(tmp_path / "val" / GOALS_FILE)["goals"]
    rows = read_log(log)
    smap = ServoMap.from_specs(robot.servos)
    knee = robot.joint_names.index("r_knee")  # a loaded joint: its feedforward goal is not its angle
    assert abs(goals[-1, knee] - qpos[-1, 7 + knee]) > 0.01
    played = rows["cmd_r_knee_rad"][rows["phase"] == "play"][-1]
    assert abs(played - goals[-1, knee]) <= 2 * np.pi / smap.ticks_per_rev[smap.joints.index("r_knee")]

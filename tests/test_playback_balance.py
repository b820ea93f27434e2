"""The torso IMU on the bus and the balance controller in the playback loop; stop signals."""

import copy
import json
import math
import os
import signal
import threading
import warnings

import numpy as np
import pytest

from motok_robot.errors import HardwareError, InputError
from motok_robot.feasibility import BalanceConfig, build_plan
from motok_robot.feasibility.balance import BalanceController
from motok_robot.robots import load
from motok_robot.servo.bus import DynamixelBus
from motok_robot.servo.config import PlaybackConfig
from motok_robot.servo.convert import ServoMap
from motok_robot.servo.emulator import emulated_chain
from motok_robot.servo.imu import ImuMount
from motok_robot.servo.playback_log import read_log
from motok_robot.servo.streamer import PlaybackInterrupted, PlaybackWarning, Streamer, Trajectory, robot_joint_ranges
from motok_robot.servo.timing import FakeClock

RATE = 125.0
G = 9.80665


@pytest.fixture(scope="module")
def robot():
    return load("op3_like")


@pytest.fixture(scope="module")
def index(robot):
    from motok_robot.robots.index import index_robot

    return index_robot(robot)


@pytest.fixture(scope="module")
def smap(robot):
    return ServoMap.from_specs(robot.servos)


@pytest.fixture(scope="module")
def stand(robot, index):
    """A 1 s standing trajectory of op3_like with its balance plan (both feet in support)."""
    qpos = np.repeat(robot.nominal_qpos()[None], 21, axis=0)
    plan = build_plan(index, qpos, 20.0, np.ones((21, 2), dtype=bool), BalanceConfig(max_offset_rad=1.0))
    return qpos, plan


def closed_loop_trajectory(robot, smap, stand):
    qpos, plan = stand
    columns = [robot.qpos_adr[robot.joint_names.index(j)] for j in smap.joints]
    return Trajectory(q=qpos[:, columns], fps=20.0, joints=smap.joints, goals="feedforward", plan=plan,
                      plan_joints=tuple(robot.joint_names))


def emulated(smap, clock, imu=True):
    chain = emulated_chain(smap, clock=clock, imu_id=200 if imu else None)
    bus = DynamixelBus("emulated", 2_000_000, port_handler=chain, imu=ImuMount() if imu else None)
    return bus, chain


# ----------------------------------------------------------------------------- the IMU
def test_emulated_opencr_returns_the_set_imu_values_scaled_and_negated(smap):
    bus, chain = emulated(smap, FakeClock())
    assert bus.ping(200) == 0x7400
    gyro_counts, accel_counts = (1640, -3280, 820), (8192, -4096, 16384)
    chain.imu.set_counts(gyro=gyro_counts, accel=accel_counts)
    # independent expectation: 2000/32800 deg/s and 2/32768 g per count; x and y negated (OP3)
    deg = math.pi / 180
    want_gyro = [-1640 * 2000 / 32800 * deg, 3280 * 2000 / 32800 * deg, 820 * 2000 / 32800 * deg]
    want_accel = [-8192 * 2 / 32768 * G, 4096 * 2 / 32768 * G, 16384 * 2 / 32768 * G]
    gyro, accel = bus.read_imu()
    assert np.allclose(gyro, want_gyro) and np.allclose(accel, want_accel)
    assert np.allclose(want_gyro, [-1.74532925, 3.4906585, 0.87266463])  # 100, -200, 50 deg/s
    bus.set_return_delay_time(smap.ids, 0)  # as pre-flight does: 20 replies in turn fit the SDK's timeout
    present, gyro2, accel2 = bus.read_present_positions_and_imu(smap.ids)  # one Bulk Read
    assert present.tolist() == bus.read_present_positions(smap.ids).tolist()
    assert np.allclose(gyro2, want_gyro) and np.allclose(accel2, want_accel)
    # another mounting from the description: frame x = sensor y, frame y = -sensor x
    from motok_robot.robots.description import ImuSpec

    turned = DynamixelBus("emulated", 2_000_000, port_handler=chain, imu=ImuMount.from_spec(ImuSpec(200, ("y", "-x", "z"))))
    gyro3, _ = turned.read_imu()
    assert np.allclose(gyro3, [-want_gyro[1], want_gyro[0], want_gyro[2]])
    # physical units in, counts on the wire, physical units out (to the register resolution)
    chain.imu.set_motion(gyro_rad_s=[0.5, -0.25, 2.0], accel_m_s2=[1.0, -2.0, 9.0])
    gyro4, accel4 = bus.read_imu()
    assert np.allclose(gyro4, [-0.5, 0.25, 2.0], atol=1.1e-3) and np.allclose(accel4, [-1.0, 2.0, 9.0], atol=6e-4)


def test_imu_mounting_in_the_robot_description(robot, tmp_path):
    assert robot.bus.imu is not None and robot.bus.imu.id == 200 and robot.bus.imu.axes == ("-x", "-y", "z")
    mount = ImuMount.from_spec(robot.bus.imu)
    assert mount.axis == (0, 1, 2) and mount.sign == (-1.0, -1.0, 1.0)
    from motok_robot.robots.description import parse_description

    text = robot.description.path.read_text()
    for bad, message in (('axes = ["-x", "-x", "z"]', "axes must name each sensor axis once"),
                         ('axes = ["-x", "-y", "z"]\nid = 1', "already used by"),
                         ('axes = ["-x", "-y", "z"]\nrate = 3', "unknown field")):
        edited = text.replace('id = 200\naxes = ["-x", "-y", "z"]', bad)
        assert edited != text
        path = tmp_path / "op3_like.toml"
        path.write_text(edited)
        (tmp_path / "op3_like.xml").write_bytes(robot.mjcf_path.read_bytes())
        with pytest.raises(InputError, match=message):
            parse_description(path)


def test_sim_rig_imu_is_validations_read_imu_on_the_same_state(robot):
    from motok_robot.feasibility.balance import imu_frame
    from motok_robot.feasibility.physics import read_imu
    from motok_robot.servo.sim_rig import SimRig

    clock = FakeClock()
    rig = SimRig(robot, clock=clock)
    ids = [int(i) for i in rig.map.ids]
    rig.write_goal_positions(ids, rig.read_present_positions(ids))
    for _ in range(5):
        clock.advance(0.2)
        gyro, accel = rig.read_imu()
        state = copy.deepcopy(rig.data)
        want_gyro, want_accel = read_imu(rig.model, state, imu_frame(rig.model, int(rig.model.jnt_bodyid[0])))
        assert np.array_equal(gyro, want_gyro) and np.array_equal(accel, want_accel)
    # standing still: specific force about +g along the IMU's z, little rotation
    assert abs(np.linalg.norm(accel) - 9.81) < 0.5 and accel[2] > 9.0 and np.linalg.norm(gyro) < 0.2
    assert rig.imu_id == 200 and rig.ping_imu() == 0


# ----------------------------------------------------------------------------- the closed loop
def test_streamer_with_a_plan_calls_the_controller_every_tick_and_the_limiter_still_applies(robot, smap, stand,
                                                                                             tmp_path):
    trajectory = closed_loop_trajectory(robot, smap, stand)
    clock = FakeClock()
    bus, chain = emulated(smap, clock)
    # the torso tips forward fast: big corrections that the clamps must cut down
    chain.imu.set_motion(gyro_rad_s=[-3.0, -4.0, 0.0], accel_m_s2=[-4.0, 0.0, 8.9])  # sensor axes
    config = PlaybackConfig(rate_hz=RATE, ramp_s=0.2)
    streamer = Streamer(bus, smap, config, clock=clock, log_path=tmp_path / "play.csv",
                        joint_range=robot_joint_ranges(robot))
    streamer.preflight(trajectory)
    controller = streamer.controller
    assert isinstance(controller, BalanceController) and controller.plan is trajectory.plan
    calls = []
    real_step = controller.step

    def spy(t, goals, gyro, accel, present=None):
        calls.append((t, goals.copy(), gyro.copy(), accel.copy(), present))
        return real_step(t, goals, gyro, accel, present)

    controller.step = spy
    with pytest.warns(PlaybackWarning, match="clamped"):
        result = streamer.play(trajectory)
    n_ramp, n_play = 25, 126
    assert result.completed and result.ticks == n_ramp + n_play and result.limited > 0
    assert result.extra["balance"]["loop"] == "closed" and result.extra["balance"]["max_correction_rad"] > 0.05
    # once per trajectory tick, t = 0 at the first frame, none during the ramp
    assert len(calls) == n_play
    assert np.allclose([c[0] for c in calls], np.arange(n_play) / RATE)
    # the IMU in the robot's frame (sensor x, y negated), goals in the plan's (robot) joint order
    assert np.allclose(calls[0][2][0], [3.0, 4.0, 0.0], atol=2e-3) and np.allclose(calls[0][3][0], [4.0, 0.0, 8.9],
                                                                                     atol=1e-3)
    knee = robot.joint_names.index("l_knee")
    assert calls[0][1][0, knee] == pytest.approx(robot.nominal_qpos()[robot.qpos_adr[knee]], abs=2e-3)
    assert calls[0][4] is not None
    # every decoded goal obeys the limiter: position limits and the per-tick step
    step = smap.step_limit_ticks(1 / RATE)
    moved = 0
    open_loop_last = smap.ticks_float(trajectory.q[-1])
    for k, servo_id in enumerate(smap.ids):
        servo = chain.servos[int(servo_id)]
        goals = np.array(servo.goal_history)
        assert servo.rejected_goals == 0
        assert goals.min() >= smap.min_ticks[k] and goals.max() <= smap.max_ticks[k]
        assert np.all(np.abs(np.diff(goals)) <= step[k])
        moved += int(abs(goals[-1] - open_loop_last[k]) > 5)
    assert moved >= 4  # the legs were corrected away from the open-loop goals
    rows = read_log(tmp_path / "play.csv")
    joint = smap.joints[0]
    assert np.allclose(rows[f"cmd_{joint}_rad"], smap.select([0]).to_rad(rows[f"cmd_{joint}_ticks"][:, None])[:, 0],
                       atol=1e-6)
    assert np.isnan(rows[f"balance_{joint}_rad"][:n_ramp]).all() and not np.isnan(rows["gyro_x_rad_s"]).any()
    leg = smap.joints.index("l_ank_pitch")
    assert np.nanmax(np.abs(rows[f"balance_{smap.joints[leg]}_rad"])) > 0.05
    assert rows["accel_z_m_s2"][0] == pytest.approx(8.9, abs=1e-3)


def test_a_plan_on_a_bus_without_imu_is_refused_unless_no_balance(robot, smap, stand):
    trajectory = closed_loop_trajectory(robot, smap, stand)
    clock = FakeClock()
    bus, chain = emulated(smap, clock, imu=False)
    streamer = Streamer(bus, smap, PlaybackConfig(rate_hz=RATE, ramp_s=0.1), clock=clock)
    with pytest.raises(InputError, match=r"closed loop .* has no IMU .*--no-balance") as info:
        streamer.preflight(trajectory)
    assert "\n" not in str(info.value)
    assert not any(s.torque_enabled for s in chain.servos.values())  # refused before anything moved
    streamer = Streamer(bus, smap, PlaybackConfig(rate_hz=RATE, ramp_s=0.5, balance=False), clock=clock)
    with pytest.warns(PlaybackWarning, match="open loop, which is not what passed validation"):
        result = streamer.play(trajectory)
    assert result.completed and streamer.controller is None and "balance OFF" in result.line()
    # a plan validated at another rate is refused too
    streamer = Streamer(emulated(smap, clock)[0], smap, PlaybackConfig(rate_hz=100.0, ramp_s=0.1), clock=clock)
    with pytest.raises(InputError, match="validated at 125 Hz, playback runs at 100 Hz"):
        streamer.preflight(trajectory)


def imu_fault_run(robot, smap, stand, tmp_path, inject, on_stop="hold", at_tick=30):
    trajectory = closed_loop_trajectory(robot, smap, stand)
    clock = FakeClock()
    bus, chain = emulated(smap, clock)

    def on_tick(k, streamer):
        if k == at_tick:
            inject(chain)

    streamer = Streamer(bus, smap, PlaybackConfig(rate_hz=RATE, ramp_s=0.2, on_stop=on_stop), clock=clock,
                        log_path=tmp_path / "play.csv", on_tick=on_tick)
    with pytest.raises(HardwareError) as info:
        streamer.play(trajectory)
    return str(info.value), read_log(tmp_path / "play.csv"), chain


@pytest.mark.parametrize("fault", ["disconnect", "drop", "corrupt", "alert"])
def test_a_fault_on_the_imu_stops_safely_naming_id_200(robot, smap, stand, tmp_path, fault):
    inject = {"disconnect": lambda c: c.disconnect(200), "drop": lambda c: c.drop_replies(200),
              "corrupt": lambda c: c.corrupt_replies(200), "alert": lambda c: c.set_hardware_error(200, 0x01)}[fault]
    message, rows, chain = imu_fault_run(robot, smap, stand, tmp_path, inject)
    assert "IMU (ID 200)" in message and "\n" not in message and "holding their present position" in message
    if fault == "alert":
        assert rows["tick"][-2] == 30  # no retries for an alert
    else:
        assert "retry budget 3" in message and rows["tick"][-2] == 33
    assert rows["phase"][-1] == "hold"
    for servo_id, servo in chain.servos.items():
        if servo_id != 200:
            assert servo.torque_enabled and abs(servo.goal_position - servo.present_position) <= 1


def test_a_dropped_imu_reply_within_the_budget_holds_the_last_correction(robot, smap, stand, tmp_path):
    trajectory = closed_loop_trajectory(robot, smap, stand)
    clock = FakeClock()
    bus, chain = emulated(smap, clock)
    chain.imu.set_motion(gyro_rad_s=[-1.0, 0.0, 0.0])

    def on_tick(k, streamer):
        if k == 60:
            chain.drop_replies(200, count=1)

    streamer = Streamer(bus, smap, PlaybackConfig(rate_hz=RATE, ramp_s=0.2), clock=clock,
                        log_path=tmp_path / "play.csv", on_tick=on_tick)
    result = streamer.play(trajectory)
    assert result.completed and result.failed_ticks == 1
    rows = read_log(tmp_path / "play.csv")
    assert np.isnan(rows["gyro_x_rad_s"][60]) and not np.isnan(rows["gyro_x_rad_s"][59])
    leg = f"balance_{smap.joints[smap.joints.index('l_ank_roll')]}_rad"
    assert rows[leg][60] == rows[leg][59] and rows[leg][59] != 0


def test_torque_off_stop_writes_the_final_row(robot, smap, stand, tmp_path):
    message, rows, chain = imu_fault_run(robot, smap, stand, tmp_path, lambda c: c.set_hardware_error(5, 0x20),
                                         on_stop="torque_off")
    assert "servo 5" in message and "torque switched off on every servo" in message
    assert rows["phase"][-1] == "torque_off" and rows["tick"][-1] == rows["tick"][-2] + 1
    assert not np.isnan(rows[f"present_{smap.joints[0]}_ticks"][-1])
    assert not any(s.torque_enabled for i, s in chain.servos.items() if i != 200)


# ----------------------------------------------------------------------------- validation -> play
def test_validation_and_playback_run_the_same_controller_on_the_same_plan(robot, index, tmp_path, monkeypatch,
                                                                         capsys):
    from motok_robot.feasibility.feedforward import load_servo_goals
    from motok_robot.sim.validate import validate_file
    from motok_robot.servo.streamer import load_trajectory

    path = tmp_path / "stand.npz"
    qpos = np.repeat(robot.nominal_qpos()[None], 21, axis=0)
    np.savez(path, qpos=qpos, joint_names=np.array(robot.joint_names), robot=robot.name, fps=20.0)
    used = []
    real_step = BalanceController.step

    def spy(self, *args, **kwargs):
        used.append(type(self))
        return real_step(self, *args, **kwargs)

    monkeypatch.setattr(BalanceController, "step", spy)
    validate_file(path, robot, out_dir=tmp_path / "val", plots=False, render=False)
    in_validation = len(used)
    assert in_validation > 100 and set(used) == {BalanceController}  # the rollout ran closed loop
    report = tmp_path / "val" / "report.json"
    if not json.loads(report.read_text())["passed"]:
        pytest.skip("standing still does not pass validation: nothing validated to play")
    trajectory = load_trajectory(path, ServoMap.from_specs(robot.servos), robot.name, report,
                                 robot_sha256=robot.description_sha256)
    stored = load_servo_goals(tmp_path / "val" / "servo_goals.npz")["plan"]
    assert trajectory.plan is not None and np.array_equal(trajectory.plan.tilt_matrix, stored.tilt_matrix)
    assert np.array_equal(trajectory.plan.down, stored.down) and trajectory.plan_joints == tuple(robot.joint_names)
    from motok_robot.servo.sim_rig import SimRig

    clock = FakeClock()
    rig = SimRig(robot, clock=clock)
    streamer = Streamer(rig, rig.map, PlaybackConfig(ramp_s=0.2), clock=clock, joint_range=robot_joint_ranges(robot))
    result = streamer.play(trajectory)
    assert type(streamer.controller) is BalanceController and streamer.controller.plan is trajectory.plan
    assert result.completed and len(used) - in_validation == 126 and not rig.fell
    import motok_robot.sim.rollout as rollout

    assert rollout.BalanceController is BalanceController
    # and the command line: the dry run closes the loop on the emulated OpenCR at ID 200
    from motok_robot.cli import main

    used.clear()
    rc = main(["play", str(path), "--dry-run", "--report", str(report), "--ramp", "0.2", "--no-realtime",
               "--log", str(tmp_path / "play.csv")])
    out = capsys.readouterr().out
    assert rc == 0 and "the balance controller runs on the torso IMU" in out and "balance closed loop" in out
    assert len(used) == 126
    rows = read_log(tmp_path / "play.csv")
    assert rows["accel_z_m_s2"][0] == pytest.approx(G, abs=1e-3) and not np.isnan(rows["balance_l_knee_rad"][-1])


# ----------------------------------------------------------------------------- signals and --rate
def write_clip(folder, robot, seconds=3.0):
    nominal = robot.nominal_qpos()
    t = np.arange(int(seconds * 20) + 1) / 20
    qpos = np.repeat(nominal[None], len(t), axis=0)
    qpos[:, robot.qpos_adr[robot.joint_names.index("head_pan")]] += 0.3 * np.sin(2 * np.pi * t)
    path = folder / "robot.npz"
    np.savez(path, qpos=qpos, joint_names=np.array(robot.joint_names), robot=robot.name, fps=20.0)
    (folder / "report.json").write_text(json.dumps({"passed": True, "robot": robot.name, "input": {"path": str(path)},
                                                    "robot_description": {"sha256": robot.description_sha256}}))
    return path


@pytest.mark.parametrize("sig, extra, final", [(signal.SIGTERM, [], "hold"), (signal.SIGHUP, [], "hold"),
                                               (signal.SIGTERM, ["--torque-off-on-stop"], "torque_off")])
def test_sigterm_and_sighup_during_a_dry_run_take_the_ctrl_c_path(robot, tmp_path, capsys, sig, extra, final):
    from motok_robot.cli import main

    clip = write_clip(tmp_path, robot)
    log = tmp_path / "robot.playback.csv"
    done = threading.Event()

    def send_when_playing():  # once the loop writes rows (its handlers are in place), as `kill` would
        while not done.wait(0.01):
            if log.is_file() and log.read_text().count("\n") > 12:
                os.kill(os.getpid(), sig)
                return

    previous = signal.signal(sig, lambda *args: None)  # outside playback a stray signal is harmless
    # what SIGINT had before playback (Python's default handler, or SIG_IGN in a process started
    # from a backgrounded shell, which ignores SIGINT): play must leave it as it found it
    sigint_before = signal.getsignal(signal.SIGINT)
    sender = threading.Thread(target=send_when_playing, daemon=True)
    sender.start()
    try:
        rc = main(["play", str(clip), "--dry-run", "--ramp", "0.2", "--no-realtime", "--joint-angles", *extra])
    finally:
        done.set()
        sender.join()
        restored = signal.signal(sig, previous)
    warning, err = capsys.readouterr().err.strip().splitlines()  # its report records no servo goals
    name = signal.Signals(sig).name
    assert rc == 128 + int(sig) and "RAW JOINT ANGLES" in warning
    assert err.startswith(f"motok-robot: interrupted ({name}); playback stopped at t=")
    assert ("holding their present position" if final == "hold" else "torque switched off on every servo") in err
    rows = read_log(tmp_path / "robot.playback.csv")
    assert rows["phase"][-1] == final and 10 < len(rows["tick"]) < 25 + 376
    stats = json.loads((tmp_path / "robot.playback.stats.json").read_text())
    assert stats["completed"] is False and name in stats["stopped_because"]
    assert restored is not None and restored.__name__ == "<lambda>"  # play restored the handler it found
    assert signal.getsignal(signal.SIGINT) is sigint_before


def test_a_second_signal_does_not_cut_the_safe_stop_short(robot, smap, tmp_path):
    from motok_robot.servo.testing import sine_trajectory

    clock = FakeClock()
    bus, chain = emulated(smap, clock, imu=False)
    traj = sine_trajectory(smap, seconds=1.0)

    def on_tick(k, streamer):
        if k == 20:
            signal.raise_signal(signal.SIGTERM)

    streamer = Streamer(bus, smap, PlaybackConfig(rate_hz=RATE, ramp_s=0.2), clock=clock,
                        log_path=tmp_path / "play.csv", on_tick=on_tick)
    real_stop = streamer._safe_stop

    def stop_twice(*args):
        signal.raise_signal(signal.SIGHUP)  # arrives during the safe stop: ignored
        return real_stop(*args)

    streamer._safe_stop = stop_twice
    with pytest.raises(PlaybackInterrupted, match=r"interrupted \(SIGTERM\).*tick 20/.*holding") as info:
        streamer.play(traj)
    assert info.value.exit_status == 143
    assert read_log(tmp_path / "play.csv")["phase"][-1] == "hold"
    assert all(s.torque_enabled for s in chain.servos.values())


@pytest.mark.parametrize("rate", ["0", "-5", "nan", "inf", "2000"])
def test_play_rate_must_be_a_positive_number_in_range(robot, tmp_path, capsys, rate):
    from motok_robot.cli import main

    clip = write_clip(tmp_path, robot, seconds=0.2)
    with warnings.catch_warnings():
        rc = main(["play", str(clip), "--dry-run", "--rate", rate])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "--rate" in err and "1..1000 Hz" in err and "\n" not in err
    assert not (tmp_path / "robot.playback.csv").exists()

"""Streaming to emulated servos: exact goals, safety limits under any input, faults fail safe."""

import json
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from motok_robot.errors import HardwareError, InputError
from motok_robot.servo import control_table as ct
from motok_robot.servo.config import PlaybackConfig
from motok_robot.servo.convert import ServoMap
from motok_robot.servo.playback_log import read_log
from motok_robot.servo.streamer import (
    PlaybackInterrupted,
    PlaybackWarning,
    Streamer,
    Trajectory,
    check_validation_report,
    load_trajectory,
    plan_targets,
)
from motok_robot.servo.testing import emulated_bus, sine_trajectory, synthetic_specs
from motok_robot.servo.timing import FakeClock

RATE = 125.0


@pytest.fixture(scope="module")
def smap():
    return ServoMap.from_specs(synthetic_specs(20))


def run(smap, trajectory, tmp_path=None, config=None, on_tick=None, chain_kwargs=None):
    clock = FakeClock()
    bus, chain = emulated_bus(smap, clock=clock, **(chain_kwargs or {}))
    config = config or PlaybackConfig(rate_hz=RATE, ramp_s=0.5)
    log = tmp_path / "play.csv" if tmp_path is not None else None
    streamer = Streamer(bus, smap, config, clock=clock, log_path=log, on_tick=on_tick)
    return streamer, chain, log


def test_dry_run_every_decoded_goal_equals_the_expected_ticks(smap, tmp_path):
    traj = sine_trajectory(smap, seconds=1.0)
    streamer, chain, log = run(smap, traj, tmp_path)
    result = streamer.play(traj)
    # independent expectation: linear interpolation of the 20 fps frames at 125 Hz, then
    # ticks = zero + sign * q * 4096 / 2pi, rounded
    n_play = int(1.0 * RATE) + 1
    t = np.arange(n_play) / RATE
    frame_t = np.arange(len(traj.q)) / traj.fps
    for k, servo_id in enumerate(smap.ids):
        q = np.interp(t, frame_t, traj.q[:, k])
        expected = np.rint(smap.zero_offset[k] + smap.sign[k] * q * 4096 / (2 * np.pi)).astype(int)
        decoded = chain.servos[int(servo_id)].goal_history
        assert decoded[-n_play:] == expected.tolist(), f"servo {servo_id}"
        assert len(decoded) == 1 + 62 + n_play  # pre-flight goal = present, ramp, trajectory
        assert chain.servos[int(servo_id)].rejected_goals == 0
    assert result.completed and result.ticks == 62 + n_play and result.ramp_ticks == 62
    assert result.limited == 0 and result.non_finite == 0 and result.failed_ticks == 0
    assert result.stats.overruns == 0 and abs(result.stats.rate_hz - RATE) < 1e-6
    rows = read_log(log)
    assert len(rows["tick"]) == result.ticks
    assert rows["phase"][0] == "ramp" and rows["phase"][-1] == "play"
    assert rows[f"cmd_{smap.joints[0]}_ticks"][-1] == chain.servos[1].goal_history[-1]
    assert not np.isnan(rows[f"present_{smap.joints[5]}_ticks"]).any()
    stats = json.loads((tmp_path / "play.stats.json").read_text())
    assert stats["completed"] is True and stats["stats"]["ticks"] == result.ticks


def test_preflight_sets_up_the_servos(smap):
    traj = sine_trajectory(smap, seconds=0.1)
    streamer, chain, _ = run(smap, traj)
    present = streamer.preflight()
    assert present.tolist() == smap.zero_ticks().tolist()
    for k, servo_id in enumerate(smap.ids):
        servo = chain.servos[int(servo_id)]
        assert servo.torque_enabled
        assert servo.table[ct.ADDR_RETURN_DELAY_TIME] == 0
        assert servo.table[ct.ADDR_BUS_WATCHDOG] == 0  # armed when streaming starts
        assert servo.peek(ct.ADDR_PROFILE_VELOCITY, 4) == ct.velocity_units_from_rad_s(4.8)


small = ServoMap.from_specs(synthetic_specs(4, seed=3))
wild = st.one_of(st.floats(-3.0, 3.0), st.floats(-1e6, 1e6),
                 st.sampled_from([np.nan, np.inf, -np.inf, 1e300, -1e300]))


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(q=hnp.arrays(np.float64, st.tuples(st.integers(1, 12), st.just(4)), elements=wild),
       fps=st.sampled_from([10.0, 20.0, 30.0]))
def test_no_command_leaves_the_limits_or_exceeds_the_step_limit(q, fps):
    traj = Trajectory(q=q, fps=fps, joints=small.joints)
    streamer, chain, _ = run(small, traj, config=PlaybackConfig(rate_hz=RATE, ramp_s=0.1))
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        result = streamer.play(traj)
    said_non_finite = any("non-finite" in str(w.message) for w in record)
    assert said_non_finite == (not np.isfinite(q).all())
    step = small.step_limit_ticks(1 / RATE)
    for k, servo_id in enumerate(small.ids):
        servo = chain.servos[int(servo_id)]
        goals = np.array(servo.goal_history)
        assert servo.rejected_goals == 0
        assert goals.min() >= small.min_ticks[k] and goals.max() <= small.max_ticks[k]
        assert np.all(np.abs(np.diff(goals)) <= step[k])
    assert result.completed


def test_non_finite_targets_hold_the_last_safe_command_and_are_counted(smap):
    traj = sine_trajectory(smap, seconds=0.5)
    traj.q[3:6, 2] = np.nan
    streamer, chain, _ = run(smap, traj)
    with pytest.warns(PlaybackWarning) as record:
        result = streamer.play(traj)
    messages = [str(w.message) for w in record]
    assert any("non-finite target at tick" in m and "servo 3 (joint_02)" in m for m in messages)
    assert any(f"{result.non_finite} non-finite servo targets" in m for m in messages)
    # ticks whose interpolation gives weight to a NaN frame
    touched = np.interp(np.arange(int(0.5 * RATE) + 1) / RATE, np.arange(len(traj.q)) / traj.fps,
                        np.isnan(traj.q[:, 2]).astype(float)) > 0
    assert result.non_finite == touched.sum() and result.completed


def fault_run(smap, tmp_path, inject, at_tick=10, config=None):
    traj = sine_trajectory(smap, seconds=1.0)
    holder = {}

    def on_tick(k, streamer):
        if k == at_tick:
            inject(holder["chain"])

    streamer, chain, log = run(smap, traj, tmp_path, config=config, on_tick=on_tick)
    holder["chain"] = chain
    with pytest.raises(HardwareError) as info:
        streamer.play(traj)
    message = str(info.value)
    rows = read_log(log)
    assert "\n" not in message
    assert str(log) in message
    # the log is intact: one row per tick until the stop, then the safe-state row
    assert rows["tick"].tolist()[:-1] == list(range(len(rows["tick"]) - 1))
    return message, rows, chain


def assert_holding(chain, except_id=None):
    for servo_id, servo in chain.servos.items():
        if servo_id == except_id:
            continue
        assert servo.torque_enabled
        assert abs(servo.goal_position - servo.present_position) <= 1


def test_fault_servo_disappears(smap, tmp_path):
    message, rows, chain = fault_run(smap, tmp_path, lambda c: c.disconnect(12))
    assert "servo 12 (joint_11)" in message and "retry budget 3" in message
    assert "holding their last commanded position" in message
    assert rows["phase"][-1] == "hold"
    for servo_id, servo in chain.servos.items():
        if servo_id != 12:
            assert servo.goal_history[-1] == int(rows[f"cmd_{smap.joints[servo_id - 1]}_ticks"][-1])


def test_fault_no_reply_forever(smap, tmp_path):
    message, rows, chain = fault_run(smap, tmp_path, lambda c: c.drop_replies(4))
    assert "servo 4 (joint_03)" in message and "no status packet" in message.lower()


def test_fault_corrupted_crc(smap, tmp_path):
    message, _, _ = fault_run(smap, tmp_path, lambda c: c.corrupt_replies(15))
    assert "servo 15 (joint_14)" in message and "Incorrect status packet" in message


def test_fault_slow_replies_beyond_the_timeout(smap, tmp_path):
    message, _, _ = fault_run(smap, tmp_path, lambda c: c.slow_replies(6, 0.05))
    assert "servo 6 (joint_05)" in message


def test_fault_hardware_error_stops_at_once_and_holds(smap, tmp_path):
    message, rows, chain = fault_run(smap, tmp_path, lambda c: c.set_hardware_error(7, 0x20))
    assert "servo 7 (joint_06)" in message and "overload" in message
    assert rows["tick"][-2] == 10  # no retries for a hardware error
    assert "holding their present position" in message
    assert_holding(chain, except_id=7)


def test_fault_hardware_error_with_torque_off_on_stop(smap, tmp_path):
    config = PlaybackConfig(rate_hz=RATE, ramp_s=0.5, on_stop="torque_off")
    message, _, chain = fault_run(smap, tmp_path, lambda c: c.set_hardware_error(2, 0x01), config=config)
    assert "servo 2 (joint_01)" in message and "input voltage" in message
    assert "torque switched off on every servo" in message
    assert not any(servo.torque_enabled for servo in chain.servos.values())


def test_host_stall_longer_than_the_bus_watchdog_stops_playback(smap, tmp_path):
    seen = {}

    def stall(chain):
        seen["armed"] = chain.servos[1].table[ct.ADDR_BUS_WATCHDOG]
        chain.clock.advance(0.25)  # the host freezes for 250 ms (watchdog 100 ms)

    message, rows, chain = fault_run(smap, tmp_path, stall, at_tick=30)
    assert seen["armed"] == 5
    assert "bus watchdog fired on 20 servo(s)" in message and "servo 1 (joint_00)" in message
    assert all(servo.table[ct.ADDR_BUS_WATCHDOG] == 0xFF for servo in chain.servos.values())
    # the servos stopped by themselves: no goal after the stall was accepted
    assert all(len(servo.goal_history) == 1 + 30 for servo in chain.servos.values())


def test_transient_dropouts_within_the_retry_budget_are_survived(smap, tmp_path):
    traj = sine_trajectory(smap, seconds=0.5)

    def on_tick(k, streamer):
        if k == 5:
            chain.drop_replies(9, count=2)

    streamer, chain, _ = run(smap, traj, tmp_path, on_tick=on_tick)
    result = streamer.play(traj)
    assert result.completed and 1 <= result.failed_ticks <= 3


def test_ctrl_c_holds_position_and_keeps_the_log(smap, tmp_path):
    traj = sine_trajectory(smap, seconds=1.0)

    def on_tick(k, streamer):
        if k == 40:
            raise KeyboardInterrupt

    streamer, chain, log = run(smap, traj, tmp_path, on_tick=on_tick)
    with pytest.raises(PlaybackInterrupted, match=r"interrupted \(Ctrl-C\).*tick 40/.*holding") as info:
        streamer.play(traj)
    assert str(log) in str(info.value)
    rows = read_log(log)
    assert len(rows["tick"]) == 41 and rows["phase"][-1] == "hold"
    assert_holding(chain)
    stats = json.loads((tmp_path / "play.stats.json").read_text())
    assert stats["completed"] is False and "Ctrl-C" in stats["stopped_because"]


def test_preflight_names_missing_servos_and_wrong_models(smap):
    traj = sine_trajectory(smap, seconds=0.1)
    streamer, chain, _ = run(smap, traj)
    chain.disconnect(3)
    chain.disconnect(17)
    with pytest.raises(HardwareError, match=r"2 servo\(s\) do not answer ping: servo 3 \(joint_02\).*servo 17"):
        streamer.preflight()
    streamer, chain, _ = run(smap, traj)
    chain.servos[8].poke(ct.ADDR_MODEL_NUMBER, 2, 1060)
    with pytest.raises(HardwareError, match=r"servo 8 \(joint_07\): model number 1060 \(XL430-W250\)"):
        streamer.preflight()
    assert not chain.servos[1].torque_enabled  # nothing was switched on


def test_preflight_refuses_hardware_errors_and_out_of_range_servos(smap):
    traj = sine_trajectory(smap, seconds=0.1)
    streamer, chain, _ = run(smap, traj)
    chain.set_hardware_error(11, 0x08)
    with pytest.raises(HardwareError, match=r"servo 11 \(joint_10\).*hardware error: motor encoder"):
        streamer.preflight()
    streamer, chain, _ = run(smap, traj)
    chain.servos[5].position = float(smap.max_ticks[4] + 40)
    chain.servos[5].advance(1.0)
    with pytest.raises(HardwareError, match=r"servo 5 \(joint_04\) at \d+ outside"):
        streamer.preflight()
    assert not any(servo.torque_enabled for servo in chain.servos.values())


def test_plan_targets_ramps_smoothly_from_the_present_pose(smap):
    traj = sine_trajectory(smap, seconds=0.5)
    start = smap.zero_ticks().astype(float)
    targets, is_ramp = plan_targets(traj, start, smap, RATE, ramp_s=0.4)
    assert is_ramp.sum() == 50 and len(targets) == 50 + int(0.5 * RATE) + 1
    first = smap.ticks_float(traj.q[0])
    assert np.allclose(targets[49], first)
    ramp = targets[:50]
    assert np.all(np.diff(np.sign(np.diff(ramp, axis=0)), axis=0) == 0)  # monotone per servo


def write_npz(path, qpos, names, robot="synthetic", fps=20.0):
    np.savez(path, qpos=qpos, joint_names=np.array(names), robot=robot, fps=fps)


def test_load_trajectory_picks_servo_columns_after_the_free_base(smap, tmp_path):
    names = list(reversed(smap.joints))
    qpos = np.zeros((5, 7 + 20))
    qpos[:, 7:] = np.arange(20)[None, :] * 0.01
    write_npz(tmp_path / "robot.npz", qpos, names)
    traj = load_trajectory(tmp_path / "robot.npz", smap, "synthetic")
    assert np.allclose(traj.q[0], (19 - np.arange(20)) * 0.01)
    with pytest.raises(InputError, match="made for robot 'synthetic', not 'op3_like'"):
        load_trajectory(tmp_path / "robot.npz", smap, "op3_like")
    write_npz(tmp_path / "short.npz", qpos[:, :-1], names[:-1])
    with pytest.raises(InputError, match="lacks the servo joint"):
        load_trajectory(tmp_path / "short.npz", smap)
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(InputError, match="junk.npz: not a readable"):
        load_trajectory(tmp_path / "junk.npz", smap)


def test_validation_report_gate(tmp_path):
    npz = tmp_path / "robot.npz"
    npz.write_bytes(b"")
    with pytest.raises(InputError, match="refusing to play: no validation report"):
        check_validation_report(npz)
    report = tmp_path / "report.json"
    report.write_text(json.dumps({"passed": False, "checks": {"balance": {"passed": False}}}))
    with pytest.raises(InputError, match=r"did not pass \(failed: balance\)"):
        check_validation_report(npz)
    with pytest.warns(PlaybackWarning, match="WITHOUT a passing validation report"):
        check_validation_report(npz, force=True)
    report.write_text(json.dumps({"passed": True, "robot": "other"}))
    with pytest.raises(InputError, match="for robot 'other'"):
        check_validation_report(npz, robot_name="op3_like")
    report.write_text(json.dumps({"passed": True, "robot": "op3_like", "input": "/x/walk.npz"}))
    with pytest.raises(InputError, match="validated /x/walk.npz"):
        check_validation_report(npz, robot_name="op3_like")
    report.write_text(json.dumps({"passed": True, "robot": "op3_like", "input": {"path": "/y/run.npz"}}))
    with pytest.raises(InputError, match="validated /y/run.npz"):
        check_validation_report(npz, robot_name="op3_like")
    report.write_text(json.dumps({"passed": True, "robot": "op3_like", "input": {"path": str(npz), "frames": 3}}))
    assert check_validation_report(npz, robot_name="op3_like")["passed"] is True
    report.write_text(json.dumps({"passed": True, "robot": "op3_like", "input": str(npz)}))
    assert check_validation_report(npz, robot_name="op3_like")["passed"] is True
    import hashlib

    npz.write_bytes(b"validated content")
    digest = hashlib.sha256(b"validated content").hexdigest()
    report.write_text(json.dumps({"passed": True, "robot": "op3_like", "input": {"path": "/old/name.npz",
                                                                               "sha256": digest}}))
    assert check_validation_report(npz, robot_name="op3_like")["passed"] is True  # renamed, same content
    npz.write_bytes(b"edited after validation")
    with pytest.raises(InputError, match="changed after it was validated"):
        check_validation_report(npz, robot_name="op3_like")
    other = tmp_path / "elsewhere.json"
    other.write_text("{not json")
    with pytest.raises(InputError, match="unreadable"):
        check_validation_report(npz, other)


def test_reading_every_fifth_tick_leaves_gaps_in_the_log_only(smap, tmp_path):
    traj = sine_trajectory(smap, seconds=0.4)
    streamer, chain, log = run(smap, traj, tmp_path, config=PlaybackConfig(rate_hz=RATE, ramp_s=0.5, read_every=5))
    result = streamer.play(traj)
    rows = read_log(log)
    present = rows[f"present_{smap.joints[0]}_ticks"]
    assert np.isnan(present).sum() == result.ticks - len(range(0, result.ticks, 5))
    assert not np.isnan(present[::5]).any()

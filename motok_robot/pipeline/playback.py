"""The playback stage: the servo streamer on an emulated Dynamixel chain, the MuJoCo model or real
servos, gated by the validation report (see :mod:`motok_robot.servo`)."""

from __future__ import annotations

import json
import os
import warnings
from dataclasses import asdict
from pathlib import Path

from motok_robot.errors import HardwareError, InputError
from motok_robot.pipeline.config import PipelineConfig
from motok_robot.pipeline.result import PlaybackSummary


def play(pipeline_config: PipelineConfig, robot, tmp: Path, mode: str, port, force: bool, render: bool, files: dict,
         notes: list) -> PlaybackSummary:
    """Play ``files["robot"]`` with the servo streamer in ``mode`` (it streams the servo goals that
    validation checked) and add the playback log, its statistics and (``"sim"`` with
    ``sim_video``) the playback video to ``files``.  Hardware playback (``"port"``) is refused
    without a passing validation report unless ``force``; a robot without servos is skipped."""
    from motok_robot.servo.bus import DynamixelBus
    from motok_robot.servo.config import PlaybackConfig
    from motok_robot.servo.convert import ServoMap
    from motok_robot.servo.imu import ImuMount
    from motok_robot.servo.streamer import PlaybackWarning, Streamer, check_validation_report, load_trajectory
    from motok_robot.servo.timing import FakeClock

    gate = None
    try:
        check_validation_report(files["robot"], files["report"], force=False, robot_name=robot.name)
    except InputError as exc:
        gate = str(exc).split("refusing to play: ", 1)[-1].split(". Validate it first", 1)[0]
        gate = gate.replace(str(tmp) + os.sep, "")  # name files relative to the output folder
    summary = PlaybackSummary(mode=mode, status="completed", gate=gate)
    if mode == "none":
        summary.status, summary.line = "skipped", "playback not asked for"
        return summary
    if not robot.servos:
        summary.status = "skipped"
        summary.line = f"robot {robot.name} has no servo map; nothing to play"
        return summary
    if mode == "port" and gate is not None:
        if not force:
            summary.status = "refused"
            summary.line = f"hardware playback refused: {gate} (pass --force to play anyway)"
            return summary
        summary.forced = True
        notes.append(f"hardware playback FORCED without a passing validation report ({gate})")
        warnings.warn(f"playing on {port} WITHOUT a passing validation report ({gate}) because of --force",
                      PlaybackWarning, stacklevel=3)
    servo_map = ServoMap.from_specs(robot.servos)
    trajectory = load_trajectory(files["robot"], servo_map, robot.name, files["report"])
    if mode == "port" and not trajectory.plan_joints and not force:  # as `play`: only validated goals
        summary.status = "refused"
        summary.line = "hardware playback refused: the report records no servo goals (pass --force to play anyway)"
        return summary
    defaults = pipeline_config.playback or PlaybackConfig()
    rate = defaults.rate_hz
    if pipeline_config.playback is None and robot.bus is not None:
        rate = robot.bus.control_hz
    config = PlaybackConfig(**{**asdict(defaults), "rate_hz": rate})
    baud = robot.bus.baud if robot.bus is not None else 2_000_000
    imu = ImuMount.from_spec(robot.bus.imu) if robot.bus is not None and robot.bus.imu is not None else None
    simulated = mode != "port" and not pipeline_config.realtime
    clock = FakeClock() if simulated else None
    log_path = tmp / "playback.csv"
    rig = None
    try:
        if mode == "dry-run":
            from motok_robot.servo.emulator import emulated_chain

            chain = emulated_chain(servo_map, baud=baud, imu_id=imu.id if imu is not None else None,
                                   **({"clock": clock} if clock else {}))
            bus = DynamixelBus(f"emulated:{robot.name}", baud, port_handler=chain, imu=imu)
        elif mode == "sim":
            from motok_robot.servo.sim_rig import SimRig

            video = tmp / "playback_sim.mp4" if render and pipeline_config.sim_video else None
            bus = rig = SimRig(robot, clock=clock, render_path=video)
        else:
            bus = DynamixelBus(port, baud, imu=imu)
    except HardwareError as exc:
        summary.status, summary.error = "error", str(exc)
        return summary
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", PlaybackWarning)
            streamer = Streamer(bus, servo_map, config, clock=clock, log_path=log_path)
            streamer.preflight()
            played = streamer.play(trajectory)
        summary.line = played.line().replace(str(log_path), log_path.name)
        notes.extend(f"playback: {w.message}" for w in caught if issubclass(w.category, PlaybackWarning))
    except HardwareError as exc:  # the streamer already stopped safely and names the servo
        summary.status, summary.error = "stopped", str(exc).replace(str(tmp) + os.sep, "")
    finally:
        bus.close()
    for key, path in (("playback_log", log_path), ("playback_stats", log_path.with_name("playback.stats.json"))):
        if path.is_file():
            files[key] = path
    if "playback_stats" in files:  # the streamer records the log's (temporary) absolute path
        stats = json.loads(files["playback_stats"].read_text(encoding="utf-8"))
        stats["log_path"] = log_path.name
        files["playback_stats"].write_text(json.dumps(stats, indent=2) + "\n", encoding="utf-8")
    if rig is not None:
        summary.fell = bool(rig.fell)
        summary.line += (f"; simulated robot {'FELL' if rig.fell else 'stayed upright'} "
                         f"(lowest base height {rig.min_base_height:.3f} m)")
        if (tmp / "playback_sim.mp4").is_file():
            files["playback_video"] = tmp / "playback_sim.mp4"
    if simulated:
        summary.line += " [simulated time]"
    return summary

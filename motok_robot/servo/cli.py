"""``motok-robot play`` and ``motok-robot servo scan|calibrate`` (light: heavy imports in handlers)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def register(commands, groups) -> None:
    play = commands.add_parser(
        "play", help="stream a validated robot.npz to Dynamixel servos (or an emulated chain / the simulator)",
        description="Stream the validated servo goals of robot.npz to the servos at a fixed rate: report gate (the "
                    "report beside robot.npz, the one `validate ROBOT.npz --out DIR` wrote in a folder below, or "
                    "--report), pre-flight, ramp to frame 0, clamped streaming, safe stop. Exits non-zero with one "
                    "line naming the servo on a fault.")
    play.add_argument("trajectory", help="robot.npz (retargeting output)")
    play.add_argument("--robot", help="robot name or PATH/NAME.toml (default: the installed robot that the 'robot' "
                                      "field of robot.npz names; a path there is refused)")
    play.add_argument("--port", help="serial device, e.g. /dev/ttyUSB0 (not needed with --dry-run / --sim)")
    play.add_argument("--baud", type=int, help="baud rate (default: the robot's bus, 2000000 for op3_like)")
    play.add_argument("--rate", type=float, help="control rate in Hz, 1..1000 (default: the robot's bus, 125)")
    mode = play.add_mutually_exclusive_group()
    mode.add_argument("--dry-run", action="store_true", help="play to an emulated servo chain (no hardware)")
    mode.add_argument("--sim", action="store_true", help="play on the MuJoCo model in real time (no hardware)")
    play.add_argument("--log", help="CSV log (default: <trajectory>.playback.csv next to robot.npz)")
    play.add_argument("--report", help="validation report (default: report.json next to robot.npz, else the "
                                       "report.json in a folder below robot.npz's folder or the current one that "
                                       "validated this file's content, as `validate ROBOT.npz --out DIR` leaves it)")
    play.add_argument("--force", action="store_true",
                      help="play without a passing validation report (warns); still streams the servo goals the "
                           "report recorded")
    play.add_argument("--joint-angles", action="store_true",
                      help="when no validated servo goals exist for the file (no report, or validated without "
                           "physics), stream its raw joint angles instead of refusing (warns)")
    play.add_argument("--ramp", type=float, default=None, help="seconds to ramp from the present pose to frame 0 (2)")
    play.add_argument("--retries", type=int, default=None, help="consecutive failed ticks tolerated (3)")
    play.add_argument("--torque-off-on-stop", action="store_true",
                      help="on a fault or Ctrl-C switch torque off instead of holding position")
    play.add_argument("--no-balance", action="store_true",
                      help="play the validated servo goals open loop even when validation ran them closed loop "
                           "(balance controller on the torso IMU); warns. Needed on a bus without an IMU")
    play.add_argument("--render", help="with --sim: record the simulated playback to this MP4/GIF")
    play.add_argument("--no-realtime", action="store_true",
                      help="do not ask for SCHED_FIFO priority for the control loop (by default it is requested; "
                           "refused without root/CAP_SYS_NICE, then a warning and normal priority)")
    play.set_defaults(func=_play)

    servo = groups["servo"]
    scan = servo.add_parser("scan", help="list the servos on a bus: IDs, models, present positions")
    scan.add_argument("--port", help="serial device, e.g. /dev/ttyUSB0")
    scan.add_argument("--baud", type=int, default=2_000_000, help="baud rate (2000000)")
    scan.add_argument("--emulate", metavar="ROBOT", help="scan an emulated chain of ROBOT's servos (no hardware)")
    scan.set_defaults(func=_scan)

    calibrate = servo.add_parser(
        "calibrate", help="record zero offsets: pose the robot in its zero pose, write a calibrated servo map",
        description="With torque off, put the robot in its zero pose (all joint angles 0) by hand; the present "
                    "positions become zero_offset_ticks (min/max ticks move with them) in a copy of the robot "
                    "description written to --out.")
    calibrate.add_argument("--robot", required=True, help="robot name or NAME.toml")
    calibrate.add_argument("--port", help="serial device, e.g. /dev/ttyUSB0")
    calibrate.add_argument("--baud", type=int, help="baud rate (default: the robot's bus)")
    calibrate.add_argument("--out", required=True, help="calibrated copy of the description (NAME.toml)")
    calibrate.add_argument("--yes", action="store_true", help="do not wait for Enter (the robot is already posed)")
    calibrate.add_argument("--emulate", action="store_true", help="calibrate against an emulated chain (no hardware)")
    calibrate.set_defaults(func=_calibrate)


def _show_warning_line(message, category, filename, lineno, file=None, line=None):
    print(f"motok-robot: warning: {message}", file=sys.stderr)


def _robot_name_from_npz(path: Path) -> str | None:
    """The ``robot`` field of ``path`` (None when absent); InputError for an unreadable file."""
    import numpy as np

    from motok_robot.npz_files import read_npz_fields

    fields = read_npz_fields(path, "trajectory file")
    if "robot" not in fields:
        return None
    value = np.asarray(fields["robot"])
    return str(value.reshape(()).item()) if value.size == 1 else repr(value.tolist())[:80]


#: a report.json below these many folder levels of robot.npz's folder / the current folder is not looked for
REPORT_SEARCH_DEPTH = 3
#: folders visited at most while looking for the report (a bound when the current folder is large)
REPORT_SEARCH_FOLDERS = 5000
#: report files larger than this are not read while searching (a validation report is tens of kB)
REPORT_SEARCH_MAX_BYTES = 16 * 2**20


def _read_report(path: Path) -> dict | None:
    import json

    try:
        if path.stat().st_size > REPORT_SEARCH_MAX_BYTES:
            return None
        report = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return report if isinstance(report, dict) else None


def _validated_digest(report: dict | None) -> str | None:
    record = report.get("input") if isinstance(report, dict) else None
    digest = record.get("sha256") if isinstance(record, dict) else None
    return digest.lower() if isinstance(digest, str) and digest else None


def _reports_below(root: Path, skip: Path):
    """report.json files at most REPORT_SEARCH_DEPTH levels below ``root`` (hidden folders
    skipped), at most REPORT_SEARCH_FOLDERS folders visited."""
    import os

    visited = 0
    base = len(root.parts)
    for here, dirs, files in os.walk(root):
        visited += 1
        if visited > REPORT_SEARCH_FOLDERS:
            return
        depth = len(Path(here).parts) - base
        dirs[:] = sorted(d for d in dirs if not d.startswith(".")) if depth < REPORT_SEARCH_DEPTH else []
        if "report.json" in files:
            candidate = Path(here) / "report.json"
            if candidate.resolve() != skip:
                yield candidate


def find_validation_report(trajectory: Path, report: str | None = None,
                           roots: tuple[Path, ...] | None = None) -> tuple[Path | None, str]:
    """The validation report for ``trajectory`` and a line saying how it was found.

    ``report`` (``--report``) wins.  Else ``report.json`` beside the trajectory when it validated
    this content (or records no digest: the gate then matches by name); else a ``report.json``
    at most :data:`REPORT_SEARCH_DEPTH` folders below the trajectory's folder or the current
    folder (``roots``) whose ``input.sha256`` is the trajectory's, as ``validate ROBOT.npz
    --out DIR`` leaves it (a passing one first, then the newest); else the report beside it
    when there is one (the gate explains why it does not fit), else None and why.
    """
    from motok_robot.servo.trajectory import file_sha256

    if report:
        return Path(report), ""
    trajectory = Path(trajectory)
    beside = trajectory.with_name("report.json")
    digest = file_sha256(trajectory)
    beside_report = _read_report(beside) if beside.is_file() else None
    if beside_report is not None and _validated_digest(beside_report) in (digest, None):
        return beside, ""
    matches = []
    seen: set[Path] = set()
    roots = tuple(dict.fromkeys(Path(r).resolve() for r in (roots or (trajectory.parent, Path.cwd()))))
    for root in roots:
        for candidate in _reports_below(root, beside.resolve()):
            if candidate.resolve() in seen:
                continue
            seen.add(candidate.resolve())
            found = _read_report(candidate)
            if _validated_digest(found) == digest:
                matches.append((found.get("passed") is True, candidate.stat().st_mtime, candidate))
    if matches:
        matches.sort(key=lambda m: (m[0], m[1]))
        chosen = matches[-1][2]
        return chosen, f"validation report: {chosen} (it validated this file's content, sha256 {digest[:12]}...)"
    if beside.is_file():
        return beside, ""
    places = " and ".join(str(r) for r in roots)
    return None, (f"no validation report at {beside}, and no report.json up to {REPORT_SEARCH_DEPTH} folders "
                  f"below {places} validated its content (sha256 {digest[:12]}...)")


def missing_goals_reason(trajectory: Path, report_path: Path | None, description_sha256: str) -> str:
    """Why playback has no validated servo goals for ``trajectory`` (one phrase)."""
    from motok_robot.servo.trajectory import file_sha256

    if report_path is None or not Path(report_path).is_file():
        return "no validation report"
    report = _read_report(Path(report_path))
    if report is None:
        return f"{report_path} is unreadable"
    validated = _validated_digest(report)
    if validated is None:
        return f"{report_path} records no sha256 of the file it validated"
    if validated != file_sha256(Path(trajectory)):
        return f"{report_path} validated other content"
    record = report.get("servo_goals")
    if not isinstance(record, dict) or not record.get("file"):
        return f"{report_path} records no servo goals (validated without physics)"
    description = report.get("robot_description")
    if not isinstance(description, dict) or str(description.get("sha256", "")).lower() != description_sha256.lower():
        return f"{report_path} was made with another robot description"
    return f"{report_path}'s servo goals were not loaded"


def _play(args: argparse.Namespace) -> int:
    import warnings

    with warnings.catch_warnings():  # warnings as one line each, restored afterwards
        warnings.simplefilter("always")
        warnings.showwarning = _show_warning_line
        return _play_inner(args)


def _play_inner(args: argparse.Namespace) -> int:
    import os

    if args.render:
        os.environ.setdefault("MUJOCO_GL", "egl")
    from motok_robot.errors import InputError
    from motok_robot.robots import load
    from motok_robot.robots.robot import installed_robot_name
    from motok_robot.servo.bus import DynamixelBus
    from motok_robot.servo.config import ON_STOP_HOLD, ON_STOP_TORQUE_OFF, PlaybackConfig
    from motok_robot.servo.convert import ServoMap
    from motok_robot.servo.emulator import emulated_chain
    from motok_robot.servo.imu import ImuMount
    from motok_robot.servo.streamer import (
        PlaybackInterrupted,
        Streamer,
        check_validation_report,
        load_trajectory,
        robot_joint_ranges,
    )

    path = Path(args.trajectory)
    if not path.is_file():
        raise InputError(f"{path}: no such trajectory file")
    if args.robot:  # the user's choice: an installed name or a description path
        robot_name = args.robot
    else:  # a data file may only NAME an installed robot, never point at a description
        saved = _robot_name_from_npz(path)
        if not saved:
            raise InputError(f"{path}: no 'robot' field; pass --robot NAME")
        robot_name = installed_robot_name(saved, str(path))
    if not (args.dry_run or args.sim) and not args.port:
        raise InputError("--port DEV is required (or --dry-run / --sim to play without hardware)")
    if args.render and not args.sim:
        raise InputError("--render needs --sim")
    robot = load(robot_name)
    digest = robot.description_sha256
    report_path, found_note = find_validation_report(path, args.report)
    if report_path is None and not args.force:
        raise InputError(f"{path}: refusing to play: {found_note}. Validate it first (motok-robot validate {path} "
                         "--out DIR), pass --report DIR/report.json, or --force to play an unvalidated trajectory")
    if found_note and report_path is not None:
        print(found_note)
    check_validation_report(path, report_path, force=args.force, robot_name=robot.name, robot_sha256=digest)
    servo_map = ServoMap.from_specs(robot.servos)
    trajectory = load_trajectory(path, servo_map, robot.name, report_path, robot_sha256=digest)
    # load_trajectory fills plan_joints exactly when it took the report's servo_goals.npz
    streams_goals = bool(trajectory.plan_joints)
    if trajectory.plan is not None:
        print("validated closed loop: " + ("playing it OPEN LOOP (--no-balance)" if args.no_balance else
                                           "the balance controller runs on the torso IMU"))
    bus_spec = robot.bus
    baud = args.baud or (bus_spec.baud if bus_spec else 2_000_000)
    from motok_robot.servo import control_table as ct

    if baud not in ct.BAUD_RATE_VALUES.values():
        raise InputError(f"--baud {baud}: not a Dynamixel baud rate (one of "
                         f"{', '.join(str(b) for b in ct.BAUD_RATE_VALUES.values())})")
    defaults = PlaybackConfig()
    config = PlaybackConfig(
        rate_hz=args.rate if args.rate is not None else (bus_spec.control_hz if bus_spec else defaults.rate_hz),
        ramp_s=defaults.ramp_s if args.ramp is None else args.ramp,
        retry_budget=defaults.retry_budget if args.retries is None else args.retries,
        on_stop=ON_STOP_TORQUE_OFF if args.torque_off_on_stop else ON_STOP_HOLD,
        realtime_priority=0 if args.no_realtime else defaults.realtime_priority,
        balance=not args.no_balance,
    )
    imu = ImuMount.from_spec(bus_spec.imu) if bus_spec is not None and bus_spec.imu is not None else None
    if not streams_goals:
        why = missing_goals_reason(path, report_path, digest)
        if not args.joint_angles:
            raise InputError(f"{path}: refusing to play: no validated servo goals for it ({why}); play streams only "
                             "the servo goals validation checked. Validate it with physics (motok-robot validate "
                             f"{path} --out DIR) or pass --joint-angles to stream its raw joint angles")
        import warnings

        from motok_robot.servo.streamer import PlaybackWarning

        warnings.warn(f"{path}: streaming the RAW JOINT ANGLES because of --joint-angles ({why}): not what "
                      "validation's physics rollout checked", PlaybackWarning, stacklevel=2)
    else:
        print({"feedforward": "streaming the validated feedforward servo goals",
               "feasibility": "streaming the feasibility stage's validated servo goals",
               "reference": "streaming the validated servo goals (reference mode: the joint angles, no feedforward)"}
              .get(trajectory.goals, f"streaming the validated servo goals ({trajectory.goals})")
              + f" of {report_path}")
    log_path = Path(args.log) if args.log else path.with_name(path.stem + ".playback.csv")
    rig = None
    if args.sim:
        from motok_robot.servo.sim_rig import SimRig

        bus = rig = SimRig(robot, render_path=args.render)
    elif args.dry_run:
        chain = emulated_chain(servo_map, baud=baud, imu_id=imu.id if imu is not None else None)
        bus = DynamixelBus(f"emulated:{robot.name}", baud, port_handler=chain, imu=imu)
    else:
        bus = DynamixelBus(args.port, baud, imu=imu)
    try:
        streamer = Streamer(bus, servo_map, config, log_path=log_path, joint_range=robot_joint_ranges(robot))
        streamer.preflight(trajectory)
        result = streamer.play(trajectory)
    except PlaybackInterrupted as exc:  # Ctrl-C 130, SIGTERM 143, SIGHUP 129, after the safe stop
        print(f"motok-robot: {exc}", file=sys.stderr)
        return exc.exit_status
    finally:
        bus.close()
    print(result.line())
    if rig is not None:
        state = "FELL" if rig.fell else "stayed upright"
        print(f"simulated robot {state}: base height {rig.start_base_height:.3f} m at start, "
              f"lowest {rig.min_base_height:.3f} m" + (f"; video {args.render}" if args.render else ""))
        return 1 if rig.fell else 0
    return 0


def _open_bus(port: str | None, baud: int, emulate_robot=None):
    from motok_robot.errors import InputError
    from motok_robot.servo.bus import DynamixelBus
    from motok_robot.servo.convert import ServoMap
    from motok_robot.servo.emulator import emulated_chain

    if emulate_robot is not None:
        chain = emulated_chain(ServoMap.from_specs(emulate_robot.servos), baud=baud)
        return DynamixelBus(f"emulated:{emulate_robot.name}", baud, port_handler=chain)
    if not port:
        raise InputError("--port DEV is required")
    return DynamixelBus(port, baud)


def _scan(args: argparse.Namespace) -> int:
    from motok_robot.servo import control_table as ct

    robot = None
    if args.emulate:
        from motok_robot.robots import load

        robot = load(args.emulate)
    bus = _open_bus(args.port, args.baud, robot)
    try:
        found = bus.scan()
        if not found:
            print(f"no servo answered on {bus.port_name} at {args.baud} baud")
            return 1
        ids = sorted(found)
        positions = bus.read_present_positions_each(ids)
        errors = bus.read_hardware_errors(ids)
    finally:
        bus.close()
    print(f"{len(ids)} servo(s) on {bus.port_name} at {args.baud} baud")
    print(f"{'id':>4}  {'model':<12} {'number':>6}  {'position':>8}  hardware error")
    for servo_id, position in zip(ids, positions):
        number = found[servo_id]
        bits = errors[servo_id]
        print(f"{servo_id:>4}  {ct.MODEL_NAMES.get(number, '?'):<12} {number:>6}  {int(position):>8}  "
              + (ct.describe_hardware_error(bits) if bits else "-"))
    return 0


def _calibrate(args: argparse.Namespace) -> int:
    from motok_robot.robots import load
    from motok_robot.servo.calibrate import calibrated_description, prepare, read_zero_pose
    from motok_robot.servo.convert import ServoMap

    robot = load(args.robot)
    servo_map = ServoMap.from_specs(robot.servos)
    baud = args.baud or (robot.bus.baud if robot.bus else 2_000_000)
    bus = _open_bus(args.port, baud, robot if args.emulate else None)
    try:
        prepare(bus, servo_map)
        if not args.yes:
            print("Torque is OFF (support the robot). Move it by hand into its zero pose "
                  "(every joint angle 0), then press Enter.")
            input()
        zero = read_zero_pose(bus, servo_map)
    finally:
        bus.close()
    out = calibrated_description(robot, zero, args.out)
    print(f"wrote {out}: zero offsets of {len(zero)} servos; check with: motok-robot robots show {out}")
    return 0

"""``motok-robot export``: the project's files in formats neighbouring tools read.

Light module: numpy and the writers are imported inside the handler.

    motok-robot export motion.npz --bvh motion.bvh            # human motion, BVH (cm, y up)
    motok-robot export robot.npz --csv robot.csv              # robot joint angles per frame (rad)
    motok-robot export robot.npz --csv goals.csv --goals      # the validated servo goals instead
    motok-robot export runs/ --lerobot dataset/               # passing trajectories as LeRobot episodes

Exit status: 0 when written, 2 for a usage or input error (one line naming the file and field).
"""

from __future__ import annotations


def register(commands, groups) -> None:
    parser = commands.add_parser(
        "export", help="write motion.npz as BVH, robot.npz as CSV, or a folder of passing runs as a LeRobot dataset",
        description="Export to the formats neighbouring tools read: the human motion of a motion.npz as BVH "
                    "(centimetres, y up), a robot.npz as CSV (one row per frame: time_s, root position m, root "
                    "quaternion w x y z, every joint in rad under its MJCF name), or every passing run folder "
                    "(robot.npz + report.json + servo_goals.npz) under a folder as a LeRobot-style episode dataset. "
                    "Formats: docs/export.md.")
    parser.add_argument("input", help="motion.npz (--bvh), robot.npz (--csv) or a folder of run folders (--lerobot)")
    target = parser.add_mutually_exclusive_group(required=True)
    target.add_argument("--bvh", metavar="OUT.bvh", help="write the human motion as BVH (centimetres, y up)")
    target.add_argument("--csv", metavar="OUT.csv", help="write the robot trajectory as CSV (radians, metres)")
    target.add_argument("--lerobot", metavar="OUT_DIR", help="write the passing trajectories as a LeRobot dataset")
    parser.add_argument("--bone-positions", action="store_true",
                        help="--bvh: position channels on every joint, so joint positions are kept exactly where "
                             "the motion's bone lengths vary (some viewers read only the root's)")
    parser.add_argument("--goals", nargs="?", const="", metavar="SERVO_GOALS.npz",
                        help="--csv: the validated servo goals as the joint columns (<joint>_goal_rad): from the "
                             "report play would use (--report, else found as play finds it), or from this file")
    parser.add_argument("--report", metavar="REPORT.json", help="--csv --goals: the validation report to take "
                                                                "the servo goals from")
    parser.add_argument("--robot", help="--lerobot: only trajectories of this robot (a dataset has one robot)")
    parser.add_argument("--npz", action="store_true",
                        help="--lerobot: write episodes as .npz even when pyarrow is installed")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing output")
    parser.set_defaults(func=run_export)


def _check_output(path, overwrite: bool, folder: bool = False):
    from pathlib import Path

    from motok_robot.errors import InputError

    out = Path(path)
    if folder:
        if out.exists() and not out.is_dir():
            raise InputError(f"{out}: is a file, not an output folder")
        if out.is_dir() and any(out.iterdir()) and not overwrite:
            raise InputError(f"{out}: output folder exists and is not empty; choose a new folder or pass --overwrite")
    elif out.exists():
        if out.is_dir():
            raise InputError(f"{out}: is a folder, not an output file")
        if not overwrite:
            raise InputError(f"{out}: exists; choose a new name or pass --overwrite")
    return out


def _misplaced(args, allowed: set[str]) -> None:
    from motok_robot.errors import InputError

    given = {"--bone-positions": args.bone_positions, "--goals": args.goals is not None, "--report": bool(args.report),
             "--robot": bool(args.robot), "--npz": args.npz}
    wrong = [name for name, used in given.items() if used and name not in allowed]
    if wrong:
        target = "--bvh" if args.bvh else "--csv" if args.csv else "--lerobot"
        raise InputError(f"{', '.join(wrong)}: not an option of export {target}")


def run_export(args) -> int:
    from motok_robot.export.progress import Progress

    if args.bvh:
        _misplaced(args, {"--bone-positions"})
        return _export_bvh(args, Progress("bvh", "frames"))
    if args.csv:
        _misplaced(args, {"--goals", "--report"})
        return _export_csv(args, Progress("csv", "frames"))
    _misplaced(args, {"--robot", "--npz"})
    return _export_lerobot(args)


def _export_bvh(args, progress) -> int:
    from retarget.io import read_motion_npz

    from motok_robot.export.bvh import write_bvh

    out = _check_output(args.bvh, args.overwrite)
    motion = read_motion_npz(args.input)
    result = write_bvh(motion.joints, motion.fps, out, bone_positions=args.bone_positions, progress=progress)
    print(result.line())
    return 0


def _export_csv(args, progress) -> int:
    from pathlib import Path

    from motok_robot.errors import InputError
    from motok_robot.export.robot_csv import read_goals_for, read_robot_table, write_robot_csv

    out = _check_output(args.csv, args.overwrite)
    table = read_robot_table(args.input)
    goals = None
    if args.goals is not None:
        if args.goals:
            goals = read_goals_for(table, args.goals)
            where = args.goals
        else:
            goals, where = _validated_goals(table, args.report)
    elif args.report:
        raise InputError("--report: only used with --goals")
    write_robot_csv(table, out, goals, progress=progress)
    what = f"the validated servo goals of {where}" if goals is not None else "the joint angles"
    print(f"wrote {out}: {table.qpos.shape[0]} frames at {table.fps:g} fps, {len(table.joint_names)} joints "
          f"({what}; time_s, root m and quaternion wxyz, joints rad) of {Path(args.input)}")
    return 0


def _validated_goals(table, report_arg):
    """The servo goals the validation report of ``table`` recorded (found as play finds it)."""
    import json

    from motok_robot.errors import InputError
    from motok_robot.export.robot_csv import read_goals_for
    from motok_robot.servo.cli import find_validation_report

    report_path, note = find_validation_report(table.path, report_arg)
    if report_path is None:
        raise InputError(f"{table.path}: --goals: {note}; pass --report REPORT.json or --goals SERVO_GOALS.npz")
    try:
        report = json.loads(report_path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise InputError(f"{report_path}: unreadable validation report ({exc})") from None
    validated = (report.get("input") or {}).get("sha256") if isinstance(report, dict) else None
    if validated != table.sha256:
        raise InputError(f"{report_path}: field 'input.sha256' is not the sha256 of {table.path}: it validated other "
                         "content, so its servo goals are not this trajectory's")
    record = report.get("servo_goals")
    if not isinstance(record, dict) or not record.get("file"):
        raise InputError(f"{report_path}: field 'servo_goals' names no goals file (validated without physics)")
    goals_path = report_path.parent / str(record["file"])
    return read_goals_for(table, goals_path, record.get("sha256")), goals_path


def _export_lerobot(args) -> int:
    from pathlib import Path

    from motok_robot.errors import InputError
    from motok_robot.export.lerobot import check_consistent, find_episodes, parquet_available, write_dataset
    from motok_robot.export.progress import Progress

    out = _check_output(args.lerobot, args.overwrite, folder=True)
    root = Path(args.input)
    scan = find_episodes(root, args.robot, progress=Progress("scan", "run folders"))
    if not scan.episodes:
        raise InputError(f"{root}: no passing trajectory to export ({len(scan.skipped)} run folder(s) skipped"
                         + (f"; first: {scan.skipped[0][0]}: {scan.skipped[0][1]})" if scan.skipped else ")"))
    check_consistent(scan.episodes, root)  # before an --overwrite removes the previous export
    if args.overwrite and out.is_dir():
        _clear_dataset(out)
    parquet = parquet_available() and not args.npz
    info = write_dataset(scan.episodes, out, source=str(root), skipped=scan.skipped, use_parquet=parquet,
                         progress=Progress("write", "episodes"))
    count = info["total_episodes"]
    kind = "Parquet" if parquet else "npz" if args.npz else "npz: pyarrow is not installed"
    print(f"wrote {out}: {count} episode{'' if count == 1 else 's'}, {info['total_frames']} frames at "
          f"{info['fps']:g} fps of {info['robot_type']} ({kind}); skipped {len(scan.skipped)} run folder(s)"
          + (f", see {out / 'meta' / 'motok_export.json'}" if scan.skipped else ""))
    for folder, reason in scan.skipped[:10]:
        print(f"  skipped {folder}: {reason}")
    if len(scan.skipped) > 10:
        print(f"  ... and {len(scan.skipped) - 10} more")
    return 0


def _clear_dataset(out) -> None:
    """Remove a previous export's data/ and meta/ (nothing else in the folder is touched)."""
    import shutil

    for name in ("data", "meta"):
        if (out / name).is_dir():
            shutil.rmtree(out / name)

"""``motok-robot validate``: check robot trajectories in MuJoCo and write a report.

Light module: MuJoCo, matplotlib and the checks are imported inside the handler.

    motok-robot validate robot.npz --robot op3_like --out val/ [--no-render] [--no-physics]
    motok-robot validate --batch clips/ --robot op3_like --out val/      # val/summary.csv
    motok-robot validate robot.npz --out val/ --set max_velocity_ratio=0.9 --set zmp_model=cart_table

Exit status: 0 when every trajectory passes, 1 when one fails validation (or, in batch mode,
cannot be read), 2 for a usage or input error (one line on stderr naming the field).
"""

from __future__ import annotations

import argparse


def register(commands, groups) -> None:
    parser = commands.add_parser(
        "validate", help="check robot trajectories in MuJoCo (skating, contact, limits, torques, balance, physics)",
        description="Validate robot.npz trajectories: kinematic checks, inverse dynamics, balance (CoM, ZMP), "
                    "a physics rollout with the robot's own servos; writes report.json, PNG plots and an MP4.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="Thresholds (--set KEY=VALUE): see docs/validation.md or motok_robot/sim/config.py.")
    parser.add_argument("input", nargs="?", help="robot.npz to validate (or use --batch)")
    parser.add_argument("--batch", metavar="DIR", help="validate every *.npz in DIR; writes OUT/summary.csv")
    parser.add_argument("--robot", help="robot name or path (default: the 'robot' field of the npz)")
    parser.add_argument("--out", required=True, metavar="DIR", help="output folder")
    parser.add_argument("--no-render", action="store_true", help="skip the MP4")
    parser.add_argument("--no-physics", action="store_true", help="skip the physics rollout")
    parser.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="override a threshold of ValidationConfig (repeatable)")
    parser.set_defaults(func=run_validate)


def run_validate(args) -> int:
    import os

    os.environ.setdefault("MUJOCO_GL", "egl")  # before mujoco is imported
    from pathlib import Path

    from motok_robot.errors import InputError
    from motok_robot.sim.config import ValidationConfig

    config = ValidationConfig().with_overrides(args.set)
    if bool(args.input) == bool(args.batch):
        raise InputError("validate: give either one robot.npz or --batch DIR")
    out = Path(args.out)
    options = dict(physics=not args.no_physics, plots=not args.no_plots, render=not args.no_render)
    if args.batch:
        return _run_batch(Path(args.batch), args.robot, out, config, options)
    result = _validate_one(Path(args.input), args.robot, out, config, options, cache={})
    print(result.summary())
    print(f"report: {out / 'report.json'}")
    return 0 if result.passed else 1


def _robot_for(path, robot_arg, cache):
    """The RobotIndex for ``robot_arg`` or for the npz's own 'robot' field (cached by name)."""
    import numpy as np

    from motok_robot.errors import InputError
    from motok_robot.robots import load
    from motok_robot.robots.index import index_robot

    name = robot_arg
    if not name:
        from motok_robot.npz_files import read_npz_fields
        from motok_robot.robots.robot import installed_robot_name

        fields = read_npz_fields(path, "trajectory file")
        raw = np.asarray(fields["robot"]) if "robot" in fields else np.asarray("")
        name = str(raw.reshape(()).item()) if raw.size == 1 else repr(raw.tolist())[:80]
        if not name:
            raise InputError(f"{path}: field 'robot' is missing; pass --robot NAME")
        name = installed_robot_name(name, str(path))  # a data file may only name an installed robot
    if name not in cache:
        cache[name] = index_robot(load(name))
    return cache[name]


def _validate_one(path, robot_arg, out, config, options, cache):
    from motok_robot.sim.validate import validate_file

    index = _robot_for(path, robot_arg, cache)
    return validate_file(path, index, config=config, out_dir=out, **options)


def _run_batch(folder, robot_arg, out, config, options) -> int:
    import csv

    from tqdm import tqdm

    from motok_robot.errors import InputError, MotokError

    if not folder.is_dir():
        raise InputError(f"--batch {folder}: not a folder")
    files = sorted(folder.glob("*.npz"))
    if not files:
        raise InputError(f"--batch {folder}: no .npz files in it")
    out.mkdir(parents=True, exist_ok=True)
    metric_keys = None
    rows = []
    cache: dict = {}
    failed = 0
    for path in tqdm(files, desc="validate", unit="clip", disable=None):
        row = {"file": path.name, "passed": False, "failed_checks": "", "error": ""}
        try:
            result = _validate_one(path, robot_arg, out / path.stem, config, options, cache)
        except (MotokError, FileNotFoundError) as exc:
            row["error"] = str(exc)
            failed += 1
        else:
            report = result.report
            metric_keys = metric_keys or [k for k in report["metrics"] if k != "passed"]
            row.update(passed=report["passed"], failed_checks=";".join(report["failed_checks"]),
                       robot=report["robot"], duration_s=round(report["input"]["duration_s"], 3))
            row.update({k: report["metrics"][k] for k in metric_keys})
            failed += 0 if report["passed"] else 1
        rows.append(row)
    columns = ["file", "robot", "duration_s", "passed", "failed_checks"] + (metric_keys or []) + ["error"]
    with open(out / "summary.csv", "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=columns, extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            writer.writerow({k: ("" if row.get(k) is None else row.get(k, "")) for k in columns})
    passed = len(files) - failed
    print(f"{passed}/{len(files)} trajectories passed; summary: {out / 'summary.csv'}")
    for row in rows:
        if row["error"]:
            print(f"  ERROR {row['file']}: {row['error']}")
        elif not row["passed"]:
            print(f"  FAIL  {row['file']}: {row['failed_checks'].replace(';', ', ')}")
    return 0 if failed == 0 else 1

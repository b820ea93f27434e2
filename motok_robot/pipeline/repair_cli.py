"""``motok-robot repair``: the repairs ``run`` tries after validation, as a stage of its own.

Light module: the pipeline (MuJoCo, CasADi) is imported inside the handler.

    motok-robot retarget motion.npz --robot op3_like --out robot.npz
    motok-robot validate robot.npz --out val/              # FAIL: zmp, fall (say)
    motok-robot repair robot.npz --motion motion.npz --out repaired/

``repair`` validates ``robot.npz`` as ``run`` does and, when it fails, tries the same two
repairs with the same code (:func:`motok_robot.pipeline.repairs.apply_repairs`): the balance
repair (the motion retargeted again with the ZMP term and a foot planted in every frame) when
a footing or balance check fails, then the slow-down when a speed check fails.  It writes the
trajectory kept (``robot.npz``), its ``report.json`` and ``servo_goals.npz``, so the stages run
one by one give what ``run`` gives.  Give the retargeting options the trajectory was made with
(``--zmp-weight``, ``--support``, ...): they decide whether the balance repair applies and are
the base of its retargeter.

Exit status: 0 when the trajectory kept passes validation, 1 when it fails, 2 for a usage or
input error.
"""

from __future__ import annotations

import argparse
from pathlib import Path


def register(commands) -> None:
    from motok_robot.pipeline.config import PipelineConfig  # light
    from retarget.cli import add_balance_arguments  # light: no casadi at import

    d = PipelineConfig()
    parser = commands.add_parser(
        "repair", help="validate a robot.npz and try run's balance repair and slow-down on it",
        description="Validate ROBOT.npz as `motok-robot run` does and, when it fails, try the same repairs with the "
                    "same code: retarget MOTION again with the ZMP term when a footing or balance check fails, play "
                    "it slower when a speed check fails. Each is kept only when it trades no passing check for a "
                    "failing one. Writes robot.npz (the trajectory kept), report.json and servo_goals.npz to --out.",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("input", type=Path, help="robot.npz from retargeting")
    parser.add_argument("--motion", type=Path, required=True, metavar="FILE",
                        help="the motion that robot.npz was retargeted from (the input of `motok-robot retarget`)")
    parser.add_argument("--skeleton", default="bandai", help="BVH skeleton of --motion (default bandai)")
    parser.add_argument("--asf", default=None, help="ASF skeleton file of an .amc --motion (default: the only .asf next to it)")
    parser.add_argument("--robot", default=None, help="robot name (default: the 'robot' field of the npz)")
    parser.add_argument("--out", required=True, type=Path, metavar="DIR", help="output folder")
    parser.add_argument("--max-retime", type=float, default=d.max_retime, metavar="S",
                        help=f"slow-down: play at most S times slower (default {d.max_retime:g}; 1 = never)")
    parser.add_argument("--balance-zmp-weight", type=float, default=d.balance_zmp_weight, metavar="W",
                        help=f"balance repair: ZMP weight of the second retargeting (default {d.balance_zmp_weight:g}; 0 = never)")
    parser.add_argument("--balance-acceleration-weight", type=float, default=d.balance_acceleration_weight,
                        metavar="W", help="balance repair: joint-acceleration weight of the second retargeting "
                                          f"(default {d.balance_acceleration_weight:g})")
    add_balance_arguments(parser)
    parser.set_defaults(func=run_repair)


def run_repair(args) -> int:
    import hashlib
    import shutil

    from motok_robot.errors import InputError
    from motok_robot.pipeline.config import PipelineConfig
    from motok_robot.pipeline.repairs import apply_repairs, balance_retargeter, violated_windows
    from motok_robot.pipeline.run import load_robot_stages
    from motok_robot.sim.report import write_report
    from motok_robot.sim.trajectory import load_robot_npz
    from motok_robot.sim.validate import validate_trajectory, write_servo_goals
    from retarget.cli import balance_config
    from retarget.io import read_input, read_robot_npz

    config = PipelineConfig(max_retime=args.max_retime, balance_zmp_weight=args.balance_zmp_weight,
                            balance_acceleration_weight=args.balance_acceleration_weight)
    for flag, value, low in (("--max-retime", config.max_retime, 1.0), ("--balance-zmp-weight", config.balance_zmp_weight, 0.0),
                             ("--balance-acceleration-weight", config.balance_acceleration_weight, 0.0)):
        if not value >= low:  # also rejects NaN
            raise InputError(f"{flag} must be >= {low:g}, got {value}")
    source = Path(args.input)
    first = read_robot_npz(source)  # InputError naming the file and field
    if not all(isinstance(w, dict) for w in first.solver_status):
        raise InputError(f"{source}: field 'solver_status' must be a JSON list of objects (one per solver window)")
    retarget_config = balance_config(args)
    motion = read_input(args.motion, skeleton=args.skeleton, asf=args.asf)
    entry = load_robot_stages(args.robot or first.robot, retarget_config)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    robot_path = out / "robot.npz"
    if robot_path.resolve() != source.resolve():
        shutil.copyfile(source, robot_path)

    def validate_robot_file():
        trajectory = load_robot_npz(robot_path, entry["robot"])
        trajectory.source = "robot.npz"
        digest = hashlib.sha256(robot_path.read_bytes()).hexdigest()  # the playback gate checks it
        return trajectory, validate_trajectory(trajectory, entry["index"], config.validation, out_dir=None,
                                               input_sha256=digest)

    notes: list[str] = []
    trajectory, validation = validate_robot_file()
    before = list(validation.report["failed_checks"])
    repaired = apply_repairs(config, lambda: balance_retargeter(entry, config.balance_zmp_weight,
                                                                config.balance_acceleration_weight),
                             motion, robot_path, float(retarget_config.weights.zmp),
                             float(retarget_config.weights.acceleration), violated_windows(first.solver_status),
                             trajectory, validation, validate_robot_file, notes,
                             stage=lambda name: print(f"{name} ...", flush=True))
    report = repaired.validation.report
    report["outputs"] = {"report": "report.json", "plots": [], "video": None}
    write_servo_goals(repaired.validation, out)
    write_report(report, out / "report.json")
    for line in notes:
        print(line)
    verdict = "PASS" if report["passed"] else "FAIL " + ", ".join(report["failed_checks"])
    print(f"{entry['robot'].name}: before {('FAIL ' + ', '.join(before)) if before else 'PASS'}; kept: {verdict} "
          f"(retime {repaired.retime_factor:g}x, ZMP weight {repaired.zmp_weight:g}); wrote {robot_path}, "
          f"{out / 'report.json'}")
    return 0 if report["passed"] else 1

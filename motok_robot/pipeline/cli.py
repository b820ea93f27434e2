"""``motok-robot run``: a sentence -> motion -> robot trajectory -> validation -> playback.

Light module: the pipeline (torch, MuJoCo, CasADi) is imported inside the handler.

    motok-robot run "a person waves the right hand" --out wave/
    motok-robot run "a person walks forward" --robot op3_like --seconds 6 --seed 1 --sim --out walk/
    motok-robot run "a person bows" --port /dev/ttyUSB0 --out bow/        # hardware: needs a PASS
    motok-robot run --prompts prompts.txt --out batch/                   # batch/summary.csv

Exit status: 0 when validation passed and playback completed; 1 when validation failed, hardware
playback was refused or stopped, the simulated robot fell, or (with ``--prompts``) any prompt did
not pass; 2 for invalid input (one line on stderr, nothing written).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def register(commands, groups) -> None:
    from motok_robot.pipeline import PipelineConfig  # light: no torch, mujoco or casadi at import
    from retarget.cli import add_balance_arguments  # light: no casadi at import
    from retarget.config import CostWeights

    parser = commands.add_parser(
        "run", help="one command: text -> motion -> robot trajectory -> MuJoCo validation -> playback",
        description="Generate a human motion for TEXT, retarget it to the robot, validate it in MuJoCo and play it "
                    "on an emulated servo chain (default), the simulator (--sim) or real servos (--port). Writes "
                    "motion.npz, robot.npz, report.json, plots, video.mp4, the playback log and summary.md to --out.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="Output is written to a hidden folder next to --out and renamed when every stage finished; a failed "
               "run leaves OUT.failed/ with FAILED.txt instead. See docs/pipeline.md.")
    parser.add_argument("text", nargs="?", default=None, help='the prompt, e.g. "a person waves the right hand"')
    parser.add_argument("--robot", default=None, help="robot name or NAME.toml (default op3, the system-identified ROBOTIS OP3; see: robots list)")
    parser.add_argument("--seconds", type=float, default=None,
                        help="clip length in seconds (default: estimated from the text; 6 with constraints)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    mode = parser.add_mutually_exclusive_group()
    mode.add_argument("--sim", action="store_true", help="play on the MuJoCo model instead of the emulated servos")
    mode.add_argument("--port", metavar="DEV", default=None,
                      help="play on real Dynamixel servos on this serial port (needs a passing report)")
    parser.add_argument("--force", action="store_true", help="with --port: play even when validation failed")
    parser.add_argument("--no-render", action="store_true", help="skip the videos (faster)")
    parser.add_argument("--no-plots", action="store_true", help="skip the validation plots (faster)")
    parser.add_argument("--sim-video", action="store_true",
                        help="with --sim: also record the simulated playback to playback_sim.mp4 (slow)")
    parser.add_argument("--realtime", action="store_true",
                        help="run the dry-run / --sim playback at the wall-clock rate (default: simulated time)")
    parser.add_argument("--motion", type=Path, default=None, metavar="FILE",
                        help="start from a motion instead of TEXT: motion.npz, .bvh, .amc (its .asf next to it) or "
                             "DeepMimic .json; skips generation (no trained models needed)")
    parser.add_argument("--skeleton", default="bandai",
                        help="BVH skeleton of --motion: bandai, acrnn or a joint-map JSON (default bandai)")
    parser.add_argument("--prompts", type=Path, default=None, metavar="FILE",
                        help="run every prompt of FILE (one per line, or CSV with the header text,seconds,seed; rows without seconds or "
                             "seed take --seconds / --seed); writes OUT/summary.csv")
    parser.add_argument("--out", required=True, type=Path, metavar="DIR", help="output folder (new or empty)")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing, non-empty --out when done")
    parser.add_argument("--feasible", action="store_true",
                        help="run the feasibility stage after retargeting: robot.npz becomes the trajectory the robot "
                        "executes closed loop (CoM path, feedforward goals, balance controller), judged against the "
                        "retarget (docs/feasibility.md); the balance repair and slow-down below are then not tried")
    parser.add_argument("--feasible-retime", type=float, default=1.0, metavar="F",
                        help="with --feasible: play the motion F times slower, 1-4 (default 1)")
    parser.add_argument("--feasible-own-steps", action="store_true",
                        help="with --feasible: a motion that travels is walked with the robot's own steps along "
                             "its path, played slower where the robot cannot step as fast (docs/feasibility.md)")
    parser.add_argument("--no-own-steps", action="store_true",
                        help="without --feasible: validate a motion that travels as retargeted, with the repairs "
                             "below (default: it is walked with the robot's own steps by the feasibility stage)")
    parser.add_argument("--max-retime", type=float, default=PipelineConfig.max_retime, metavar="S",
                        help="when the motion is too fast for the servos (the torque, joint_velocity or "
                        "joint_acceleration check fails), play it up to S times slower until those checks pass "
                        "(default %(default)g; 1 = never)")
    parser.add_argument("--balance-zmp-weight", type=float, default=PipelineConfig.balance_zmp_weight, metavar="W",
                        help="when the robot loses its footing or balance (the floating, zmp, static_balance, "
                        "center_of_pressure, fall or base_drift check fails) after retargeting without the ZMP term, "
                        "retarget again with this ZMP weight and a foot planted in every frame (--support always) and "
                        "keep that trajectory if it fails fewer checks (default %(default)g; 0 = never)")
    parser.add_argument("--balance-acceleration-weight", type=float,
                        default=PipelineConfig.balance_acceleration_weight, metavar="W",
                        help="joint-acceleration weight of that re-solve: keeps the ZMP term from balancing with "
                        "frame-to-frame zig-zags the servos cannot follow (default %(default)g; plain retargeting: "
                        f"{CostWeights.acceleration:g})")
    add_balance_arguments(parser.add_argument_group("retargeting"))
    models = parser.add_argument_group("models")
    models.add_argument("--planner", choices=("masked", "ar"), default="masked", help="planner (default masked)")
    models.add_argument("--tokenizer", type=Path, default=None, help="tokenizer run (default models/tokenizer)")
    models.add_argument("--planner-run", type=Path, default=None, help="planner run (default models/planner_<kind>)")
    models.add_argument("--cfg", type=float, default=None, help="classifier-free guidance scale (default 2.5)")
    models.add_argument("--device", default="cpu", help="torch device for generation (default cpu)")
    try:
        from motok_robot.control.options import add_control_arguments
    except ModuleNotFoundError:  # pragma: no cover - control stage not installed
        pass
    else:
        add_control_arguments(parser)
    parser.set_defaults(func=run_command)

    from motok_robot.pipeline.repair_cli import register as register_repair  # light

    register_repair(commands)  # run's repairs as a stage of their own


def run_command(args: argparse.Namespace) -> int:
    import os

    os.environ.setdefault("MUJOCO_GL", "egl")  # before MuJoCo is imported (headless video)
    from motok_robot.errors import InputError
    from motok_robot.pipeline import (
        Pipeline, check_out_dir, check_playback, check_robot, check_seconds, check_seed, check_text, read_prompts,
    )
    from motok_robot.robots import DEFAULT_ROBOT

    robot = args.robot or DEFAULT_ROBOT
    playback = "sim" if args.sim else "port" if args.port else "dry-run"
    if args.sim_video and not args.sim:
        raise InputError("--sim-video needs --sim")
    if args.force and not args.port:
        raise InputError("--force only applies to hardware playback (--port DEV)")
    control = has_constraints(args)
    seconds, seed = check_seconds(args.seconds, "--seconds"), check_seed(args.seed, "--seed")
    if args.prompts is not None:
        if args.text is not None:
            raise InputError("give either TEXT or --prompts FILE, not both")
        if control:
            raise InputError("constraint options apply to one prompt; they cannot be combined with --prompts")
        if args.port:
            raise InputError("--prompts cannot play on hardware; run one prompt with --port")
        prompts = read_prompts(args.prompts, seconds, seed)  # --seconds / --seed: for rows that give none
        check_robot(robot)
        check_playback(playback, None)
        check_out_dir(args.out, args.overwrite)
    else:
        if args.text is None and args.motion is None:
            raise InputError('give a TEXT prompt (e.g. motok-robot run "a person walks forward" --out walk/), '
                             "--motion FILE or --prompts FILE")
        if args.motion is not None and control:
            raise InputError("constraint options apply to generation; they cannot be combined with --motion")
        if args.text is not None:
            check_text(args.text)
        check_robot(robot)
        check_playback(playback, args.port)
        check_out_dir(args.out, args.overwrite)
    pipe = Pipeline(pipeline_config(args))
    if args.prompts is not None:
        return _run_batch(pipe, prompts, args, robot, playback)

    seconds, constraints, control_config = constraint_arguments(args, seconds)
    result = pipe.run(args.text, robot=robot, seconds=seconds, seed=seed, constraints=constraints,
                      out_dir=args.out, playback=playback, port=args.port, force=args.force,
                      render=not args.no_render, control=control_config,
                      control_path=getattr(args, "control_path", "both"), overwrite=args.overwrite, progress=None,
                      motion=args.motion, skeleton=args.skeleton)
    print(format_result(result))
    return 0 if result.ok else 1


def has_constraints(args: argparse.Namespace) -> bool:
    """The options lay kinematic constraints on generation (``--trajectory`` and the like)."""
    try:
        from motok_robot.control.options import has_control
    except ModuleNotFoundError:  # pragma: no cover
        return False
    return has_control(args)


def format_result(result) -> str:
    """The short summary printed by ``run``: verdict, failing checks, per-stage times, files."""
    from motok_robot.pipeline import STAGES

    t = result.timings
    stages = " | ".join(f"{k} {t[k]:.2f} s" for k in ("load", "setup", *STAGES) if k in t)
    pb = result.playback
    lines = [result.line(),
             "  failed checks: " + (", ".join(result.failed_checks) if result.failed_checks else "none"),
             f"  playback ({pb.mode}): {pb.status}" + (f" - {pb.error}" if pb.error else "")
             + (f" - {pb.line}" if pb.status in ("refused", "skipped") else "")
             + (" - the simulated robot FELL" if pb.fell else ""),
             f"  times: {stages} | total {t.get('total', 0.0):.2f} s",
             f"  summary: {result.files['summary']}"]
    lines += [f"  note: {n}" for n in result.notes]
    return "\n".join(lines)


def _run_batch(pipe, prompts, args, robot: str, playback: str) -> int:
    import csv

    path = pipe.run_batch(prompts, args.out, robot=robot, playback=playback, render=not args.no_render,
                          overwrite=args.overwrite, progress=None)
    with open(path, newline="", encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    passed = sum(r["passed"] == "True" for r in rows)
    print(f"{passed}/{len(rows)} prompts passed validation; summary: {path}")
    for r in rows:
        if r["error"]:
            print(f"  ERROR {r['folder']}: {r['error']}", file=sys.stderr)
        elif r["passed"] != "True":
            print(f"  FAIL  {r['folder']}: {r['failed_checks'].replace(';', ', ')}")
    return 0 if passed == len(rows) else 1


def pipeline_config(args: argparse.Namespace, plots: bool | None = None, sim_video: bool | None = None):
    """The :class:`~motok_robot.pipeline.PipelineConfig` of parsed ``run`` options (``plots`` and
    ``sim_video`` override ``--no-plots`` / ``--sim-video``; a sweep sets them itself)."""
    from motok_robot.pipeline import PipelineConfig
    from retarget.cli import balance_config

    generation = {"cfg_scale": args.cfg} if args.cfg is not None else {}
    return PipelineConfig(planner=args.planner, tokenizer_run=args.tokenizer, planner_run=args.planner_run,
                          device=args.device, generation=generation,
                          plots=not args.no_plots if plots is None else plots, realtime=args.realtime,
                          sim_video=args.sim_video if sim_video is None else sim_video, max_retime=args.max_retime,
                          balance_zmp_weight=args.balance_zmp_weight,
                          balance_acceleration_weight=args.balance_acceleration_weight, retarget=balance_config(args),
                          feasibility=feasibility_config(args),
                          walk_own_steps=not getattr(args, "no_own_steps", False))


def constraint_arguments(args: argparse.Namespace, seconds: float | None):
    """``(seconds, constraints, control config)`` of the constraint options (``--trajectory`` and
    the like; both None without them): constrained clips default to
    :data:`~motok_robot.pipeline.DEFAULT_CONSTRAINED_SECONDS`."""
    if not has_constraints(args):
        return seconds, None, None
    from motok_robot.control.options import constraints_from_args, control_config_from_args
    from motok_robot.pipeline import DEFAULT_CONSTRAINED_SECONDS

    seconds = seconds or DEFAULT_CONSTRAINED_SECONDS
    return seconds, constraints_from_args(args, round(seconds * 20)), control_config_from_args(args)


def feasibility_config(args: argparse.Namespace):
    """The feasibility stage's settings asked for by ``--feasible`` / ``--feasible-retime`` /
    ``--feasible-own-steps``, as a dict applied over the robot's own settings
    (:func:`motok_robot.feasibility.config.robot_config`); None: off."""
    if not args.feasible:
        for flag, used in (("--feasible-retime", args.feasible_retime != 1.0),
                           ("--feasible-own-steps", getattr(args, "feasible_own_steps", False))):
            if used:
                from motok_robot.errors import InputError

                raise InputError(f"{flag} needs --feasible")
        return None
    settings: dict = {"retime": args.feasible_retime} if args.feasible_retime != 1.0 else {}
    if getattr(args, "feasible_own_steps", False):
        settings["gait"] = {"enabled": True}
    return settings

"""CLI of the control stage (light module: numpy and torch load inside the handlers).

* ``motok-robot generate ... --trajectory/--keyframes/--obstacles/--prefix/--suffix/--edit``:
  the planner stage owns ``generate`` (text -> motion); this module, registered after it, adds
  the constraint options to that command and, when any is given, makes each motion with
  :func:`motok_robot.control.generate.generate_motion`. So the planner package never imports
  the control stage (data flows one way: planner -> control), and there is one ``generate``
  command whose ``--help`` lists every option.
* ``motok-robot eval control --data DIR [--json FILE]``: the GMD / OmniControl protocol table.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from motok_robot.control.options import add_control_arguments, add_mechanism_arguments, has_control
from motok_robot.errors import InputError


def register(commands, groups) -> None:
    gen = commands.choices.get("generate") if hasattr(commands, "choices") else None
    if gen is not None:  # the planner stage's command (absent when that stage is not installed)
        add_control_arguments(gen)
        planner_handler = gen.get_default("func")
        gen.set_defaults(func=lambda args: generate_command(args, planner_handler))

    ev = groups["eval"].add_parser(
        "control",
        help="trajectory / keyframe / obstacle control on test clips (GMD / OmniControl protocol)",
        description="Take root trajectories, sparse keyframes and obstacle scenes from held-out test clips, "
        "generate with their captions under each setting (no control; planner only / decoder only / both; "
        "MoTok refinement vs GMD vs MDM inpainting) with fixed seeds, and print foot skating, trajectory error "
        "(fraction of clips over 50 / 20 cm), location error (keyframes over 50 cm), average error, foot "
        "penetration / floating and obstacle hits. --source tokens decodes each clip's own tokens instead "
        "(no planner): the decoder's part alone.",
    )
    ev.add_argument("--data", required=True, type=Path, help="prepared dataset directory (its test split is used)")
    ev.add_argument("--json", type=Path, default=None, help="write the results here as JSON")
    ev.add_argument("--clips", type=int, default=None, help="test clips for the trajectory and keyframe tasks (default 32)")
    ev.add_argument("--scenes", type=int, default=None, help="obstacle scenes (default 20; 0 = skip)")
    ev.add_argument("--tasks", nargs="+", choices=("trajectory", "keyframes", "obstacles"), default=None,
                    help="tasks to run (default all)")
    ev.add_argument("--source", choices=("planner", "tokens"), default="planner",
                    help="tokens from the planner with the clip's caption (default), or the clip's own tokens")
    ev.add_argument("--planner", choices=("masked", "ar"), default="masked", help="planner (default masked)")
    ev.add_argument("--tokenizer", type=Path, default=None, help="tokenizer run (default models/tokenizer)")
    ev.add_argument("--planner-run", type=Path, default=None, help="planner run (default models/planner_<kind>)")
    ev.add_argument("--guidance", default=None, help="the default mechanism(s) of the dual-path rows (default gmd,motok)")
    add_mechanism_arguments(ev)
    ev.add_argument("--foot-physics", action="store_true", help="physics terms (no foot sliding or sinking) in every controlled row")
    ev.add_argument("--decoder-steps", type=int, default=None, help="decoder DDIM steps (default: the tokenizer's)")
    ev.add_argument("--max-seconds", type=float, default=None, help="crop clips to this length")
    ev.add_argument("--seed", type=int, default=0, help="base seed (clip i uses seed + i)")
    ev.add_argument("--device", default="cpu", help="torch device (default cpu)")
    ev.set_defaults(func=_eval_control)


def generate_command(args: argparse.Namespace, planner_handler) -> int:
    """``motok-robot generate`` with constraints: the planner's handler, each motion made by
    :func:`~motok_robot.control.generate.generate_motion`. Constraint files are read (and
    rejected with a one-line error) before any model loads."""
    if not has_control(args):
        return planner_handler(args)
    from motok_robot.control.options import constraints_from_args, control_config_from_args, frames_from_args
    from motok_robot.motion.skeleton import FPS

    if args.seconds is not None and args.seconds <= 0:
        raise InputError(f"--seconds must be positive (got {args.seconds:g})")
    if args.seconds is not None:
        from motok_robot.limits import check_seconds

        check_seconds(args.seconds, "generate", "--seconds")  # before any array of that length exists
    config = control_config_from_args(args)
    frames = frames_from_args(args, FPS)
    constraints = constraints_from_args(args, frames)
    args.seconds = frames / FPS

    def generate_one(generator, **kwargs):
        from motok_robot.control.generate import generate_motion

        return generate_motion(constraints=constraints, control=config, control_path=args.control_path,
                               generator=generator, **kwargs)

    return planner_handler(args, generate_one=generate_one)


def _eval_control(args: argparse.Namespace) -> int:
    from motok_robot.control.evaluate import ControlEvalConfig, evaluate_control, format_table

    over = {}
    if args.clips is not None:
        over["clips"] = args.clips
    if args.scenes is not None:
        over["obstacle_scenes"] = args.scenes
    if args.tasks:
        over["tasks"] = tuple(args.tasks)
    if args.decoder_steps is not None:
        if args.decoder_steps < 1:
            raise InputError(f"--decoder-steps must be >= 1 (got {args.decoder_steps})")
        over["decoder_steps"] = args.decoder_steps
    if args.max_seconds is not None:
        if args.max_seconds <= 0:
            raise InputError(f"--max-seconds must be positive (got {args.max_seconds:g})")
        over["max_frames"] = max(1, round(args.max_seconds * 20))
    from motok_robot.control.options import control_config_from_args

    over["control"] = control_config_from_args(args)
    if over["control"].mechanisms == ("none",):
        raise InputError("--guidance none: the default mechanism of the controlled rows must be a real one")
    if args.seed < 0:
        raise InputError(f"--seed must be >= 0 (got {args.seed})")
    if not args.data.is_dir():
        raise InputError(f"--data {args.data}: not a directory (a prepared dataset from `motok-robot data prepare`)")
    if args.json is not None and args.json.is_dir():
        raise InputError(f"--json {args.json}: is a directory")
    config = ControlEvalConfig(seed=args.seed, foot_physics=args.foot_physics, **over)
    result = evaluate_control(args.data, source=args.source, planner=args.planner, tokenizer_run=args.tokenizer,
                              planner_run=args.planner_run, device=args.device, config=config)
    print(format_table(result))
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(result, indent=2) + "\n")
        print(f"results written to {args.json}")
    return 0

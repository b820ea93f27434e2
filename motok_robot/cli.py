"""``motok-robot`` command line.

Every stage registers its own subcommands from a light module ``<stage>/cli.py`` that
exposes ``register(commands, groups)``: ``commands`` is the top-level subparsers object,
``groups`` maps the shared command groups (``data``, ``train``, ``eval``, ``robots``,
``servo``) to their subparsers.  A registered parser sets ``func=handler`` where
``handler(args) -> int``.  Handlers import their heavy dependencies (torch, mujoco,
casadi) inside the function, so ``motok-robot --help`` stays fast.

Errors derived from :class:`motok_robot.errors.MotokError` (and ``FileNotFoundError``)
are printed as one line ``motok-robot: error: ...`` with exit status 2; Ctrl-C exits 130.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from motok_robot import __version__
from motok_robot.errors import MotokError

GROUPS = {
    "data": "prepare and look at motion datasets",
    "train": "train the tokenizer, the planners and the evaluator",
    "eval": "measure reconstruction, generation and control quality",
    "robots": "list and inspect the robot models",
    "servo": "scan and calibrate a Dynamixel servo bus",
}

# Modules that add subcommands, in the order they appear in --help. The LEADING ones add only
# top-level commands and come before the groups.
LEADING = ("motok_robot.pipeline.cli",)
REGISTRARS = (
    "motok_robot.pipeline.cli",
    "motok_robot.data.cli",
    "motok_robot.planner.cli",
    "motok_robot.control.cli",
    "motok_robot.tokenizer.cli",
    "motok_robot.robots.cli",
    "retarget.cli",
    "motok_robot.feasibility.cli",
    "motok_robot.sim.cli",
    "motok_robot.servo.cli",
    "motok_robot.export.cli",
    "motok_robot.eval.cli",
    "motok_robot.sweep.cli",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="motok-robot",
        description="Text -> human motion -> humanoid robot trajectory -> MuJoCo validation -> Dynamixel playback.",
    )
    parser.add_argument("--version", action="version", version=f"motok-robot {__version__}")
    parser.add_argument("--limit", action="append", default=[], metavar="NAME=VALUE", dest="size_limits",
                        help="raise a bound on input sizes for this run (frames, seconds, rate, min_rate, joints, "
                             "file_bytes, inflated_bytes; the same as the MOTOK_MAX_* / MOTOK_MIN_RATE variables, "
                             "see motok_robot/limits.py)")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND")
    groups: dict = {}
    for module_name in REGISTRARS:
        if module_name not in LEADING and not groups:  # the groups follow the leading commands in --help
            for name, help_text in GROUPS.items():
                group_parser = commands.add_parser(name, help=help_text, description=help_text)
                groups[name] = group_parser.add_subparsers(dest=f"{name}_command", metavar="SUBCOMMAND")
                group_parser.set_defaults(func=_group_help(group_parser))
        importlib.import_module(module_name).register(commands, groups)
    return parser


def _group_help(group_parser: argparse.ArgumentParser):
    def show(_args: argparse.Namespace) -> int:
        group_parser.print_help()
        return 2

    return show


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        from motok_robot.limits import set_limit

        for assignment in getattr(args, "size_limits", None) or []:
            set_limit(assignment)
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("motok-robot: interrupted", file=sys.stderr)
        return 130
    except (MotokError, FileNotFoundError, PermissionError, IsADirectoryError) as exc:
        print(f"motok-robot: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

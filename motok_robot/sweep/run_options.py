"""A variant's ``run`` options -> the :class:`~motok_robot.pipeline.PipelineConfig` and ``Pipeline.run`` arguments.

The options are parsed by the ``run`` command's own parser (built by the ``register`` function
of the ``run`` command's module), so a sweep knows every ``run`` option, its type and its default
exactly as ``run`` does.  :func:`pipeline_config` and :func:`run_arguments` then map the parsed
options with the functions ``run``'s handler uses (:mod:`motok_robot.pipeline.cli`).
"""

from __future__ import annotations

import argparse
import functools
from pathlib import Path

from motok_robot.errors import InputError

#: ``run`` options a spec may not set, and why
NOT_IN_A_SWEEP = {
    "out": "the sweep's --out holds every cell",
    "overwrite": "the sweep's --out holds every cell (use --resume)",
    "prompts": "list the prompts in the spec's `prompts`",
    "motion": "list the motion files in the spec's `motions`",
    "robot": "list the robots in the spec's `robots`",
    "seed": "list the seeds in the spec's `seeds`",
    "port": "a sweep never plays on hardware",
    "force": "a sweep never plays on hardware",
    "no-render": "a sweep never renders videos",
    "sim-video": "a sweep never renders videos",
    "no-plots": "set the spec's `plots` instead",
    "help": "not a setting",
}
#: metavars of the ``run`` options that name a file (a relative path is taken from the spec's folder)
_FILE_METAVARS = ("FILE", "MOTION", "DIR")


class _OptionError(Exception):
    pass


class _RaisingParser(argparse.ArgumentParser):
    """An argument parser that raises instead of printing usage and exiting."""

    def error(self, message):  # noqa: D401 - argparse's hook
        raise _OptionError(message)

    def exit(self, status=0, message=None):
        raise _OptionError(message or "not a setting")


@functools.lru_cache(maxsize=1)
def run_parser() -> argparse.ArgumentParser:
    """The ``run`` command's parser (raising on errors)."""
    from motok_robot.pipeline.cli import register

    commands = _RaisingParser(prog="motok-robot").add_subparsers()
    register(commands, {})
    return commands.choices["run"]


def variant_argv(options: dict, field: str, spec_path: Path) -> tuple[str, ...]:
    """The command-line arguments of the ``run`` options in table ``field`` of the spec."""
    parser = run_parser()
    actions = parser._option_string_actions  # noqa: SLF001 - argparse has no public lookup
    argv: list[str] = []
    for key, value in options.items():
        name = str(key).replace("_", "-")
        where = f"{spec_path}: field '{field}.{key}'"
        if name in NOT_IN_A_SWEEP:
            raise InputError(f"{where}: not a sweep setting: {NOT_IN_A_SWEEP[name]}")
        flag = f"--{name}"
        action = actions.get(flag)
        if action is None:
            raise InputError(f"{where}: unknown `run` option {flag} (see: motok-robot run --help)")
        if isinstance(value, bool):
            given = [flag] if value else []
        elif isinstance(value, (int, float, str)):
            text = str(value)
            if isinstance(value, str) and (action.type is Path or action.metavar in _FILE_METAVARS):
                p = Path(value).expanduser()
                text = str(p if p.is_absolute() else (spec_path.parent / p).resolve())
            given = [flag, text]
        else:
            raise InputError(f"{where}: give one value (true / false, a number or a string), got {type(value).__name__}")
        try:
            parser.parse_args([*given, "--out", "_"])
        except _OptionError as exc:
            raise InputError(f"{where}: {exc}") from None
        argv += given
    return tuple(argv)


def parse(argv, where: str = "run options") -> argparse.Namespace:
    """``argv`` parsed by the ``run`` parser (with a placeholder ``--out``)."""
    try:
        return run_parser().parse_args([*argv, "--out", "_"])
    except _OptionError as exc:
        raise InputError(f"{where}: {exc}") from None


def pipeline_config(args: argparse.Namespace, plots: bool = False):
    """The :class:`~motok_robot.pipeline.PipelineConfig` of parsed ``run`` options (as ``run`` builds
    it, with the spec's ``plots`` and no simulated-playback video)."""
    from motok_robot.pipeline.cli import pipeline_config as run_pipeline_config

    return run_pipeline_config(args, plots=plots, sim_video=False)


def run_arguments(args: argparse.Namespace) -> dict:
    """The keyword arguments of ``Pipeline.run`` that parsed ``run`` options give (no render, no hardware)."""
    from motok_robot.pipeline.cli import constraint_arguments
    from motok_robot.text.prompts import check_seconds

    seconds, constraints, control = constraint_arguments(args, check_seconds(args.seconds, "--seconds"))
    return dict(seconds=seconds, playback="sim" if args.sim else "none", constraints=constraints, control=control,
                control_path=getattr(args, "control_path", "both"), skeleton=args.skeleton, render=False)


def check_variants(spec) -> None:
    """Every variant's settings make a valid pipeline for its cells, checked before any work."""
    from motok_robot.pipeline import Pipeline
    from motok_robot.pipeline.cli import has_constraints

    for name, variant in spec.variants.items():
        where = f"{spec.path}: field 'variants.{name}'"
        args = parse(variant.argv, where)
        try:
            Pipeline(pipeline_config(args, spec.plots))
            if has_constraints(args) and any(c.variant == name and c.motion is not None for c in spec.cells):
                raise InputError("constraint options apply to generation; they cannot be combined with motion files")
            run_arguments(args)  # checks --seconds, reads the constraint files
        except InputError as exc:
            raise InputError(f"{where}: {exc}") from None

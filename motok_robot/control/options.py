"""Command-line options of controlled generation, shared by ``generate`` and ``run``.

Light module (numpy, no torch): it only declares arguments and turns them into a
:class:`~motok_robot.control.constraints.Constraints` for a clip of known length.
"""

from __future__ import annotations

import argparse

import numpy as np

from motok_robot.control.config import MECHANISMS, ControlConfig


def add_control_arguments(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("kinematic control (file formats: docs/control.md, examples/)")
    group.add_argument("--trajectory", metavar="FILE",
                       help="root trajectory on the ground: .csv (frame,x,y[,z] rows; or x,y[,z] per frame without "
                       "header), .npz (root [T, 2|3]) or .npy [T, 2|3] (NaN = free); sets the length without --seconds")
    group.add_argument("--keyframes", metavar="FILE", help="joint-position keyframes, .json")
    group.add_argument("--obstacles", metavar="FILE", help="ground obstacles (circles, boxes), .json")
    group.add_argument("--prefix", metavar="MOTION", help="motion.npz whose frames start the clip (in-betweening)")
    group.add_argument("--suffix", metavar="MOTION", help="motion.npz whose frames end the clip (in-betweening)")
    group.add_argument("--edit", metavar="MOTION", help="motion.npz to edit: keep --keep joints, re-synthesise the rest")
    group.add_argument("--keep", default="lower_body", help="joints or group kept by --edit (lower_body, upper_body, left_arm, right_arm, legs, or joint names)")
    group.add_argument(
        "--foot-physics",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="feet in contact do not slide or sink (physics-aware decoding); on by default whenever a trajectory, "
        "keyframes, obstacles, prefix/suffix or edit is given (--no-foot-physics turns it off)",
    )
    group.add_argument(
        "--guidance",
        default=None,
        help=f"decoder mechanisms, comma-separated from {', '.join(MECHANISMS)}, applied in this order "
        f"(default {','.join(ControlConfig().mechanisms)})",
    )
    add_mechanism_arguments(group)
    group.add_argument("--control-path", choices=("both", "planner", "decoder"), default="both", help="send local conditions to the planner, the decoder, or both")


def add_mechanism_arguments(group) -> None:
    """Settings of the decoder mechanisms (defaults: :class:`ControlConfig`)."""
    d = ControlConfig()
    group.add_argument("--guidance-scale", type=float, default=None, help=f"GMD dense-guidance scale s (default {d.gmd_scale:g})")
    group.add_argument("--refine-lr", type=float, default=None, help=f"MoTok refinement step size eta (default {d.refine_lr:g})")
    group.add_argument("--refine-iters", type=int, default=None, help=f"MoTok refinement iterations per denoising step (default {d.refine_iters})")
    group.add_argument("--refine-final-iters", type=int, default=None,
                       help=f"MoTok refinement iterations at the last, clean step (default {d.refine_final_iters})")


def has_control(args: argparse.Namespace) -> bool:
    return any(getattr(args, name, None) for name in (*_CONSTRAINT_OPTIONS, "foot_physics"))


#: options that lay kinematic constraints on the clip
_CONSTRAINT_OPTIONS = ("trajectory", "keyframes", "obstacles", "prefix", "suffix", "edit")


def constraints_from_args(args: argparse.Namespace, frames: int):
    """The constraints named on the command line for a clip of ``frames`` frames (or None)."""
    from motok_robot.control import constraints as C

    if not has_control(args):
        return None
    c = C.Constraints(frames)
    if args.trajectory:
        C.add_trajectory(c, args.trajectory)
    if args.keyframes:
        C.add_keyframes(c, args.keyframes)
    if args.obstacles:
        C.add_obstacles(c, args.obstacles)
    if args.prefix:
        C.add_prefix(c, args.prefix)
    if args.suffix:
        C.add_suffix(c, args.suffix)
    if args.edit:
        C.add_edit(c, args.edit, args.keep)
    # physics-aware decoding is the default with any kinematic constraint: without it the body is
    # moved along the path while the decoded legs do not step at the new speed (feet slide)
    c.foot_physics = args.foot_physics if args.foot_physics is not None else True
    return c


def control_config_from_args(args: argparse.Namespace) -> ControlConfig:
    from motok_robot.errors import InputError

    cfg = ControlConfig() if args.guidance is None else ControlConfig(mechanisms=args.guidance)
    for option, attr, low in (("guidance_scale", "gmd_scale", 0.0), ("refine_lr", "refine_lr", 0.0),
                              ("refine_iters", "refine_iters", 0), ("refine_final_iters", "refine_final_iters", 0)):
        value = getattr(args, option, None)
        if value is None:
            continue
        if not (value >= low and np.isfinite(value)):
            raise InputError(f"--{option.replace('_', '-')} must be >= {low:g} (got {value})")
        setattr(cfg, attr, value)
    return cfg


#: clip length when constraints are given without --seconds and no file fixes it
DEFAULT_CONSTRAINED_SECONDS = 6.0
#: the longest clip a constraint file may describe when probing its length (10 minutes at 20 fps)
_PROBE_FRAMES = 12000


def frames_from_args(args: argparse.Namespace, fps: int = 20, default_seconds: float = DEFAULT_CONSTRAINED_SECONDS) -> int:
    """Clip length (frames) for the constraints on the command line.

    ``--seconds`` when given; else the motion to ``--edit``; else the last frame of the
    ``--trajectory``; else ``default_seconds``, long enough for the keyframes and for
    ``--prefix`` + ``--suffix`` with one free second between them.
    """
    from motok_robot.control import constraints as C

    if getattr(args, "seconds", None) is not None:
        return max(1, round(args.seconds * fps))
    if args.edit:
        return len(C._read_motion(args.edit, "edit")[0])
    if args.trajectory:
        probe = C.add_trajectory(C.Constraints(_PROBE_FRAMES), args.trajectory, fps=fps)
        return int(np.flatnonzero(probe.joint_mask[:, 0]).max()) + 1
    frames = round(default_seconds * fps)
    if args.keyframes:
        probe = C.add_keyframes(C.Constraints(_PROBE_FRAMES), args.keyframes, fps=fps)
        frames = max(frames, int(np.flatnonzero(probe.joint_mask.any(axis=1)).max()) + 1)
    given = sum(len(C._read_motion(path, what)[0]) for path, what in ((args.prefix, "prefix"), (args.suffix, "suffix")) if path)
    if given:
        frames = max(frames, given + fps)
    return frames

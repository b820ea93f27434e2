"""Command-line options of controlled generation, shared by ``generate`` and ``run``.

Light module (no torch): it only declares arguments and turns them into a
:class:`~motok_robot.control.constraints.Constraints` for a clip of known length.
"""

from __future__ import annotations

import argparse

from motok_robot.control.config import MECHANISMS, ControlConfig


def add_control_arguments(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("kinematic control (file formats: README, examples/)")
    group.add_argument("--trajectory", metavar="FILE", help="root trajectory on the ground, .csv (frame,x,y[,z]) or .npz")
    group.add_argument("--keyframes", metavar="FILE", help="joint-position keyframes, .json")
    group.add_argument("--obstacles", metavar="FILE", help="ground obstacles (circles, boxes), .json")
    group.add_argument("--prefix", metavar="MOTION", help="motion.npz whose frames start the clip (in-betweening)")
    group.add_argument("--suffix", metavar="MOTION", help="motion.npz whose frames end the clip (in-betweening)")
    group.add_argument("--edit", metavar="MOTION", help="motion.npz to edit: keep --keep joints, re-synthesise the rest")
    group.add_argument("--keep", default="lower_body", help="joints or group kept by --edit (lower_body, upper_body, left_arm, right_arm, legs, or joint names)")
    group.add_argument("--foot-physics", action="store_true", help="feet in contact do not slide or sink (physics-aware decoding)")
    group.add_argument(
        "--guidance",
        default="motok",
        help=f"decoder mechanisms, comma-separated from {', '.join(MECHANISMS)} (default motok)",
    )
    group.add_argument("--guidance-scale", type=float, default=None, help="GMD dense-guidance scale s")
    group.add_argument("--control-path", choices=("both", "planner", "decoder"), default="both", help="send local conditions to the planner, the decoder, or both")


def has_control(args: argparse.Namespace) -> bool:
    return any(getattr(args, name, None) for name in ("trajectory", "keyframes", "obstacles", "prefix", "suffix", "edit", "foot_physics"))


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
    c.foot_physics = bool(args.foot_physics)
    return c


def control_config_from_args(args: argparse.Namespace) -> ControlConfig:
    cfg = ControlConfig(mechanisms=args.guidance)
    if args.guidance_scale is not None:
        cfg.gmd_scale = args.guidance_scale
    return cfg

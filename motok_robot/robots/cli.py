"""``motok-robot robots list``, ``motok-robot robots show NAME [--render FILE.png]`` and
``motok-robot robots add MJCF --out NAME.toml`` (draft a description for a new robot).

Light module: mujoco is imported inside the handlers only.
"""

from __future__ import annotations

import argparse
import math


def register(commands, groups) -> None:
    robots = groups["robots"]
    p = robots.add_parser("list", help="list the robot models", description="List the robots in models/mjcf (or $MOTOK_ROBOT_MODELS/mjcf).")
    p.set_defaults(func=cmd_list)

    p = robots.add_parser(
        "show",
        help="print a robot's joints, limits and servo map",
        description="Print a robot's joints (range, velocity and torque limits, nominal angle), keypoints, soles and servo map.",
    )
    p.add_argument("robot", metavar="NAME", help="robot name (see `motok-robot robots list`) or path to NAME.toml")
    p.add_argument("--render", metavar="FILE.png", help="also draw the nominal standing pose into this PNG")
    p.add_argument("--size", default="640x800", metavar="WxH", help="render size in pixels (default 640x800)")
    p.set_defaults(func=cmd_show)

    p = robots.add_parser(
        "add",
        help="draft a robot description (NAME.toml) from an MJCF",
        description="Draft NAME.toml for a humanoid from its MJCF: feet, legs, arms and head from the kinematic tree, "
                    "keypoint and sole sites (added to a copy NAME.xml beside the TOML; the input is never written), "
                    "limb scales, a nominal pose, limits. Renders a check image (NAME.png) and lists what it could "
                    "not infer, each with the line to edit (docs/robots.md, 'Adding a robot').",
    )
    p.add_argument("mjcf", metavar="MJCF", help="the robot's MJCF (.xml); it needs a free joint and hinges")
    p.add_argument("--out", required=True, metavar="NAME.toml", help="the description to write (NAME is the robot name)")
    p.add_argument("--name", default=None, help="robot name (default: the --out file's stem)")
    p.add_argument("--render", default="", metavar="FILE.png", help="check image (default NAME.png beside the TOML)")
    p.add_argument("--no-render", action="store_true", help="do not draw the check image")
    p.add_argument("--knee-bend", type=float, default=0.4, metavar="RAD", help="knee bend of the nominal pose (default 0.4; 0: zero pose)")
    p.add_argument("--force", action="store_true", help="overwrite an earlier draft (NAME.toml, NAME.xml, NAME.png)")
    p.set_defaults(func=cmd_add)


def cmd_list(args: argparse.Namespace) -> int:
    from motok_robot.robots import list_robots, load, models_dir

    names = list_robots()
    if not names:
        print(f"no robots in {models_dir()}")
        return 1
    print(f"{'robot':<14} {'joints':>6} {'mass kg':>8} {'height m':>9} {'servos':>6}  summary")
    for name in names:
        robot = load(name)
        print(
            f"{name:<14} {robot.nj:>6} {robot.total_mass():>8.2f} {robot.height():>9.3f} {len(robot.servos):>6}  "
            f"{robot.description.summary}"
        )
    return 0


def format_robot(robot) -> str:
    """The text that ``robots show`` prints (joints table, keypoints, soles, bus and servos)."""
    d = robot.description
    lines = [
        f"{robot.name}: {d.summary}",
        f"  model {robot.mjcf_path}",
        f"  description {d.path}",
        f"  mass {robot.total_mass():.3f} kg (documented {d.mass_range[0]}-{d.mass_range[1]}), "
        f"height {robot.height():.3f} m (documented {d.height_range[0]}-{d.height_range[1]}), "
        f"nominal base height {robot.nominal_qpos()[2]:.4f} m, timestep {robot.model.opt.timestep} s",
        "",
    ]
    nominal = robot.nominal_joints()
    header = f"  {'joint':<14} {'min rad':>8} {'max rad':>8} {'min deg':>8} {'max deg':>8} {'vel rad/s':>9} {'torque Nm':>9} {'nominal':>8}"
    has_servos = bool(robot.servos)
    if has_servos:
        header += f"  {'id':>3} {'model':<11} {'sign':>4} {'zero':>5} {'min tk':>6} {'max tk':>6}"
    lines.append(header)
    for i, name in enumerate(robot.joint_names):
        lo, hi = robot.joint_range[i]
        row = (
            f"  {name:<14} {lo:>8.3f} {hi:>8.3f} {math.degrees(lo):>8.1f} {math.degrees(hi):>8.1f} "
            f"{robot.velocity_limit[i]:>9.2f} {robot.torque_limit[i]:>9.2f} {nominal[i]:>8.3f}"
        )
        servo = d.servo_for(name)
        if servo is not None:
            row += (
                f"  {servo.id:>3} {servo.model:<11} {servo.sign:>+4d} {servo.zero_offset_ticks:>5} "
                f"{servo.min_ticks:>6} {servo.max_ticks:>6}"
            )
        lines.append(row)
    if robot.bus is not None:
        b = robot.bus
        lines += ["", f"  bus: Dynamixel protocol {b.protocol}, {b.baud} baud, {b.control_hz:g} Hz control cycle"]
    lines += ["", "  keypoints (human joint -> site, weight):"]
    lines += [f"    {k.human_joint:<15} {k.site:<12} {k.weight:g}" for k in robot.keypoints]
    lines += ["", "  soles:"]
    for side, s in robot.soles.items():
        lines.append(
            f"    {side:<6} body {s.body}, centre {s.site}, corners {', '.join(s.corner_sites)}, "
            f"half size {s.half_size[0]:g} x {s.half_size[1]:g} m"
        )
    lines += ["", "  limb scale (robot / canonical human): " + ", ".join(f"{k} {v:g}" for k, v in robot.limb_scale.items())]
    return "\n".join(lines)


def cmd_show(args: argparse.Namespace) -> int:
    import os

    if args.render:  # the GL backend is chosen when mujoco is first imported
        os.environ.setdefault("MUJOCO_GL", "egl")
    from motok_robot.errors import InputError
    from motok_robot.robots import load

    robot = load(args.robot)
    print(format_robot(robot))
    if args.render:
        try:
            width, height = (int(v) for v in args.size.lower().split("x"))
        except ValueError:
            raise InputError(f"--size must be WIDTHxHEIGHT in pixels, got {args.size!r}") from None
        from motok_robot.robots.render import render_pose, save_png

        image = render_pose(robot, robot.nominal_qpos(), width=width, height=height)
        save_png(image, args.render)
        print(f"\nwrote {args.render} ({width}x{height}, nominal pose, camera 'track')")
    return 0


def cmd_add(args: argparse.Namespace) -> int:
    import os

    if not args.no_render:
        os.environ.setdefault("MUJOCO_GL", "egl")
    from motok_robot.robots.draft import draft

    result = draft(args.mjcf, args.out, name=args.name, knee_bend=args.knee_bend,
                   render=None if args.no_render else args.render, force=args.force)
    print(f"wrote {result.toml_path}" + (f" and {result.mjcf_path} (a copy of {args.mjcf})" if result.copied else ""))
    if result.image_path:
        print(f"wrote {result.image_path} (nominal pose, front and side, keypoint and sole sites labelled)")
    print("\ninferred:")
    for line in result.summary:
        print(f"  {line}")
    if result.load_error:
        print(f"\nthe draft does not load yet: {result.load_error}")
    if result.unsure:
        print(f"\ncould not infer ({len(result.unsure)}): edit these lines")
        for u in result.unsure:
            print(f"  {u.format()}")
    else:
        print("\ncould not infer: nothing")
    print(f"\nthen: motok-robot robots show {result.toml_path} --render pose.png")
    return 0 if result.load_error is None else 1

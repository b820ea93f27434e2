"""``motok-robot retarget``: human motion (motion.npz or mocap file) -> robot.npz.

Light module: casadi / mujoco are imported inside the handler.
"""

from __future__ import annotations

import argparse
import sys


def register(commands, groups) -> None:
    from retarget.config import RetargetConfig

    d = RetargetConfig()
    p = commands.add_parser(
        "retarget",
        help="retarget a human motion onto a robot (contact-aware trajectory optimisation)",
        description=(
            "Retarget INPUT (motion.npz from generation, or a BVH / ASF+AMC / DeepMimic mocap file) onto a "
            "robot with windowed CasADi/IPOPT trajectory optimisation: keypoint tracking, planted feet during "
            "contact phases, joint and velocity limits. Writes robot.npz (docs/CONTRACTS.md)."
        ),
    )
    p.add_argument("input", metavar="INPUT", help="motion.npz, .bvh, .amc (with its .asf) or DeepMimic .json/.txt")
    p.add_argument("--robot", required=True, help="robot name (motok-robot robots list) or path to its MJCF/description")
    p.add_argument("--out", required=True, help="output robot.npz")
    p.add_argument("--window", type=int, default=d.window, help=f"frames optimised together (default {d.window})")
    p.add_argument("--overlap", type=int, default=d.overlap, help=f"look-ahead frames shared by consecutive windows (default {d.overlap})")
    p.add_argument("--mode", choices=("trajectory", "per-frame"), default=d.mode, help="windowed trajectory optimisation or the per-frame IK baseline")
    p.add_argument("--allow-partial", action="store_true", help="write the output even if some window did not converge")
    p.add_argument("--no-scale", action="store_true", help="use the joints as robot targets unscaled (motion already robot-sized)")
    p.add_argument("--skeleton", default="bandai", help="BVH joint map: bandai, acrnn or a joint-map JSON file (default bandai)")
    p.add_argument("--asf", default=None, help="ASF skeleton file for an .amc input (default: the only .asf next to it)")
    p.add_argument("--swing-height", type=float, default=d.swing.height, metavar="M",
                   help=f"mid-swing clearance of the lowest sole corner in metres (default {d.swing.height}; 0 = no swing-foot constraints)")
    p.add_argument("--foot-gap", type=float, default=d.min_foot_gap, metavar="LEGS",
                   help=f"smallest gap between the inner sole edges across the heading, robot leg lengths (default {d.min_foot_gap}; negative = off)")
    p.add_argument("--no-cache", action="store_true",
                   help="do not use or write the compiled-problem cache ($MOTOK_ROBOT_CACHE, default ~/.cache/motok-robot)")
    add_balance_arguments(p)
    p.add_argument("--plot", default=None, metavar="FILE.png", help="also draw the result (targets vs robot, sole heights, errors)")
    p.set_defaults(func=run)


def add_balance_arguments(parser) -> None:
    """The retargeting options ``motok-robot run`` shares: balance terms, contact support, self-collision."""
    from retarget.config import RetargetConfig
    from retarget.contacts import SUPPORT_MODES

    d = RetargetConfig()
    parser.add_argument("--com-weight", type=float, default=d.weights.com, metavar="W",
                        help=f"soft CoM-over-support weight (default {d.weights.com:g} = off)")
    parser.add_argument("--zmp-weight", type=float, default=d.weights.zmp, metavar="W",
                        help=f"soft cart-table ZMP-over-support weight (default {d.weights.zmp:g} = off; 1000 lets a slow "
                             "walk pass in physics on op3_like, see docs/retarget.md)")
    parser.add_argument("--support", choices=SUPPORT_MODES, default=d.contacts.support,
                        help="frames where no human foot is planted: 'always' plants the lower robot foot (no flight "
                             "phase), 'near' only where a foot is near the floor, 'off' leaves both feet up "
                             f"(default {d.contacts.support})")
    parser.add_argument("--double-support", type=int, default=d.contacts.min_double_support, metavar="FRAMES",
                        help="at each step keep the old foot planted until this many frames after the new one touches "
                             f"down (default {d.contacts.min_double_support} = as in the motion)")
    parser.add_argument("--no-self-collision", action="store_true",
                        help="do not keep the robot's bodies apart (faster; the validator's self_collision check may then fail)")


def balance_config(args: argparse.Namespace, config=None):
    """``config`` (default: :class:`RetargetConfig`) with the options of :func:`add_balance_arguments`."""
    from dataclasses import replace

    from motok_robot.errors import InputError
    from retarget.config import RetargetConfig

    config = config or RetargetConfig()
    for name in ("com_weight", "zmp_weight"):
        value = getattr(args, name)
        if not value >= 0:  # also rejects NaN
            raise InputError(f"--{name.replace('_', '-')} must be >= 0, got {value}")
    if args.double_support < 0:
        raise InputError(f"--double-support must be >= 0 frames, got {args.double_support}")
    return replace(config, weights=replace(config.weights, com=float(args.com_weight), zmp=float(args.zmp_weight)),
                   contacts=replace(config.contacts, support=args.support, min_double_support=int(args.double_support)),
                   collision=replace(config.collision, enabled=not args.no_self_collision))


def _cache_words(statuses: list[str]) -> str:
    if not statuses or all(s == "off" for s in statuses):
        return "cache off"
    hit = sum(s == "hit" for s in statuses)
    if hit == len(statuses):
        return "compiled, from the cache"
    return f"{hit} of {len(statuses)} from the cache, the rest built; compiling them in the background"


def run(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from motok_robot.errors import InputError, MotokError
    from retarget.config import RetargetConfig
    from retarget.io import read_input, write_robot_npz
    from retarget.metrics import measure
    from retarget.robot_model import load_robot
    from retarget.solve import Retargeter

    config = replace(
        RetargetConfig(), window=args.window, overlap=args.overlap, mode=args.mode,
        allow_partial=args.allow_partial, scale=not args.no_scale,
    )
    if not args.swing_height >= 0:  # also rejects NaN
        raise InputError(f"--swing-height must be >= 0, got {args.swing_height}")
    gap = args.foot_gap
    if gap is not None and gap != gap:  # NaN
        raise InputError("--foot-gap must be a number")
    config = replace(balance_config(args, config), min_foot_gap=None if gap is None or gap < 0 else gap,
                     swing=replace(config.swing, height=args.swing_height))
    motion = read_input(args.input, skeleton=args.skeleton, asf=args.asf)
    robot = load_robot(args.robot)
    import time

    t0 = time.perf_counter()
    retargeter = Retargeter(robot, config, cache=False if args.no_cache else None)
    retargeter.prepare(len(motion.joints))
    build = time.perf_counter() - t0
    hits = [p.cache_status for p in retargeter._problems.values()]
    result = retargeter.run(motion.joints, motion.fps, source=motion.name)
    m = measure(retargeter.kin, result.x, result.contacts, result.keypoint_error, result.fps, config.ground_height)
    failed = result.failed_windows()
    print(
        f"{robot.name}: {m.frames} frames, {len(result.windows)} windows ({config.mode}), problem ready in {build:.1f} s "
        f"({_cache_words(hits)}), "
        f"solved in {result.solve_seconds:.2f} s ({m.frames / max(result.solve_seconds, 1e-9):.0f} frames/s)\n"
        f"  keypoint error mean {m.keypoint_error_mean * 100:.2f} cm; {m.contact_phases} contact phases, sole drift max "
        f"{m.sole_drift_max * 1000:.2f} mm, lowest sole corner {m.sole_min_height * 1000:.2f} mm\n"
        f"  joint range excess {m.joint_range_excess:.2e} rad, max velocity {m.velocity_ratio_max * 100:.0f}% of limit, "
        f"mean joint acceleration {m.joint_acceleration_mean:.1f} rad/s^2"
    )
    if result.collision_pairs:
        print(f"  self-collision: {len(result.collision_pairs)} geom pairs came close and were kept apart in "
              f"{result.collision_rounds} re-solve(s): {', '.join(result.collision_pairs)}")
    for w in failed:
        print(f"  window frames {w.start}-{w.stop - 1}: {w.status}; violated: {w.violated or 'none'} ({w.violation:.3g})", file=sys.stderr)
    if failed and not config.allow_partial:
        raise MotokError(
            f"{len(failed)} of {len(result.windows)} windows did not converge (first: frames {failed[0].start}-{failed[0].stop - 1}, "
            f"{failed[0].violated or failed[0].status}); nothing written, use --allow-partial to keep the result"
        )
    path = write_robot_npz(args.out, result)
    print(f"wrote {path}")
    if args.plot:
        from retarget.plots import plot_result

        print(f"wrote {plot_result(args.plot, retargeter.kin, result, title=f'{robot.name}: {motion.name}')}")
    return 0

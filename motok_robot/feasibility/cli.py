"""``motok-robot feasible``: turn a retargeted robot.npz into the trajectory the robot executes.

Light module: MuJoCo and the stage are imported inside the handler.

    motok-robot feasible robot.npz --out feasible/            # feasible/robot.npz, servo_goals.npz, feasibility.json
    motok-robot validate feasible/robot.npz --out feasible/   # judged against the reference it was asked to do
    motok-robot feasible robot.npz --out f/ --retime 1.5 --refine --samples 16

Exit status: 0 when the executed robot stayed up, 1 when it fell, 2 for a usage or input error.
"""

from __future__ import annotations

import argparse


def register(commands, groups) -> None:
    parser = commands.add_parser(
        "feasible", help="make a robot trajectory executable in physics (balance controller, CoM path, refinement)",
        description="Feasibility stage: from a retargeted robot.npz, compute servo goals (ZMP-consistent CoM path, "
                    "inverse-dynamics feedforward, optional predictive-sampling refinement over MuJoCo rollouts) and "
                    "the balance controller's plan, roll the robot out from rest with the controller in the loop, "
                    "and write the executed robot.npz (with the reference it was asked to do), servo_goals.npz "
                    "and feasibility.json. Validate the result with `motok-robot validate OUT/robot.npz`.",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("input", help="robot.npz from retargeting")
    parser.add_argument("--out", required=True, metavar="DIR", help="output folder")
    parser.add_argument("--robot", help="installed robot name (default: the 'robot' field of the npz)")
    parser.add_argument("--retime", type=float, default=None, metavar="F",
                        help="play the motion F times slower, 1-4 (default 1: human timing)")
    parser.add_argument("--no-zmp-shift", action="store_true", help="keep the retargeted CoM path")
    parser.add_argument("--zmp-axes", choices=("lateral", "both"), default=None,
                        help="directions the CoM may move (default lateral)")
    parser.add_argument("--own-steps", action="store_true",
                        help="walk a motion that travels with the robot's own steps along its path (footsteps, CoM "
                             "and swing planned for the robot; played slower where it cannot step as fast)")
    parser.add_argument("--max-torque-share", type=float, default=None, metavar="S",
                        help="a motion on the spot is played slower while it needs more than S of a servo's "
                             "torque limit, 0.5-1 (default: the robot's, else 0.9; 1: never slowed for torque)")
    parser.add_argument("--damping-speed-share", type=float, default=None, metavar="S",
                        help="with --own-steps: the walk's joints move no faster than where their damping takes S of "
                             "the torque limit, 0-1 (default: the robot's [feasibility.gait] setting, else 0: off; "
                             "op3 sets 0.75)")
    parser.add_argument("--no-foothold-tracking", action="store_true",
                        help="with --own-steps: do not correct each step from the measured last one (leg odometry)")
    parser.add_argument("--spot-steps", action="store_true",
                        help="a motion on the spot that lifts a foot: plan its own steps with the weight moved onto "
                             "the stance foot first (experimental, off by default; docs/feasibility.md)")
    parser.add_argument("--no-balance", action="store_true", help="no balance controller (open-loop goals)")
    parser.add_argument("--refine", action="store_true", help="refine the goals by predictive sampling (slower)")
    parser.add_argument("--samples", type=int, default=None, help="refinement: rollouts per planning step (default 16)")
    parser.add_argument("--horizon", type=float, default=None, metavar="S", help="refinement: horizon in s (default 0.4)")
    parser.set_defaults(func=run_feasible)


def run_feasible(args) -> int:
    import sys
    from pathlib import Path

    from motok_robot.errors import InputError
    from motok_robot.feasibility.config import robot_config
    from motok_robot.sim.cli import _robot_for

    # only what was asked for: the rest comes from the robot's description, else the defaults
    settings: dict = {"gait": {"enabled": True}} if args.own_steps else {}
    for key, value in (("retime", args.retime), ("zmp_axes", args.zmp_axes), ("max_torque_share", args.max_torque_share)):
        if value is not None:
            settings[key] = value
    if args.no_zmp_shift:
        settings["zmp_shift"] = False
    if args.refine:
        settings["refine"] = True
    if args.spot_steps:
        settings["spot_steps"] = {"enabled": True}
    if args.no_balance:
        settings["balance"] = {"enabled": False}
    if args.no_foothold_tracking:
        settings.setdefault("balance", {})["foothold_gain"] = 0.0
    if args.damping_speed_share is not None:
        settings.setdefault("gait", {})["damping_speed_share"] = args.damping_speed_share
    if args.samples is not None:
        settings.setdefault("refine_config", {})["samples"] = args.samples
    if args.horizon is not None:
        settings.setdefault("refine_config", {})["horizon_s"] = args.horizon
    path = Path(args.input)
    if not path.is_file():
        raise InputError(f"{path}: file not found")
    from retarget.io import read_robot_npz

    from motok_robot.feasibility.clearance import clearance_note
    from motok_robot.feasibility.stage import make_feasible, write_feasible

    index = _robot_for(path, args.robot, {})
    trajectory = read_robot_npz(path)
    if len(trajectory.joint_names) != index.nj or list(trajectory.joint_names) != list(index.joint_names):
        raise InputError(f"{path}: field 'joint_names' does not match robot '{index.name}'")
    config = robot_config(index, settings)

    def progress(done, total):
        print(f"\rrefine {done:5.1f} / {total:.1f} s", end="" if sys.stdout.isatty() else "\n", flush=True)

    result = make_feasible(trajectory, index, config, progress=progress if config.refine else None)
    if config.refine and sys.stdout.isatty():
        print()
    out = write_feasible(result, args.out, index.name)
    rec = result.record
    shift = rec.get("zmp_shift")
    walk = rec.get("gait")
    slow = rec.get("torque_retime")
    print(f"{index.name}: {result.trajectory.qpos.shape[0]} frames, time warp {rec['time_warp']:.2f}x"
          + (f", CoM moved up to {shift['com_shift_m_max'] * 100:.1f} cm (cart-table ZMP outside "
             f"{shift['zmp_outside_before']:.0%} -> {shift['zmp_outside_after']:.0%} of support frames)" if shift else "")
          + (f", walked with {walk['steps']} steps of its own (lead-in {walk['lead_in_s']:.1f} s, lead-out "
             f"{walk['lead_out_s']:.1f} s)" if walk else "")
          + clearance_note((walk or {}).get("arm_clearance"))
          + (f", played {slow['factor']:.2f}x slower for the servos' torque (needed {slow['torque_share_before']:.2f} "
             f"of a limit, now {slow['torque_share_after']:.2f})" if slow and slow["factor"] > 1 else ""))
    spot = rec.get("spot_steps")
    if spot:
        print(f"  spot steps: {spot['steps']} swing(s), paused {spot.get('pause_s', 0.0):.2f} s to move the weight"
              if spot["steps"] else f"  spot steps: none ({spot['reason']})")
    if config.gait.enabled and not walk:
        print("  --own-steps: the motion does not travel (or lifts a foot higher than a step): its legs are kept")
    print(f"  executed from rest{' with the balance controller' if result.plan is not None else ' open loop'}: "
          f"{'FELL at %.2f s' % rec['executed']['fall_time_s'] if result.fell else 'stayed up'}, root "
          f"{rec['executed']['base_drift_max_m']:.3f} m from the reference at most{' before that' if result.fell else ''}; "
          f"{rec['timing_s']['total']:.1f} s")
    print(f"wrote {out} (+ servo_goals.npz, feasibility.json); validate it: motok-robot validate {out} --out {Path(args.out)}")
    return 1 if result.fell else 0

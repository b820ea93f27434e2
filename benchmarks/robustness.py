"""Robustness of validation's verdict to physics the goals were not made for, closed loop vs open loop.

For trajectories that pass validation nominally on ``--robot`` (closed loop, validation's
default), each is validated again with the PHYSICS model changed and nothing else (the
reference, the servo goals and the balance plan are what validation computes for the nominal
robot, as a real rig faces them):

* servo stiffness x0.8 and x1.2 (position-actuator kp and its bias term) and every link mass and
  inertia x0.9 and x1.1 (``balance_push.varied_model``);
* a torso push: a horizontal force on the base body for 0.1 s from mid-clip, forward, backward
  and sideways (left) of the reference's heading at that time, sized as a fraction of the
  robot's weight (``--push-fractions``);

each closed loop (``BalanceConfig()``) and open loop (``BalanceConfig(enabled=False)``).
Clips: the clean motions of ``motok_robot.sim.synthetic`` (standing, squat, an arm swing at half
the servo velocity limit, a two-step walk) and, when ``--datasets`` exists, the real clips of
``benchmarks/feasibility_mocap.py`` whose retarget is cached under
``--work/retarget/ROBOT/CLIP/robot.npz`` (``--retarget [GLOB ...]`` retargets the missing ones, or
those matching a glob, as that script does and into its cache: seconds to minutes each).

With ``--stage`` the clips are instead the feasibility stage's executed walks and motions of
``feasibility_mocap.py --variants D --work WORK`` (``WORK/runs/ROBOT/CLIP/D/feasible``), played
with the stage's own servo goals: closed loop with its balance plan (foothold tracking included),
open loop without it.

    python benchmarks/robustness.py [--robot op3_like] [--push-fractions 0.2 0.3 0.4] [--walk-period S] [--max-clips N]
        [--no-mocap] [--clips GLOB ...] [--retarget [GLOB ...]] [--stage] [--work WORK] [--out JSON]

Prints a line per clip and the table perturbation x mode (clips, passed, fell, pass rate);
writes benchmarks/results/robustness_ROBOT.json with the rows and the machine description.
"""

from __future__ import annotations

import argparse
import fnmatch
import math
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from balance_push import DIRECTIONS, VARIANTS, varied_model  # noqa: E402
from common import REPO_ROOT, RESULTS_DIR, machine_description, print_table, write_json  # noqa: E402

FPS = 20.0
PUSH_S = 0.1
PUSH_DIRECTIONS = ("forward", "backward", "left")  # the robots are left-right symmetric
MODES = ("closed", "open")


# -- perturbations ----------------------------------------------------------------------------------
def perturbations(push_fractions) -> list[dict]:
    """The physics variants: ``{"name", "stiffness", "mass", "push": None | {"direction", "fraction"}}``."""
    out = [{"name": name, "stiffness": k, "mass": m, "push": None} for name, (k, m) in VARIANTS.items()]
    for fraction in push_fractions:
        for direction in PUSH_DIRECTIONS:
            out.append({"name": f"push {direction} {fraction:g} x weight", "stiffness": 1.0, "mass": 1.0,
                        "push": {"direction": direction, "fraction": float(fraction)}})
    return out


def heading(qpos_row: np.ndarray) -> float:
    """Yaw (rad) of a free base with orientation ``qpos_row[3:7]`` (wxyz)."""
    w, x, y, z = qpos_row[3:7]
    return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def torso_push(index, qpos: np.ndarray, fps: float, direction: str, fraction: float, duration_s: float = PUSH_S):
    """A :class:`~motok_robot.sim.rollout.Push` on the base body from mid-clip: ``fraction`` x the
    robot's weight, horizontal, ``direction`` (forward, backward, left, right) relative to the
    reference's heading at the push."""
    from motok_robot.sim.rollout import Push

    start = 0.5 * (qpos.shape[0] - 1) / fps
    yaw = heading(qpos[int(round(start * fps))])
    ahead, left = DIRECTIONS[direction]
    magnitude = fraction * index.total_mass * float(-index.model.opt.gravity[2])
    fx = magnitude * (ahead * math.cos(yaw) - left * math.sin(yaw))
    fy = magnitude * (ahead * math.sin(yaw) + left * math.cos(yaw))
    return Push(body=int(index.root_body), force=(fx, fy, 0.0), start_s=start, duration_s=duration_s)


def validate_perturbed(trajectory, index, perturbation: dict, mode: str, models: dict, goals: dict | None = None):
    """``validate_trajectory`` of ``trajectory`` with ``perturbation``'s physics, ``mode``
    closed or open loop; ``models`` caches the varied servo models by (stiffness, mass)
    (``varied_model`` builds them with ``servo_model``'s defaults, which are ``ValidationConfig``'s).
    ``goals``: the feasibility stage's servo goals of ``trajectory`` (``load_servo_goals``), played
    with the stage's balance plan (closed) or without it (open) instead of validation's own."""
    from motok_robot.feasibility import BalanceConfig
    from motok_robot.sim.validate import validate_trajectory

    key = (perturbation["stiffness"], perturbation["mass"])
    model = None
    if key != (1.0, 1.0):
        if key not in models:
            models[key] = varied_model(index, *key)
        model = models[key]
    push = perturbation["push"]
    pushes = [] if push is None else [torso_push(index, trajectory.qpos, trajectory.fps, push["direction"],
                                                 push["fraction"])]
    if goals is not None:
        played = goals if mode == "closed" else {**goals, "plan": None}
        return validate_trajectory(trajectory, index, plots=False, servo_goals=played, physics_model=model, pushes=pushes)
    balance = BalanceConfig() if mode == "closed" else BalanceConfig(enabled=False)
    return validate_trajectory(trajectory, index, plots=False, balance=balance, physics_model=model, pushes=pushes)


# -- clips ------------------------------------------------------------------------------------------
def synthetic_clips(index, walk_period_s: float = 3.2) -> list[dict]:
    """The clean motions of ``motok_robot.sim.synthetic`` (qpos at FPS); the walk takes
    ``walk_period_s`` per step."""
    from motok_robot.sim import synthetic as S

    clips = [("stand_4s", lambda: S.standing(index, 4.0, FPS)),
             ("squat_3s", lambda: S.squat(index, 3.0, FPS)),
             ("arm_swing_3s", lambda: S.too_fast(index, 3.0, FPS, speed_ratio=0.5)[0]),
             ("walk_2_steps", lambda: S.walk(index, steps=2, step_period_s=walk_period_s, fps=FPS))]
    out = []
    for name, make in clips:
        try:
            out.append({"clip": name, "group": "synthetic", "qpos": make()})
        except ValueError as exc:  # the motion is beyond this robot's legs
            print(f"skip {name}: {exc}", file=sys.stderr)
    return out


def _matches(name: str, globs: list[str] | None) -> bool:
    return not globs or any(fnmatch.fnmatch(name, g) for g in globs)


def mocap_clips(robot_name: str, datasets: Path, work: Path, retarget: list[str] | None,
                globs: list[str] | None = None) -> tuple[list[dict], list[str]]:
    """feasibility_mocap's clips (those matching one of ``globs``) with a cached retarget;
    ``retarget`` (None: none; [] all; else globs) names the missing ones to retarget now.
    Returns (clips with ``npz``, names left out for want of a retarget)."""
    from feasibility_mocap import find_clips, retarget_cached

    clips, _ = find_clips(datasets, work)
    out, missing = [], []
    for clip in clips:
        if not _matches(clip["clip"], globs):
            continue
        npz = work / "retarget" / robot_name / clip["clip"] / "robot.npz"
        if not npz.is_file():
            if retarget is None or not _matches(clip["clip"], retarget):
                missing.append(clip["clip"])
                continue
            try:
                npz, _ = retarget_cached(clip, robot_name, work)
            except Exception as exc:  # recorded, the run goes on
                print(f"skip {clip['clip']}: retarget failed: {type(exc).__name__}: {exc}", file=sys.stderr)
                missing.append(clip["clip"])
                continue
        out.append({"clip": clip["clip"], "group": clip["group"], "npz": npz})
    return out, missing


def stage_clips(robot_name: str, work: Path, datasets: Path, globs: list[str] | None = None) -> list[dict]:
    """The feasibility stage's outputs of ``feasibility_mocap.py --variants D`` under
    ``work/runs/ROBOT/CLIP/D/feasible`` (``robot.npz``; the ``servo_goals.npz`` made from it is read
    with it), for clips matching one of ``globs``; the group (locomotion, other) from the datasets when found."""
    groups = {}
    if datasets.is_dir():
        from feasibility_mocap import find_clips

        groups = {c["clip"]: c["group"] for c in find_clips(datasets, work)[0]}
    out = []
    for npz in sorted((work / "runs" / robot_name).glob("*/D/feasible/robot.npz")):
        name = npz.parent.parent.parent.name
        if _matches(name, globs):
            out.append({"clip": name, "group": groups.get(name, "stage"), "npz": npz, "stage": True})
    return out


# -- tables -----------------------------------------------------------------------------------------
def summary_rows(rows: list[dict], names: list[str], group: str | None = None) -> list[dict]:
    """Per perturbation x mode: clips, passed, fell, pass rate (rows of ``group`` or all)."""
    out = []
    for name in names:
        for mode in MODES:
            sel = [r for r in rows if r["perturbation"] == name and r["mode"] == mode and group in (None, r["group"])]
            if not sel:
                continue
            passed = sum(r["passed"] for r in sel)
            out.append({"perturbation": name, "mode": mode, "clips": len(sel), "passed": passed,
                        "fell": sum(r["fell"] for r in sel), "pass_rate": passed / len(sel)})
    return out


def payload(meta: dict, machine: dict, rows: list[dict], names: list[str], clips: int, wall_s: float) -> dict:
    """The JSON: settings, machine, summaries (all clips and per group) and the rows."""
    groups = sorted({r["group"] for r in rows})
    return {**meta, "machine": machine, "wall_s": wall_s, "clips": clips, "summary": summary_rows(rows, names),
            "summary_per_group": {g: summary_rows(rows, names, g) for g in groups}, "rows": rows}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--robot", default="op3_like")
    ap.add_argument("--push-fractions", type=float, nargs="+", default=[0.2, 0.3, 0.4], metavar="F",
                    help="push sizes as fractions of the robot's weight (0.1 s each)")
    ap.add_argument("--max-clips", type=int, default=None, metavar="N", help="the first N clips that pass nominally")
    ap.add_argument("--walk-period", type=float, default=3.2, metavar="S",
                    help="step period of the synthetic walk (the OP3 needs 6.4 s to pass the torque check)")
    ap.add_argument("--no-mocap", action="store_true", help="synthetic clips only")
    ap.add_argument("--clips", nargs="+", default=None, metavar="GLOB",
                    help="keep mocap clips whose name matches one glob")
    ap.add_argument("--retarget", nargs="*", default=None, metavar="GLOB",
                    help="retarget the mocap clips without a cached retarget (those matching one GLOB when given)")
    ap.add_argument("--datasets", type=Path, default=REPO_ROOT.parent / "shared" / "datasets")
    ap.add_argument("--work", type=Path, default=Path("/tmp/feasibility_mocap"),
                    help="feasibility_mocap's work folder (extracted clips, cached retargets)")
    ap.add_argument("--stage", action="store_true",
                    help="the feasibility stage's executed walks of --work (feasibility_mocap.py --variants D) "
                         "with their own servo goals and balance plan, instead of the retargeted clips")
    ap.add_argument("--out", type=Path, default=None, help="JSON (default benchmarks/results/robustness_ROBOT.json)")
    args = ap.parse_args(argv)
    out = args.out or RESULTS_DIR / f"robustness_{args.robot}.json"

    from motok_robot.robots import load
    from motok_robot.robots.index import index_robot
    from motok_robot.sim.trajectory import RobotTrajectory, load_robot_npz

    robot = load(args.robot)
    index = index_robot(robot)
    started = time.perf_counter()
    clips = stage_clips(args.robot, args.work, args.datasets, args.clips) if args.stage else \
        synthetic_clips(index, args.walk_period)
    missing: list[str] = []
    if args.stage:
        if not clips:
            print(f"no feasibility stage outputs under {args.work / 'runs' / args.robot} (run feasibility_mocap.py "
                  f"--variants D --work {args.work} first)", flush=True)
    elif not args.no_mocap:
        if args.datasets.is_dir():
            real, missing = mocap_clips(args.robot, args.datasets, args.work, args.retarget, args.clips)
            clips += real
            if missing:
                print(f"{len(missing)} mocap clips without a cached retarget on {args.robot} left out "
                      f"(--retarget makes them)", flush=True)
        else:
            print(f"no mocap: datasets folder {args.datasets} not found", flush=True)
    variants = perturbations(args.push_fractions)
    names = [v["name"] for v in variants]
    weight = index.total_mass * float(-index.model.opt.gravity[2])
    meta = {"robot": args.robot, "weight_n": weight, "push_s": PUSH_S, "push_start": "mid-clip",
            "push_fractions": args.push_fractions, "walk_step_period_s": args.walk_period, "push_body": index.model.body(index.root_body).name,
            "perturbations": variants,
            "modes": ({"closed": "the stage's servo goals and balance plan", "open": "the stage's servo goals, no controller"}
                      if args.stage else {"closed": "BalanceConfig()", "open": "BalanceConfig(enabled=False)"}),
            "clips_from": "feasibility stage outputs (variant D)" if args.stage else "retargeted",
            "nominal_screen": [], "mocap_without_retarget": missing}
    machine = machine_description()
    models: dict = {}
    rows: list[dict] = []
    kept = 0
    for clip in clips:
        if args.max_clips is not None and kept >= args.max_clips:
            break
        t0 = time.perf_counter()
        goals = None
        if "npz" in clip:
            trajectory = load_robot_npz(clip["npz"], robot)
            if clip.get("stage"):
                from motok_robot.sim.validate import stage_goals_beside

                goals = stage_goals_beside(clip["npz"])
                if goals is None:
                    print(f"{clip['clip']}: no servo_goals.npz made from {clip['npz']} beside it, left out", flush=True)
                    continue
        else:
            trajectory = RobotTrajectory(clip["qpos"], FPS, index.joint_names, index.name, source=clip["clip"])
        nominal = validate_perturbed(trajectory, index, variants[0], "closed", models, goals)
        screen = {"clip": clip["clip"], "group": clip["group"], "duration_s": trajectory.duration_s,
                  "passed": nominal.passed, "failed_checks": nominal.report["failed_checks"]}
        meta["nominal_screen"].append(screen)
        if not nominal.passed:
            print(f"{clip['clip']}: fails nominally ({', '.join(screen['failed_checks'])}), left out", flush=True)
            continue
        kept += 1
        verdicts = []
        for variant in variants:
            for mode in MODES:
                result = nominal if (variant is variants[0] and mode == "closed") else \
                    validate_perturbed(trajectory, index, variant, mode, models, goals)
                m = result.report["metrics"]
                rows.append({"clip": clip["clip"], "group": clip["group"], "perturbation": variant["name"],
                             "mode": mode, "passed": result.passed, "fell": bool(m.get("fell")),
                             "fall_time_s": m.get("fall_time_s"), "failed_checks": result.report["failed_checks"]})
                verdicts.append("P" if result.passed else "F" if m.get("fell") else "x")
        print(f"[{kept}] {clip['clip']} ({clip['group']}, {trajectory.duration_s:.1f} s): closed "
              f"{''.join(verdicts[0::2])} open {''.join(verdicts[1::2])} ({time.perf_counter() - t0:.0f} s; "
              f"{time.perf_counter() - started:.0f} s so far)", flush=True)
        write_json(out, payload(meta, machine, rows, names, kept, time.perf_counter() - started))
    print(f"\nP pass, F fell, x fails another check; columns in the order: {', '.join(names)}\n")
    print_table(summary_rows(rows, names), ["perturbation", "mode", "clips", "passed", "fell", "pass_rate"],
                title=f"validation under changed physics ({args.robot}, {kept} clips that pass nominally)")
    machine["load_average_end"] = [round(x, 2) for x in os.getloadavg()]
    write_json(out, payload(meta, machine, rows, names, kept, time.perf_counter() - started))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

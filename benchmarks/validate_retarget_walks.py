"""Physics validation of retargeted walking mocap: before/after table per clip and robot.

Retargets the first ``--seconds`` of each clip (resampled to 20 fps by the mocap reader) with
three configurations and validates each result with ``motok-robot validate`` (physics on,
no video):

* ``before``: no swing-foot constraints and no foot gap (the solver before they existed);
* ``after``: the defaults;
* ``zmp300`` (any ``zmpW``): the defaults plus the soft ZMP term at weight W (op3_like only by default).

Usage::

    python benchmarks/validate_retarget_walks.py [--robots op3_like humanoid25] [--variants before after zmp300]
        [--bandai DIR] [--cmu DIR] [--seconds 6] [--out benchmarks/results/retarget_validation.json]

Clips: Bandai ``dataset-1_walk_{normal,happy,old,tired}_001.bvh`` (``--bandai``, default
``../scratch/raw/bandai``) and CMU ``02_01.amc`` with ``02.asf`` (``--cmu``, default
``../scratch/raw/cmu-asf-amc``, searched recursively). Missing clips are skipped with a message.
Prints a Markdown table and writes JSON (machine description included).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

REPO = Path(__file__).resolve().parents[1]
BANDAI = ("walk_normal_001", "walk_happy_001", "walk_old_001", "walk_tired_001")


def variant_config(name: str):
    from retarget.config import RetargetConfig

    d = RetargetConfig()
    if name == "before":
        return replace(d, swing=replace(d.swing, height=0.0), min_foot_gap=None)
    if name == "after":
        return d
    if name.startswith("zmp") and name[3:].isdigit():  # zmp300, zmp1000: the soft ZMP term at that weight
        return replace(d, weights=replace(d.weights, zmp=float(name[3:])))
    raise SystemExit(f"unknown variant {name!r} (before, after, zmpWEIGHT such as zmp300)")


def find_clips(bandai: Path, cmu: Path) -> list[tuple[str, Path, Path | None]]:
    out = []
    for name in BANDAI:
        hits = sorted(bandai.rglob(f"dataset-1_{name}.bvh")) if bandai.exists() else []
        if hits:
            out.append((name, hits[0], None))
        else:
            print(f"skip {name}: not found under {bandai}", file=sys.stderr)
    amc = sorted(cmu.rglob("02_01.amc")) if cmu.exists() else []
    if amc and (amc[0].parent / "02.asf").exists():
        out.append(("cmu_02_01", amc[0], amc[0].parent / "02.asf"))
    else:
        print(f"skip cmu_02_01: not found under {cmu}", file=sys.stderr)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--robots", nargs="+", default=["op3_like", "humanoid25"])
    ap.add_argument("--variants", nargs="+", default=["before", "after", "zmp300"])
    ap.add_argument("--zmp-robots", nargs="+", default=["op3_like"], help="robots that run the zmpW variants")
    ap.add_argument("--bandai", type=Path, default=REPO.parent / "scratch" / "raw" / "bandai")
    ap.add_argument("--cmu", type=Path, default=REPO.parent / "scratch" / "raw" / "cmu-asf-amc")
    ap.add_argument("--seconds", type=float, default=6.0)
    ap.add_argument("--work", type=Path, default=Path("/tmp/validate_retarget_walks"), help="robot.npz and reports go here")
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "retarget_validation.json")
    args = ap.parse_args(argv)

    import numpy as np

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_retarget import machine
    from motok_robot.robots import load
    from motok_robot.sim.validate import validate_file
    from retarget.io import read_input, write_robot_npz
    from retarget.robot_model import RetargetRobot
    from retarget.solve import Retargeter

    clips = find_clips(args.bandai, args.cmu)
    if not clips:
        print("no clips found; nothing to do", file=sys.stderr)
        return 0
    rows = []
    for robot_name in args.robots:
        robot = load(robot_name)
        for variant in args.variants:
            if variant.startswith("zmp") and robot_name not in args.zmp_robots:
                continue
            rt = Retargeter(RetargetRobot.from_robot(robot), variant_config(variant))
            for clip, path, asf in clips:
                motion = read_input(path, asf=asf)
                T = min(len(motion.joints), int(round(args.seconds * motion.fps)))
                rt.prepare(T)
                c0 = time.process_time()
                res = rt.run(motion.joints[:T], motion.fps, progress=False, source=str(path))
                cpu = time.process_time() - c0
                work = args.work / f"{robot_name}_{variant}_{clip}"
                npz = write_robot_npz(work / "robot.npz", res)
                report = validate_file(npz, robot, out_dir=work, render=False).report
                m = report["metrics"]
                row = {
                    "robot": robot_name, "clip": clip, "variant": variant, "frames": T,
                    "keypoint_error_cm": float(np.mean(res.keypoint_error)) * 100, "solved": res.success,
                    "fps_cpu": T / max(cpu, 1e-9), "passed": report["passed"], "failed_checks": report["failed_checks"],
                    **{k: m[k] for k in ("foot_skate_ratio", "foot_skate_distance_m", "self_collision_frames",
                                         "max_torque_ratio", "zmp_outside_ratio", "fell", "fall_time_s")},
                }
                rows.append(row)
                print(f"{robot_name} {clip} {variant}: {'PASS' if row['passed'] else 'FAIL ' + ', '.join(row['failed_checks'])}", flush=True)
    print("\n| robot | clip | variant | kp err cm | CPU frames/s | skate ratio | skate dist m | self-coll frames | torque ratio | ZMP outside | fall | failed checks |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        fall = f"{r['fall_time_s']:.2f} s" if r["fell"] else "no"
        print(f"| {r['robot']} | {r['clip']} | {r['variant']} | {r['keypoint_error_cm']:.2f} | {r['fps_cpu']:.0f} | {r['foot_skate_ratio']:.2f} | "
              f"{r['foot_skate_distance_m']:.2f} | {r['self_collision_frames']} | {r['max_torque_ratio']:.2f} | {r['zmp_outside_ratio']:.2f} | "
              f"{fall} | {', '.join(r['failed_checks']) or 'PASS'} |")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"machine": machine(), "seconds": args.seconds, "rows": rows}, indent=1, default=str))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

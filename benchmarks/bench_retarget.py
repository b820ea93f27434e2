"""Retargeting benchmark on real walking mocap (Bandai Namco), both robots, trajectory vs per-frame.

For each clip and robot: mean keypoint error, sole drift during contact, lowest sole corner,
joint-range and velocity-limit checks measured on the output, mean joint acceleration of the
windowed trajectory optimisation and of the per-frame IK baseline, and frames per second
(problem construction excluded; wall clock and process CPU time). Speed is also reported on
"10 s clips": clips of at least 200 frames cut to exactly 200 frames (10 s at 20 fps).

Usage::

    python benchmarks/bench_retarget.py [--data DIR] [--max-clips 12] [--robots op3_like humanoid25]
                                        [--out benchmarks/results/retarget.json]

DIR holds the Bandai BVH files (searched recursively for ``dataset-1_walk_*.bvh`` and
``dataset-2_walk_*.bvh``); default: ``../scratch/raw/bandai`` or, failing that, the archive
``../shared/datasets/bandai-namco-bvh.tar.xz`` (read without extracting). Skips with a message
when neither exists. Runs single-threaded (OMP_NUM_THREADS=1): one solver per core.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import sys
import tarfile
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
PATTERN = re.compile(r"dataset-[12]_walk_[a-z-]+_\d+\.bvh$")


def find_clips(data: Path | None, max_clips: int) -> list[tuple[str, str | None, Path]]:
    """``[(name, text or None, path)]`` of walking BVH clips, spread over styles."""
    candidates = [data] if data else [REPO.parent / "scratch" / "raw" / "bandai", REPO.parent / "shared" / "datasets" / "bandai-namco-bvh.tar.xz"]
    for c in candidates:
        if c is None or not c.exists():
            continue
        if c.is_dir():
            files = sorted(p for p in c.rglob("*.bvh") if PATTERN.search(p.name))
            chosen = _spread(files, max_clips, key=lambda p: p.name)
            return [(p.name, None, p) for p in chosen]
        with tarfile.open(c) as tar:
            members = sorted((m for m in tar.getmembers() if PATTERN.search(m.name)), key=lambda m: m.name)
            chosen = _spread(members, max_clips, key=lambda m: m.name)
            names = {m.name for m in chosen}
            out = []
            for m in tar:  # one sequential pass through the archive
                if m.name in names:
                    out.append((Path(m.name).name, tar.extractfile(m).read().decode("utf-8", "replace"), Path(m.name)))
            return sorted(out, key=lambda x: x[0])
    return []


def find_long_clips(data: Path | None, count: int, seconds: float = 10.0) -> list[Path]:
    """Up to ``count`` walking BVH files (extracted folder only) lasting at least ``seconds``, from the header."""
    folder = data if data and data.is_dir() else REPO.parent / "scratch" / "raw" / "bandai"
    if not folder.is_dir():
        return []
    out = []
    for p in sorted(folder.rglob("*.bvh")):
        if not PATTERN.search(p.name):
            continue
        with open(p, errors="replace") as f:
            head = f.read(65536)  # HIERARCHY and the MOTION header
        frames = re.search(r"Frames:\s*(\d+)", head)
        ftime = re.search(r"Frame Time:\s*([0-9.eE+-]+)", head)
        if frames and ftime and int(frames.group(1)) * float(ftime.group(1)) >= seconds:
            out.append(p)
    return _spread(out, count, key=lambda q: q.name)


def _spread(items, n, key):
    """Up to ``n`` items: half from dataset-1, half from dataset-2, evenly spaced in name order."""
    out = []
    for ds in ("dataset-1", "dataset-2"):
        group = [i for i in items if key(i).startswith(ds)]
        k = min(len(group), (n + 1) // 2 if ds == "dataset-1" else n - len(out))
        if k:
            out += [group[int(round(x))] for x in np.linspace(0, len(group) - 1, k)]
    return out


def machine() -> dict:
    cpu = platform.processor()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    import casadi

    return {
        "cpu": cpu,
        "cores_visible": os.cpu_count(),
        "load_average_at_start": os.getloadavg(),
        "python": platform.python_version(),
        "casadi": casadi.__version__,
        "platform": platform.platform(),
        "threads": "OMP_NUM_THREADS=" + os.environ.get("OMP_NUM_THREADS", ""),
    }


def run_clip(retargeter, joints, fps):
    from retarget.metrics import measure

    c0 = time.process_time()
    res = retargeter.run(joints, fps, progress=False)
    cpu = time.process_time() - c0
    m = measure(retargeter.kin, res.x, res.contacts, res.keypoint_error, res.fps)
    return res, m, cpu


def _speed_worker(robot_name, clips, barrier, queue):
    """One process: build the problem, wait for the others, then time its share of the clips."""
    from retarget.config import RetargetConfig
    from retarget.robot_model import load_robot
    from retarget.solve import Retargeter

    rt = Retargeter(load_robot(robot_name), RetargetConfig())
    rt.prepare(200)
    barrier.wait()
    t0, c0 = time.perf_counter(), time.process_time()
    frames = 0
    for joints, fps in clips:
        rt.run(joints, fps, progress=False)
        frames += len(joints)
    queue.put((frames, time.perf_counter() - t0, time.process_time() - c0))


def parallel_speed(robot_name, clips, workers: int) -> dict:
    """Aggregate frames/s of ``workers`` processes (one per core) sharing the clips; construction excluded."""
    import multiprocessing as mp

    ctx = mp.get_context("spawn")
    barrier, queue = ctx.Barrier(workers), ctx.Queue()
    shares = [clips[i::workers] for i in range(workers)]
    procs = [ctx.Process(target=_speed_worker, args=(robot_name, sh, barrier, queue)) for sh in shares]
    for p in procs:
        p.start()
    results = [queue.get() for _ in procs]
    for p in procs:
        p.join()
    frames = sum(r[0] for r in results)
    return {"workers": workers, "frames": frames, "fps_wall": frames / max(r[1] for r in results),
            "fps_cpu_per_worker": [r[0] / r[2] for r in results]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=None)
    ap.add_argument("--max-clips", type=int, default=12)
    ap.add_argument("--robots", nargs="+", default=["op3_like", "humanoid25"])
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "retarget.json")
    ap.add_argument("--no-baseline", action="store_true", help="skip the per-frame IK baseline")
    ap.add_argument("--speed-clips", type=int, default=6, help="10 s clips for the speed measurement (default 6)")
    ap.add_argument("--workers", type=int, default=2, help="processes for the aggregate 10 s-clip throughput (default 2 = 2 cores)")
    args = ap.parse_args(argv)

    clips = find_clips(args.data, args.max_clips)
    if not clips:
        print("bench_retarget: no Bandai walking BVH clips found (../scratch/raw/bandai or ../shared/datasets); skipped")
        return 0

    from dataclasses import replace

    from motok_robot.data.bvh import load_clip
    from retarget.config import RetargetConfig
    from retarget.robot_model import load_robot
    from retarget.solve import Retargeter

    motions = []
    for name, text, path in clips:
        clip = load_clip(path, skeleton="bandai", text=text) if text is not None else load_clip(path, skeleton="bandai")
        motions.append((name, np.asarray(clip.joints, dtype=np.float64), float(clip.fps)))
    print(f"{len(motions)} walking clips, {sum(len(j) for _, j, _ in motions)} frames at 20 fps")

    report = {"machine": machine(), "config": {}, "clips": [], "speed_10s": {}, "summary": {}}
    rows = []
    for robot_name in args.robots:
        robot = load_robot(robot_name)
        cfg = RetargetConfig()
        report["config"] = {"window": cfg.window, "overlap": cfg.overlap, "solver": cfg.solver.__dict__ | {"extra": list(cfg.solver.extra)}}
        t0 = time.perf_counter()
        traj = Retargeter(robot, cfg)
        traj.prepare(cfg.window)
        per_frame = Retargeter(robot, replace(cfg, mode="per-frame"))
        per_frame.prepare(1)
        build = time.perf_counter() - t0
        print(f"\n{robot_name}: problems built in {build:.1f} s (window {cfg.window}, overlap {cfg.overlap})")
        for name, joints, fps in motions:
            traj.prepare(min(cfg.window, len(joints)))
            res, m, cpu = run_clip(traj, joints, fps)
            entry = {
                "robot": robot_name, "clip": name, "frames": len(joints),
                "trajectory": m.as_dict() | {"seconds": res.solve_seconds, "cpu_seconds": cpu,
                                             "fps_wall": len(joints) / res.solve_seconds, "fps_cpu": len(joints) / cpu,
                                             "windows": len(res.windows), "failed_windows": [w.__dict__ for w in res.failed_windows()]},
            }
            if not args.no_baseline:
                res_b, mb, cpu_b = run_clip(per_frame, joints, fps)
                entry["per_frame"] = mb.as_dict() | {"seconds": res_b.solve_seconds, "cpu_seconds": cpu_b,
                                                     "fps_wall": len(joints) / res_b.solve_seconds,
                                                     "failed_frames": len(res_b.failed_windows())}
            if name == motions[0][0] and not args.no_baseline:
                from retarget.plots import plot_result

                png = args.out.parent / f"retarget_{robot_name}.png"
                plot_result(png, traj.kin, res, baseline=res_b, title=f"{robot_name}: {name}")
                print(f"  wrote {png}")
            report["clips"].append(entry)
            rows.append(entry)
            pf = entry.get("per_frame")
            print(
                f"  {name:40s} {len(joints):4d} fr  kp {m.keypoint_error_mean * 100:5.2f} cm  drift {m.sole_drift_max * 1000:6.3f} mm  "
                f"minz {m.sole_min_height * 1000:7.3f} mm  range+ {m.joint_range_excess:.1e}  vel {m.velocity_ratio_max:4.2f}  "
                f"acc {m.joint_acceleration_mean:6.1f}" + (f" (per-frame {pf['joint_acceleration_mean']:6.1f}, kp {pf['keypoint_error_mean'] * 100:5.2f})" if pf else "")
                + f"  {len(joints) / res.solve_seconds:5.0f} fps wall {len(joints) / cpu:5.0f} cpu"
                + (f"  FAILED {len(res.failed_windows())} windows" if not res.success else "")
            )
        # speed on 10 s clips: clips with >= 200 frames, cut to 200
        long = [(n, j[:200], f) for n, j, f in motions if len(j) >= 200]
        have = {n for n, _, _ in long}
        for p in find_long_clips(args.data, args.speed_clips):
            if len(long) >= args.speed_clips:
                break
            if p.name not in have:
                j = np.asarray(load_clip(p, skeleton="bandai").joints, dtype=np.float64)
                if len(j) >= 200:
                    long.append((p.name, j[:200], 20.0))
        if long:
            walls, cpus = [], []
            for n, j, f in long:
                res, _, cpu = run_clip(traj, j, f)
                walls.append(res.solve_seconds)
                cpus.append(cpu)
            frames = 200 * len(long)
            report["speed_10s"][robot_name] = {
                "clips": [n for n, _, _ in long], "frames": frames,
                "fps_wall": frames / sum(walls), "fps_cpu": frames / sum(cpus),
                "load_average_after": os.getloadavg(),
            }
            print(f"  10 s clips ({len(long)}): {frames / sum(walls):.0f} frames/s wall, {frames / sum(cpus):.0f} frames/s CPU (1 process)")
            if args.workers > 1:
                par = parallel_speed(robot_name, [(j, f) for _, j, f in long] * 2, args.workers)
                report["speed_10s"][robot_name]["parallel"] = par
                print(f"  10 s clips, {args.workers} processes: {par['fps_wall']:.0f} frames/s wall (aggregate)")

    for robot_name in args.robots:
        rs = [r for r in rows if r["robot"] == robot_name]
        if not rs:
            continue
        t = [r["trajectory"] for r in rs]
        s = {
            "clips": len(rs),
            "keypoint_error_mean_cm": float(np.mean([x["keypoint_error_mean"] for x in t]) * 100),
            "keypoint_error_max_clip_cm": float(np.max([x["keypoint_error_mean"] for x in t]) * 100),
            "sole_drift_max_mm": float(np.max([x["sole_drift_max"] for x in t]) * 1000),
            "sole_min_height_mm": float(np.min([x["sole_min_height"] for x in t]) * 1000),
            "joint_range_excess_max_rad": float(np.max([x["joint_range_excess"] for x in t])),
            "velocity_ratio_max": float(np.max([x["velocity_ratio_max"] for x in t])),
            "joint_acceleration_mean": float(np.mean([x["joint_acceleration_mean"] for x in t])),
            "fps_wall_all_clips": float(sum(r["frames"] for r in rs) / sum(x["seconds"] for x in t)),
            "fps_cpu_all_clips": float(sum(r["frames"] for r in rs) / sum(x["cpu_seconds"] for x in t)),
            "failed_windows": int(sum(len(x["failed_windows"]) for x in t)),
        }
        if all("per_frame" in r for r in rs):
            p = [r["per_frame"] for r in rs]
            s["per_frame_joint_acceleration_mean"] = float(np.mean([x["joint_acceleration_mean"] for x in p]))
            s["per_frame_keypoint_error_mean_cm"] = float(np.mean([x["keypoint_error_mean"] for x in p]) * 100)
            s["per_frame_sole_drift_max_mm"] = float(np.max([x["sole_drift_max"] for x in p]) * 1000)
            s["smoother_than_per_frame_on_clips"] = int(sum(r["trajectory"]["joint_acceleration_mean"] < r["per_frame"]["joint_acceleration_mean"] for r in rs))
        report["summary"][robot_name] = s

    print("\nsummary")
    header = f"{'robot':12s} {'clips':>5s} {'kp cm':>6s} {'worst clip':>10s} {'drift mm':>8s} {'min z mm':>8s} {'range+':>8s} {'vel/lim':>7s} {'acc':>6s} {'acc pf':>6s} {'fps wall':>8s} {'fps cpu':>7s} {'10s wall':>8s} {'10s cpu':>7s} {'10s par':>7s}"
    print(header)
    for robot_name, s in report["summary"].items():
        sp = report["speed_10s"].get(robot_name, {})
        print(
            f"{robot_name:12s} {s['clips']:5d} {s['keypoint_error_mean_cm']:6.2f} {s['keypoint_error_max_clip_cm']:10.2f} {s['sole_drift_max_mm']:8.4f} "
            f"{s['sole_min_height_mm']:8.4f} {s['joint_range_excess_max_rad']:8.1e} {s['velocity_ratio_max']:7.3f} {s['joint_acceleration_mean']:6.1f} "
            f"{s.get('per_frame_joint_acceleration_mean', float('nan')):6.1f} {s['fps_wall_all_clips']:8.0f} {s['fps_cpu_all_clips']:7.0f} "
            f"{sp.get('fps_wall', float('nan')):8.0f} {sp.get('fps_cpu', float('nan')):7.0f} "
            f"{sp.get('parallel', {}).get('fps_wall', float('nan')):7.0f}"
        )
    report["machine"]["load_average_at_end"] = os.getloadavg()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(report, indent=1, default=float))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(REPO))
    sys.exit(main())

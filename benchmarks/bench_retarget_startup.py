"""Start-up of a fresh retargeting process: cold (empty problem cache) vs warm (compiled problems cached).

For each clip, three fresh processes retarget it onto the robot, as ``motok-robot retarget CLIP
--robot ROBOT --out X.npz`` does (default settings):

* ``no cache``: ``--no-cache`` (the problem is built in memory and solved by CasADi's virtual machine);
* ``cold``: an empty cache folder; the problem is built in memory, and its C code is written and
  compiled in the background after the clip is solved;
* ``warm``: the same folder once the background compile has finished (the compiled library is loaded).

Reported per process (seconds, wall clock from just before the process is spawned): ``ready`` (imports,
clip read, problems built or loaded), ``first window`` (the first window solved, presolve included),
``total`` (clip solved), process CPU time, and the background compile time after the cold run.

Usage::

    python benchmarks/bench_retarget_startup.py [--clips PATH.bvh ...] [--robot op3_like]
                                                [--out benchmarks/results/retarget_startup.json]

Default clip: ``dataset-1_walk_normal_001.bvh`` found under /tmp (extract
../shared/datasets/bandai-namco-bvh.tar.xz there) or ``--data DIR``. Skips with a message when absent.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import REPO_ROOT, machine_summary, print_table, write_json  # noqa: E402

CHILD = r"""
import json, os, resource, sys, time
t_spawned = float(sys.argv[1])
from retarget.config import RetargetConfig
from retarget.io import read_input
from retarget.robot_model import load_robot
from retarget.solve import Retargeter
motion = read_input(sys.argv[2])
robot = load_robot(sys.argv[3])
rt = Retargeter(robot, RetargetConfig(), cache=None if sys.argv[4] == "cache" else False)
rt.prepare(len(motion.joints))
t_ready = time.time()
res = rt.run(motion.joints, motion.fps, progress=False)
t_done = time.time()
u = resource.getrusage(resource.RUSAGE_SELF)
print("RESULT " + json.dumps({
    "ready": t_ready - t_spawned, "first_window": t_ready - t_spawned + res.first_window_seconds,
    "total": t_done - t_spawned, "cpu": u.ru_utime + u.ru_stime, "frames": int(len(res.x)),
    "success": bool(res.success), "keypoint_error_cm": float(res.keypoint_error.mean() * 100),
    "cache": sorted(p.cache_status for p in rt._problems.values()),
}))
"""


def run_child(clip: Path, robot: str, cache: str, folder: Path | None) -> dict:
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONPATH=str(REPO_ROOT))
    if folder is not None:
        env["MOTOK_ROBOT_CACHE"] = str(folder)
    t = time.time()
    out = subprocess.run([sys.executable, "-c", CHILD, repr(t), str(clip), robot, cache], env=env,
                         capture_output=True, text=True, check=True)
    line = [ln for ln in out.stdout.splitlines() if ln.startswith("RESULT ")][-1]
    return json.loads(line[len("RESULT "):])


def wait_compiled(folder: Path, timeout: float = 1800.0) -> float:
    t = time.time()
    while time.time() - t < timeout:
        if not list(folder.glob("*.lock")) and list(folder.glob("*.json")):
            return time.time() - t
        time.sleep(0.5)
    raise TimeoutError(f"background compile did not finish in {timeout} s")


def find_default_clip(data: Path | None) -> Path | None:
    roots = [data] if data else [Path("/tmp")]
    for root in roots:
        for p in sorted(root.glob("**/dataset-1_walk_normal_001.bvh")):
            return p
    return None


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--clips", nargs="*", type=Path, default=None)
    ap.add_argument("--data", type=Path, default=None)
    ap.add_argument("--robot", default="op3_like")
    ap.add_argument("--out", type=Path, default=REPO_ROOT / "benchmarks" / "results" / "retarget_startup.json")
    args = ap.parse_args()
    clips = args.clips or [c for c in [find_default_clip(args.data)] if c]
    if not clips:
        print("no clip found (extract ../shared/datasets/bandai-namco-bvh.tar.xz to /tmp or pass --clips); skipped")
        return 0
    rows = []
    for clip in clips:
        with tempfile.TemporaryDirectory(prefix="motok-cache-") as tmp:
            folder = Path(tmp)
            none = run_child(clip, args.robot, "nocache", None)
            cold = run_child(clip, args.robot, "cache", folder)
            compile_s = wait_compiled(folder)
            warm = run_child(clip, args.robot, "cache", folder)
        for name, r in (("no cache", none), ("cold", cold), ("warm", warm)):
            rows.append({"clip": clip.stem, "frames": r["frames"], "process": name, "ready s": r["ready"],
                         "first window s": r["first_window"], "total s": r["total"], "CPU s": r["cpu"],
                         "kp err cm": r["keypoint_error_cm"], "ok": r["success"],
                         "compile s (background, after)": compile_s if name == "cold" else None,
                         "problems": ",".join(r["cache"])})
    print_table(rows, title=f"fresh-process start-up, {args.robot}")
    path = write_json(args.out, {"robot": args.robot, "rows": rows})
    payload = json.loads(Path(path).read_text())
    print(machine_summary(payload.get("machine", {})) if "machine" in payload else "")
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Speed of the motion representation: features, decoders, stick-figure rendering.

Run: python benchmarks/motion_features.py [--out benchmarks/results/motion_features.json]
Prints a table and writes JSON with a machine description. Uses one CPU thread.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from motok_robot.motion import features as F  # noqa: E402
from motok_robot.motion import synthetic  # noqa: E402


def _time(fn, repeat: int) -> float:
    fn()  # warm up
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/motion_features.json"))
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    rows = []
    for seconds in (10, 60):
        clip = synthetic.walking_clip(seconds * 20 + 1)
        t = _time(lambda: F.features_from_joints(clip), args.repeat)
        rows.append(("features_from_joints (numpy)", f"{seconds} s clip", t * 1000, seconds * 20 / t))
        feats = F.features_from_joints(clip)
        t = _time(lambda: F.joints_from_features(feats), args.repeat)
        rows.append(("joints_from_features (numpy)", f"{seconds} s clip", t * 1000, seconds * 20 / t))
    try:
        import torch

        torch.set_num_threads(1)
        from motok_robot.motion import features_torch as FT

        batch = torch.from_numpy(np.stack([F.features_from_joints(synthetic.walking_clip(197))] * 64))
        x = batch.clone().requires_grad_(True)

        def fwd_bwd():
            FT.joints_from_features(x).square().sum().backward()

        t = _time(lambda: FT.joints_from_features(batch), args.repeat)
        rows.append(("joints_from_features (torch, cpu)", "64 x 196 frames", t * 1000, 64 * 196 / t))
        t = _time(fwd_bwd, args.repeat)
        rows.append(("  ... forward + backward", "64 x 196 frames", t * 1000, 64 * 196 / t))
    except ImportError:
        pass
    from motok_robot.motion import render

    clip = F.normalise_joints(synthetic.walking_clip(40))
    with tempfile.TemporaryDirectory() as tmp:
        t = _time(lambda: render.render_stick_figure(clip, Path(tmp) / "a.mp4"), 1)
        rows.append(("render_stick_figure mp4", "40 frames, 1 panel", t * 1000, 40 / t))
        t = _time(lambda: render.render_stick_figure(clip, Path(tmp) / "a.gif"), 1)
        rows.append(("render_stick_figure gif", "40 frames, 1 panel", t * 1000, 40 / t))

    print(f"{'operation':<36}{'input':<20}{'ms (best)':>12}{'frames/s':>14}")
    for name, what, ms, fps in rows:
        print(f"{name:<36}{what:<20}{ms:>12.2f}{fps:>14.0f}")
    machine = {"platform": platform.platform(), "processor": platform.processor() or platform.machine(),
               "python": platform.python_version(), "numpy": np.__version__, "cpu_count": os.cpu_count(),
               "threads": os.environ.get("OMP_NUM_THREADS")}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"machine": machine, "results": [
        {"operation": n, "input": w, "ms_best": ms, "frames_per_s": f} for n, w, ms, f in rows]}, indent=1))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()

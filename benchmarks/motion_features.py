"""Speed of the motion representation: features, decoders, stick-figure rendering.

Run: python benchmarks/motion_features.py [--repeat 5] [--out benchmarks/results/motion_features.json]
Prints a table of median times (``--repeat`` runs after one warm-up; the renders once) and
writes JSON with a machine description. Uses one CPU thread.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine_description, machine_summary, print_table, time_median, write_json  # noqa: E402

from motok_robot.motion import features as F  # noqa: E402
from motok_robot.motion import synthetic  # noqa: E402


def _time(fn, repeat: int) -> float:
    """Median wall time (s) of ``repeat`` calls after one warm-up."""
    return time_median(fn, repeat=repeat, warmup=1)["median_s"]


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

    results = [{"operation": n, "input": w, "ms_median": ms, "frames_per_s": f} for n, w, ms, f in rows]
    machine = machine_description(threads=1)
    print(machine_summary(machine))
    print_table(results, headers={"ms_median": "ms (median)", "frames_per_s": "frames/s"})
    write_json(args.out, {"benchmark": "motion_features", "statistic": "median", "repeat": args.repeat,
                          "machine": machine, "results": results})
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()

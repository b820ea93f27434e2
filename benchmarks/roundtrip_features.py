"""Feature round-trip error over every clip of a prepared dataset, per source.

Run: python benchmarks/roundtrip_features.py DIR [--limit N] [--out benchmarks/results/roundtrip_features.json]

For every clip in ``DIR/index.jsonl`` it loads ``joints/ID.npy`` (float32 ``[T, 22, 3]``, the
skeleton-normalised joints that ``data prepare`` stored, metres, z up) and ``features/ID.npy``
(float32 ``[T-1, 263]``, computed by ``features_from_joints`` from the *imported* joints) and
measures, in millimetres (see :func:`motok_robot.motion.roundtrip.check_clip`):

* ``decode_mm``    max |joints_from_features(features) - joints[:-1]|: the acceptance check of
  issue 2 (the features of an imported clip reproduce its skeleton-normalised joints);
* ``normalise_mm`` max |normalise_joints(joints) - joints| (stored joints are normalised);
* ``recompute_mm`` max |joints_from_features(features_from_joints(joints)) - joints[:-1]|.

Prints a table (max / mean / 99th percentile per source and overall, clips above 1 mm) and
writes JSON with a machine description.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine_description, write_json  # noqa: E402

KEYS = ("decode_mm", "normalise_mm", "recompute_mm")


def main(argv: list[str] | None = None) -> int:
    from tqdm import tqdm

    from motok_robot.data.dataset import PreparedDataset
    from motok_robot.motion.roundtrip import check_clip

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dataset", type=Path)
    ap.add_argument("--limit", type=int, default=None, help="first N clips only")
    ap.add_argument("--tolerance-mm", type=float, default=1.0)
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/roundtrip_features.json"))
    args = ap.parse_args(argv)

    ds = PreparedDataset(args.dataset, "all")
    ids = ds.clip_ids[: args.limit] if args.limit else ds.clip_ids
    per_clip: dict[str, dict] = {}
    t0 = time.perf_counter()
    frames = 0
    for cid in tqdm(ids, desc="round trip", unit="clip", disable=None):
        j, f = ds.joints(cid), ds.features(cid)
        frames += j.shape[0]
        r = check_clip(j, f)
        r["source"] = ds.record(cid)["source"]
        r["frames"] = int(j.shape[0])
        per_clip[cid] = r
    wall = time.perf_counter() - t0

    groups: dict[str, list[str]] = {}
    for cid, r in per_clip.items():
        groups.setdefault(r["source"], []).append(cid)
    groups["all"] = list(per_clip)
    table = {}
    print(f"{'source':<11}{'clips':>7}  " + "  ".join(f"{k + ' max/mean/p99':>30}" for k in KEYS))
    for g, cids in groups.items():
        row = {"clips": len(cids)}
        cells = []
        for k in KEYS:
            v = np.array([per_clip[c][k] for c in cids])
            row[k] = {"max": float(v.max()), "mean": float(v.mean()), "p99": float(np.percentile(v, 99))}
            cells.append(f"{v.max():>10.4f}{v.mean():>10.4f}{np.percentile(v, 99):>10.4f}")
        row["over_tolerance"] = sorted(c for c in cids if per_clip[c]["decode_mm"] > args.tolerance_mm)
        table[g] = row
        print(f"{g:<11}{len(cids):>7}  " + "  ".join(cells))
    worst = sorted(per_clip.items(), key=lambda kv: -kv[1]["decode_mm"])[:5]
    print("worst decode_mm: " + ", ".join(f"{c} {r['decode_mm']:.4f}" for c, r in worst))
    over = table["all"]["over_tolerance"]
    print(f"{len(per_clip)} clips, {frames} frames in {wall:.1f} s; {len(over)} above {args.tolerance_mm} mm")

    write_json(args.out, {
        "dataset": str(args.dataset), "tolerance_mm": args.tolerance_mm, "wall_s": round(wall, 2), "frames": frames,
        "machine": machine_description(), "by_source": table, "clips": per_clip,
    })
    print(f"wrote {args.out}")
    return 1 if over else 0


if __name__ == "__main__":
    sys.exit(main())

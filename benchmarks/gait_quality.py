"""Gait quality of generated locomotion: how often no foot is planted, next to real mocap.

Run: python benchmarks/gait_quality.py [--planner masked ar] [--seeds 6] [--data runs/prepared]
       [--threads 2] [--out benchmarks/results/gait_quality.json]

A frame has no foot planted when neither foot is in contact by
:func:`retarget.contacts.detect_contacts` (toe or ankle near the floor *and* nearly still; the
thresholds of :class:`retarget.config.ContactConfig`). Such a frame is *airborne* when neither
foot is even near the floor, else *sliding* (a foot near the floor but moving). Retargeting
cannot repair either: a robot needs a planted foot to stand on. For every planner and prompt
the script generates seeds ``0..N-1`` with the default sampling settings and length, and, with
``--data`` (a prepared dataset), measures the Bandai Namco walks and runs per style as the
reference. Prints a table and writes JSON with the machine description
(docs/retarget.md, "Generated locomotion").
"""

from __future__ import annotations

import argparse
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import print_table, write_json  # noqa: E402

PROMPTS = ("a person walks forward", "a person walks and turns left")


def unplanted_shares(joints: np.ndarray, fps: float) -> dict[str, float]:
    """Shares of frames of ``joints[T, 22, 3]`` with no foot planted, airborne and sliding."""
    from retarget.contacts import detect_contacts, near_floor

    none = ~detect_contacts(joints, fps).any(axis=1)
    near = near_floor(joints).any(axis=1)
    return {"unplanted": float(none.mean()), "airborne": float((none & ~near).mean()),
            "sliding": float((none & near).mean())}


def _span(values: list[float]) -> str:
    return f"{100 * min(values):.0f}-{100 * max(values):.0f} %"


def generated_rows(planners: list[str], prompts: list[str], seeds: int) -> list[dict]:
    from motok_robot.planner.generate import MotionGenerator

    rows = []
    for kind in planners:
        gen = MotionGenerator(kind)
        for prompt in prompts:
            per_seed = []
            for seed in range(seeds):
                motion = gen.generate(prompt, seed=seed)
                per_seed.append({"seed": seed, "seconds": motion.seconds, **unplanted_shares(motion.joints, motion.fps)})
            rows.append({"motion": f"{kind}: {prompt!r}", "model": gen.model_id, "seeds": per_seed,
                         **{k: _span([s[k] for s in per_seed]) for k in ("unplanted", "airborne", "sliding")}})
            print(f"  {rows[-1]['motion']}: no foot planted {rows[-1]['unplanted']}", flush=True)
    return rows


def reference_rows(data: Path) -> list[dict]:
    """Bandai Namco walks (every walk-* content) and runs, per style mean (originals, no mirrors)."""
    from motok_robot.data.dataset import PreparedDataset
    from motok_robot.data.groups import clip_action

    dataset = PreparedDataset(data, "all")
    by_style: dict[str, dict[str, list[dict]]] = {"walks": defaultdict(list), "runs": defaultdict(list)}
    for clip_id in dataset.clip_ids:
        record = dataset.record(clip_id)
        if record["source"] != "bandai" or record.get("mirror_of"):
            continue
        content = clip_action(record) or ""
        group = "walks" if content.startswith("walk") else "runs" if content == "run" else None
        if group is None:
            continue
        style = clip_id.split("/")[-1].split("_")[2]  # dataset-N_content_style_take
        by_style[group][style].append(unplanted_shares(dataset.joints(clip_id), float(record["fps"])))
    rows = []
    for group, styles in by_style.items():
        if not styles:
            continue
        means = {k: [float(np.mean([c[k] for c in clips])) for clips in styles.values()] for k in ("unplanted", "airborne", "sliding")}
        rows.append({"motion": f"real Bandai {group} ({sum(len(c) for c in styles.values())} clips, {len(styles)} styles; per style mean)",
                     **{k: _span(v) for k, v in means.items()}})
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--planner", nargs="+", choices=("masked", "ar"), default=["masked", "ar"])
    parser.add_argument("--prompt", nargs="+", default=list(PROMPTS))
    parser.add_argument("--seeds", type=int, default=6)
    parser.add_argument("--data", type=Path, default=None, help="prepared dataset for the real-mocap reference rows")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/gait_quality.json"))
    args = parser.parse_args()
    if args.seeds < 1:
        parser.error("--seeds must be >= 1")
    if args.data is not None and not (args.data / "index.jsonl").is_file():
        parser.error(f"--data {args.data}: no index.jsonl (make one with motok-robot data prepare)")

    import torch

    torch.set_num_threads(args.threads)
    rows = reference_rows(args.data) if args.data is not None else []
    rows += generated_rows(args.planner, args.prompt, args.seeds)
    print_table(rows, ["motion", "unplanted", "airborne", "sliding"],
                title=f"Frames with no foot planted (airborne / sliding), seeds 0-{args.seeds - 1}, default sampling")
    path = write_json(args.out, {"benchmark": "gait_quality", "seeds": args.seeds, "rows": rows}, threads=args.threads)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

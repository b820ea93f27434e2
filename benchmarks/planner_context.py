"""How much each planner uses the tokens around a position, per kind of motion.

Run: python benchmarks/planner_context.py --data runs/prepared [--split train] [--per-content 20]
       [--masked RUN] [--ar RUN] [--threads 2] [--out benchmarks/results/planner_context.json]

For clips of a prepared dataset (up to ``--per-content`` per action label; clips without one are
grouped by source), tokenised with the planners' tokenizer and cut to the planners' longest
plan, it measures top-1 token accuracy three ways, with each clip's own first caption as the
condition and no guidance:

* masked, infill: one position masked, every other token of the clip given (the easiest case
  for a bidirectional planner: the most context it can have);
* masked, text only: every position masked (what the text alone decides);
* AR, next token: the causal planner given the clip's earlier tokens (teacher forcing).

A planner that models motion, not just the caption, is far more accurate with context than
without. Prints a table per label and writes JSON with the machine description
(docs/planner.md, "What the planners learned").
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import print_table, write_json  # noqa: E402


def clip_groups(dataset, per_content: int, seed: int = 0) -> dict[str, list[str]]:
    """Clip ids of a prepared ``dataset`` (one split) with a caption, up to ``per_content`` per
    action label (or source)."""
    from motok_robot.data.groups import clip_action

    groups: dict[str, list[str]] = defaultdict(list)
    for clip_id in dataset.clip_ids:
        record = dataset.record(clip_id)
        if dataset.texts(clip_id):
            groups[clip_action(record) or str(record.get("source", "other"))].append(clip_id)
    rng = np.random.default_rng(seed)
    return {g: sorted(rng.choice(ids, size=min(per_content, len(ids)), replace=False).tolist())
            for g, ids in sorted(groups.items())}


def context_accuracy(masked, ar, tokenizer, text_encoder, dataset, clip_ids: list[str]) -> dict[str, float]:
    """Token counts and correct predictions of the three measures over ``clip_ids``."""
    import torch

    from motok_robot.planner.conditions import Conditions

    ds = tokenizer.frames_per_token
    n_max = masked.config.max_tokens
    hits = {"infill": 0, "text_only": 0, "ar_next": 0}
    total = 0
    for clip_id in clip_ids:
        feats = np.asarray(dataset.features(clip_id), dtype=np.float32)
        usable = min(feats.shape[0] // ds, n_max) * ds
        if usable < 2 * ds:
            continue
        with torch.no_grad():
            tokens = tokenizer.encode(torch.from_numpy(feats[None, :usable]))
            n = tokens.shape[1]
            emb = text_encoder.encode([dataset.texts(clip_id)[0]])
            one = Conditions(text_embedding=emb)
            many = Conditions(text_embedding=emb.expand(n, -1))
            holes = tokens.repeat(n, 1)
            holes[torch.arange(n), torch.arange(n)] = masked.mask_id
            infill = masked.logits(holes, torch.full((n,), n), many)[torch.arange(n), torch.arange(n)]
            blank = masked.logits(torch.full_like(tokens, masked.mask_id), torch.tensor([n]), one)[0]
            nxt = ar.logits(tokens, one)[0, :n, : ar.config.codebook_size]
        truth = tokens[0]
        hits["infill"] += int((infill.argmax(-1) == truth).sum())
        hits["text_only"] += int((blank.argmax(-1) == truth).sum())
        hits["ar_next"] += int((nxt.argmax(-1) == truth).sum())
        total += n
    return {"tokens": total, **{k: v / max(total, 1) for k, v in hits.items()}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, required=True, help="prepared dataset")
    parser.add_argument("--split", default="train", choices=("train", "val", "test"))
    parser.add_argument("--per-content", type=int, default=20, help="clips per action label / source")
    parser.add_argument("--masked", type=Path, default=None, help="masked planner run (default: models/)")
    parser.add_argument("--ar", type=Path, default=None, help="AR planner run (default: models/)")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/planner_context.json"))
    args = parser.parse_args()

    import torch

    from motok_robot.planner.data import open_dataset
    from motok_robot.planner.generate import MotionGenerator

    torch.set_num_threads(args.threads)
    masked_gen = MotionGenerator("masked", planner_run=args.masked)
    ar_gen = MotionGenerator("ar", planner_run=args.ar)
    masked, ar = masked_gen.planner.eval(), ar_gen.planner.eval()
    dataset = open_dataset(args.data, args.split)
    rows = []
    for group, ids in clip_groups(dataset, args.per_content).items():
        acc = context_accuracy(masked, ar, masked_gen.tokenizer, masked_gen.text_encoder, dataset, ids)
        if acc["tokens"]:
            rows.append({"label": group, "clips": len(ids), **acc})
    total = sum(r["tokens"] for r in rows)
    overall = {k: sum(r[k] * r["tokens"] for r in rows) / max(total, 1) for k in ("infill", "text_only", "ar_next")}
    rows.sort(key=lambda r: r["infill"])
    table = [{"label": r["label"], "clips": r["clips"], "tokens": r["tokens"], "masked infill": f"{r['infill']:.3f}",
              "masked text only": f"{r['text_only']:.3f}", "AR next token": f"{r['ar_next']:.3f}"} for r in rows]
    table.append({"label": "all", "clips": sum(r["clips"] for r in rows), "tokens": total,
                  "masked infill": f"{overall['infill']:.3f}", "masked text only": f"{overall['text_only']:.3f}",
                  "AR next token": f"{overall['ar_next']:.3f}"})
    print_table(table, title=f"top-1 token accuracy, {args.split} split (masked: {masked_gen.model_id})")
    write_json(args.out, {"split": args.split, "per_content": args.per_content,
                          "masked": masked_gen.model_id, "ar": ar_gen.model_id,
                          "overall": overall, "rows": rows})


if __name__ == "__main__":
    main()

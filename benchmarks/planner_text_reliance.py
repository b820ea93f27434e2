"""How much an AR planner's next-token predictions rest on the caption, with and without the end.

Run: python benchmarks/planner_text_reliance.py --data runs/prepared [--ar RUN ...] [--split val]
       [--tokenizer RUN] [--threads 2] [--out benchmarks/results/planner_text_reliance.json]

For every clip of the split with a caption (the first crop of at most the planner's longest
plan, as in the training's validation), it measures the mean negative log-likelihood per motion
token (teacher forcing, nats; [END] targets left out so that planners with and without an end
embedding are scored on the same targets) six ways: with the clip's own caption, with the
caption of the next clip in the split ("other caption"), and with the null condition, each with
the end known (planners with ``end_embedding`` are told how many tokens are still to draw) and
unknown. The *text gain* is what the own caption saves over another clip's: the larger, the more
the planner's tokens follow the text. Prints a table and writes JSON with the machine
description (models/MODEL_CARD.md, "The AR planner with a capped end embedding").
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import print_table, write_json  # noqa: E402

TEXTS = ("caption", "other caption", "none")
ENDS = ("known", "unknown")


def token_nll(model, data, text: str, end: str, batch_size: int = 64) -> tuple[float, int]:
    """Mean NLL per motion token of ``model`` over the captioned clips of ``data`` (a
    :class:`~motok_robot.planner.data.PlannerData`), and the number of tokens."""
    import torch
    import torch.nn.functional as F

    rng = np.random.default_rng(1234)
    total, count = 0.0, 0
    for start in range(0, len(data), batch_size):
        idx = list(range(start, min(len(data), start + batch_size)))
        tokens, lengths, ends, cond, _ = data.batch(idx, rng, None, random_crop=False, action_prob=0.0)
        keep = torch.nonzero(cond.text_present).flatten()
        if len(keep) == 0:
            continue
        tokens, lengths, ends, cond = tokens[keep], lengths[keep], ends[keep], cond.select(keep)
        if text == "other caption":
            cond.text_embedding = cond.text_embedding.roll(1, dims=0)
        drop = torch.full((len(keep),), text == "none")
        n = tokens.shape[1]
        valid = torch.arange(n)[None] < lengths[:, None]
        inputs = tokens.masked_fill(~valid, model.pad_id)
        with torch.no_grad():
            logits = model.logits(inputs, cond, n, drop, lengths, ends if end == "known" else torch.zeros_like(ends))
        nll = F.cross_entropy(logits[:, :n].reshape(-1, logits.shape[-1]), tokens.reshape(-1), reduction="none")
        total += float(nll[valid.reshape(-1)].sum())
        count += int(valid.sum())
    return total / max(count, 1), count


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, required=True, help="prepared dataset")
    parser.add_argument("--split", default="val", choices=("train", "val", "test"))
    parser.add_argument("--ar", type=Path, nargs="+", default=None, help="AR planner runs (default: models/planner_ar)")
    parser.add_argument("--tokenizer", type=Path, default=None, help="tokenizer run (default: models/tokenizer)")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/planner_text_reliance.json"))
    args = parser.parse_args()

    import tempfile

    import torch

    from motok_robot.errors import InputError
    from motok_robot.paths import models_dir
    from motok_robot.planner.checkpoint import load_planner, tokenizer_record
    from motok_robot.planner.data import load_planner_data
    from motok_robot.text import load_text_encoder
    from motok_robot.tokenizer import load_tokenizer

    torch.set_num_threads(args.threads)
    tok_dir = args.tokenizer or models_dir() / "tokenizer"
    tokenizer = load_tokenizer(tok_dir, device="cpu")
    key = tokenizer_record(tok_dir, tokenizer)["tokens_sha256"]
    runs = args.ar or [models_dir() / "planner_ar"]
    rows, data, first = [], None, None
    with tempfile.TemporaryDirectory() as cache:
        for run in runs:
            model, saved = load_planner(run)
            if model.config.kind != "ar":
                raise InputError(f"{run}: a {model.config.kind!r} planner run; this benchmark measures AR planners")
            if saved.get("tokenizer", {}).get("tokens_sha256") not in (None, key):
                raise InputError(f"{run}: trained on other tokens than {tok_dir} gives")
            if data is None:
                first = model.config
                data = load_planner_data(args.data, args.split, tokenizer, key, load_text_encoder(model.config.text_encoder),
                                         Path(cache), model.config.action_labels, model.config.max_tokens)
            elif (model.config.text_encoder, model.config.max_tokens) != (first.text_encoder, first.max_tokens):
                raise InputError(f"{run}: text encoder or longest plan differs from {runs[0]}'s; measure it separately")
            model.eval()
            row = {"run": str(run), "end_embedding": model.config.end_embedding,
                   "end_horizon": model.config.end_horizon}
            for text in TEXTS:
                for end in ENDS:
                    row[f"{text}, end {end}"], row["tokens"] = token_nll(model, data, text, end)
            for end in ENDS:
                row[f"text gain, end {end}"] = row[f"other caption, end {end}"] - row[f"caption, end {end}"]
            rows.append(row)
    columns = ["run", "caption, end known", "other caption, end known", "none, end known",
               "caption, end unknown", "text gain, end known", "text gain, end unknown"]
    print_table([{k: f"{v:.3f}" if isinstance(v, float) else v for k, v in r.items()} for r in rows], columns=columns,
                title=f"NLL per motion token (nats), {args.split} split, {rows[0]['tokens']} tokens of captioned clips")
    write_json(args.out, {"split": args.split, "tokenizer": str(tok_dir), "rows": rows}, threads=args.threads)


if __name__ == "__main__":
    main()

"""Training throughput (samples per second) and peak memory of the tokenizer, both planners and the
text-motion evaluator, with their default model and batch configurations.

Run: python benchmarks/bench_training.py [--parts tokenizer masked ar evaluator] [--steps 5]
       [--threads 2] [--device cpu] [--out benchmarks/results/bench_training.json]

Each part builds its model from the default config (random initialisation: speed does not
depend on the weights), an AdamW optimiser as its trainer uses, and synthetic batches of the
default batch size: windows of procedural walking clips (``motok_robot.motion.synthetic``) for
the tokenizer and the evaluator, random token sequences and text embeddings for the planners.
One warm-up step, then ``--steps`` timed optimiser steps (forward, backward, gradient clipping,
update); the median step time gives samples/s. Peak memory is the highest resident set size
sampled while the steps run (and the CUDA peak on a GPU), each part in a fresh process. A part whose module is missing is
skipped with a message. Prints a table and writes JSON with the machine description.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import PeakMemory, machine_description, machine_summary, print_table, time_median, write_json  # noqa: E402

PARTS = ("tokenizer", "masked", "ar", "evaluator")


def synthetic_features(n_clips: int = 24, frames: int = 241, seed: int = 0):
    """float32 ``[n_clips, frames - 1, 263]`` features of procedural walks (varied speed and turn)."""
    import numpy as np

    from motok_robot.motion.features import features_from_joints
    from motok_robot.motion.synthetic import walking_clip

    rng = np.random.default_rng(seed)
    clips = [features_from_joints(walking_clip(frames, speed=float(rng.uniform(0.6, 2.0)),
                                               turn_rate=float(rng.uniform(-0.6, 0.6)))) for _ in range(n_clips)]
    return np.stack(clips).astype(np.float32)


def windows(pool, batch: int, length: int, rng):
    import numpy as np

    clip = rng.integers(0, len(pool), batch)
    start = rng.integers(0, pool.shape[1] - length + 1, batch)
    return np.stack([pool[c, s : s + length] for c, s in zip(clip, start)])


def tokenizer_part(pool, device):
    import numpy as np
    import torch

    from motok_robot.tokenizer import MoTok, TokenizerConfig, TrainConfig

    cfg, train = TokenizerConfig(), TrainConfig()
    model = MoTok(cfg, pool.reshape(-1, 263).mean(0), pool.reshape(-1, 263).std(0) + 1e-3).to(device).train()
    optimiser = torch.optim.AdamW(model.parameters(), lr=train.lr, weight_decay=train.weight_decay)
    window = max(train.window - train.window % cfg.downsample, cfg.downsample)
    rng, generator = np.random.default_rng(0), torch.Generator().manual_seed(0)

    def step():
        batch = torch.as_tensor(windows(pool, train.batch_size, window, rng), device=device)
        losses = model.training_losses(batch, generator)
        optimiser.zero_grad(set_to_none=True)
        losses["loss"].backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), train.grad_clip)
        optimiser.step()

    return model, step, train.batch_size, f"{window} frames"


def planner_part(kind, device):
    import torch

    from motok_robot.planner.checkpoint import build_planner
    from motok_robot.planner.conditions import Conditions
    from motok_robot.planner.config import PlannerConfig, PlannerTrainConfig

    cfg, train = PlannerConfig(kind=kind), PlannerTrainConfig()
    model = build_planner(cfg).to(device).train()
    optimiser = torch.optim.AdamW(model.parameters(), lr=train.lr, weight_decay=train.weight_decay)
    generator = torch.Generator().manual_seed(0)
    n_max = min(cfg.max_tokens, 49)  # HumanML3D's longest clip: 196 frames = 49 tokens

    def step():
        b = train.batch_size
        lengths = torch.randint(10, n_max + 1, (b,), generator=generator)
        tokens = torch.randint(0, cfg.codebook_size, (b, n_max), generator=generator)
        text = torch.randn(b, cfg.text_dim, generator=generator)
        cond = Conditions(text_embedding=text.to(device), text_present=torch.ones(b, dtype=torch.bool, device=device))
        drop = torch.rand(b, generator=generator) < train.cond_drop_prob
        ends = torch.ones(b, dtype=torch.bool)
        out = model.loss(tokens.to(device), lengths.to(device), cond, generator, drop=drop.to(device), ends=ends.to(device))
        loss = out["loss"] + train.length_loss_weight * model.length_estimator.loss(cond.text_embedding, lengths.to(device))
        optimiser.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), train.grad_clip)
        optimiser.step()

    return model, step, train.batch_size, f"10..{n_max} tokens"


def evaluator_part(pool, device):
    import numpy as np
    import torch

    from motok_robot.eval.config import EvaluatorConfig
    from motok_robot.eval.evaluator import TextMotionEvaluator

    cfg = EvaluatorConfig()
    text_dim = 384  # MiniLM, the default text encoder (frozen, so its embeddings are inputs)
    flat = pool.reshape(-1, 263)
    model = TextMotionEvaluator(cfg, text_dim, flat.mean(0), flat.std(0) + 1e-3).to(device).train()
    optimiser = torch.optim.AdamW(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    rng = np.random.default_rng(0)
    longest = min(cfg.max_frames, pool.shape[1])

    def step():
        b = cfg.batch_size
        lengths = rng.integers(cfg.min_frames, longest + 1, b)
        feats = np.zeros((b, cfg.max_frames, 263), np.float32)
        crops = windows(pool, b, longest, rng)
        for i, n in enumerate(lengths):
            feats[i, :n] = crops[i, :n]
        text = torch.randn(b, text_dim, device=device)
        same = torch.zeros(b, b, dtype=torch.bool, device=device)
        loss = model.contrastive_loss(model.embed_text(text),
                                      model.embed_motion(torch.as_tensor(feats, device=device), torch.as_tensor(lengths, device=device)),
                                      same)
        optimiser.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
        optimiser.step()

    return model, step, cfg.batch_size, f"{cfg.min_frames}..{longest} frames"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--parts", nargs="+", choices=PARTS, default=list(PARTS))
    parser.add_argument("--steps", type=int, default=5, help="timed optimiser steps per part (median reported)")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/bench_training.json"))
    parser.add_argument("--in-process", action="store_true", help="run all parts in this process (memory then accumulates)")
    parser.add_argument("--quiet", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", str(args.threads))
    try:
        import torch
    except ImportError:
        print("torch is not installed: nothing to benchmark")
        return 1
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    device = torch.device(args.device)
    sync = torch.cuda.synchronize if device.type == "cuda" else None
    if len(args.parts) > 1 and not args.in_process:
        return run_isolated(args)
    pool = synthetic_features()
    rows, skipped = [], {}
    for part in args.parts:
        try:
            if part == "tokenizer":
                model, step, batch, sample = tokenizer_part(pool, device)
            elif part in ("masked", "ar"):
                model, step, batch, sample = planner_part(part, device)
            else:
                model, step, batch, sample = evaluator_part(pool, device)
        except ModuleNotFoundError as exc:
            skipped[part] = f"module {exc.name} is not there yet"
            print(f"skipping {part}: {skipped[part]}")
            continue
        params = sum(p.numel() for p in model.parameters())
        with PeakMemory() as mem:
            timing = time_median(step, repeat=args.steps, warmup=1, sync=sync)
        rows.append({
            "part": part if part in ("tokenizer", "evaluator") else f"planner ({part})",
            "params_M": params / 1e6,
            "batch": batch,
            "sample": sample,
            "step_ms": 1000 * timing["median_s"],
            "cpu_step_ms": 1000 * timing["cpu_median_s"],
            "samples_per_s": batch / timing["median_s"],
            "rss_peak_mb": mem.rss_peak_mb,
            "rss_increase_mb": mem.rss_increase_mb,
            "cuda_peak_mb": mem.cuda_peak_mb,
            "steps_timed": timing["repeat"],
            "step_s_runs": timing["runs_s"],
        })
        del model, step
    return report(args, rows, skipped)


def run_isolated(args) -> int:
    """One fresh process per part, so each part's peak memory is its own."""
    import json
    import subprocess
    import tempfile

    rows, skipped = [], {}
    with tempfile.TemporaryDirectory() as tmp:
        for part in args.parts:
            out = Path(tmp) / f"{part}.json"
            cmd = [sys.executable, __file__, "--parts", part, "--steps", str(args.steps), "--threads", str(args.threads),
                   "--device", args.device, "--out", str(out), "--quiet"]
            done = subprocess.run(cmd, capture_output=True, text=True)
            if done.returncode != 0 or not out.is_file():
                skipped[part] = f"failed (exit {done.returncode}): {done.stderr.strip().splitlines()[-1:] or ''}"
                print(f"{part}: {skipped[part]}")
                continue
            result = json.loads(out.read_text())
            rows += result["rows"]
            skipped.update(result["skipped"])
    return report(args, rows, skipped)


def report(args, rows, skipped) -> int:
    machine = machine_description(args.threads)
    if args.quiet:
        write_json(args.out, {"rows": rows, "skipped": skipped, "machine": machine})
        return 0
    print(f"training throughput, default configs, synthetic batches, median of {args.steps} steps, "
          f"{args.threads} thread(s), device {args.device}")
    print(machine_summary(machine))
    print_table(rows, ["part", "params_M", "batch", "sample", "step_ms", "cpu_step_ms", "samples_per_s", "rss_peak_mb",
                       "rss_increase_mb"])
    write_json(args.out, {"benchmark": "bench_training", "statistic": "median", "steps": args.steps,
                          "device": args.device, "rows": rows, "skipped": skipped, "machine": machine})
    print(f"written {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

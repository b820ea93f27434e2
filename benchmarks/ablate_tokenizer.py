"""Tokenizer ablation (MoTok paper): diffusion vs convolutional decoder at the same token rate,
temporal downsampling 2 / 4 / 8, encoder/decoder kernel sizes; optionally eps vs x0 and the
emphasis projection.

Usage::

    python benchmarks/ablate_tokenizer.py PREPARED_DIR [--out runs/ablation] [--steps 3000]
        [--size small|default] [--window 64] [--only diffusion_ds4_k3 conv_ds4_k3 ...] [--extras]
        [--split val] [--limit 200] [--device cpu|cuda] [--json FILE]

Each configuration is trained from scratch for ``--steps`` steps (same seed, data, batch and
window) into ``OUT/NAME`` (resumed if already there), then every clip of ``--split`` is
reconstructed (:mod:`motok_robot.tokenizer.evaluate`).  Prints a table and writes JSON with
a machine description.  This is a long job: run it on the full data when the CPU/GPU is free.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine_description, machine_summary, print_table, write_json  # noqa: E402

from motok_robot.tokenizer import TokenizerConfig, TrainConfig, load_tokenizer  # noqa: E402
from motok_robot.tokenizer.evaluate import reconstruct_dataset  # noqa: E402
from motok_robot.tokenizer.train import dataset_statistics, load_split, train_tokenizer  # noqa: E402

SIZES = {
    "small": {"width": 128, "code_dim": 128, "denoiser_width": 128, "denoiser_blocks": 6},
    "default": {},
}

CONFIGS = {
    "diffusion_ds4_k3": {},
    "conv_ds4_k3": {"decoder": "conv"},
    "diffusion_ds2_k3": {"downsample": 2},
    "diffusion_ds8_k3": {"downsample": 8},
    "conv_ds2_k3": {"decoder": "conv", "downsample": 2},
    "conv_ds8_k3": {"decoder": "conv", "downsample": 8},
    "diffusion_ds4_k5": {"kernel_size": 5},
    "diffusion_ds4_k7": {"kernel_size": 7},
}
EXTRAS = {
    "diffusion_ds4_k3_eps": {"parameterisation": "eps"},
    "diffusion_ds4_k3_emphasis": {"emphasis": True},
    "diffusion_ds4_k3_no_geometric": {"joint_weight": 0.0, "velocity_weight": 0.0, "foot_weight": 0.0},
}
COLUMNS = {  # result key -> table header
    "name": "config",
    "token_rate_hz": "tok/s",
    "mpjpe_cm": "MPJPE cm",
    "mpjpe_root_aligned_cm": "aligned cm",
    "root_trajectory_error_cm": "root cm",
    "foot_skating_ratio_reconstructed": "skate",
    "foot_skating_ratio_original": "skate GT",
    "codebook_usage": "usage",
    "perplexity": "ppl",
    "train_minutes": "train min",
}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("data", type=Path, help="prepared dataset directory")
    parser.add_argument("--out", type=Path, default=Path("runs/ablation"))
    parser.add_argument("--steps", type=int, default=3000)
    parser.add_argument("--batch-size", type=int, default=64)
    parser.add_argument("--window", type=int, default=64, help="training window, frames")
    parser.add_argument("--size", choices=tuple(SIZES), default="small")
    parser.add_argument("--only", nargs="+", default=None, help="configuration names to run")
    parser.add_argument("--extras", action="store_true", help="also eps, emphasis and no-geometric-loss variants")
    parser.add_argument("--split", default="val", choices=("train", "val", "test", "all"))
    parser.add_argument("--limit", type=int, default=None, help="evaluate the first N clips of the split")
    parser.add_argument("--sample-steps", type=int, default=None, help="DDIM steps at evaluation (default: config's)")
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--threads", type=int, default=0)
    parser.add_argument("--json", type=Path, default=Path("benchmarks/results/ablate_tokenizer.json"))
    args = parser.parse_args(argv)

    configs = dict(CONFIGS, **(EXTRAS if args.extras else {}))
    if args.only:
        unknown = sorted(set(args.only) - set(CONFIGS) - set(EXTRAS))
        if unknown:
            parser.error(f"unknown configuration(s) {unknown}; known: {sorted({**CONFIGS, **EXTRAS})}")
        configs = {k: {**CONFIGS, **EXTRAS}[k] for k in args.only}
    if args.threads:
        torch.set_num_threads(args.threads)

    train = load_split(args.data, "train")
    val = load_split(args.data, "val")
    mean, std = dataset_statistics(args.data)
    results = []
    for name, overrides in configs.items():
        tok_cfg = TokenizerConfig(**{**SIZES[args.size], **overrides})
        train_cfg = TrainConfig(steps=args.steps, batch_size=args.batch_size, window=args.window, device=args.device, num_threads=args.threads,
                                checkpoint_every=500, warmup_steps=min(500, args.steps // 10), val_clips=32)
        run = args.out / name
        start = time.perf_counter()
        resume = (run / "train_state.safetensors").is_file()
        print(f"== {name}: {overrides or 'default'} ({'resuming' if resume else 'new'}) -> {run}")
        train_tokenizer(train, val if val.ids else None, mean, std, run, tok_cfg, train_cfg, resume=resume,
                        overrides={"steps": args.steps, "device": args.device} if resume else None)
        minutes = (time.perf_counter() - start) / 60
        tok = load_tokenizer(run, device=args.device)
        metrics = reconstruct_dataset(tok, args.data, args.split, steps=args.sample_steps, limit=args.limit)
        metrics.pop("machine", None)
        results.append({"name": name, "overrides": overrides, "train_minutes": minutes, **metrics})

    machine = machine_description(args.threads or torch.get_num_threads())
    print(machine_summary(machine))
    print_table(results, list(COLUMNS), headers=COLUMNS)
    out = {
        "benchmark": "tokenizer ablation",
        "data": str(args.data),
        "split": args.split,
        "steps": args.steps,
        "batch_size": args.batch_size,
        "size": args.size,
        "results": results,
        "machine": machine,
    }
    write_json(args.json, out)
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

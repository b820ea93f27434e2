"""Speed of the MoTok tokenizer: encode and decode a 10 s clip (200 frames, 50 tokens).

Usage::

    python benchmarks/bench_tokenizer.py [--tokenizer RUN] [--threads 1 2] [--steps 10 20]
                                         [--device cpu] [--repeats 5] [--json FILE]

Without ``--tokenizer`` an untrained tokenizer of the default architecture is timed (speed
does not depend on the weights).  Prints a table and writes JSON with a machine description.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine_description, machine_summary, print_table, time_median, write_json  # noqa: E402

from motok_robot.tokenizer import MoTok, TokenizerConfig, load_tokenizer  # noqa: E402
from motok_robot.tokenizer.model import parameter_count  # noqa: E402


def _time(fn, repeats: int, device: torch.device) -> float:
    """Median wall time (s) of ``repeats`` calls after one warm-up (CUDA synchronised)."""
    sync = torch.cuda.synchronize if device.type == "cuda" else None
    return time_median(fn, repeat=repeats, warmup=1, sync=sync)["median_s"]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--tokenizer", type=Path, default=None, help="run directory (default: untrained default config)")
    parser.add_argument("--config", type=Path, default=None, help="JSON with a 'tokenizer' section (untrained)")
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--steps", type=int, nargs="+", default=[10, 20])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--batch", type=int, default=1)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--json", type=Path, default=Path("benchmarks/results/bench_tokenizer.json"))
    args = parser.parse_args(argv)

    device = torch.device(args.device)
    if args.tokenizer:
        tok = load_tokenizer(args.tokenizer, device=device)
    else:
        section = json.loads(args.config.read_text()).get("tokenizer", {}) if args.config else {}
        torch.manual_seed(0)
        tok = MoTok(TokenizerConfig(**section)).to(device).eval()
        with torch.no_grad():  # a non-degenerate codebook / output layer so decoding does real work
            tok.quantizer.codebook.normal_()
            if tok.denoiser is not None:
                tok.denoiser.output.weight.normal_(std=0.01)
    cfg = tok.config
    frames = int(round(args.seconds * cfg.fps))
    frames -= frames % tok.frames_per_token
    x = torch.randn(args.batch, frames, cfg.feature_dim, generator=torch.Generator().manual_seed(0)).to(device)
    x = tok.denormalise(x)
    tokens = tok.encode(x)
    rows = []
    for threads in args.threads if device.type == "cpu" else [torch.get_num_threads()]:
        torch.set_num_threads(threads)
        encode_s = _time(lambda: tok.encode(x), args.repeats, device)
        rows.append({"threads": threads, "what": "encode", "steps": 0, "seconds": encode_s})
        step_list = args.steps if cfg.decoder == "diffusion" else [0]
        for steps in step_list:
            decode_s = _time(lambda s=steps: tok.decode(tokens, length=frames, steps=s or None, seed=0), args.repeats, device)
            rows.append({"threads": threads, "what": "decode", "steps": steps, "seconds": decode_s})
    clip_seconds = frames / cfg.fps
    what = args.tokenizer or (f"untrained, {args.config}" if args.config else "untrained default config")
    print(f"tokenizer: {what}; decoder {cfg.decoder}, downsample {cfg.downsample}, "
          f"params {parameter_count(tok) / 1e6:.2f} M (denoiser {parameter_count(tok.denoiser) / 1e6 if tok.denoiser else 0:.2f} M); "
          f"clip {clip_seconds:.1f} s = {frames} frames = {tokens.shape[1]} tokens, batch {args.batch}, device {device}")
    for r in rows:
        r["ms"] = 1000 * r["seconds"]
        r["realtime_factor"] = args.batch * clip_seconds / r["seconds"]
    machine = machine_description(torch.get_num_threads())
    print(machine_summary(machine))
    print_table(rows, ["threads", "what", "steps", "ms", "realtime_factor"], headers={"realtime_factor": "x realtime"})
    out = {
        "benchmark": "tokenizer encode/decode",
        "clip_seconds": clip_seconds,
        "frames": frames,
        "tokens": int(tokens.shape[1]),
        "batch": args.batch,
        "tokenizer": str(what),
        "config": {"decoder": cfg.decoder, "downsample": cfg.downsample, "denoiser_width": cfg.denoiser_width,
                   "denoiser_blocks": cfg.denoiser_blocks, "width": cfg.width},
        "parameters": parameter_count(tok),
        "rows": rows,
        "machine": machine,
    }
    write_json(args.json, out)
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

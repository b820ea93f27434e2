"""Text-to-motion latency per stage: text encoding, planning, decoding (and joints), models loaded.

Run: python benchmarks/bench_generate.py [--planner masked|ar] [--threads 2] [--random-init]
       [--tokenizer RUN --planner-run RUN] [--out benchmarks/results/bench_generate.json]

For 2 / 6 / 10 s clips it generates ``--repeat`` times (default 5, after one warm-up) with the
default sampling settings (guidance 2.5, 10 unmasking steps, the tokenizer's default decoder
steps), clears the text-embedding cache before each run so text encoding is really measured,
and reports the median of each stage.  ``--random-init`` times freshly initialised models of the
default sizes (latency depends on the architecture, not on the weights) when no trained models
are available.  Prints a table and writes JSON with a machine description.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

SECONDS = (2.0, 6.0, 10.0)
STAGES = ("text", "plan", "decode", "joints")


def _random_runs(kind: str, root: Path) -> tuple[Path, Path]:
    """Write default-size tokenizer and planner runs with random weights into ``root``."""
    import torch

    from motok_robot.planner.checkpoint import build_planner, save_planner_weights, write_run_config
    from motok_robot.planner.config import PlannerConfig
    from motok_robot.planner.data import file_digest
    from motok_robot.tokenizer import MoTok, TokenizerConfig, save_tokenizer

    torch.manual_seed(0)
    tok = MoTok(TokenizerConfig())
    save_tokenizer(tok, root / "tokenizer")
    cfg = PlannerConfig(kind=kind, codebook_size=tok.config.codebook_size, downsample=tok.frames_per_token)
    planner = build_planner(cfg)
    write_run_config(root / "planner", cfg, {"tokenizer": {"sha256": file_digest(root / "tokenizer" / "model.safetensors")}})
    save_planner_weights(planner, root / "planner")
    return root / "tokenizer", root / "planner"


def _machine(threads: int) -> dict:
    import torch

    info = {
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "python": platform.python_version(),
        "torch": torch.__version__,
        "cpu_count": os.cpu_count(),
        "torch_threads": threads,
    }
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                info["cpu_model"] = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        info["load_average"] = os.getloadavg()
    except OSError:
        pass
    return info


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--planner", choices=("masked", "ar"), default="masked")
    parser.add_argument("--tokenizer", type=Path, default=None)
    parser.add_argument("--planner-run", type=Path, default=None)
    parser.add_argument("--random-init", action="store_true", help="time default-size models with random weights")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/bench_generate.json"))
    args = parser.parse_args()

    import torch

    torch.set_num_threads(args.threads)
    from motok_robot.planner.generate import MotionGenerator

    tmp = None
    tok_run, plan_run = args.tokenizer, args.planner_run
    if args.random_init:
        tmp = tempfile.TemporaryDirectory()
        tok_run, plan_run = _random_runs(args.planner, Path(tmp.name))
    t_load = time.perf_counter()
    gen = MotionGenerator(args.planner, tok_run, plan_run, device=args.device)
    load_s = time.perf_counter() - t_load
    prompt = "a person walks forward and waves the right hand"
    gen.generate(prompt, seconds=2.0, seed=0)  # warm-up
    rows = []
    for seconds in SECONDS:
        samples = {s: [] for s in STAGES + ("total",)}
        for rep in range(args.repeat):
            gen.text_encoder.clear_cache()
            start = time.perf_counter()
            motion = gen.generate(prompt, seconds=seconds, seed=rep)
            samples["total"].append(time.perf_counter() - start)
            for s in STAGES:
                samples[s].append(motion.timings[s])
        rows.append({"seconds": seconds, "frames": int(motion.joints.shape[0]), "tokens": int(len(motion.tokens)),
                     **{f"{s}_ms": 1000 * statistics.median(v) for s, v in samples.items()}})
    header = f"{'clip':>6} {'tokens':>6} " + " ".join(f"{s + ' ms':>10}" for s in STAGES + ("total",))
    print(f"planner={args.planner}  model={gen.model_id}  threads={args.threads}  median of {args.repeat}"
          + ("  (random-init weights)" if args.random_init else ""))
    print(header)
    for r in rows:
        print(f"{r['seconds']:>5.0f}s {r['tokens']:>6} " + " ".join(f"{r[s + '_ms']:>10.1f}" for s in STAGES + ("total",)))
    result = {
        "benchmark": "bench_generate",
        "planner": args.planner,
        "random_init": args.random_init,
        "model": gen.model_id,
        "repeat": args.repeat,
        "statistic": "median",
        "model_load_s": load_s,
        "sampling": {"cfg_scale": 2.5, "planner_steps": 10,
                     "decoder_steps": gen.tokenizer.config.sample_steps},
        "rows": rows,
        "machine": _machine(args.threads),
        "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"written {args.out}")
    if tmp is not None:
        tmp.cleanup()
    return 0


if __name__ == "__main__":
    sys.exit(main())

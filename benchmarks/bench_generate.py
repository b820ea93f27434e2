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
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine_description, machine_summary, print_table, random_model_runs, time_median, write_json  # noqa: E402

SECONDS = (2.0, 6.0, 10.0)
STAGES = ("text", "plan", "decode", "joints")


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
        tok_run, plan_run = random_model_runs(args.planner, Path(tmp.name))
    t_load = time.perf_counter()
    gen = MotionGenerator(args.planner, tok_run, plan_run, device=args.device)
    load_s = time.perf_counter() - t_load
    prompt = "a person walks forward and waves the right hand"
    gen.generate(prompt, seconds=2.0, seed=0)  # warm-up
    rows = []
    for seconds in SECONDS:
        samples = {s: [] for s in STAGES}
        seeds = iter(range(args.repeat))
        box = {}

        def run(seconds=seconds, samples=samples, seeds=seeds, box=box):
            gen.text_encoder.clear_cache()  # so that text encoding is really measured
            box["motion"] = motion = gen.generate(prompt, seconds=seconds, seed=next(seeds))
            for s in STAGES:
                samples[s].append(motion.timings[s])

        total = time_median(run, repeat=args.repeat, warmup=0)
        motion = box["motion"]
        rows.append({"seconds": seconds, "frames": int(motion.joints.shape[0]), "tokens": int(len(motion.tokens)),
                     **{f"{s}_ms": 1000 * statistics.median(v) for s, v in samples.items()},
                     "total_ms": 1000 * total["median_s"], "total_cpu_ms": 1000 * total["cpu_median_s"]})
    machine = machine_description(args.threads)
    print(f"planner={args.planner}  model={gen.model_id}  threads={args.threads}  median of {args.repeat}"
          + ("  (random-init weights)" if args.random_init else ""))
    print(machine_summary(machine))
    print_table(rows, ["seconds", "tokens", *(f"{s}_ms" for s in STAGES), "total_ms", "total_cpu_ms"],
                headers={"seconds": "clip s"}, digits=1)
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
        "machine": machine,
    }
    write_json(args.out, result)
    print(f"written {args.out}")
    if tmp is not None:
        tmp.cleanup()
    return 0


if __name__ == "__main__":
    sys.exit(main())

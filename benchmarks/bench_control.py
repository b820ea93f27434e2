"""Controlled decoding time per mechanism, for one 6 s clip (120 frames, 30 tokens).

Run: python benchmarks/bench_control.py [--tokenizer RUN] [--threads 1] [--repeat 5]
       [--device cpu] [--out benchmarks/results/bench_control.json]

Decodes the same tokens with a dense root trajectory (every frame) and, separately, five sparse
keyframes, under no control and under each decoder mechanism (MoTok refinement, GMD,
MDM inpainting, the default GMD + refinement, with and without the physics terms), with the
default :class:`ControlConfig` settings, and
reports the median of ``--repeat`` runs after one warm-up. Without ``--tokenizer`` the
tokenizer has the default size and random weights (decoding time depends on the architecture
and the number of steps, not on the weights). Prints a table and writes JSON with a machine
description.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import RESULTS_DIR, machine_summary, markdown_table, time_median, write_json  # noqa: E402

FRAMES = 120
SETTINGS = (
    ("none", ("none",), False),
    ("motok", ("motok",), False),
    ("gmd", ("gmd",), False),
    ("inpaint", ("inpaint",), False),
    ("gmd+motok (default)", ("gmd", "motok"), False),
    ("gmd+motok + foot physics", ("gmd", "motok"), True),
)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tokenizer", type=Path, default=None, help="trained tokenizer run (default: random default-size)")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--out", type=Path, default=RESULTS_DIR / "bench_control.json")
    args = parser.parse_args()

    import torch

    from motok_robot.control.config import ControlConfig
    from motok_robot.control.constraints import Constraints
    from motok_robot.control.decode import decode_with_control
    from motok_robot.motion.features import features_from_joints, joints_from_features
    from motok_robot.motion.synthetic import walking_clip
    from motok_robot.tokenizer import MoTok, TokenizerConfig, load_tokenizer

    torch.set_num_threads(args.threads)
    if args.tokenizer is not None:
        tok = load_tokenizer(args.tokenizer, device=args.device)
        model = str(args.tokenizer)
    else:
        torch.manual_seed(0)
        tok = MoTok(TokenizerConfig()).to(args.device).eval()
        model = "random default-size tokenizer"
    feats = features_from_joints(walking_clip(frames=FRAMES + 1, speed=1.2, turn_rate=0.3))
    target = joints_from_features(feats)
    tokens = tok.encode(torch.as_tensor(feats, dtype=torch.float32)[None].to(tok.device))
    dense = Constraints(FRAMES)
    for f in range(FRAMES):
        dense.set_joint(f, 0, target[f, 0, :2])
    sparse = Constraints(FRAMES)
    for f, j in zip((20, 45, 70, 95, 119), (0, 21, 10, 15, 20)):
        sparse.set_joint(f, j, target[f, j])

    rows = []
    sync = torch.cuda.synchronize if str(args.device).startswith("cuda") else None
    for task, constraints in (("dense root trajectory", dense), ("5 sparse keyframes", sparse)):
        for name, mechanisms, foot in SETTINGS:
            c = replace(constraints, foot_physics=foot)
            config = ControlConfig(mechanisms=mechanisms)

            def run(c=c, config=config):
                with torch.no_grad():
                    return decode_with_control(tok, tokens, FRAMES, None if mechanisms == ("none",) else c, config, seed=0)

            timing = time_median(run, repeat=args.repeat, warmup=1, sync=sync)
            rows.append({"task": task, "mechanism": name, "median_s": timing["median_s"], "min_s": timing["min_s"],
                         "max_s": timing["max_s"], "cpu_median_s": timing["cpu_median_s"],
                         "realtime_factor": FRAMES / 20 / timing["median_s"]})
            print(f"{task:22s} {name:22s} {timing['median_s']:.3f} s", flush=True)
    payload = {"benchmark": "controlled decoding of a 6 s clip", "frames": FRAMES, "tokens": int(tokens.shape[1]),
               "decoder_steps": tok.config.sample_steps, "control": vars(ControlConfig()), "model": model,
               "device": args.device, "threads": args.threads, "repeat": args.repeat, "rows": rows}
    path = write_json(args.out, payload, threads=args.threads)
    print()
    print(markdown_table(rows, ["task", "mechanism", "median_s", "min_s", "max_s", "cpu_median_s", "realtime_factor"]))
    print(f"\n{machine_summary(json.loads(path.read_text())['machine'])}\nresults written to {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

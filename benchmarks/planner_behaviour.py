"""Behaviour pass rates of the planners over many seeds (the tests check seed 0, and floors over 0-7).

Run: python benchmarks/planner_behaviour.py [--planner masked ar] [--seeds 12] [--first-seed 0] [--seconds S|auto]
       [--cfg S] [--steps N] [--temperature T] [--decoder-steps N] [--decoder-seed K ...]
       [--data runs/prepared [--reference-only]]
       [--threads 2] [--out benchmarks/results/planner_behaviour.json]

For every planner and seed ``F..F+N-1`` (``--first-seed``, default 0) it generates the five prompts of
:mod:`motok_robot.eval.behaviour` and runs its six checks (walk, a planted foot, run faster than
walk, wave the right hand, raise both hands, bow and come back up) on the configured models
(``models/`` or ``$MOTOK_ROBOT_MODELS``), with the default sampling settings unless ``--cfg`` (guidance scale), ``--steps``
(the masked planner's unmasking iterations) or ``--temperature`` (0 = greedy) is given, at the checks' lengths (6 s for the walk, run and wave; the planner's own length, from its
length estimator, for raising both hands and bowing); ``--seconds`` sets one length for all (a
number, or ``auto`` for the planner's own). ``--decoder-steps`` sets the tokenizer decoder's DDIM
steps; ``--decoder-seed K`` decodes every seed's tokens from the noise of seed K instead of the
seed's own (the tokens stay those of the seed), which separates what the planner's tokens decide
from what the decoder's noise adds (the real clips' round trip then uses that noise too, instead
of seed 0's). With ``--data`` (a prepared dataset) the bow and
raise-both-hands checks also run on the real Bandai Namco clips of those labels, at their own
lengths, and on the same clips encoded and decoded by the tokenizer: what a planner could reach
with the best token sequence (every bow's values are listed per clip); ``--reference-only`` runs
only those rows, to compare tokenizers (put one in ``$MOTOK_ROBOT_MODELS/tokenizer``). Prints a
table of passes per check and writes JSON with every seed's measured values and motion lengths,
and the machine description.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import print_table, write_json  # noqa: E402

from motok_robot.eval import behaviour as B  # noqa: E402

#: real-clip reference: Bandai label -> (check name, the check that applies to one clip of it)
REFERENCE = {"bow": ("bow", B.check_bow), "raise-up-both-hands": ("raise_both_hands", B.check_raise_both_hands)}
#: labels whose reference rows also list every clip's check values (the 15 bows; not the 434 hands)
DETAILED = ("bow",)


def planner_rows(planners: list[str], seeds: range, th: B.BehaviourThresholds, cfg: float | None,
                 steps: int | None = None, decoder_steps: int | None = None,
                 decoder_seed: int | None = None, temperature: float | None = None) -> list[dict]:
    from motok_robot.planner.generate import MotionGenerator

    extra: dict = {}
    if decoder_steps is not None:
        extra["decoder_steps"] = decoder_steps
    if decoder_seed is not None:
        extra["decoder_seed"] = decoder_seed
    if temperature is not None:
        extra["temperature"] = temperature

    rows = []
    for kind in planners:
        gen = MotionGenerator(kind)
        per_seed = []
        for seed in seeds:
            lengths: dict[str, float] = {}

            def make(text: str, seconds: float | None) -> np.ndarray:
                motion = gen.generate(text, seconds=seconds, seed=seed, cfg_scale=cfg, steps=steps, **extra)
                lengths[text] = motion.seconds
                return motion.joints.astype(np.float64)

            results = B.check_all(make, th=th)
            per_seed.append({"seed": seed, "seconds": lengths, **{name: r.to_dict() for name, r in results.items()}})
            print(f"  {kind} seed {seed}: " + ", ".join(f"{n} {'ok' if r.passed else 'MISS'}" for n, r in results.items()),
                  flush=True)
        noise = "" if decoder_seed is None else f", decoder noise {decoder_seed}"
        row = {"rows": f"{kind} planner{noise}", "planner": kind, "model": gen.model_id, "decoder_seed": decoder_seed,
               "seeds": per_seed}
        for name in B.CHECKS:
            passed = [s["seed"] for s in per_seed if s[name]["passed"]]
            row[name] = f"{len(passed)}/{len(seeds)}"
            row[f"{name}_seeds"] = passed
        rows.append(row)
    return rows


def noise_summary(rows: list[dict]) -> list[dict]:
    """For each planner measured under several decoder noises (rows of :func:`planner_rows` with
    a ``decoder_seed``): per check, how many seeds' token plans pass under every noise, under some
    and under none, and the pass rate over all plans and noises."""
    by_kind: dict[str, list[dict]] = {}
    for row in rows:
        if row.get("decoder_seed") is not None:
            by_kind.setdefault(row["planner"], []).append(row)
    summary = []
    for kind, group in by_kind.items():
        if len(group) < 2:
            continue
        seeds = [s["seed"] for s in group[0]["seeds"]]
        out = {"rows": f"{kind} planner over {len(group)} decoder noises", "planner": kind,
               "decoder_seeds": [r["decoder_seed"] for r in group]}
        for name in B.CHECKS:
            counts = [sum(s in set(r[f"{name}_seeds"]) for r in group) for s in seeds]
            every = sum(c == len(group) for c in counts)
            none = sum(c == 0 for c in counts)
            rate = sum(counts) / (len(group) * len(seeds))
            out[name] = f"{every} / {len(seeds) - every - none} / {none} ({100 * rate:.0f} %)"
            out[f"{name}_counts"] = {"every": every, "some": len(seeds) - every - none, "none": none, "rate": rate}
        summary.append(out)
    return summary


def reference_rows(data: Path, decoder_seeds: list[int | None] = (None,), decoder_steps: int | None = None) -> list[dict]:
    """The bow and raise-both-hands checks on the real Bandai clips of those labels (originals, at
    their own lengths), and on the same clips encoded and decoded by the tokenizer (what the best
    possible token sequence gives; the configured tokenizer, one row per decoder noise seed in
    ``decoder_seeds``, None meaning seed 0, with ``decoder_steps`` DDIM steps, default the
    tokenizer's).  Each row's ``clips`` lists the check values of every clip of the
    :data:`DETAILED` labels (a bow's peak pitch, when and how far back up)."""
    import torch

    from motok_robot.data.dataset import PreparedDataset
    from motok_robot.motion.features import joints_from_features
    from motok_robot.data.groups import clip_action
    from motok_robot.planner.generate import default_run
    from motok_robot.tokenizer import load_tokenizer

    tokenizer_run = default_run("tokenizer")
    tokenizer = load_tokenizer(tokenizer_run)
    ds = tokenizer.frames_per_token
    dataset = PreparedDataset(data, "all")
    real: dict[str, list[bool]] = {label: [] for label in REFERENCE}
    decoded = {noise: {label: [] for label in REFERENCE} for noise in decoder_seeds}
    details: dict = {"real": [], **{noise: [] for noise in decoder_seeds}}

    def note(where, clip_id: str, label: str, result) -> bool:
        if label in DETAILED:
            details[where].append({"clip": clip_id, "label": label, "passed": result.passed, **result.values})
        return result.passed

    for clip_id in dataset.clip_ids:
        record = dataset.record(clip_id)
        label = clip_action(record) if record["source"] == "bandai" and not record.get("mirror_of") else None
        if label not in REFERENCE:
            continue
        features = np.asarray(dataset.features(clip_id), dtype=np.float32)
        usable = (len(features) // ds) * ds
        check = REFERENCE[label][1]
        real[label].append(note("real", clip_id, label, check(joints_from_features(features[:usable]).astype(np.float64))))
        with torch.no_grad():
            tokens = tokenizer.encode(torch.from_numpy(features[None, :usable]))
            for noise in decoder_seeds:
                y = tokenizer.decode(tokens, length=usable, steps=decoder_steps, seed=0 if noise is None else noise)
                result = check(joints_from_features(y[0].numpy()).astype(np.float64))
                decoded[noise][label].append(note(noise, clip_id, label, result))
    rows = []
    named = [("real Bandai clips (own length)", real, str(data), "real")]
    named += [("the same clips through the tokenizer" + ("" if noise is None else f", decoder noise {noise}"),
               decoded[noise], str(tokenizer_run), noise) for noise in decoder_seeds]
    for name, outcomes, source, where in named:
        row = {"rows": name, "model": source}
        for label, (check_name, _) in REFERENCE.items():
            row[check_name] = f"{sum(outcomes[label])}/{len(outcomes[label])}" if outcomes[label] else "-"
        row["clips"] = details[where]
        rows.append(row)
    return rows


def clip_round_trips(reference: list[dict]) -> list[dict]:
    """Per clip of the :data:`DETAILED` labels: whether the real clip passes its check and under how
    many of the decoder noises its tokenizer round trip does (from :func:`reference_rows`' rows);
    clips that rarely survive the round trip are candidates for a planner's ``exclude_clips``."""
    real, *decoded = reference
    out = []
    for k, clip in enumerate(real["clips"]):
        passes = [row["clips"][k]["passed"] for row in decoded]
        out.append({"rows": clip["clip"], "label": clip["label"], "real": "pass" if clip["passed"] else "MISS",
                    "round trip": f"{sum(passes)}/{len(passes)}", "round_trip_passes": sum(passes),
                    "noises": len(passes)})
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--planner", nargs="+", choices=("masked", "ar"), default=["masked", "ar"])
    parser.add_argument("--seeds", type=int, default=12)
    parser.add_argument("--first-seed", type=int, default=0,
                        help="first seed (default 0); a fresh range checks a choice made on seeds 0..N-1")
    parser.add_argument("--seconds", default=None,
                        help="one length for every motion, seconds or 'auto' (default: the checks' own lengths)")
    parser.add_argument("--cfg", type=float, default=None, help="guidance scale (default: the sampling default)")
    parser.add_argument("--steps", type=int, default=None,
                        help="masked planner unmasking iterations (default: the sampling default, 10)")
    parser.add_argument("--temperature", type=float, default=None,
                        help="sampling temperature, 0 = greedy (default: the sampling default, 1)")
    parser.add_argument("--decoder-steps", type=int, default=None,
                        help="tokenizer decoder DDIM steps (default: the tokenizer's, 20)")
    parser.add_argument("--decoder-seed", type=int, nargs="+", default=None,
                        help="decode every seed's tokens from this noise seed (default: the seed's own); several: "
                             "one row per noise, and a summary of the seeds passing under every / some / no noise")
    parser.add_argument("--data", type=Path, default=None, help="prepared dataset for the real-clip reference row")
    parser.add_argument("--reference-only", action="store_true",
                        help="only the real clips and their tokenizer round trip (needs --data; no planner is loaded): "
                             "compares tokenizers, e.g. a candidate in $MOTOK_ROBOT_MODELS/tokenizer")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/planner_behaviour.json"))
    args = parser.parse_args()
    if args.seeds < 1:
        parser.error("--seeds must be >= 1")
    if args.first_seed < 0:
        parser.error("--first-seed must be >= 0")
    if args.steps is not None and args.steps < 1:
        parser.error("--steps must be >= 1")
    if args.decoder_steps is not None and args.decoder_steps < 1:
        parser.error("--decoder-steps must be >= 1")
    if args.temperature is not None and not args.temperature >= 0:
        parser.error("--temperature must be >= 0")
    if args.decoder_seed is not None and (min(args.decoder_seed) < 0 or len(set(args.decoder_seed)) < len(args.decoder_seed)):
        parser.error("--decoder-seed: seeds must be >= 0 and distinct")
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    th = B.BehaviourThresholds()
    if args.seconds is not None:
        try:
            seconds = None if args.seconds == "auto" else float(args.seconds)
        except ValueError:
            parser.error(f"--seconds must be a number or 'auto' (got {args.seconds!r})")
        if seconds is not None and seconds <= 0:
            parser.error("--seconds must be > 0")
        th = replace(th, seconds=seconds, action_seconds=seconds)
    if args.reference_only and args.data is None:
        parser.error("--reference-only needs --data")
    if args.data is not None and not (args.data / "index.jsonl").is_file():
        parser.error(f"--data {args.data}: no index.jsonl (make one with motok-robot data prepare)")

    import torch

    torch.set_num_threads(args.threads)
    noises = args.decoder_seed or [None]
    rows = []
    for kind in [] if args.reference_only else args.planner:
        for noise in noises:
            rows += planner_rows([kind], seeds, th, args.cfg, args.steps, args.decoder_steps, noise, args.temperature)
    summary = noise_summary(rows)
    per_clip = []
    if args.data is not None:
        reference = reference_rows(args.data, noises, args.decoder_steps)
        rows += reference
        per_clip = clip_round_trips(reference)
    def length(s: float | None) -> str:
        return "own length" if s is None else f"{s:g} s"

    noise = "each seed's own" if args.decoder_seed is None else "of the seed in the row"
    decoder = (f"decoder steps {'default' if args.decoder_steps is None else args.decoder_steps}; "
               f"decoder noise {noise}")
    if args.reference_only:
        from motok_robot.planner.generate import default_run

        title = f"Real clips and their tokenizer round trip ({default_run('tokenizer')}); {decoder}"
    else:
        title = (f"Behaviour checks passed, seeds {seeds[0]}-{seeds[-1]}; walk, run, wave {length(th.seconds)}, hands "
                 f"and bow {length(th.action_seconds)}; guidance {'default' if args.cfg is None else args.cfg}; "
                 f"masked steps {'default' if args.steps is None else args.steps}; "
                 f"temperature {'default' if args.temperature is None else args.temperature}; {decoder}")
    print_table(rows, ["rows", *B.CHECKS], title=title)
    if summary:
        print_table(summary, ["rows", *B.CHECKS], title="Seeds whose token plan passes under every / some / no decoder noise "
                    "(pass rate over all plans and noises)")
    if per_clip:
        print_table(per_clip, ["rows", "label", "real", "round trip"],
                    title="Per clip: the real clip's check, and the decoder noises under which its round trip passes")
    path = write_json(args.out, {"benchmark": "planner_behaviour", "seeds": 0 if args.reference_only else args.seeds,
                                 "first_seed": args.first_seed, "cfg_scale": args.cfg, "steps": args.steps,
                                 "temperature": args.temperature,
                                 "decoder_steps": args.decoder_steps, "decoder_seed": args.decoder_seed, "thresholds": asdict(th),
                                 "rows": rows, "noise_summary": summary, "clip_round_trips": per_clip},
                      threads=args.threads)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

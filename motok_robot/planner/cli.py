"""CLI of the planning stage: ``motok-robot train planner``, ``motok-robot generate`` and
``motok-robot vocab`` (what the planners were trained on).

Light module: torch and the models are imported inside the handlers.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from motok_robot.errors import InputError


def register(commands, groups) -> None:
    train = groups["train"].add_parser(
        "planner",
        help="train a masked (discrete diffusion) or autoregressive token planner",
        description="Train a planner on a prepared dataset, tokenised once with a trained tokenizer. "
        "Writes RUN/config.json, RUN/model.safetensors, a resumable RUN/checkpoint.safetensors and "
        "RUN/metrics.csv (validation loss and token accuracy).",
    )
    train.add_argument("--data", required=True, type=Path, help="prepared dataset directory (motok-robot data prepare)")
    train.add_argument("--tokenizer", required=True, type=Path, help="tokenizer run directory")
    train.add_argument("--kind", choices=("masked", "ar"), default="masked", help="planner type (default masked)")
    train.add_argument("--out", required=True, type=Path, help="run directory to write")
    train.add_argument("--resume", action="store_true", help="continue the run in --out from its checkpoint")
    train.add_argument("--init-from", type=Path, default=None,
                       help="start from this trained planner run's weights and architecture (fine-tuning; "
                            "fresh optimiser and schedule, same tokenizer and action labels; --config's "
                            "'planner' section may only switch on end_embedding)")
    train.add_argument("--seed", type=int, default=None, help="random seed (default 0)")
    train.add_argument("--steps", type=int, default=None, help="optimiser steps in total (default 5000)")
    train.add_argument("--batch-size", type=int, default=None, help="clips per batch (default 32)")
    train.add_argument("--val-every", type=int, default=None, help="steps between validation/checkpoints (default 500)")
    train.add_argument("--text-encoder", default=None, help="'minilm' (default) or 'clip:/path/to/clip'")
    train.add_argument("--config", type=Path, default=None,
                       help="JSON file with optional 'planner' and 'train' sections overriding the defaults")
    train.add_argument("--action-share", nargs="+", default=None, metavar="LABEL=SHARE",
                       help="draw the clips of an action label with this share of all clips (e.g. bow=0.05; "
                            "train.action_share of --config)")
    train.add_argument("--device", default=None, help="torch device (default cpu)")
    train.set_defaults(func=_train)

    gen = commands.add_parser(
        "generate",
        help="text -> motion.npz (joints, features, tokens) with the trained planner and tokenizer",
        description="Generate human motion from a sentence. The same --seed gives the same file.",
    )
    gen.add_argument("text", nargs="?", default=None, help="the prompt, e.g. \"a person walks forward\"")
    gen.add_argument("--seconds", type=float, default=None, help="duration (default: estimated from the text)")
    gen.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    gen.add_argument("--planner", choices=("masked", "ar"), default="masked", help="planner (default masked)")
    gen.add_argument("--cfg", type=float, default=None, help="classifier-free guidance scale (default 2.5)")
    who = gen.add_mutually_exclusive_group()
    who.add_argument("--action", default=None, help="generate an action label instead of text")
    who.add_argument("--unconditional", action="store_true", help="generate without text")
    gen.add_argument("--prompts", type=Path, default=None, help="file with one prompt per line (# comments), or CSV with the header text,seconds,seed "
                     "(the format of run --prompts; rows without seconds or seed take --seconds / --seed); "
                     "--out is a directory")
    gen.add_argument("--out", required=True, type=Path, help="motion.npz, or a directory")
    gen.add_argument("--tokenizer", type=Path, default=None, help="tokenizer run (default models/tokenizer)")
    gen.add_argument("--planner-run", type=Path, default=None, help="planner run (default models/planner_<kind>)")
    gen.add_argument("--steps", type=int, default=None, help="masked planner unmasking steps (default 10)")
    gen.add_argument("--decoder-steps", type=int, default=None, help="tokenizer decoder steps (default: tokenizer's)")
    gen.add_argument("--decoder-seed", type=int, default=None,
                     help="seed of the decoder's noise (default: --seed); the tokens stay those of --seed")
    gen.add_argument("--temperature", type=float, default=None, help="token sampling temperature (default 1; 0 = greedy)")
    gen.add_argument("--top-k", type=int, default=None)
    gen.add_argument("--top-p", type=float, default=None)
    gen.add_argument("--device", default="cpu")
    # the control stage (motok_robot/control/cli.py, registered after this module) adds the
    # constraint options (--trajectory, --keyframes, ...) to this parser and wraps the handler
    gen.set_defaults(func=generate_command)

    voc = commands.add_parser(
        "vocab",
        help="list the actions, styles and captions the shipped planners were trained on; check prompts against them",
        description="What the planners were trained on (models/vocabulary.json, built from their training data): "
        "actions and styles with their train clip counts, and with PROMPT arguments how near each prompt is to "
        "the training captions (MiniLM cosine similarity) and whether generation would warn about it. "
        "See docs/vocabulary.md.",
    )
    voc.add_argument("prompts", nargs="*", metavar="PROMPT", help="prompts to check (needs the MiniLM text encoder)")
    voc.add_argument("--captions", action="store_true", help="also list the captions prompts are compared with")
    voc.add_argument("--file", type=Path, default=None, help="vocabulary file (default models/vocabulary.json)")
    voc.set_defaults(func=vocab_command)


def _train(args: argparse.Namespace) -> int:
    from motok_robot.planner.train import train_planner

    planner_over, train_over = {}, {}
    if args.config is not None:
        from motok_robot.config_utils import read_json_object

        data = read_json_object(args.config, "--config")
        if set(data) - {"planner", "train"}:
            raise InputError(f"--config {args.config}: expected an object with 'planner' and/or 'train' sections")
        planner_over = dict(data.get("planner", {}))
        train_over = dict(data.get("train", {}))
    for name, key in (("steps", "steps"), ("batch_size", "batch_size"), ("val_every", "val_every")):
        value = getattr(args, name)
        if value is not None:
            if value < 1:
                raise InputError(f"--{name.replace('_', '-')} must be >= 1 (got {value})")
            train_over[key] = value
    if args.action_share:
        from motok_robot.data.groups import parse_action_shares

        train_over["action_share"] = parse_action_shares(args.action_share)
    run = train_planner(args.data, args.tokenizer, args.kind, args.out, resume=args.resume, seed=args.seed,
                        planner_overrides=planner_over, train_overrides=train_over,
                        text_encoder=args.text_encoder, device=args.device, init_from=args.init_from)
    print(f"planner run written to {run}")
    return 0


def _slug(text: str) -> str:
    return re.sub(r"[^a-z0-9]+", "_", text.lower()).strip("_")[:48] or "motion"


def generate_command(args: argparse.Namespace, generate_one=None) -> int:
    """``motok-robot generate``. ``generate_one(generator, text=, action=, unconditional=, seconds=,
    seed=, ...)`` makes one motion (default ``generator.generate``); the control stage passes
    its constrained generation here."""
    from tqdm import tqdm

    from motok_robot.planner.generate import check_text, load_generator

    if args.prompts is not None and (args.text is not None or args.action or args.unconditional):
        raise InputError("--prompts cannot be combined with a TEXT argument, --action or --unconditional")
    if args.prompts is None and args.text is None and not args.action and not args.unconditional:
        raise InputError("give a TEXT prompt, --prompts FILE, --action LABEL or --unconditional")
    if args.seed < 0:
        raise InputError(f"--seed must be >= 0 (got {args.seed})")
    if args.decoder_seed is not None and args.decoder_seed < 0:
        raise InputError(f"--decoder-seed must be >= 0 (got {args.decoder_seed})")
    if args.seconds is not None and args.seconds <= 0:
        raise InputError(f"--seconds must be positive (got {args.seconds:g})")
    if args.seed is not None and not 0 <= args.seed <= 2**63 - 1:  # checked before any model loads
        raise InputError(f"--seed {args.seed} outside 0..{2**63 - 1} (torch and numpy take signed 64-bit seeds)")
    if args.seconds is not None:
        from motok_robot.limits import check_seconds

        check_seconds(args.seconds, "generate", "--seconds")
    if args.text is not None:
        check_text(args.text)
    from motok_robot.text.prompts import read_prompts  # the same file format as run --prompts

    prompts = read_prompts(args.prompts, args.seconds, args.seed) if args.prompts is not None else None
    if prompts is not None:
        if args.out.suffix == ".npz" or (args.out.exists() and not args.out.is_dir()):
            raise InputError(f"--out {args.out}: with --prompts, --out must be a directory")
        out = None
    else:
        out = args.out if args.out.suffix == ".npz" else args.out / "motion.npz"
        if out.is_dir() or (out.parent.exists() and not out.parent.is_dir()):
            raise InputError(f"--out {args.out}: cannot write {out} (a directory or a file is in the way)")
    gen = load_generator(args.planner, args.tokenizer, args.planner_run, args.device)
    plain = generate_one or (lambda generator, **kwargs: generator.generate(**kwargs))

    def one(generator, **kwargs):
        return _reporting_vocabulary(plain, generator, **kwargs)

    options = dict(seconds=args.seconds, seed=args.seed, cfg_scale=args.cfg, steps=args.steps,
                   decoder_steps=args.decoder_steps, temperature=args.temperature, top_k=args.top_k,
                   top_p=args.top_p, decoder_seed=args.decoder_seed)
    if prompts is not None:
        for i, prompt in enumerate(tqdm(prompts, desc="generating", unit="prompt", disable=None)):
            motion = one(gen, **{**options, "text": prompt.text, "seconds": prompt.seconds, "seed": prompt.seed})
            motion.save(args.out / f"{i:03d}_{_slug(prompt.text)}.npz")
        print(f"{len(prompts)} motions written to {args.out}")
        _note_unchecked(gen)
        return 0
    motion = one(gen, text=args.text, action=args.action, unconditional=args.unconditional, **options)
    motion.save(out)
    t = motion.timings
    print(f"{out}: {motion.joints.shape[0]} frames ({motion.seconds:.2f} s), {len(motion.tokens)} tokens; "
          f"text {t['text']:.3f} s, plan {t['plan']:.3f} s, decode {t['decode']:.3f} s"
          + (f", vocabulary check {t['vocabulary']:.3f} s" if "vocabulary" in t else ""))
    if args.text is not None:
        _note_unchecked(gen)
    return 0


def _note_unchecked(generator) -> None:
    """Say once, after the motions are written, why prompts were not checked against the vocabulary."""
    if getattr(generator, "vocabulary", None) is None and getattr(generator, "vocabulary_status", ""):
        print(f"motok-robot: note: {generator.vocabulary_status}", file=sys.stderr)


def _reporting_vocabulary(generate_one, generator, **kwargs):
    """``generate_one(generator, **kwargs)``, printing a far-from-the-vocabulary warning as one line."""
    import warnings

    from tqdm import tqdm

    from motok_robot.text.vocabulary import VocabularyWarning

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", VocabularyWarning)
        motion = generate_one(generator, **kwargs)
    for w in caught:
        if issubclass(w.category, VocabularyWarning):
            tqdm.write(f"motok-robot: warning: {w.message}", file=sys.stderr)
        else:
            warnings.showwarning(w.message, w.category, w.filename, w.lineno)
    return motion


def vocab_command(args: argparse.Namespace) -> int:
    """``motok-robot vocab``: the training vocabulary, and with prompts, how near each is to it."""
    from motok_robot.text.vocabulary import load_vocabulary

    vocab = load_vocabulary(args.file)
    print(format_vocabulary(vocab, captions=args.captions))
    if not args.prompts:
        return 0
    import torch

    from motok_robot.text.vocabulary import check_prompt

    torch.set_num_threads(1)
    print()
    for prompt in args.prompts:
        check = check_prompt(prompt, vocab)
        print(("FAR   " if check.far else "near  ") + check.message)
    return 0


def format_vocabulary(vocab, captions: bool = False) -> str:
    """The text ``motok-robot vocab`` prints: actions per source, styles, the threshold, the captions."""
    data = vocab.data
    clips = data.get("clips", {})
    lines = [f"{vocab.path}: what the planners ({', '.join(sorted(vocab.planners))}) were trained on",
             f"train split: {clips.get('train', '?')} clips with mirrors "
             f"({', '.join(f'{k} {v}' for k, v in data.get('train_clips_by_source', {}).items())}); "
             f"val {clips.get('val', '?')}, test {clips.get('test', '?')} held out", ""]
    by_source: dict[str, list[dict]] = {}
    for action in vocab.actions:
        by_source.setdefault(action["source"], []).append(action)
    for source, actions in by_source.items():
        lines.append(f"{source}: {len(actions)} action(s) (train clips with mirrors, seconds)")
        for a in actions:
            label = a["action"] if len(a["action"]) <= 60 else a["action"][:59] + "\u2026"
            lines.append(f"  {label:<60} {a['clips']:>5} {a.get('seconds', 0.0):>7.0f}")
    if vocab.styles:
        lines += ["", "styles (Bandai Namco, train clips): "
                  + ", ".join(f"{k} {v}" for k, v in sorted(vocab.styles.items(), key=lambda x: (-x[1], x[0])))]
    lines += ["", "a prompt is far from the vocabulary when its nearest caption's cosine similarity "
              f"({vocab.encoder_name}) is below {vocab.threshold:.2f}; {len(vocab.captions)} captions are compared"
              + (f", {len(vocab.partial)} partial ones (one part of a longer clip) are not" if vocab.partial else "")]
    if captions:
        lines += ["", "captions compared (train clips they stand for):"]
        lines += [f"  {c.clips:>5}  {c.text}" for c in vocab.captions]
        if vocab.partial:
            lines += ["", "partial captions, never compared (train clips):"]
            lines += [f"  {c.clips:>5}  {c.text}" for c in vocab.partial]
    return "\n".join(lines)

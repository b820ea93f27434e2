"""CLI of the evaluation stage (light module: torch and the models load inside the handlers).

* ``motok-robot train evaluator --data DIR [--out RUN]``: train the text-motion evaluator;
* ``motok-robot eval generation --data DIR [--model RUN_OR_DIR ...] [--planner masked ar]``: the
  HumanML3D-protocol table for generated motions, the real test motions and a shuffled-text control;
* ``motok-robot eval evaluator --data DIR``: the evaluator's sanity checks (no generation).
"""

from __future__ import annotations

import argparse
import json
import shlex
from pathlib import Path

from motok_robot.errors import InputError

TRAIN_EVALUATOR_HINT = "motok-robot train evaluator --data DIR --out {path}"


def register(commands, groups) -> None:
    train = groups["train"].add_parser(
        "evaluator",
        help="train the contrastive text-motion evaluator used by `eval generation`",
        description="Train the text-motion evaluator (frozen sentence encoder + MLP, conv + transformer motion "
        "encoder, symmetric InfoNCE) on the train split of a prepared dataset; validation R-precision on the val "
        "split goes to RUN/metrics.csv. Writes RUN/config.json, RUN/model.safetensors, a resumable "
        "RUN/train_state.safetensors, RUN/training.json (with this command) and RUN/cache/ (caption embeddings).",
    )
    train.add_argument("--data", required=True, type=Path, help="prepared dataset directory (motok-robot data prepare)")
    train.add_argument("--out", type=Path, default=None, help="run directory (default models/evaluator)")
    train.add_argument("--steps", type=int, default=None, help="optimiser steps in total (default 3000)")
    train.add_argument("--batch-size", type=int, default=None, help="pairs per batch (default 64)")
    train.add_argument("--eval-every", type=int, default=None, help="steps between validations/checkpoints (default 500)")
    train.add_argument("--resume", action="store_true", help="continue the run in --out from its last checkpoint")
    train.add_argument("--seed", type=int, default=None, help="random seed (default 0)")
    train.add_argument("--text-encoder", default=None, help="'minilm' (default) or 'clip:/path/to/clip'")
    train.add_argument("--config", type=Path, default=None,
                       help="JSON object of EvaluatorConfig fields overriding the defaults (e.g. {\"width\": 128})")
    train.add_argument("--device", default="cpu", help="torch device (default cpu)")
    train.set_defaults(func=_train_evaluator)

    gen = groups["eval"].add_parser(
        "generation",
        help="FID, R-precision, MM-dist, diversity, multimodality of generated motions (HumanML3D protocol)",
        description="Generate a motion for every test-split caption (at the real clip's length) with each planner, "
        "embed texts and motions with the evaluator and print mean ± 95 % CI over --repeats of FID, R-precision "
        "top-1/2/3 (batches of 32), MM-dist, diversity (300 pairs) and multimodality, next to the same metrics for "
        "the real test motions (reference row) and for real motions with shuffled captions (control row).",
    )
    _data_and_evaluator_args(gen)
    gen.add_argument("--model", type=Path, nargs="+", default=None, metavar="RUN_OR_DIR",
                     help="planner run(s), or folder(s) holding tokenizer/ and planner_<kind>/ (default models/)")
    gen.add_argument("--planner", nargs="+", choices=("masked", "ar"), default=["masked"],
                     help="planner kind(s) to take from a models folder (default masked)")
    gen.add_argument("--tokenizer", type=Path, default=None, help="tokenizer run (default: the models folder's)")
    gen.add_argument("--mm-texts", type=int, default=None, help="captions for multimodality (default 100; 0 = skip)")
    gen.add_argument("--mm-repeats", type=int, default=None, help="generations per multimodality caption (default 30)")
    gen.add_argument("--batch-size", type=int, default=None, help="captions per generation batch (default 64)")
    gen.add_argument("--cfg", type=float, default=None, help="classifier-free guidance scale (default 2.5)")
    gen.add_argument("--steps", type=int, default=None, help="masked planner unmasking steps (default 10)")
    gen.add_argument("--decoder-steps", type=int, default=None, help="tokenizer decoder steps (default: tokenizer's)")
    gen.set_defaults(func=_eval_generation)

    sanity = groups["eval"].add_parser(
        "evaluator",
        help="sanity checks of a text-motion evaluator on real motions (no generation)",
        description="Real test motions vs captions, vs shuffled captions, and vs the train split (FID), with the "
        "protocol run twice with different sampling seeds to check that results repeat within the CI.",
    )
    _data_and_evaluator_args(sanity)
    sanity.set_defaults(func=_eval_evaluator)


def _data_and_evaluator_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--data", required=True, type=Path, help="prepared dataset directory (its test split is evaluated)")
    p.add_argument("--evaluator", type=Path, default=None, help="evaluator run (default models/evaluator)")
    off = p.add_argument_group("official HumanML3D evaluator (instead of --evaluator)")
    off.add_argument("--official", type=Path, default=None, metavar="CKPT",
                     help="text_mot_match/model/finest.tar of the HumanML3D release")
    off.add_argument("--glove", type=Path, default=None, help="folder with our_vab_data.npy / our_vab_idx.pkl")
    off.add_argument("--mean", type=Path, default=None, help="the evaluator's mean.npy [263]")
    off.add_argument("--std", type=Path, default=None, help="the evaluator's std.npy [263]")
    off.add_argument("--hml-texts", type=Path, default=None,
                     help="HumanML3D texts/ folder (captions with POS tags, which the official text encoder reads)")
    p.add_argument("--repeats", type=int, default=None, help="repeated runs for mean ± 95 %% CI (default 20)")
    p.add_argument("--max-clips", type=int, default=None, help="evaluate only the first N usable test clips")
    p.add_argument("--seed", type=int, default=0, help="sampling seed of the protocol (default 0)")
    p.add_argument("--no-train-reference", action="store_true",
                   help="skip the train split (the reference row's FID, test vs as many train clips, is then left empty)")
    p.add_argument("--json", type=Path, default=None, help="also write the results as JSON")
    p.add_argument("--markdown", type=Path, default=None, help="also write the table as markdown")
    p.add_argument("--device", default="cpu", help="torch device (default cpu)")


# -- helpers --------------------------------------------------------------------------------------
def _positive(name: str, value, allow_zero: bool = False) -> None:
    if value is not None and (value < 0 or (value == 0 and not allow_zero)):
        raise InputError(f"--{name} must be {'>= 0' if allow_zero else '>= 1'} (got {value})")


def _load_split(data: Path, split: str):
    from motok_robot.data.dataset import PreparedDataset

    if not data.exists():
        raise InputError(f"--data {data} does not exist; prepare one with: motok-robot data prepare ... --out {data}")
    return PreparedDataset(data, split)


def _wants_official(args: argparse.Namespace) -> bool:
    """Check the evaluator options (cheap, before anything loads); True for the official evaluator."""
    official = [args.official, args.glove, args.mean, args.std]
    if not any(x is not None for x in official):
        if args.hml_texts is not None:
            raise InputError("--hml-texts is only used with the official evaluator (--official ...)")
        return False
    if not all(x is not None for x in official):
        raise InputError("the official evaluator needs all of --official CKPT --glove DIR --mean FILE --std FILE")
    if args.evaluator is not None:
        raise InputError("give either --evaluator or the official evaluator (--official ...), not both")
    return True


def load_embedder(args: argparse.Namespace):
    """The evaluator named by the arguments, as a protocol :class:`~motok_robot.eval.protocol.Embedder`."""
    if _wants_official(args):
        from motok_robot.eval.embedders import OfficialEmbedder, humanml3d_token_captions
        from motok_robot.eval.official import load_official_evaluator

        for flag, path in (("--mean", args.mean), ("--std", args.std)):
            if not path.is_file():
                raise InputError(f"{flag} {path}: file not found")
        evaluator = load_official_evaluator(args.official, args.glove, args.mean, args.std)
        tokens = humanml3d_token_captions(args.hml_texts) if args.hml_texts is not None else None
        return OfficialEmbedder(evaluator, tokens), f"official HumanML3D evaluator ({args.official})"
    from motok_robot.eval.config import default_evaluator_dir
    from motok_robot.eval.embedders import OwnEvaluatorEmbedder
    from motok_robot.eval.evaluator import load_evaluator

    run = args.evaluator or default_evaluator_dir()
    if not (run / "model.safetensors").is_file() or not (run / "config.json").is_file():
        raise InputError(f"no trained evaluator in {run} (config.json + model.safetensors); train one with: "
                         f"{TRAIN_EVALUATOR_HINT.format(path=run)}")
    return OwnEvaluatorEmbedder(load_evaluator(run, device=args.device)), f"motok-robot evaluator ({run})"


def _protocol_config(args: argparse.Namespace):
    from motok_robot.eval.config import GenerationEvalConfig

    cfg = GenerationEvalConfig(seed=args.seed)
    _positive("repeats", args.repeats)
    _positive("max-clips", args.max_clips)
    if args.repeats is not None:
        cfg.repeats = args.repeats
    cfg.max_clips = args.max_clips
    for name in ("mm_texts", "mm_repeats", "batch_size"):
        value = getattr(args, name, None)
        _positive(name.replace("_", "-"), value, allow_zero=name != "batch_size")
        if value is not None:
            setattr(cfg, name, value)
    if cfg.mm_texts == 0:
        cfg.mm_repeats = 0
    return cfg


def _load_clips(args: argparse.Namespace, embedder, cfg):
    from motok_robot.eval.protocol import clips_from_dataset, sample_clips

    test = clips_from_dataset(_load_split(args.data, "test"), embedder.min_frames, cfg.max_clips)
    reference = None
    if not args.no_train_reference:
        reference = sample_clips(_load_split(args.data, "train"), embedder.min_frames, len(test), seed=cfg.seed)
    return test, reference


def _write_outputs(args: argparse.Namespace, table: str, payload: dict) -> None:
    print(table)
    if args.markdown is not None:
        args.markdown.parent.mkdir(parents=True, exist_ok=True)
        args.markdown.write_text(table + "\n")
        print(f"table written to {args.markdown}")
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(payload, indent=2))
        print(f"results written to {args.json}")


def _config_file(path: Path | None, cfg):
    from motok_robot.eval.config import EvaluatorConfig

    if path is None:
        return cfg
    from motok_robot.config_utils import read_json_object

    data = read_json_object(path, "--config")
    try:
        return EvaluatorConfig.from_dict({**cfg.to_dict(), **data})
    except InputError as exc:
        raise InputError(f"--config {path}: {exc}") from None


def _command_line(prefix: str, args: argparse.Namespace) -> str:
    """The command that reproduces ``args`` (options in long form, defaults left out)."""
    parts = ["motok-robot"]
    for assignment in getattr(args, "size_limits", None) or []:  # the top-level --limit NAME=VALUE
        parts += ["--limit", str(assignment)]
    parts += prefix.split()
    skip = {"func", "command", "train_command", "eval_command", "data_command", "robots_command", "servo_command",
            "size_limits"}
    for key, value in vars(args).items():
        if key in skip or value is None or value is False or (isinstance(value, list) and not value):
            continue
        flag = "--" + key.replace("_", "-")
        if value is True:
            parts.append(flag)
        elif isinstance(value, list):
            parts += [flag, *(str(v) for v in value)]
        else:
            parts += [flag, str(value)]
    return " ".join(shlex.quote(p) for p in parts)


# -- handlers -------------------------------------------------------------------------------------
def _train_evaluator(args: argparse.Namespace) -> int:
    from motok_robot.eval.config import EvaluatorConfig, default_evaluator_dir
    from motok_robot.eval.train_evaluator import CachedTextEmbedder, train_evaluator
    from motok_robot.text import load_text_encoder

    for name in ("steps", "batch_size", "eval_every"):
        _positive(name.replace("_", "-"), getattr(args, name))
    train_set = _load_split(args.data, "train")
    val_set = _load_split(args.data, "val")
    for split in (train_set, val_set):
        if not split.clip_ids:
            raise InputError(f"{args.data}: the {split.split} split is empty; the evaluator needs train and val clips")
    out = args.out or default_evaluator_dir()
    cfg = EvaluatorConfig()
    saved = out / "config.json"
    if args.resume:
        if args.config is not None:
            raise InputError("--config cannot be combined with --resume: the run's own config.json is used")
        if not (out / "train_state.safetensors").is_file():
            raise InputError(f"--resume: no checkpoint {out / 'train_state.safetensors'}; start a run without --resume")
        cfg = EvaluatorConfig.from_dict(json.loads(saved.read_text())["evaluator"])
        if args.text_encoder is not None and args.text_encoder != cfg.text_encoder:
            raise InputError(f"--resume: the run in {out} uses text encoder {cfg.text_encoder!r}, not {args.text_encoder!r}")
    elif (out / "train_state.safetensors").is_file():
        raise InputError(f"{out} already holds an evaluator run; pass --resume to continue it or choose another --out")
    else:
        cfg = _config_file(args.config, cfg)
    for name in ("steps", "batch_size", "eval_every", "seed"):
        if getattr(args, name) is not None:
            if args.resume and name in ("batch_size", "seed") and getattr(args, name) != getattr(cfg, name):
                raise InputError(f"--resume: --{name.replace('_', '-')} differs from the run's ({getattr(cfg, name)})")
            setattr(cfg, name, getattr(args, name))
    if args.text_encoder is not None:
        cfg.text_encoder = args.text_encoder
    encoder = load_text_encoder(cfg.text_encoder, device=args.device)
    embed = CachedTextEmbedder(lambda texts: encoder.encode(texts).numpy(), encoder.name,
                               out / "cache" / "captions.npz")
    meta = {"command": _command_line("train evaluator", args), "data": str(Path(args.data).resolve()), "text_encoder": encoder.name}
    run = train_evaluator(train_set, val_set, embed, encoder.dim, out, cfg, resume=args.resume, device=args.device,
                          meta=meta)
    print(f"evaluator written to {run} (validation R-precision per step in {run / 'metrics.csv'})")
    return 0


def _eval_generation(args: argparse.Namespace) -> int:
    from motok_robot.eval.generation import planner_generate_fn, resolve_models
    from motok_robot.eval.protocol import format_table, run_protocol

    cfg = _protocol_config(args)
    _wants_official(args)
    _positive("steps", args.steps)
    _positive("decoder-steps", args.decoder_steps)
    _load_split(args.data, "test")  # fail early (cheap), before loading any model
    specs = resolve_models(args.model, args.planner, args.tokenizer)
    embedder, evaluator_name = load_embedder(args)
    test, reference = _load_clips(args, embedder, cfg)

    from motok_robot.planner.generate import MotionGenerator

    generators = {}
    model_ids = {}
    for spec in specs:
        gen = MotionGenerator(spec.kind, spec.tokenizer_run, spec.planner_run, device=args.device)
        generators[spec.name] = planner_generate_fn(gen, cfg_scale=args.cfg, steps=args.steps,
                                                    decoder_steps=args.decoder_steps)
        model_ids[spec.name] = gen.model_id
    result = run_protocol(test, embedder, generators, cfg, reference)
    title = f"Generation quality on {args.data} (test split), evaluator: {evaluator_name}"
    payload = {"command": _command_line("eval generation", args), "evaluator": evaluator_name, "data": str(args.data),
               "models": model_ids, **result.to_dict()}
    _write_outputs(args, format_table(result, title), payload)
    return 0


def _eval_evaluator(args: argparse.Namespace) -> int:
    from motok_robot.eval.protocol import clips_from_dataset, content_matched_clips, format_table, sample_clips
    from motok_robot.eval.sanity import evaluator_sanity, format_sanity

    cfg = _protocol_config(args)
    _wants_official(args)
    embedder, evaluator_name = load_embedder(args)
    test_set = _load_split(args.data, "test")
    test = clips_from_dataset(test_set, embedder.min_frames, cfg.max_clips)
    # datasets prepared before --split-by existed were split by group
    split_by = test_set.summary().get("split_by", "group")
    reference = floor = matched = None
    if not args.no_train_reference:  # two disjoint train samples as large as the test set
        train = _load_split(args.data, "train")
        both = sample_clips(train, embedder.min_frames, 2 * len(test), seed=cfg.seed)
        reference, floor = both[: len(test)], both[len(test) :] or None
        matched = content_matched_clips(test, train, embedder.min_frames, seed=cfg.seed)
    report = evaluator_sanity(test, embedder, cfg, reference, floor, matched)
    title = f"Evaluator sanity on {args.data} (test split), evaluator: {evaluator_name}"
    table = format_table(report.result, title) + "\n\n" + format_sanity(report)
    check = report.checks.get("fid_test_vs_train_small")
    if check is not None and not check["passed"] and split_by == "group":
        table += ("\nThis dataset holds out whole content+style groups (data prepare --split-by group), so its test "
                  "motions are unlike the train ones and test vs train FID stays large even for a good evaluator; "
                  "the check is meant for a split by clip (--split-by clip, docs/evaluation.md).")
    payload = {"command": _command_line("eval evaluator", args), "evaluator": evaluator_name, "data": str(args.data),
               "split_by": split_by, **report.to_dict()}
    _write_outputs(args, table, payload)
    return 0

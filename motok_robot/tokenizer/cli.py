"""CLI of the tokenizer stage: ``motok-robot train tokenizer`` and ``motok-robot eval reconstruct``.

Light module: torch and the models are imported inside the handlers.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from motok_robot.errors import InputError
from motok_robot.paths import models_dir


def default_tokenizer_dir() -> Path:
    """``$MOTOK_ROBOT_MODELS/tokenizer`` or ``models/tokenizer`` at the repository root."""
    return models_dir() / "tokenizer"


def register(commands, groups) -> None:
    train = groups["train"].add_parser(
        "tokenizer",
        help="train the MoTok tokenizer (conv encoder, one codebook, diffusion decoder)",
        description="Train a MoTok tokenizer on the train split of a prepared dataset. Writes RUN/config.json, "
        "RUN/model.safetensors, a resumable RUN/train_state.safetensors (optimiser, RNG; safetensors, no pickle) "
        "and RUN/metrics.csv (validation reconstruction per epoch).",
    )
    train.add_argument("--data", required=True, type=Path, help="prepared dataset directory (motok-robot data prepare)")
    train.add_argument("--out", required=True, type=Path, help="run directory to write")
    train.add_argument("--config", type=Path, default=None,
                       help="JSON file with optional 'tokenizer' and 'train' sections overriding the defaults")
    train.add_argument("--resume", action="store_true", help="continue the run in --out from its last checkpoint")
    train.add_argument("--epochs", type=int, default=None,
                       help="train for this many epochs instead of a step count (ignored when --steps is given)")
    train.add_argument("--steps", type=int, default=None, help="optimiser steps in total (default 5000)")
    train.add_argument("--batch-size", type=int, default=None, help="windows per step (default 64)")
    train.add_argument("--seed", type=int, default=None, help="random seed (default 0)")
    train.add_argument("--device", default=None, help="cpu or cuda (default cpu)")
    train.add_argument("--threads", type=int, default=None, help="torch CPU threads (default: torch's)")
    train.add_argument("--init-from", type=Path, default=None,
                       help="start from the weights (and architecture) of this tokenizer run")
    train.add_argument("--only-actions", nargs="+", default=None, metavar="LABEL",
                       help="train and validate only on the clips of these action labels (e.g. bow)")
    train.add_argument("--action-share", nargs="+", default=None, metavar="LABEL=SHARE",
                       help="draw the clips of an action label with this share of all windows (e.g. bow=0.05)")
    train.add_argument("--freeze-tokens", action="store_true",
                       help="with --init-from: train only the decoder side; encoder and codebook stay fixed, so "
                       "every clip keeps its tokens and planners trained on them stay valid")
    train.set_defaults(func=_train)

    rec = groups["eval"].add_parser(
        "reconstruct",
        help="encode + decode every clip of a prepared dataset; MPJPE, root error, foot skating, codebook usage",
        description="Reconstruction quality of a tokenizer on any prepared dataset (also one it never saw).",
    )
    rec.add_argument("--data", required=True, type=Path, help="prepared dataset directory")
    rec.add_argument("--split", default="test", choices=("train", "val", "test", "all"), help="split (default test)")
    rec.add_argument("--tokenizer", type=Path, default=None, help="tokenizer run directory (default models/tokenizer)")
    rec.add_argument("--steps", type=int, default=None, help="DDIM steps (default: the tokenizer's)")
    rec.add_argument("--seed", type=int, default=0, help="noise seed of the decoder (default 0)")
    rec.add_argument("--limit", type=int, default=None, help="evaluate the first N clips only")
    rec.add_argument("--device", default=None, help="cpu or cuda (default: cuda if available)")
    rec.add_argument("--json", type=Path, default=None, help="also write the metrics to this JSON file")
    rec.add_argument("--plot", type=Path, default=None,
                     help="PNG of the worst, median and best clips: root path, MPJPE per frame, foot heights")
    rec.set_defaults(func=_reconstruct)


def _train(args) -> int:
    from motok_robot.tokenizer.config import read_config_file, tokenizer_config_from_dict, train_config_from_dict

    tok_section, train_section = read_config_file(args.config) if args.config else ({}, {})
    for flag, key in (("epochs", "epochs"), ("steps", "steps"), ("batch_size", "batch_size"), ("seed", "seed"),
                      ("device", "device"), ("threads", "num_threads")):
        value = getattr(args, flag)
        if value is not None:
            train_section[key] = value
    if args.epochs is not None and args.steps is None:
        train_section["steps"] = 0  # the epoch count decides the length
    if args.init_from is not None:
        train_section["init_from"] = str(args.init_from)
    if args.freeze_tokens:
        train_section["freeze_tokens"] = True
    if args.only_actions:
        train_section["only_actions"] = list(args.only_actions)
    if args.action_share:
        from motok_robot.data.groups import parse_action_shares

        train_section["action_share"] = parse_action_shares(args.action_share)
    where = str(args.config) if args.config else "defaults"
    tok_cfg = tokenizer_config_from_dict(tok_section, where=f"{where} 'tokenizer'")
    train_cfg = train_config_from_dict(train_section, where=f"{where} 'train'")

    import torch  # noqa: F401  (heavy imports only now)

    from motok_robot.tokenizer.train import dataset_statistics, load_split, resume_conflicts, train_tokenizer

    if args.resume:
        changed = resume_conflicts(args.out, tok_section, train_section)
        if changed:
            raise InputError(f"--resume continues {args.out} with its own config.json, and the command asks for other "
                             f"settings: {'; '.join(changed)}. Drop them, or start a new run in another --out")

    train_clips = load_split(args.data, "train")
    val_clips = load_split(args.data, "val")
    mean, std = dataset_statistics(args.data)
    print(f"train clips {len(train_clips.ids)}, val clips {len(val_clips.ids)} from {args.data}")
    overrides = {key: train_section[key] for key in ("steps", "epochs", "device", "num_threads") if key in train_section}
    summary = train_tokenizer(
        train_clips, val_clips if val_clips.ids else None, mean, std, args.out,
        tok_cfg if tok_section else None, train_cfg, resume=args.resume, overrides=overrides if args.resume else None,
    )
    last = summary.get("last") or {}
    print(json.dumps({k: v for k, v in summary.items() if k != "last"}))
    if last:
        shown = {k: last[k] for k in ("epoch", "step", "train_loss", "val_mpjpe_cm", "val_usage") if k in last}
        print("last epoch:", json.dumps(shown))
    return 0


def _reconstruct(args) -> int:
    from motok_robot.tokenizer.checkpoint import load_tokenizer
    from motok_robot.tokenizer.evaluate import reconstruct_dataset

    run = args.tokenizer or default_tokenizer_dir()
    if not (Path(run) / "model.safetensors").is_file():
        raise InputError(f"no trained tokenizer in {run} (config.json + model.safetensors); "
                         f"train one with: motok-robot train tokenizer --data DIR --out {run}")
    tokenizer = load_tokenizer(run, device=args.device)
    result = reconstruct_dataset(tokenizer, args.data, args.split, steps=args.steps, seed=args.seed, limit=args.limit)
    result["tokenizer"] = str(run)
    keys = ("clips", "seconds_of_motion", "mpjpe_cm", "mpjpe_root_aligned_cm", "root_trajectory_error_cm",
            "foot_skating_ratio_reconstructed", "foot_skating_ratio_original", "codebook_usage", "perplexity",
            "token_rate_hz", "tokens_per_second", "realtime_factor")
    width = max(len(k) for k in keys)
    for key in keys:
        value = result[key]
        print(f"{key:<{width}}  {value:.4g}" if isinstance(value, float) and math.isfinite(value) else f"{key:<{width}}  {value}")
    if args.plot:
        from motok_robot.data.dataset import PreparedDataset
        from motok_robot.tokenizer.evaluate import plot_reconstructions

        ranked = [c["id"] for c in result["clip_errors"]]
        chosen = list(dict.fromkeys([ranked[0], ranked[len(ranked) // 2], ranked[-1]]))
        dataset = PreparedDataset(args.data, args.split)
        plot_reconstructions(tokenizer, [(i, dataset.features(i)) for i in chosen], args.plot, steps=args.steps, seed=args.seed)
        print(f"wrote {args.plot}")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(result, indent=2) + "\n")
        print(f"wrote {args.json}")
    return 0

"""Training loop of the planners (``motok-robot train planner``).

Seeded (torch + numpy generators saved in the checkpoint, so a resumed run continues the same
random stream), resumable after a kill (``--resume``), can start from a trained planner
(``--init-from``, fine-tuning), progress bar, periodic validation
(loss and token accuracy, length-estimator accuracy) logged to ``RUN/metrics.csv``,
safetensors checkpoints only.
"""

from __future__ import annotations

import csv
import json
import math
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from motok_robot.checkpoint import WEIGHTS_FILE, load_checked_weights, load_training_state, save_training_state
from motok_robot.config_utils import changed_fields
from motok_robot.errors import InputError
from motok_robot.planner.checkpoint import (
    CONFIG_FILE, atomic_write_text, build_planner, read_run_config, save_planner_weights, tokenizer_mismatch,
    tokenizer_record, write_run_config,
)
from motok_robot.planner.config import (
    PlannerConfig, PlannerTrainConfig, planner_config_from_dict, saved_planner_config, to_dict, train_config_from_dict,
)
from motok_robot.planner.data import PlannerData, action_labels_of, excluded_clips, load_planner_data, open_dataset

CHECKPOINT_FILE = "checkpoint.safetensors"
STATE_FILE = "train_state.json"
METRICS_FILE = "metrics.csv"
METRIC_FIELDS = ["step", "lr", "train_loss", "train_accuracy", "val_loss", "val_accuracy", "val_length_loss",
                 "val_length_within_1", "seconds"]


def _lr_at(step: int, cfg: PlannerTrainConfig) -> float:
    if step < cfg.warmup_steps:
        return cfg.lr * (step + 1) / cfg.warmup_steps
    progress = (step - cfg.warmup_steps) / max(1, cfg.steps - cfg.warmup_steps)
    return cfg.lr * 0.5 * (1.0 + math.cos(math.pi * min(1.0, progress)))


@torch.no_grad()
def evaluate(model, data: PlannerData, cfg: PlannerTrainConfig, device) -> dict[str, float]:
    """Validation loss / token accuracy (fixed seed, first crops, no control) + length estimator."""
    model.eval()
    rng = np.random.default_rng(1234)
    gen = torch.Generator().manual_seed(1234)
    totals = {"loss": 0.0, "acc": 0.0, "count": 0.0, "len_loss": 0.0, "len_ok": 0.0, "n": 0.0}
    order = np.arange(len(data))
    for start in range(0, min(len(data), cfg.val_batches * cfg.batch_size), cfg.batch_size):
        idx = order[start:start + cfg.batch_size].tolist()
        tokens, lengths, ends, cond, full = data.batch(idx, rng, None, random_crop=False)
        out = model.loss(tokens.to(device), lengths.to(device), cond.to(device), gen, ends=ends.to(device))
        c = float(out["count"])
        totals["loss"] += float(out["loss"]) * c
        totals["acc"] += float(out["accuracy"]) * c
        totals["count"] += c
        has_text = cond.text_present if cond.text_present is not None else torch.zeros(len(idx), dtype=torch.bool)
        if cond.text_embedding is not None and bool(has_text.any()):
            emb = cond.text_embedding[has_text].to(device)
            target = full[has_text].to(device).clamp(1, model.config.max_tokens)
            totals["len_loss"] += float(model.length_estimator.loss(emb, target)) * len(target)
            pred = model.length_estimator.predict(emb)
            totals["len_ok"] += float(((pred - target).abs() <= 1).sum())
            totals["n"] += len(target)
    model.train()
    n = max(totals["n"], 1.0)
    count = max(totals["count"], 1.0)
    return {"val_loss": totals["loss"] / count, "val_accuracy": totals["acc"] / count,
            "val_length_loss": totals["len_loss"] / n, "val_length_within_1": totals["len_ok"] / n}


def _resume_conflicts(config: PlannerConfig, train_cfg: PlannerTrainConfig, planner_overrides: dict | None,
                      train_overrides: dict | None, seed: int | None, text_encoder: str | None) -> list[str]:
    """The settings a ``--resume`` command asks for that differ from the run's saved config, as
    ``"section.field is SAVED (asked ASKED)"``: a resumed run keeps its config, so a different value
    would otherwise be dropped without a word.  ``steps`` may change (extending a run); the device may too."""
    changed: list[str] = []
    if planner_overrides:
        saved = to_dict(config)
        asked = to_dict(planner_config_from_dict({**saved, **planner_overrides, "kind": config.kind},
                                                 where="--config 'planner'"))
        changed += changed_fields("planner", saved, asked, planner_overrides)
    train_asked = {key: value for key, value in (train_overrides or {}).items() if key not in ("steps", "device")}
    if seed is not None:
        train_asked["seed"] = int(seed)
    if train_asked:
        saved = to_dict(train_cfg)
        asked_cfg = train_config_from_dict({**saved, **train_asked}, where="--config 'train'")
        asked_cfg.validate(config.kind)
        changed += changed_fields("train", saved, to_dict(asked_cfg), train_asked)
    if text_encoder is not None and text_encoder != config.text_encoder:
        changed.append(f"planner.text_encoder is {config.text_encoder!r} (asked {text_encoder!r})")
    return changed


def train_planner(
    data_dir: str | Path,
    tokenizer_run: str | Path,
    kind: str,
    out_dir: str | Path,
    resume: bool = False,
    seed: int | None = None,
    planner_overrides: dict | None = None,
    train_overrides: dict | None = None,
    text_encoder: str | None = None,
    device: str | None = None,
    init_from: str | Path | None = None,
) -> Path:
    """Train a planner of ``kind`` ("masked" | "ar") on a prepared dataset; returns the run directory.

    ``init_from`` names a trained planner run to start from (fine-tuning): its architecture, text
    encoder and weights are taken, the optimiser and the learning-rate schedule start afresh with
    this run's training settings, and the tokenizer and action labels must be the ones it was
    trained with.  ``planner_overrides`` may then only switch on the modules of
    :data:`SWITCHES_ON_INIT`, which start at zero."""
    from motok_robot.text import load_text_encoder
    from motok_robot.tokenizer import load_tokenizer

    out = Path(out_dir)
    ckpt = out / CHECKPOINT_FILE
    if resume and init_from is not None:
        raise InputError("--init-from starts a new run from trained weights; it cannot be combined with --resume")
    if resume:
        if not ckpt.is_file():
            raise InputError(f"--resume: {ckpt} not found (start a new run without --resume)")
        saved = read_run_config(out)
        config = saved_planner_config(saved["planner"], where=f"{out / CONFIG_FILE} 'planner'")
        train_cfg = train_config_from_dict(saved.get("train", {}), where=f"{out / CONFIG_FILE} 'train'")
        if config.kind != kind:
            raise InputError(f"--resume: {out} is a {config.kind!r} planner run, not {kind!r}")
        changed = _resume_conflicts(config, train_cfg, planner_overrides, train_overrides, seed, text_encoder)
        if changed:
            raise InputError(f"--resume continues {out} with its own {CONFIG_FILE}, and the command asks for other "
                             f"settings: {'; '.join(changed)}. Drop them, or start a new run in another --out")
        if train_overrides and "steps" in train_overrides:
            train_cfg.steps = int(train_overrides["steps"])  # allow extending a finished run
    else:
        if ckpt.is_file():
            raise InputError(f"{out} already holds a planner run; pass --resume to continue it or choose another --out")
        config = PlannerConfig(kind=kind)
        train_cfg = PlannerTrainConfig()
        if init_from is not None:
            init_saved, config, added = _init_run_config(init_from, kind, planner_overrides, text_encoder)
        elif planner_overrides:
            config = planner_config_from_dict({**to_dict(config), **planner_overrides, "kind": kind})
        if train_overrides:
            merged = {**to_dict(train_cfg), **train_overrides}
            train_cfg = train_config_from_dict(merged)
        if seed is not None:
            train_cfg.seed = int(seed)
        if text_encoder is not None and init_from is None:
            config.text_encoder = text_encoder
    if device is not None:
        train_cfg.device = device
    train_cfg.validate(kind)
    dev = torch.device(train_cfg.device)
    torch.manual_seed(train_cfg.seed)

    tok_dir = Path(tokenizer_run)
    tokenizer = load_tokenizer(tok_dir, device=dev)
    record = tokenizer_record(tok_dir, tokenizer)
    tokenizer_key = record["tokens_sha256"]
    mismatch = tokenizer_mismatch(saved.get("tokenizer") or {}, tok_dir, tokenizer) if resume else None
    if mismatch:
        raise InputError(f"--resume: tokenizer {tok_dir} is not the one this run was trained with: {mismatch}")
    if init_from is not None:
        mismatch = tokenizer_mismatch(init_saved.get("tokenizer") or {}, tok_dir, tokenizer)
        if mismatch:
            raise InputError(f"--init-from {init_from}: tokenizer {tok_dir} is not the one that planner was trained with: {mismatch}")
        labels = action_labels_of(data_dir, "train")
        if list(labels) != list(config.action_labels):
            raise InputError(f"--init-from {init_from}: the action labels of {data_dir} ({len(labels)}) differ from the ones "
                             f"that planner was trained with ({len(config.action_labels)}); fine-tune on data with "
                             "the same labels, or train a new planner")
    encoder = load_text_encoder(config.text_encoder)
    if not resume and init_from is None:
        config = replace(config, codebook_size=tokenizer.config.codebook_size, downsample=tokenizer.frames_per_token,
                         fps=int(getattr(tokenizer.config, "fps", config.fps)), text_dim=encoder.dim,
                         action_labels=action_labels_of(data_dir, "train"))
        config.validate()
    unknown = [label for label in train_cfg.action_share if label not in config.action_labels]
    if unknown:  # before the run folder is written and the clips are tokenised
        raise InputError(f"train config: action_share names {unknown[0]!r}, which no clip of {data_dir} has "
                         f"(labels there: {', '.join(sorted(config.action_labels)) or 'none'})")
    if train_cfg.exclude_clips:  # also before the run folder is written: a wrong id is an error naming it
        left_out = excluded_clips(open_dataset(data_dir, "train"), train_cfg.exclude_clips, f"{data_dir} (train split)")
        print(f"left out of training: {len(left_out)} clips ({len(train_cfg.exclude_clips)} named in exclude_clips, "
              "with their mirrors)")
    extra = {"train": to_dict(train_cfg),
             "tokenizer": record,
             "text_encoder": encoder.name, "data": str(Path(data_dir).resolve())}
    if init_from is not None:
        extra["init_from"] = init_record(init_from)
    elif resume and saved.get("init_from"):
        extra["init_from"] = saved["init_from"]
    write_run_config(out, config, extra)

    cache = out / "cache"
    train_data = load_planner_data(data_dir, "train", tokenizer, tokenizer_key, encoder, cache,
                                   config.action_labels, config.max_tokens, phases=train_cfg.token_phases,
                                   exclude=train_cfg.exclude_clips)
    try:
        val_data = load_planner_data(data_dir, "val", tokenizer, tokenizer_key, encoder, cache,
                                     config.action_labels, config.max_tokens)
    except InputError as exc:  # tiny datasets without a usable val split
        print(f"warning: no usable val split ({exc}); validation metrics are computed on the train split")
        val_data = train_data
    del tokenizer

    draw_p = train_data.sampling_probabilities(train_cfg.balance_groups, train_cfg.action_share, config.action_labels)
    model = build_planner(config).to(dev)
    if init_from is not None:
        with torch.no_grad():  # switched-on modules start at zero: the fine-tune starts from the named model
            for name, param in model.named_parameters():
                if name.startswith(added):
                    param.zero_()
        load_checked_weights(model, Path(init_from) / WEIGHTS_FILE, may_lack=added)
    decay = [p for n, p in model.named_parameters() if p.dim() >= 2]
    no_decay = [p for n, p in model.named_parameters() if p.dim() < 2]
    optimiser = torch.optim.AdamW([{"params": decay, "weight_decay": train_cfg.weight_decay},
                                   {"params": no_decay, "weight_decay": 0.0}], lr=train_cfg.lr, betas=(0.9, 0.98))
    generator = torch.Generator().manual_seed(train_cfg.seed)
    rng = np.random.default_rng(train_cfg.seed)
    step = 0
    if resume:
        step, extra_t = load_training_state(ckpt, model, optimiser)
        if "torch_rng" in extra_t:
            generator.set_state(extra_t["torch_rng"].to(torch.uint8))
        if "global_rng" in extra_t:  # dropout draws from the global generator
            torch.set_rng_state(extra_t["global_rng"].to(torch.uint8))
        state = json.loads((out / STATE_FILE).read_text()) if (out / STATE_FILE).is_file() else {}
        if "numpy_rng" in state:
            rng.bit_generator.state = state["numpy_rng"]
    metrics_path = out / METRICS_FILE
    if not metrics_path.is_file():
        with open(metrics_path, "w", newline="") as fh:
            csv.writer(fh).writerow(METRIC_FIELDS)
    best_loss = _best_val_loss(metrics_path, step) if resume else float("inf")

    # the kind-specific loss switches (the masked and AR losses take different keywords)
    loss_options: dict = {"corruption": train_cfg.input_corruption} if train_cfg.input_corruption > 0 else {}
    if train_cfg.masked_loss_average == "sample":
        loss_options["per_sample"] = True
    model.train()
    t0 = time.time()
    running_loss, running_acc, running_n = 0.0, 0.0, 0
    bar = tqdm(total=train_cfg.steps, initial=step, desc=f"train planner ({kind})", unit="step", disable=None)
    while step < train_cfg.steps:
        lr = _lr_at(step, train_cfg)
        for group in optimiser.param_groups:
            group["lr"] = lr
        if draw_p is None:
            idx = rng.integers(0, len(train_data), size=train_cfg.batch_size).tolist()
        else:
            idx = rng.choice(len(train_data), size=train_cfg.batch_size, p=draw_p).tolist()
        tokens, lengths, ends, cond, full = train_data.batch(idx, rng, train_cfg.control,
                                                             action_prob=train_cfg.action_prob)
        cond = cond.to(dev)
        drop = torch.rand(len(idx), generator=generator) < train_cfg.cond_drop_prob
        if config.end_embedding and train_cfg.end_unknown_prob > 0:  # some ends stay unknown (no length given)
            ends = ends & (torch.rand(len(idx), generator=generator) >= train_cfg.end_unknown_prob)
        out_loss = model.loss(tokens.to(dev), lengths.to(dev), cond, generator, drop=drop.to(dev), ends=ends.to(dev),
                              **loss_options)
        loss = out_loss["loss"]
        if cond.text_embedding is not None and cond.text_present is not None and bool(cond.text_present.any()):
            has = cond.text_present
            loss = loss + train_cfg.length_loss_weight * model.length_estimator.loss(
                cond.text_embedding[has], full.to(dev)[has])
        optimiser.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), train_cfg.grad_clip)
        optimiser.step()
        step += 1
        running_loss += float(out_loss["loss"].detach())
        running_acc += float(out_loss["accuracy"].detach())
        running_n += 1
        bar.update(1)
        bar.set_postfix(loss=f"{float(out_loss['loss'].detach()):.3f}", acc=f"{float(out_loss['accuracy'].detach()):.3f}")
        if step % train_cfg.val_every == 0 or step == train_cfg.steps:
            metrics = evaluate(model, val_data, train_cfg, dev)
            row = {"step": step, "lr": lr, "train_loss": running_loss / running_n,
                   "train_accuracy": running_acc / running_n, **metrics, "seconds": time.time() - t0}
            with open(metrics_path, "a", newline="") as fh:
                csv.writer(fh).writerow([f"{row[k]:.6g}" if isinstance(row[k], float) else row[k] for k in METRIC_FIELDS])
            running_loss, running_acc, running_n = 0.0, 0.0, 0
            improved = metrics["val_loss"] < best_loss
            if improved or not train_cfg.keep_best:
                save_planner_weights(model, out)
            best_loss = min(best_loss, metrics["val_loss"])
            save_training_state(ckpt, model, optimiser, step, extra={"torch_rng": generator.get_state(),
                                                                           "global_rng": torch.get_rng_state()})
            atomic_write_text(out / STATE_FILE, json.dumps({"numpy_rng": rng.bit_generator.state, "step": step}))
            kept = " (kept in model.safetensors)" if improved and train_cfg.keep_best else ""
            bar.write(f"step {step}: val loss {metrics['val_loss']:.4f}, token accuracy {metrics['val_accuracy']:.3f}{kept}")
    bar.close()
    return out


#: Architecture switches a fine-tune (``--init-from``) may turn on, each with the name prefix of the
#: parameters it adds.  Those start at zero, so the fine-tune starts from exactly the named model.
SWITCHES_ON_INIT = {"end_embedding": "end_embedding."}


def _init_run_config(init_from: str | Path, kind: str, planner_overrides: dict | None,
                     text_encoder: str | None) -> tuple[dict, PlannerConfig, tuple[str, ...]]:
    """The run config and architecture of the planner run ``--init-from`` names, checked for a
    fine-tune, with the switches of :data:`SWITCHES_ON_INIT` the ``planner`` overrides turn on;
    also the name prefixes of the parameters those add."""
    init_from = Path(init_from)
    if not (init_from / WEIGHTS_FILE).is_file():
        raise InputError(f"--init-from {init_from}: no {WEIGHTS_FILE} there (expected a trained planner run directory)")
    saved = read_run_config(init_from)
    config = saved_planner_config(saved["planner"], where=f"{init_from / CONFIG_FILE} 'planner'")
    if config.kind != kind:
        raise InputError(f"--init-from {init_from} is a {config.kind!r} planner run, not {kind!r}")
    overrides = dict(planner_overrides or {})
    other = sorted(k for k in overrides if k not in SWITCHES_ON_INIT)
    if other:
        raise InputError(f"--init-from {init_from}: the architecture comes from that run; remove {', '.join(other)} "
                         f"from the 'planner' section of --config (a fine-tune may only switch on "
                         f"{', '.join(SWITCHES_ON_INIT)})")
    added = []
    for key, value in overrides.items():
        if value is not True and value != getattr(config, key):
            raise InputError(f"--init-from {init_from}: 'planner' {key} can only be switched on (true) in a fine-tune "
                             f"(that run has {getattr(config, key)!r}, --config asks for {value!r})")
        if value is True and not getattr(config, key):
            added.append(SWITCHES_ON_INIT[key])
    config = replace(config, **overrides).validate()
    if text_encoder is not None and text_encoder != config.text_encoder:
        raise InputError(f"--init-from {init_from} was trained with text encoder {config.text_encoder!r}, not {text_encoder!r}")
    return saved, config, tuple(added)


def init_record(init_from: str | Path) -> dict[str, str]:
    """What a fine-tuned run stores about the run it started from: path and weights digest."""
    from motok_robot.planner.data import file_digest

    init_from = Path(init_from)
    return {"path": str(init_from.resolve()), "sha256": file_digest(init_from / WEIGHTS_FILE)}


def _best_val_loss(metrics_path: Path, step: int) -> float:
    """Lowest val loss logged up to ``step`` (inf when none): where a resumed run's
    ``keep_best`` continues from."""
    with open(metrics_path, newline="") as fh:
        losses = [float(r["val_loss"]) for r in csv.DictReader(fh) if r.get("val_loss") and int(float(r["step"])) <= step]
    return min(losses, default=float("inf"))

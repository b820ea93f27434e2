# Size (475 lines): one resumable training loop and the state it saves.
"""Training of a MoTok tokenizer: windows of motion features -> AdamW on the tokenizer losses.

Deterministic given ``TrainConfig.seed``: the initialisation uses ``torch.manual_seed(seed)``
and every later random draw (windows, timesteps, noise, codebook restarts) a dedicated CPU
``torch.Generator`` whose state is saved in the checkpoint, so a run killed and resumed
with ``resume=True`` continues exactly as the uninterrupted run would (on CPU; CUDA kernels
may differ in the last bits).

Checkpoint = ``model.safetensors`` + ``config.json`` (see :mod:`.checkpoint`) +
``train_state.safetensors`` (AdamW moments ``optim.<param index>.<key>``, the generator
state ``rng``; step, epoch, running sums and the AdamW param groups as JSON metadata).
Validation metrics go to ``metrics.csv``, one row per epoch.
"""

from __future__ import annotations

import csv
import json
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from safetensors.torch import load_file
from tqdm import tqdm

from motok_robot.config_utils import changed_fields
from motok_robot.data.groups import action_labels_shown, balanced_weights, clip_group, with_action_shares
from motok_robot.errors import InputError
from motok_robot.tokenizer.checkpoint import CONFIG_FILE, WEIGHTS_FILE, atomic_save_tensors, read_run_config, save_tokenizer
from motok_robot.tokenizer.config import TokenizerConfig, TrainConfig, to_dict, tokenizer_config_from_dict, train_config_from_dict
from motok_robot.tokenizer.model import MoTok
from motok_robot.tokenizer.quantizer import code_statistics

STATE_FILE = "train_state.safetensors"
RESUME_OVERRIDES = ("steps", "epochs", "device", "num_threads")
METRICS_FILE = "metrics.csv"
METRIC_COLUMNS = (
    "epoch",
    "step",
    "lr",
    "train_loss",
    "train_reconstruction",
    "train_commitment",
    "train_perplexity",
    "train_usage",
    "val_feature_mse",
    "val_mpjpe_cm",
    "val_usage",
    "val_perplexity",
    "restarts",
    "focus_error_cm",
    "focus_error_p90_cm",
    "seconds",
)
_RUNNING = ("loss", "reconstruction", "commitment", "perplexity", "usage")


@dataclass
class Clips:
    """Feature sequences of one split: ``features[i]`` float32 ``[T_i, F]`` (raw), ``ids[i]``,
    and the balancing group of each clip (:func:`motok_robot.data.groups.clip_group`; None: every
    clip its own group)."""

    ids: list[str]
    features: list[np.ndarray]
    groups: list[tuple[str, str]] | None = None

    def with_actions(self, labels: tuple[str, ...], what: str, required: bool = True) -> Clips:
        """The clips whose group is one of the action ``labels``; with ``required``, an error
        naming the labels there when one of them has no clip."""
        have = {g[1] for g in self.groups or [] if g[0] == "action"}
        missing = [label for label in labels if label not in have]
        if missing and required:
            raise InputError(f"only_actions: {what} split has no clip of action {missing} "
                             f"(labels there: {action_labels_shown(self.groups or [])})")
        keep = [i for i, g in enumerate(self.groups or []) if g[0] == "action" and g[1] in labels]
        return Clips([self.ids[i] for i in keep], [self.features[i] for i in keep], [self.groups[i] for i in keep])


class WindowSampler:
    """Random fixed-length windows ``[B, window, F]`` with a mask of real frames ``[B, window]``.

    A clip is drawn with probability proportional to ``max(frames, window)``, so every frame
    of the data is (in expectation) seen equally often, divided by ``n ** balance`` for a clip
    of a group of ``n`` (:func:`~motok_robot.data.groups.balanced_weights`); the clips of the
    action labels in ``shares`` then hold that share of the draws
    (:func:`~motok_robot.data.groups.with_action_shares`); a window starts uniformly inside it.
    Clips shorter than the window are used whole, padded by repeating their last frame (the
    mask excludes the padding from the losses).  Clips shorter than ``min_frames`` are skipped.
    """

    def __init__(self, clips: Clips, window: int, min_frames: int = 1, what: str = "train", balance: float = 0.0,
                 shares: dict[str, float] | None = None):
        keep = [i for i, f in enumerate(clips.features) if f.shape[0] >= min_frames]
        if not keep:
            longest = max((f.shape[0] for f in clips.features), default=0)
            raise InputError(f"{what} split: no clip has >= {min_frames} frames (longest {longest})")
        self.window = window
        self.features = [clips.features[i] for i in keep]
        self.skipped = len(clips.features) - len(keep)
        self.padded = sum(f.shape[0] < window for f in self.features)
        groups = [clips.groups[i] for i in keep] if clips.groups is not None else [clips.ids[i] for i in keep]
        self.base = balanced_weights(groups, balance, [max(f.shape[0], window) for f in self.features])
        if shares:
            self.base = with_action_shares(self.base, groups, shares, f"{what} split")
        self.set_focus(np.ones(len(self.features)))

    def set_focus(self, factors: np.ndarray) -> None:
        """Multiply every clip's draw weight by ``factors[i]`` (> 0; see :func:`focus_factors`)."""
        factors = np.asarray(factors, dtype=np.float64)
        if factors.shape != (len(self.features),) or not np.all(np.isfinite(factors) & (factors > 0)):
            raise InputError(f"window sampler: focus needs {len(self.features)} positive finite factors")
        self.focus = factors
        weights = self.base * factors
        self.weights = torch.from_numpy(weights / weights.sum())

    def sample(self, batch: int, generator: torch.Generator) -> tuple[torch.Tensor, torch.Tensor]:
        which = torch.multinomial(self.weights, batch, replacement=True, generator=generator).tolist()
        out = np.empty((batch, self.window, self.features[0].shape[1]), dtype=np.float32)
        mask = np.zeros((batch, self.window), dtype=bool)
        for b, i in enumerate(which):
            clip = self.features[i]
            if clip.shape[0] >= self.window:
                start = int(torch.randint(0, clip.shape[0] - self.window + 1, (1,), generator=generator))
                out[b] = clip[start : start + self.window]
                mask[b] = True
            else:
                out[b, : clip.shape[0]] = clip
                out[b, clip.shape[0] :] = clip[-1]
                mask[b, : clip.shape[0]] = True
        return torch.from_numpy(out), torch.from_numpy(mask)


def clip_errors(model: MoTok, features: list[np.ndarray], progress: bool | None = None) -> np.ndarray:
    """Each clip's root-relative mean joint error (cm) through ``model``: its tokens decoded in
    one deterministic step (the denoiser's clean-motion estimate from noise seed 0; the conv
    decoder's output), so the number does not depend on sampling noise.  The model is put in
    eval mode for the pass and restored after."""
    from motok_robot.motion.features import joints_from_features
    from motok_robot.motion.metrics import mpjpe

    was_training = model.training
    model.eval()
    errors = np.empty(len(features), dtype=np.float64)
    try:
        bar = tqdm(features, desc="clip errors", unit="clip", leave=False, disable=None if progress is None else not progress)
        for i, clip in enumerate(bar):
            x = torch.from_numpy(np.ascontiguousarray(clip[None], dtype=np.float32)).to(model.device)
            decoded = model.reconstruct(x, steps=1, seed=0)[0].cpu().numpy()
            errors[i] = mpjpe(joints_from_features(decoded), joints_from_features(clip), align_root=True) * 100.0
    finally:
        model.train(was_training)
    return errors


def focus_factors(errors: np.ndarray, power: float, cap: float) -> np.ndarray:
    """Draw-weight factors of hard-example sampling: ``(error / mean error) ** power`` clamped
    to ``[1 / cap, cap]`` (all ones when ``power`` is 0)."""
    errors = np.asarray(errors, dtype=np.float64)
    if errors.size == 0 or not np.all(np.isfinite(errors) & (errors >= 0)):
        raise InputError("focus: clip errors must be finite and >= 0")
    mean = errors.mean()
    if power == 0 or mean <= 0:
        return np.ones_like(errors)
    return np.clip((errors / mean) ** power, 1.0 / cap, cap)


def learning_rate(step: int, total: int, cfg: TrainConfig) -> float:
    """Linear warm-up over ``warmup_steps``, then cosine decay to ``lr_min_ratio * lr`` at ``total``."""
    if cfg.warmup_steps and step < cfg.warmup_steps:
        return cfg.lr * (step + 1) / cfg.warmup_steps
    span = max(total - cfg.warmup_steps, 1)
    progress = min(max(step - cfg.warmup_steps, 0) / span, 1.0)
    return cfg.lr * (cfg.lr_min_ratio + (1 - cfg.lr_min_ratio) * 0.5 * (1 + math.cos(math.pi * progress)))


# -- optimiser state <-> safetensors --------------------------------------------------------
def _optimizer_tensors(optimizer: torch.optim.Optimizer) -> tuple[dict[str, torch.Tensor], list[dict[str, Any]]]:
    sd = optimizer.state_dict()
    tensors = {}
    for idx, state in sd["state"].items():
        for key, value in state.items():
            tensors[f"optim.{idx}.{key}"] = value if torch.is_tensor(value) else torch.tensor(value)
    return tensors, sd["param_groups"]


def _load_optimizer(optimizer: torch.optim.Optimizer, tensors: dict[str, torch.Tensor], groups: list[dict[str, Any]]) -> None:
    state: dict[int, dict[str, torch.Tensor]] = {}
    for name, value in tensors.items():
        if not name.startswith("optim."):
            continue
        _, idx, key = name.split(".", 2)
        state.setdefault(int(idx), {})[key] = value
    optimizer.load_state_dict({"state": state, "param_groups": groups})


def _write_metrics(path: Path, rows: list[dict[str, Any]]) -> None:
    tmp = path.with_name(path.name + ".tmp")
    with tmp.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=METRIC_COLUMNS)
        writer.writeheader()
        for row in rows:
            writer.writerow({k: row.get(k, "") for k in METRIC_COLUMNS})
    tmp.replace(path)


def _read_metrics(path: Path) -> list[dict[str, Any]]:
    if not path.is_file():
        return []
    with path.open() as fh:
        return list(csv.DictReader(fh))


# -- validation ----------------------------------------------------------------------------
def validation_windows(clips: Clips, window: int, count: int, seed: int, min_frames: int = 1) -> tuple[torch.Tensor, torch.Tensor] | None:
    """A fixed set of ``count`` windows (and masks) from the val clips, or None."""
    if count < 1 or not any(f.shape[0] >= min_frames for f in clips.features):
        return None
    generator = torch.Generator().manual_seed(seed + 7919)
    return WindowSampler(clips, window, min_frames, "val").sample(count, generator)


@torch.no_grad()
def evaluate_windows(model: MoTok, windows: torch.Tensor, mask: torch.Tensor, steps: int, batch: int = 32) -> dict[str, float]:
    """Reconstruct ``windows [n, T, F]`` (real frames where ``mask [n, T]``): feature MSE
    (normalised units), MPJPE (cm, no alignment), codebook usage and perplexity of their tokens."""
    was_training = model.training
    model.eval()
    from motok_robot.motion.features_torch import joints_from_features

    sq, frames, mpjpe_sum, tokens = 0.0, 0.0, 0.0, []
    for start in range(0, windows.shape[0], batch):
        x = windows[start : start + batch].to(model.device)
        m = mask[start : start + batch].to(model.device).float()
        z = model.encode(x)
        y = model.decode(z, length=x.shape[1], steps=steps, seed=start)
        tokens.append(z.reshape(-1).cpu())
        sq += float(((model.normalise(y) - model.normalise(x)).pow(2).mean(-1) * m).sum())
        # joints of the real frames only: the padding would integrate the root further
        err = (joints_from_features(y) - joints_from_features(x)).norm(dim=-1).mean(-1)  # [b, T]
        mpjpe_sum += float((err * m).sum())
        frames += float(m.sum())
    model.train(was_training)
    stats = code_statistics(torch.cat(tokens), model.config.codebook_size)
    return {
        "val_feature_mse": sq / max(frames, 1.0),
        "val_mpjpe_cm": 100.0 * mpjpe_sum / max(frames, 1.0),
        "val_usage": float(stats["usage"]),
        "val_perplexity": float(stats["perplexity"]),
    }


def _require_resumable(out: Path) -> None:
    if not (out / STATE_FILE).is_file():
        raise InputError(f"{out}: nothing to resume ({STATE_FILE} not found)")


def resume_conflicts(out: str | Path, tokenizer_section: dict[str, Any], train_section: dict[str, Any]) -> list[str]:
    """The settings a ``--resume`` command asks for (its ``--config`` sections and flags) that differ
    from run ``out``'s saved config.json, as ``"section.field is SAVED (asked ASKED)"``: a resumed run
    keeps its config, so a different value would otherwise be dropped without a word.  The fields of
    :data:`RESUME_OVERRIDES` may change; asking for a saved value again is no conflict."""
    out = Path(out)
    _require_resumable(out)
    saved = read_run_config(out)
    changed: list[str] = []
    sections = (("tokenizer", tokenizer_section, tokenizer_config_from_dict),
                ("train", {k: v for k, v in train_section.items() if k not in RESUME_OVERRIDES}, train_config_from_dict))
    for name, asked_values, from_dict in sections:
        if not asked_values:
            continue
        before = to_dict(from_dict(saved.get(name) or {}, where=f"{out / CONFIG_FILE} {name!r}"))
        after = to_dict(from_dict({**before, **asked_values}, where=f"--config {name!r}"))
        changed += changed_fields(name, before, after, asked_values)
    return changed


# -- training loop -------------------------------------------------------------------------
def train_tokenizer(
    train: Clips,
    val: Clips | None,
    mean: np.ndarray,
    std: np.ndarray,
    out: str | Path,
    tokenizer_config: TokenizerConfig | None = None,
    train_config: TrainConfig | None = None,
    *,
    resume: bool = False,
    overrides: dict[str, Any] | None = None,
    progress: bool | None = None,
    stop_at: int | None = None,
) -> dict[str, Any]:
    """Train a tokenizer into run directory ``out``; return a summary dict.

    ``resume=True`` continues from ``out``'s last checkpoint with the run's own config.json
    (the config arguments are ignored); ``overrides`` may change ``steps``, ``epochs``,
    ``device`` and ``num_threads`` (e.g. to train longer).
    ``stop_at`` ends the run after that step with a checkpoint (used to test resuming).
    """
    out = Path(out)
    tok_cfg = tokenizer_config or TokenizerConfig()
    cfg = train_config or TrainConfig()
    state_path = out / STATE_FILE
    if resume:
        _require_resumable(out)
        saved = read_run_config(out)
        tok_cfg = tokenizer_config_from_dict(saved["tokenizer"], where=f"{out / CONFIG_FILE} 'tokenizer'")
        saved_train = dict(saved.get("train") or {})
        for key, value in (overrides or {}).items():
            if key not in RESUME_OVERRIDES:
                raise InputError(f"resume: {key!r} cannot change when resuming (only {sorted(RESUME_OVERRIDES)})")
            saved_train[key] = value
        if (overrides or {}).get("epochs") is not None and "steps" not in (overrides or {}):
            saved_train["steps"] = 0  # --epochs given: the epoch count decides the length
        cfg = train_config_from_dict(saved_train, where=f"{out / CONFIG_FILE} 'train'")
    elif (out / WEIGHTS_FILE).exists() or state_path.exists():
        raise InputError(f"{out}: already holds a tokenizer run; pass --resume to continue it or choose a new --out")
    initial = None
    if cfg.init_from and not resume:
        source = Path(cfg.init_from)
        if not (source / WEIGHTS_FILE).is_file():
            raise InputError(f"init_from: {source} is not a tokenizer run (no {WEIGHTS_FILE})")
        source_cfg = tokenizer_config_from_dict(read_run_config(source)["tokenizer"], where=f"{source / CONFIG_FILE} 'tokenizer'")
        if tokenizer_config is not None and to_dict(tokenizer_config) != to_dict(source_cfg):
            raise InputError(f"init_from: the tokenizer config given differs from {source / CONFIG_FILE}; "
                             "a run started from another keeps its architecture (drop the 'tokenizer' section)")
        tok_cfg, initial = source_cfg, load_file(str(source / WEIGHTS_FILE))
    out.mkdir(parents=True, exist_ok=True)
    if cfg.num_threads:
        torch.set_num_threads(cfg.num_threads)
    if cfg.device.startswith("cuda") and not torch.cuda.is_available():
        raise InputError(f"train config: device {cfg.device!r} requested but CUDA is not available")
    device = torch.device(cfg.device)

    if cfg.only_actions:
        train = train.with_actions(cfg.only_actions, "train")
        val = val.with_actions(cfg.only_actions, "val", required=False) if val is not None else None
    window = max(cfg.window - cfg.window % tok_cfg.downsample, tok_cfg.downsample)
    min_frames = 2 * tok_cfg.downsample
    sampler = WindowSampler(train, window, min_frames, "train", cfg.balance_groups, cfg.action_share)
    val_windows = validation_windows(val, window, cfg.val_clips, cfg.seed, min_frames) if val is not None else None
    steps_per_epoch = cfg.steps_per_epoch or max(1, math.ceil(len(sampler.features) / cfg.batch_size))
    total = cfg.steps if cfg.steps > 0 else cfg.epochs * steps_per_epoch

    torch.manual_seed(cfg.seed)
    model = MoTok(tok_cfg, mean, std)
    if initial is not None:
        model.load_state_dict(initial)  # normalisation included: the source's mean/std win
    model = model.to(device)
    if cfg.freeze_tokens:
        model.freeze_tokens()
    trainable = [p for p in model.parameters() if p.requires_grad]
    optimizer = torch.optim.AdamW(trainable, lr=cfg.lr, weight_decay=cfg.weight_decay)
    generator = torch.Generator().manual_seed(cfg.seed)
    step, running = 0, {k: 0.0 for k in _RUNNING}
    running_n = 0
    rows: list[dict[str, Any]] = []
    if resume:
        weights = load_file(str(out / WEIGHTS_FILE))
        model.load_state_dict(weights)
        tensors = load_file(str(state_path), device="cpu")
        from safetensors import safe_open

        with safe_open(str(state_path), framework="pt") as fh:
            meta = fh.metadata() or {}
        info = json.loads(meta["info"])
        with safe_open(str(out / WEIGHTS_FILE), framework="pt") as fh:
            weights_step = (fh.metadata() or {}).get("step")
        if weights_step is not None and int(weights_step) != int(info["step"]):
            raise InputError(
                f"{out}: {WEIGHTS_FILE} is from step {weights_step} but {STATE_FILE} from step {info['step']} "
                "(the run was killed while writing a checkpoint); restart the run or restore both files"
            )
        _load_optimizer(optimizer, {k: v.to(device) if not k.endswith(".step") else v for k, v in tensors.items()}, info["param_groups"])
        generator.set_state(tensors["rng"])
        if "focus" in tensors:
            sampler.set_focus(tensors["focus"].double().numpy())
        step = int(info["step"])
        running = {k: float(v) for k, v in info["running"].items()}
        running_n = int(info["running_n"])
        rows = [r for r in _read_metrics(out / METRICS_FILE) if int(r["step"]) <= step]
    train_dict = to_dict(cfg)
    model.train()

    def checkpoint() -> None:
        save_tokenizer(model, out, train=train_dict, step=step)  # weights first, then the state
        tensors, groups = _optimizer_tensors(optimizer)
        tensors["rng"] = generator.get_state()
        if cfg.focus_errors:
            tensors["focus"] = torch.from_numpy(sampler.focus.copy())
        info = {"step": step, "running": running, "running_n": running_n, "param_groups": groups, "total": total}
        atomic_save_tensors(tensors, state_path, metadata={"info": json.dumps(info)})
        _write_metrics(out / METRICS_FILE, rows)

    def refocus() -> dict[str, float]:
        """Re-measure every train clip's error, set the draw weights from it, return its summary."""
        errors = clip_errors(model, sampler.features, progress)
        sampler.set_focus(focus_factors(errors, cfg.focus_errors, cfg.focus_cap))
        return {"focus_error_cm": float(errors.mean()), "focus_error_p90_cm": float(np.percentile(errors, 90))}

    if cfg.focus_errors and not (resume and "focus" in tensors):
        refocus()
    started = time.perf_counter()
    bar = tqdm(total=total, initial=step, desc="train tokenizer", unit="step", disable=None if progress is None else not progress)
    while step < total:
        lr = learning_rate(step, total, cfg)
        for group in optimizer.param_groups:
            group["lr"] = lr
        batch, mask = sampler.sample(cfg.batch_size, generator)
        losses = model.training_losses(batch.to(device), generator, mask.to(device))
        optimizer.zero_grad(set_to_none=True)
        losses["loss"].backward()
        if cfg.grad_clip > 0:
            torch.nn.utils.clip_grad_norm_(trainable, cfg.grad_clip)
        optimizer.step()
        step += 1
        for key in _RUNNING:
            running[key] += float(losses[key].detach())
        running_n += 1
        bar.update(1)
        bar.set_postfix(loss=f"{float(losses['loss'].detach()):.4f}", usage=f"{float(losses['usage']):.2f}")
        epoch_end = step % steps_per_epoch == 0 or step == total
        if epoch_end:
            row: dict[str, Any] = {"epoch": math.ceil(step / steps_per_epoch), "step": step, "lr": lr}
            for key in _RUNNING:
                row[f"train_{key}"] = running[key] / max(running_n, 1)
            if val_windows is not None:
                row.update(evaluate_windows(model, *val_windows, steps=cfg.val_sample_steps))
            row["restarts"] = int(model.quantizer.restarts)
            if cfg.focus_errors and step < total:
                row.update(refocus())  # weights for the next epoch's draws; the row reports the errors measured now
            row["seconds"] = round(time.perf_counter() - started, 2)
            rows.append(row)
            running, running_n = {k: 0.0 for k in _RUNNING}, 0
            if progress is not False:  # one line per epoch, also in logs where the bar is hidden
                shown = ("epoch", "step", "train_loss", "train_usage", "val_feature_mse", "val_mpjpe_cm", "val_usage", "restarts", "focus_error_cm", "seconds")
                tqdm.write(" ".join(f"{k}={row[k]:.4g}" if isinstance(row[k], float) else f"{k}={row[k]}" for k in shown if k in row))
        if epoch_end or step % cfg.checkpoint_every == 0 or step == stop_at:
            checkpoint()
        if stop_at is not None and step >= stop_at:
            break
    bar.close()
    return {
        "run": str(out),
        "steps": step,
        "total_steps": total,
        "steps_per_epoch": steps_per_epoch,
        "window": window,
        "train_clips": len(sampler.features),
        "train_clips_padded": sampler.padded,
        "train_clips_skipped": sampler.skipped,
        "last": rows[-1] if rows else None,
    }


def load_split(data_dir: str | Path, split: str) -> Clips:
    """Feature sequences of a prepared dataset split (via :class:`PreparedDataset`)."""
    from motok_robot.data.dataset import PreparedDataset

    dataset = PreparedDataset(data_dir, split)
    ids = list(dataset.clip_ids)
    return Clips(ids, [np.asarray(dataset.features(i), dtype=np.float32) for i in ids],
                 [clip_group(dataset.record(i), i) for i in ids])


def dataset_statistics(data_dir: str | Path) -> tuple[np.ndarray, np.ndarray]:
    from motok_robot.data.dataset import PreparedDataset

    dataset = PreparedDataset(data_dir, "train")
    return np.asarray(dataset.mean, dtype=np.float32), np.asarray(dataset.std, dtype=np.float32)


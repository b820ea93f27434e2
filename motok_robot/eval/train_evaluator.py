"""Training of the text-motion evaluator (``motok-robot train evaluator``).

Every clip of the prepared train split contributes (random caption, random crop of
``min_frames..max_frames`` frames) pairs; captions are embedded once with the frozen
sentence encoder and cached. Checkpoints are safetensors (weights and optimiser state)
plus JSON, written atomically; ``resume=True`` continues from the last one exactly.
Validation (R-precision top-1/3 in batches of 32 on the val split, fixed crops) is logged
to ``metrics.csv``.
"""

from __future__ import annotations

import csv
import json
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from motok_robot.checkpoint import load_training_state, save_training_state
from motok_robot.errors import InputError
from motok_robot.eval import metrics
from motok_robot.eval.config import EvaluatorConfig
from motok_robot.eval.corruptions import CORRUPTIONS, corrupt
from motok_robot.eval.evaluator import TextMotionEvaluator, save_evaluator

TextEmbedder = Callable[[list[str]], np.ndarray]


class CaptionedClips:
    """Features and captions of one split, held in memory (the prepared data is small)."""

    def __init__(self, dataset, embed_text: TextEmbedder, min_frames: int):
        self.features: list[np.ndarray] = []
        self.captions: list[list[str]] = []
        for clip_id in dataset.clip_ids:
            feats = dataset.features(clip_id)
            texts = [t for t in dataset.texts(clip_id) if t.strip()]
            if len(feats) < min_frames or not texts:
                continue
            self.features.append(feats.astype(np.float32))
            self.captions.append(texts)
        if not self.features:
            raise InputError(f"no clip of at least {min_frames} frames with a caption in the split")
        unique = sorted({t for caps in self.captions for t in caps})
        vectors = embed_text(unique)
        self.caption_index = {t: i for i, t in enumerate(unique)}
        self.caption_vectors = torch.as_tensor(np.asarray(vectors, np.float32))

    def __len__(self) -> int:
        return len(self.features)

    def batch(self, indices: np.ndarray, rng: np.random.Generator, cfg: EvaluatorConfig, fixed: bool = False):
        """Crops ``[B, max_frames, 263]`` (zero padded), lengths, caption vectors, caption ids."""
        out = np.zeros((len(indices), cfg.max_frames, cfg.feature_dim), np.float32)
        lengths = np.zeros(len(indices), np.int64)
        caption_ids = np.zeros(len(indices), np.int64)
        for row, i in enumerate(indices):
            feats = self.features[i]
            if fixed:
                length = min(len(feats), cfg.max_frames)
                start = 0
                caption = self.captions[i][0]
            else:
                length = int(rng.integers(cfg.min_frames, min(len(feats), cfg.max_frames) + 1))
                start = int(rng.integers(0, len(feats) - length + 1))
                caption = self.captions[i][int(rng.integers(len(self.captions[i])))]
            out[row, :length] = feats[start : start + length]
            lengths[row] = length
            caption_ids[row] = self.caption_index[caption]
        ids = torch.as_tensor(caption_ids)
        return torch.as_tensor(out), torch.as_tensor(lengths), self.caption_vectors[ids], ids


def corrupted_copies(feats: torch.Tensor, lengths: torch.Tensor, count: int, rng: np.random.Generator):
    """Corrupted copies of ``count`` random rows of a padded batch ``[B, T, 263]`` (+ lengths)."""
    rows = rng.choice(len(feats), size=min(count, len(feats)), replace=False)
    out = torch.zeros((len(rows), *feats.shape[1:]), dtype=feats.dtype)
    for k, row in enumerate(rows):
        n = int(lengths[row])
        kind = CORRUPTIONS[int(rng.integers(len(CORRUPTIONS)))]
        out[k, :n] = torch.as_tensor(corrupt(feats[row, :n].numpy(), kind, rng))
    return out, lengths[torch.as_tensor(rows)]


@torch.no_grad()
def validation_r_precision(model: TextMotionEvaluator, clips: CaptionedClips, cfg: EvaluatorConfig) -> np.ndarray:
    model.eval()
    device = model.mean.device
    rng = np.random.default_rng(0)
    order = rng.permutation(len(clips))
    text_z, motion_z = [], []
    for start in range(0, len(order), cfg.batch_size):
        feats, lengths, caption_vecs, _ = clips.batch(order[start : start + cfg.batch_size], rng, cfg, fixed=True)
        motion_z.append(model.embed_motion(feats.to(device), lengths.to(device)).cpu().numpy())
        text_z.append(model.embed_text(caption_vecs.to(device)).cpu().numpy())
    model.train()
    text_all, motion_all = np.concatenate(text_z), np.concatenate(motion_z)
    if len(text_all) < metrics.R_PRECISION_BATCH:
        return np.full(3, np.nan)
    return metrics.r_precision(text_all, motion_all)


class CachedTextEmbedder:
    """Wrap ``encode(list[str]) -> [B, D]`` with a file cache ``cache_file`` (``.npz``: ``texts``
    unicode ``[N]``, ``vectors`` float32 ``[N, D]``, ``encoder`` name), so a resumed or repeated
    training does not embed the captions again. A cache written by another encoder is ignored."""

    def __init__(self, encode, encoder_name: str, cache_file: str | Path):
        self.encode = encode
        self.encoder_name = encoder_name
        self.cache_file = Path(cache_file)
        self.table: dict[str, np.ndarray] = {}
        if self.cache_file.is_file():
            try:
                with np.load(self.cache_file, allow_pickle=False) as data:
                    if str(data["encoder"]) == encoder_name:
                        self.table = dict(zip(data["texts"].tolist(), data["vectors"]))
            except (OSError, KeyError, ValueError):
                self.table = {}  # unreadable cache: embed again and overwrite it

    def __call__(self, texts: list[str]) -> np.ndarray:
        missing = [t for t in dict.fromkeys(texts) if t not in self.table]
        if missing:
            vectors = np.asarray(self.encode(missing), np.float32)
            self.table.update(zip(missing, vectors))
            self.cache_file.parent.mkdir(parents=True, exist_ok=True)
            tmp = self.cache_file.with_name(self.cache_file.name + ".tmp.npz")
            keys = list(self.table)
            np.savez(tmp, texts=np.array(keys, dtype=str), vectors=np.stack([self.table[k] for k in keys]),
                     encoder=np.array(self.encoder_name))
            tmp.replace(self.cache_file)
        return np.stack([self.table[t] for t in texts]) if texts else np.zeros((0, 0), np.float32)


def train_evaluator(
    train_set,
    val_set,
    embed_text: TextEmbedder,
    text_dim: int,
    out_dir: str | Path,
    cfg: EvaluatorConfig | None = None,
    resume: bool = False,
    device: str = "cpu",
    meta: dict | None = None,
) -> Path:
    """Train and save to ``out_dir``; returns the run directory.

    ``train_set``/``val_set``: splits with ``clip_ids``, ``features(id)``, ``texts(id)`` and
    (train) ``mean``/``std`` (e.g. :class:`motok_robot.data.dataset.PreparedDataset`);
    ``embed_text``: captions -> frozen sentence embeddings ``[B, text_dim]``; ``meta``: extra
    JSON-able facts (training command, data folder) written to ``training.json``.
    """
    cfg = cfg or EvaluatorConfig()
    run = Path(out_dir)
    run.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(cfg.seed)
    train = CaptionedClips(train_set, embed_text, cfg.min_frames)
    val = CaptionedClips(val_set, embed_text, cfg.min_frames)
    model = TextMotionEvaluator(cfg, text_dim, train_set.mean, train_set.std).to(device)
    optimiser = torch.optim.AdamW(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    step = 0
    state_file = run / "train_state.safetensors"
    if resume and state_file.exists():
        step, _ = load_training_state(state_file, model, optimiser)
    metrics_file = run / "metrics.csv"
    new_log = not (resume and metrics_file.exists())
    with open(metrics_file, "w" if new_log else "a", newline="") as handle:
        writer = csv.writer(handle)
        if new_log:
            writer.writerow(["step", "train_loss", "val_r1", "val_r2", "val_r3", "seconds"])
        start_time = time.time()
        losses: list[float] = []
        bar = tqdm(total=cfg.steps, initial=step, desc="train evaluator", disable=None)
        while step < cfg.steps:
            rng = np.random.default_rng([cfg.seed, step])
            torch.manual_seed(cfg.seed * 1_000_003 + step)  # dropout masks repeat after a resume
            indices = rng.choice(len(train), size=min(cfg.batch_size, len(train)), replace=False)
            feats, lengths, caption_vecs, caption_ids = train.batch(indices, rng, cfg)
            same = caption_ids[:, None] == caption_ids[None, :]
            text_z = model.embed_text(caption_vecs.to(device))
            n_bad = int(round(cfg.corrupt_negatives * len(indices)))
            if n_bad:
                bad_feats, bad_lengths = corrupted_copies(feats, lengths, n_bad, rng)
                all_z = model.embed_motion(torch.cat([feats, bad_feats]).to(device), torch.cat([lengths, bad_lengths]).to(device))
                motion_z, bad_z = all_z[: len(indices)], all_z[len(indices) :]
            else:
                motion_z, bad_z = model.embed_motion(feats.to(device), lengths.to(device)), None
            loss = model.contrastive_loss(text_z, motion_z, same.to(device), bad_z)
            optimiser.zero_grad(set_to_none=True)
            loss.backward()
            torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
            optimiser.step()
            losses.append(float(loss.detach()))
            step += 1
            bar.update(1)
            if step % cfg.eval_every == 0 or step == cfg.steps:
                r = validation_r_precision(model, val, cfg)
                writer.writerow([step, np.mean(losses), *np.round(r, 4), round(time.time() - start_time, 1)])
                handle.flush()
                bar.set_postfix(loss=f"{np.mean(losses):.3f}", r1=f"{r[0]:.3f}")
                losses = []
                save_evaluator(model, run)
                save_training_state(state_file, model, optimiser, step)
        bar.close()
    info = {"steps": step, "train_clips": len(train), "val_clips": len(val), **(meta or {})}
    (run / "training.json").write_text(json.dumps(info, indent=2))
    return run

"""Training data for the planners: a prepared dataset tokenised once, text embeddings cached.

Cache files (in ``RUN/cache/``; plain numpy / safetensors, no pickle):

* ``tokens_<split>.npz``: ``ids`` (str ``[C]``), ``offsets`` (int64 ``[C + 1]``), ``tokens`` (int64,
  all clips concatenated), ``key`` (str: tokenizer weights hash, data directory, split, size and
  modification time of ``index.jsonl``); rebuilt when the key differs.
* ``text_<encoder>.safetensors`` + ``text_<encoder>.json``: embeddings ``[U, D]`` of every unique
  sentence and the sentences in row order.

In memory every clip keeps its tokens, its features (float16, cropped to a whole number of tokens,
for deriving local conditions of any crop) and its sentences / action label.
"""

from __future__ import annotations

import hashlib
import json
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from motok_robot.data.groups import balanced_weights, clip_action, with_action_shares
from motok_robot.errors import InputError
from motok_robot.planner.conditions import Conditions, LocalConditions, random_local_conditions, stack_local
from motok_robot.planner.config import ControlConfig


@dataclass
class TokenisedClip:
    """One clip: ``tokens`` int64 ``[N]``, ``features`` float16 ``[N * downsample, 263]`` (raw),
    ``text_rows`` indices into the text-embedding table, ``action`` label index or -1."""

    clip_id: str
    tokens: np.ndarray
    features: np.ndarray
    text_rows: list[int]
    action: int


def file_digest(path: str | Path, length: int = 16) -> str:
    """First ``length`` hex digits of the SHA-256 of a file."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()[:length]


def open_dataset(data_dir: str | Path, split: str):
    """``PreparedDataset(data_dir, split)`` with a clear error when the directory is not one."""
    from motok_robot.data.dataset import PreparedDataset

    data_dir = Path(data_dir)
    if not (data_dir / "index.jsonl").is_file():
        raise InputError(f"{data_dir}: not a prepared dataset (no index.jsonl); run 'motok-robot data prepare' first")
    return PreparedDataset(data_dir, split)


def tokenise_split(dataset, tokenizer, cache_file: Path, key: str, offset: int = 0) -> dict[str, np.ndarray]:
    """Tokens of every clip of ``dataset`` (cached in ``cache_file`` under ``key``) -> ``{id: tokens [N]}``.

    ``offset``: the clip is tokenised from that frame on (a token grid shifted by ``offset``
    frames); clips with less than one token left are skipped.
    """
    if cache_file.is_file():
        with np.load(cache_file, allow_pickle=False) as z:
            if str(z["key"]) == key:
                ids, offsets, tokens = z["ids"], z["offsets"], z["tokens"]
                return {str(i): tokens[offsets[k]:offsets[k + 1]] for k, i in enumerate(ids)}
    ds = tokenizer.frames_per_token
    out: dict[str, np.ndarray] = {}
    device = next(tokenizer.parameters()).device
    for clip_id in tqdm(list(dataset.clip_ids), desc=f"tokenising {cache_file.stem}", unit="clip", disable=None):
        feats = np.asarray(dataset.features(clip_id), dtype=np.float32)[offset:]
        usable = (feats.shape[0] // ds) * ds
        if usable < ds:
            continue
        with torch.no_grad():
            tok = tokenizer.encode(torch.from_numpy(feats[None, :usable]).to(device))
        out[clip_id] = tok[0].cpu().numpy().astype(np.int64)
    ids = list(out)
    offsets = np.concatenate([[0], np.cumsum([len(out[i]) for i in ids])]).astype(np.int64)
    tokens = np.concatenate([out[i] for i in ids]) if ids else np.zeros(0, np.int64)
    cache_file.parent.mkdir(parents=True, exist_ok=True)
    tmp = cache_file.with_name(cache_file.stem + ".tmp.npz")
    np.savez(tmp, ids=np.array(ids, dtype=str), offsets=offsets, tokens=tokens, key=np.array(key))
    tmp.replace(cache_file)
    return out


def _slug(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9]+", "_", name).strip("_")[:60] + "_" + hashlib.sha256(name.encode()).hexdigest()[:8]


def embed_texts(texts: list[str], encoder, cache_dir: Path, batch: int = 256) -> torch.Tensor:
    """Embeddings ``[len(texts), D]`` of unique ``texts`` (cached on disk per encoder)."""
    from safetensors.torch import load_file, save_file

    stem = cache_dir / f"text_{_slug(encoder.name)}"
    known: dict[str, torch.Tensor] = {}
    if stem.with_suffix(".json").is_file() and stem.with_suffix(".safetensors").is_file():
        rows = json.loads(stem.with_suffix(".json").read_text())
        emb = load_file(str(stem.with_suffix(".safetensors")))["embeddings"]
        if emb.shape[0] == len(rows):
            known = {t: emb[i] for i, t in enumerate(rows)}
    missing = [t for t in texts if t not in known]
    for start in tqdm(range(0, len(missing), batch), desc="encoding texts", unit="batch", disable=None):
        chunk = missing[start:start + batch]
        for t, e in zip(chunk, encoder.encode(chunk)):
            known[t] = e
    if missing:
        rows = list(known)
        cache_dir.mkdir(parents=True, exist_ok=True)
        save_file({"embeddings": torch.stack([known[t] for t in rows]).contiguous()},
                  str(stem.with_suffix(".safetensors")))
        stem.with_suffix(".json").write_text(json.dumps(rows))
    if not texts:
        return torch.zeros(0, encoder.dim)
    return torch.stack([known[t] for t in texts])


def normalise_text(text: str) -> str:
    return " ".join(str(text).split())


class PlannerData:
    """Clips of one split, ready for batching."""

    def __init__(self, clips: list[TokenisedClip], text_table: torch.Tensor, downsample: int, max_tokens: int):
        if not clips:
            raise InputError("no usable clips (every clip is shorter than one token?)")
        self.clips = clips
        self.text_table = text_table
        self.downsample = downsample
        self.max_tokens = max_tokens

    def __len__(self) -> int:
        return len(self.clips)

    def lengths(self) -> np.ndarray:
        return np.array([len(c.tokens) for c in self.clips])

    def group_of(self, i: int) -> tuple:
        """What the clip shows, for balancing: its action label, else its first sentence, else its id."""
        clip = self.clips[i]
        if clip.action >= 0:
            return ("action", clip.action)
        if clip.text_rows:
            return ("text", clip.text_rows[0])
        return ("clip", clip.clip_id.split("@")[0])

    def sampling_probabilities(self, balance: float, action_share: dict[str, float] | None = None,
                               action_labels: list[str] | None = None) -> np.ndarray | None:
        """Probability of drawing each clip when a group of ``n`` clips is drawn with total weight
        ``n ** (1 - balance)``: 0 = every clip equally often (returns None, unless
        ``action_share`` is given), 1 = every group (action label or caption) equally often, 0.5 =
        square-root balancing.  ``action_share`` (``{label: share}``, labels from
        ``action_labels``, the planner's label list that ``TokenisedClip.action`` indexes) then
        gives the clips of each named label that share of the draws."""
        if balance == 0 and not action_share:
            return None
        groups = [self.group_of(i) for i in range(len(self.clips))]
        weights = balanced_weights(groups, balance)
        if not action_share:
            return weights
        labels = list(action_labels or [])
        named = [("action", labels[g[1]]) if g[0] == "action" and 0 <= g[1] < len(labels) else g for g in groups]
        return with_action_shares(weights, named, action_share, "planner train split")

    def batch(
        self,
        indices: list[int],
        rng: np.random.Generator,
        control: ControlConfig | None,
        random_crop: bool = True,
        action_prob: float = 0.2,
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, Conditions, torch.Tensor]:
        """A training batch.

        Returns ``(tokens [B, N] padded with 0, lengths [B], ends [B] bool -- the crop reaches the
        clip's end, conditions, full_lengths [B] -- whole-clip token counts for the length estimator)``.
        Crops of at most ``max_tokens`` tokens start at a random token (or 0 when ``random_crop`` is
        False); local conditions come from the crop's own joints (``joints_from_features``), so they
        live in the frame of a generated motion.
        """
        from motok_robot.motion.features import joints_from_features

        b = len(indices)
        crops, starts = [], []
        for i in indices:
            n = len(self.clips[i].tokens)
            length = min(n, self.max_tokens)
            start = int(rng.integers(0, n - length + 1)) if random_crop else 0
            crops.append(length)
            starts.append(start)
        big_n = max(crops)
        tokens = torch.zeros(b, big_n, dtype=torch.long)
        text_rows = torch.zeros(b, dtype=torch.long)
        text_present = torch.zeros(b, dtype=torch.bool)
        action = torch.full((b,), -1, dtype=torch.long)
        ends = torch.zeros(b, dtype=torch.bool)
        full = torch.zeros(b, dtype=torch.long)
        locals_: list[LocalConditions] = []
        ds = self.downsample
        for row, (i, length, start) in enumerate(zip(indices, crops, starts)):
            clip = self.clips[i]
            tokens[row, :length] = torch.from_numpy(clip.tokens[start:start + length])
            ends[row] = start + length == len(clip.tokens)
            full[row] = len(clip.tokens)
            use_action = clip.action >= 0 and (not clip.text_rows or rng.random() < action_prob)
            if use_action:
                action[row] = clip.action
            elif clip.text_rows:
                text_rows[row] = clip.text_rows[int(rng.integers(len(clip.text_rows)))]
                text_present[row] = True
            if control is not None:
                feats = clip.features[start * ds:(start + length) * ds].astype(np.float32)
                local = random_local_conditions(joints_from_features(feats), control, rng)
                locals_.append(local.fit_frames(big_n * ds))
        cond = Conditions(
            text_embedding=self.text_table[text_rows] if len(self.text_table) else None,
            text_present=text_present,
            action=action,
            local=stack_local(locals_) if locals_ else None,
            batch=b,
        )
        return tokens, torch.tensor(crops), ends, cond, full


def load_planner_data(
    data_dir: str | Path, split: str, tokenizer, tokenizer_key: str, encoder, cache_dir: Path,
    action_labels: list[str], max_tokens: int, phases: int = 1, exclude: list[str] | tuple = (),
) -> PlannerData:
    """Tokenise (cached), embed texts (cached) and assemble :class:`PlannerData` for ``split``.

    ``phases`` > 1 also tokenises every clip from frames ``1 .. phases - 1`` on (at most
    ``downsample - 1``): the same motion seen through shifted token grids, each one more
    training sequence (a clip id gets the suffix ``@<offset>``).  ``exclude``: clip ids of the
    split left out, with their mirrored copies (see :func:`excluded_clips`).
    """
    dataset = open_dataset(data_dir, split)
    left_out = excluded_clips(dataset, exclude, f"{data_dir} ({split} split)")
    index = Path(data_dir) / "index.jsonl"
    stat = index.stat()
    key = f"{tokenizer_key}|{Path(data_dir).resolve()}|{split}|{stat.st_size}|{stat.st_mtime_ns}"
    ds = tokenizer.frames_per_token
    if not 1 <= phases <= ds:
        raise InputError(f"token phases must be in 1..{ds} (the tokenizer's frames per token), got {phases}")
    token_maps = {0: tokenise_split(dataset, tokenizer, cache_dir / f"tokens_{split}.npz", key)}
    for offset in range(1, phases):
        token_maps[offset] = tokenise_split(dataset, tokenizer, cache_dir / f"tokens_{split}_offset{offset}.npz",
                                            f"{key}|offset {offset}", offset=offset)
    texts_per_clip: dict[str, list[str]] = {}
    for clip_id in [c for c in token_maps[0] if c not in left_out]:
        texts_per_clip[clip_id] = [t for t in (normalise_text(x) for x in dataset.texts(clip_id)) if t][:32]
    unique = sorted({t for ts in texts_per_clip.values() for t in ts})
    table = embed_texts(unique, encoder, cache_dir)
    row_of = {t: i for i, t in enumerate(unique)}
    label_index = {label: i for i, label in enumerate(action_labels)}
    clips = []
    for clip_id, tokens in tqdm(token_maps[0].items(), desc=f"loading {split}", unit="clip", disable=None):
        if clip_id in left_out:
            continue
        feats = np.asarray(dataset.features(clip_id), dtype=np.float16)
        label = label_index.get(clip_action(dataset.record(clip_id)), -1)
        rows = [row_of[t] for t in texts_per_clip[clip_id]]
        clips.append(TokenisedClip(clip_id, tokens, feats[: len(tokens) * ds], rows, label))
        for offset in range(1, phases):
            shifted = token_maps[offset].get(clip_id)
            if shifted is not None:  # views of the same array: no extra copy of the features
                clips.append(TokenisedClip(f"{clip_id}@{offset}", shifted,
                                           feats[offset: offset + len(shifted) * ds], rows, label))
    return PlannerData(clips, table, ds, max_tokens)


def excluded_clips(dataset, exclude: list[str] | tuple, where: str) -> set[str]:
    """The clip ids of ``dataset`` that ``exclude`` leaves out: every listed id and every clip
    whose ``mirror_of`` is one of them.  A listed id that is not in the dataset is an error (a
    typo would otherwise train on the clip it meant to drop)."""
    if not exclude:
        return set()
    present = set(dataset.clip_ids)
    missing = [c for c in exclude if c not in present]
    if missing:
        raise InputError(f"{where}: exclude_clips names {missing[0]!r}, which is not a clip there"
                         + (f" ({len(missing) - 1} more missing)" if len(missing) > 1 else ""))
    named = set(exclude)
    return named | {c for c in dataset.clip_ids if dataset.record(c).get("mirror_of") in named}


def action_labels_of(data_dir: str | Path, split: str = "train") -> list[str]:
    """Sorted action labels present in a split (empty when the index has none)."""
    dataset = open_dataset(data_dir, split)
    return sorted({a for a in (clip_action(dataset.record(i)) for i in dataset.clip_ids) if a})

"""Reader of a prepared dataset (the output of ``motok-robot data prepare``); numpy only, no torch.

>>> ds = PreparedDataset("prepared", split="train")
>>> ds.clip_ids[:2], ds.features(ds.clip_ids[0]).shape      # float32 [T-1, 263]
>>> ds.joints(ds.clip_ids[0]).shape                          # float32 [T, 22, 3] metres, z up
>>> ds.texts(ds.clip_ids[0]), ds.record(ds.clip_ids[0])["licence"]
>>> ds.mean.shape, ds.std.shape                              # float32 [263] (train split)
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from motok_robot.errors import InputError

SPLITS = ("train", "val", "test")


class PreparedDataset:
    """Clips of one split (``"train"``, ``"val"``, ``"test"`` or ``"all"``) of a prepared folder.

    Attributes:
        root: the folder.
        split: the split read.
        clip_ids: clip ids of the split, in the order of ``splits/<split>.txt``.
        mean, std: float32 ``[263]`` feature statistics over the train split.
    """

    def __init__(self, root: str | Path, split: str = "train"):
        self.root = Path(root)
        if split not in SPLITS + ("all",):
            raise InputError(f"split must be one of {SPLITS + ('all',)}, got {split!r}")
        index = self.root / "index.jsonl"
        if not index.is_file():
            raise InputError(f"{self.root}: not a prepared dataset (no index.jsonl); run 'motok-robot data prepare'")
        self._records: dict[str, dict] = {}
        for lineno, line in enumerate(index.read_text().splitlines(), 1):
            if not line.strip():
                continue
            try:
                rec = json.loads(line)
            except json.JSONDecodeError as exc:
                raise InputError(f"{index}: line {lineno}: bad JSON ({exc.msg})") from None
            self._records[rec["id"]] = rec
        self.split = split
        if split == "all":
            self.clip_ids = list(self._records)
        else:
            f = self.root / "splits" / f"{split}.txt"
            if not f.is_file():
                raise InputError(f"{f}: missing split file")
            self.clip_ids = [s for s in f.read_text().split() if s]
            unknown = [c for c in self.clip_ids if c not in self._records]
            if unknown:
                raise InputError(f"{f}: clip id(s) not in index.jsonl: {unknown[:5]}")
        self.mean = self._load_stat("mean.npy")
        self.std = self._load_stat("std.npy")

    def _load_stat(self, name: str) -> np.ndarray:
        f = self.root / name
        if not f.is_file():
            raise InputError(f"{f}: missing")
        return np.load(f).astype(np.float32)

    def __len__(self) -> int:
        return len(self.clip_ids)

    def __iter__(self):
        return iter(self.clip_ids)

    def __contains__(self, clip_id: str) -> bool:
        return clip_id in self._records

    def _file(self, sub: str, clip_id: str, ext: str) -> Path:
        if clip_id not in self._records:
            raise InputError(f"{self.root}: no clip {clip_id!r} (see index.jsonl)")
        return self.root / sub / (clip_id.replace("/", "__") + ext)

    def record(self, clip_id: str) -> dict:
        """The index.jsonl entry: id, source, licence, fps, frames, seconds, texts, split, file,
        mirror_of, derived_joints."""
        if clip_id not in self._records:
            raise InputError(f"{self.root}: no clip {clip_id!r} (see index.jsonl)")
        return dict(self._records[clip_id])

    def features(self, clip_id: str) -> np.ndarray:
        """float32 ``[T-1, 263]`` HumanML3D features (un-normalised; use ``mean``/``std``)."""
        return np.load(self._file("features", clip_id, ".npy")).astype(np.float32, copy=False)

    def joints(self, clip_id: str) -> np.ndarray:
        """float32 ``[T, 22, 3]`` skeleton-normalised joints, metres, z up, facing +x at frame 0."""
        return np.load(self._file("joints", clip_id, ".npy")).astype(np.float32, copy=False)

    def texts(self, clip_id: str) -> list[str]:
        """Descriptions, one sentence each (may be empty)."""
        f = self._file("texts", clip_id, ".txt")
        return [ln for ln in f.read_text().splitlines() if ln.strip()] if f.is_file() else []

    def summary(self) -> dict:
        f = self.root / "summary.json"
        return json.loads(f.read_text()) if f.is_file() else {}

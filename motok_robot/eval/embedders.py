"""Adapters that give the protocol (:mod:`motok_robot.eval.protocol`) one interface over both
text-motion evaluators:

* :class:`OwnEvaluatorEmbedder`: motok-robot's contrastive evaluator + its frozen text encoder;
* :class:`OfficialEmbedder`: the official HumanML3D evaluator, whose text side reads POS-tagged
  HumanML3D token strings; :func:`humanml3d_token_captions` maps plain captions to them.

Both take raw (unnormalised) 263-d features, one ``[T_i, 263]`` array per motion, and return
float64 embeddings ``[N, D]``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import torch

from motok_robot.errors import InputError
from motok_robot.eval.evaluator import TextMotionEvaluator
from motok_robot.eval.official import UNIT_LENGTH, OfficialEvaluator


def pad_batch(features: Sequence[np.ndarray], max_frames: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Zero-pad ``[T_i, F]`` arrays into ``[B, max T_i, F]`` plus lengths ``[B]`` (frames).
    Raises when a motion is longer than ``max_frames``."""
    lengths = np.array([len(f) for f in features], np.int64)
    if max_frames is not None and len(lengths) and lengths.max() > max_frames:
        raise InputError(f"a motion of {lengths.max()} frames is longer than the evaluator's {max_frames}")
    out = np.zeros((len(features), int(lengths.max(initial=1)), features[0].shape[-1]), np.float32)
    for i, f in enumerate(features):
        out[i, : len(f)] = f
    return out, lengths


class OwnEvaluatorEmbedder:
    """motok-robot's :class:`TextMotionEvaluator` with the text encoder it was trained on.

    Args:
        model: a loaded evaluator (:func:`motok_robot.eval.evaluator.load_evaluator`).
        encode_text: sentences -> frozen sentence embeddings ``[B, text_dim]`` (default: the
            :mod:`motok_robot.text` encoder named in the evaluator's config).
        batch_size: motions per forward pass.
    """

    def __init__(self, model: TextMotionEvaluator, encode_text: Callable[[list[str]], np.ndarray] | None = None,
                 batch_size: int = 128):
        self.model = model.eval()
        self.min_frames = model.cfg.min_frames
        self.max_frames = model.cfg.max_frames
        self.batch_size = batch_size
        if encode_text is None:
            from motok_robot.text import load_text_encoder

            encoder = load_text_encoder(model.cfg.text_encoder)
            if encoder.dim != model.text_dim:
                raise InputError(f"text encoder {model.cfg.text_encoder!r} gives {encoder.dim}-d embeddings, "
                                 f"the evaluator expects {model.text_dim}")
            encode_text = lambda texts: encoder.encode(texts).numpy()  # noqa: E731
        self.encode_text = encode_text

    @property
    def device(self) -> torch.device:
        return self.model.mean.device

    @torch.no_grad()
    def embed_text(self, captions: list[str]) -> np.ndarray:
        vectors = torch.as_tensor(np.asarray(self.encode_text(list(captions)), np.float32), device=self.device)
        return self.model.embed_text(vectors).double().cpu().numpy()

    @torch.no_grad()
    def embed_motion(self, features: list[np.ndarray]) -> np.ndarray:
        out = []
        for start in range(0, len(features), self.batch_size):
            feats, lengths = pad_batch(features[start : start + self.batch_size], self.max_frames)
            z = self.model.embed_motion(torch.as_tensor(feats, device=self.device), torch.as_tensor(lengths, device=self.device))
            out.append(z.double().cpu().numpy())
        return np.concatenate(out)


def _caption_key(text: str) -> str:
    return " ".join(text.lower().split())


def humanml3d_token_captions(texts_dir: str | Path) -> dict[str, str]:
    """Read every HumanML3D ``texts/*.txt`` (lines ``caption#tokens#from#to``) into
    ``{normalised caption: token string}`` for the official evaluator's text side."""
    folder = Path(texts_dir)
    if not folder.is_dir():
        raise InputError(f"HumanML3D texts folder {folder} does not exist")
    table: dict[str, str] = {}
    for path in sorted(folder.glob("*.txt")):
        for line in path.read_text(encoding="utf-8", errors="replace").splitlines():
            parts = line.split("#")
            if len(parts) >= 2 and parts[0].strip() and parts[1].strip():
                table.setdefault(_caption_key(parts[0]), parts[1].strip())
    if not table:
        raise InputError(f"{folder}: no HumanML3D caption lines 'caption#word/POS ...#from#to' found")
    return table


class OfficialEmbedder:
    """The official HumanML3D evaluator (:func:`motok_robot.eval.official.load_official_evaluator`).

    Captions are turned into HumanML3D token strings with ``token_captions`` (plain caption ->
    ``"word/POS ..."``); a caption already in that form is used as is. Motions are cropped to a
    multiple of 4 frames, as the official evaluation does.
    """

    min_frames = 40
    max_frames = 196

    def __init__(self, evaluator: OfficialEvaluator, token_captions: dict[str, str] | None = None, batch_size: int = 128):
        self.evaluator = evaluator
        self.token_captions = token_captions or {}
        self.batch_size = batch_size

    def tokens_for(self, caption: str) -> str:
        if "/" in caption and all("/" in tok for tok in caption.split()):
            return caption
        try:
            return self.token_captions[_caption_key(caption)]
        except KeyError:
            raise InputError(f"caption {caption!r} has no HumanML3D token string (word/POS ...); the official "
                             "evaluator needs the HumanML3D texts/ folder of the evaluated clips (--hml-texts)") from None

    def embed_text(self, captions: list[str]) -> np.ndarray:
        tokens = [self.tokens_for(c) for c in captions]
        return np.concatenate([self.evaluator.embed_text(tokens[i : i + self.batch_size])
                               for i in range(0, len(tokens), self.batch_size)]).astype(np.float64)

    def embed_motion(self, features: list[np.ndarray]) -> np.ndarray:
        cropped = [f[: max(UNIT_LENGTH, len(f) - len(f) % UNIT_LENGTH)] for f in features]
        out = []
        for start in range(0, len(cropped), self.batch_size):
            feats, lengths = pad_batch(cropped[start : start + self.batch_size])
            out.append(self.evaluator.embed_motion(feats, lengths))
        return np.concatenate(out).astype(np.float64)

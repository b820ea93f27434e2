"""A contrastive text-motion evaluator trained on the project's own prepared data.

HumanML3D's official evaluator cannot be downloaded here, so motok-robot trains its own
(:class:`TextMotionEvaluator`): frozen sentence embeddings -> MLP on the text side, normalised
263-d features -> strided conv + transformer on the motion side, trained with a symmetric
InfoNCE loss (TMR-style) where captions identical to the positive are not used as negatives,
and corrupted copies of some batch motions (frames shuffled, time reversed, frozen, jittered) are added
as negatives for every caption, so the embedding also tells plausible from implausible motion.
Embeddings are unit-norm ``[B, latent_dim]``.

Files (a "run" directory): ``config.json`` (:class:`EvaluatorConfig` + data mean/std path
free), ``model.safetensors`` (weights, and the dataset ``mean``/``std`` of the features).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from motok_robot.errors import InputError
from motok_robot.eval.config import EvaluatorConfig


class MotionEncoder(nn.Module):
    """Normalised features ``[B, T, 263]`` + lengths ``[B]`` -> unit embeddings ``[B, latent]``.

    With ``cfg.motion_deltas`` the frame-to-frame differences of the normalised features are
    extra input channels, so per-frame jitter reaches the network as magnitude, not only as
    zero-mean noise that the convolutions and the pooling average away.
    """

    def __init__(self, cfg: EvaluatorConfig):
        super().__init__()
        w = cfg.width
        self.deltas = cfg.motion_deltas
        self.stem = nn.Sequential(
            nn.Conv1d(cfg.feature_dim * (2 if cfg.motion_deltas else 1), w, 4, stride=2, padding=1),
            nn.GELU(),
            nn.Conv1d(w, w, 4, stride=2, padding=1),
            nn.GELU(),
        )
        layer = nn.TransformerEncoderLayer(w, cfg.heads, 2 * w, cfg.dropout, batch_first=True, norm_first=True)
        self.transformer = nn.TransformerEncoder(layer, cfg.layers, enable_nested_tensor=False)
        self.position = nn.Parameter(torch.zeros(1, cfg.max_frames // 4 + 2, w))
        nn.init.normal_(self.position, std=0.02)
        self.out = nn.Linear(w, cfg.latent_dim)

    @staticmethod
    def _valid(steps: int, lengths: torch.Tensor) -> torch.Tensor:
        """``[B, 1, steps]`` mask of the steps before each length (the conv layers' padding is zero)."""
        return (torch.arange(steps, device=lengths.device)[None, :] < lengths[:, None]).unsqueeze(1).float()

    def forward(self, features: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
        # frames past each length are zeroed, so the embedding does not depend on the padding
        # (and the clip is padded to a multiple of 4 frames, so every token sees the same frames)
        extra = -features.shape[1] % 4
        if extra:
            features = F.pad(features, (0, 0, 0, extra))
        valid = self._valid(features.shape[1], lengths)
        h = features.transpose(1, 2) * valid  # [B, F, T]
        if self.deltas:  # frame-to-frame changes as extra channels (0 at the first and past the last frame)
            delta = torch.diff(h, dim=2, prepend=h[:, :, :1]) * valid
            h = torch.cat([h, delta], dim=1)  # [B, 2F, T]
        h = self.stem[1](self.stem[0](h))  # [B, w, T/2]
        h = h * self._valid(h.shape[2], (lengths + 1) // 2)
        h = self.stem[3](self.stem[2](h)).transpose(1, 2)  # [B, T/4, w]
        n = h.shape[1]
        if n > self.position.shape[1]:
            raise InputError(f"motion of {features.shape[1]} frames is longer than the evaluator's maximum")
        h = h + self.position[:, :n]
        token_lengths = torch.clamp((lengths + 3) // 4, min=1, max=n)
        pad = torch.arange(n, device=h.device)[None, :] >= token_lengths[:, None]
        h = self.transformer(h, src_key_padding_mask=pad)
        keep = (~pad).unsqueeze(-1).to(h.dtype)
        pooled = (h * keep).sum(1) / keep.sum(1)
        return F.normalize(self.out(pooled), dim=-1)


class TextHead(nn.Module):
    """Frozen sentence embedding ``[B, text_dim]`` -> unit embedding ``[B, latent]``."""

    def __init__(self, text_dim: int, cfg: EvaluatorConfig):
        super().__init__()
        self.net = nn.Sequential(
            nn.Linear(text_dim, cfg.width), nn.GELU(), nn.Dropout(cfg.dropout), nn.Linear(cfg.width, cfg.latent_dim)
        )

    def forward(self, sentence_embedding: torch.Tensor) -> torch.Tensor:
        return F.normalize(self.net(sentence_embedding), dim=-1)


class TextMotionEvaluator(nn.Module):
    def __init__(self, cfg: EvaluatorConfig, text_dim: int, mean: np.ndarray, std: np.ndarray):
        super().__init__()
        self.cfg = cfg
        self.text_dim = text_dim
        self.motion = MotionEncoder(cfg)
        self.text = TextHead(text_dim, cfg)
        self.register_buffer("mean", torch.as_tensor(np.asarray(mean, np.float32)))
        self.register_buffer("std", torch.as_tensor(np.maximum(np.asarray(std, np.float32), 1e-4)))
        self.log_scale = nn.Parameter(torch.tensor(math.log(1.0 / cfg.temperature)))

    def embed_motion(self, raw_features: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
        """Raw (unnormalised) features ``[B, T, 263]`` (zero padded past ``lengths [B]`` frames,
        padding ignored) -> unit embeddings ``[B, latent]``."""
        return self.motion((raw_features - self.mean) / self.std, lengths)

    def embed_text(self, sentence_embedding: torch.Tensor) -> torch.Tensor:
        """Frozen sentence-encoder output ``[B, text_dim]`` -> unit embeddings ``[B, latent]``."""
        return self.text(sentence_embedding)

    def contrastive_loss(self, text_z: torch.Tensor, motion_z: torch.Tensor, same_text: torch.Tensor,
                         extra_motion_z: torch.Tensor | None = None) -> torch.Tensor:
        """Symmetric InfoNCE over ``[B, latent]`` text and motion embeddings.

        ``same_text [B, B]`` marks off-diagonal pairs that share a caption (not negatives);
        ``extra_motion_z [K, latent]`` (corrupted motions) are extra negatives for every text.
        """
        scale = self.log_scale.exp().clamp(max=100.0)
        logits = scale * text_z @ motion_z.T
        eye = torch.eye(len(logits), dtype=torch.bool, device=logits.device)
        logits = logits.masked_fill(same_text & ~eye, float("-inf"))
        target = torch.arange(len(logits), device=logits.device)
        text_to_motion = logits if extra_motion_z is None else torch.cat([logits, scale * text_z @ extra_motion_z.T], 1)
        return 0.5 * (F.cross_entropy(text_to_motion, target) + F.cross_entropy(logits.T, target))


def save_evaluator(model: TextMotionEvaluator, run_dir: str | Path) -> None:
    from motok_robot.checkpoint import atomic_save_tensors

    run = Path(run_dir)
    run.mkdir(parents=True, exist_ok=True)
    config = {"evaluator": model.cfg.to_dict(), "text_dim": model.text_dim}
    atomic_save_tensors(model.state_dict(), run / "model.safetensors")
    (run / "config.json").write_text(json.dumps(config, indent=2))


def load_evaluator(run_dir: str | Path, device: str = "cpu") -> TextMotionEvaluator:
    from safetensors.torch import load_file

    run = Path(run_dir)
    for name in ("config.json", "model.safetensors"):
        if not (run / name).exists():
            raise InputError(f"evaluator run {run}: missing {name} (train one with `motok-robot train evaluator`)")
    config = json.loads((run / "config.json").read_text())
    # runs written before these options existed used neither
    cfg = EvaluatorConfig.from_dict({"motion_deltas": False, "corrupt_negatives": 0.0, **config["evaluator"]})
    state = load_file(str(run / "model.safetensors"))
    model = TextMotionEvaluator(cfg, int(config["text_dim"]), state["mean"].numpy(), state["std"].numpy())
    missing, unexpected = model.load_state_dict(state, strict=False)
    if missing or unexpected:
        raise InputError(f"evaluator weights {run / 'model.safetensors'}: missing {missing}, unexpected {unexpected}")
    return model.to(device).eval()

"""Configuration of the text-motion evaluator and of the generation evaluation (defaults in one place)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path

from motok_robot.config_utils import dataclass_from_dict
from motok_robot.paths import models_dir

__all__ = ["EvaluatorConfig", "GenerationEvalConfig", "default_evaluator_dir"]


@dataclass
class EvaluatorConfig:
    """Contrastive text-motion evaluator (in the spirit of the HumanML3D evaluator and TMR).

    The text side is a frozen sentence encoder (``text_encoder``, see :mod:`motok_robot.text`)
    followed by a learned MLP; the motion side is a strided 1-D conv + transformer over the
    normalised 263-d features. Both end in ``latent_dim`` unit-norm embeddings, so Euclidean
    distances used by the metrics are monotone in cosine similarity.
    """

    text_encoder: str = "minilm"
    feature_dim: int = 263
    latent_dim: int = 256
    width: int = 256
    layers: int = 3
    heads: int = 4
    dropout: float = 0.1
    temperature: float = 0.07
    #: share of each batch whose motion gets a corrupted copy (frames shuffled, time reversed,
    #: frozen or jittered) used as an extra negative for every caption (0 = plain InfoNCE)
    corrupt_negatives: float = 0.25
    #: feed frame-to-frame feature differences to the motion encoder as extra channels
    motion_deltas: bool = True
    min_frames: int = 40  # 2 s at 20 fps
    max_frames: int = 196  # 9.8 s, as HumanML3D
    batch_size: int = 64
    lr: float = 3e-4
    weight_decay: float = 1e-4
    steps: int = 3000
    eval_every: int = 500
    seed: int = 0

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> "EvaluatorConfig":
        return dataclass_from_dict(cls, data, "evaluator config", noun="field")


@dataclass
class GenerationEvalConfig:
    """HumanML3D protocol settings for ``motok-robot eval generation``."""

    repeats: int = 20
    r_precision_batch: int = 32
    diversity_times: int = 300
    mm_texts: int = 100
    mm_repeats: int = 30
    mm_times: int = 10
    max_clips: int | None = None
    batch_size: int = 64  #: texts per generator call
    seed: int = 0
    extra: dict = field(default_factory=dict)


def default_evaluator_dir() -> Path:
    """Where ``motok-robot train evaluator`` writes and ``eval generation`` reads by default."""
    return models_dir() / "evaluator"

"""What both planners share: condition encoders, length estimator, the ``plan`` interface."""

from __future__ import annotations

from abc import ABC, abstractmethod

import torch
from torch import nn

from motok_robot.errors import InputError
from motok_robot.planner.conditions import Conditions, GlobalConditionEncoder, LocalConditionEncoder
from motok_robot.planner.config import PlannerConfig
from motok_robot.planner.length import LengthEstimator
from motok_robot.planner.transformer import Transformer


def end_embedding(entries: int, width: int) -> nn.Embedding:
    """The learned embedding of the distance to the sequence end (``PlannerConfig.end_embedding``),
    initialised small like the position embedding: at ``nn.Embedding``'s unit scale (norm about
    ``sqrt(width)``) each length starts as a large random vector that outweighs the text feature
    ``M_g`` (AR planners trained so on the shared data bowed in 3-11 of 48 seeds against 14-23
    without it; models/MODEL_CARD.md, "The AR planner with the end embedding")."""
    embedding = nn.Embedding(entries, width)
    nn.init.normal_(embedding.weight, std=0.02)
    return embedding


class Planner(nn.Module, ABC):
    """A token planner: conditions -> MoTok token ids.

    Subclasses: :class:`~motok_robot.planner.masked.MaskedPlanner` (discrete diffusion,
    bidirectional) and :class:`~motok_robot.planner.autoregressive.ARPlanner` (causal). Both put
    ``M_g`` at sequence position 0 and add the local features ``M_s`` to token embeddings.
    """

    causal: bool = False
    #: extra ids after the K codes (mask / end / pad)
    n_special: int = 2

    def __init__(self, config: PlannerConfig) -> None:
        super().__init__()
        self.config = config.validate()
        c = config
        self.global_encoder = GlobalConditionEncoder(c.text_dim, c.width, len(c.action_labels))
        self.local_encoder = LocalConditionEncoder(c.downsample, c.width, c.local_hidden)
        self.token_embedding = nn.Embedding(c.codebook_size + self.n_special, c.width)
        self.position_embedding = nn.Parameter(torch.randn(c.max_tokens + 2, c.width) * 0.02)
        self.transformer = Transformer(c.width, c.layers, c.heads, c.ff_mult * c.width, c.dropout, causal=self.causal)
        self.length_estimator = LengthEstimator(c.text_dim, c.length_hidden, c.max_tokens)

    @property
    def device(self) -> torch.device:
        return self.position_embedding.device

    def _check_n_tokens(self, n_tokens: int | torch.Tensor, batch: int) -> torch.Tensor:
        n = torch.as_tensor(n_tokens, dtype=torch.long).reshape(-1)
        if n.numel() == 1:
            n = n.expand(batch)
        if n.numel() != batch:
            raise InputError(f"n_tokens has {n.numel()} entries for a batch of {batch}")
        if int(n.min()) < 1 or int(n.max()) > self.config.max_tokens:
            raise InputError(f"n_tokens must be in 1..{self.config.max_tokens} "
                             f"(at most {self.config.max_seconds:g} s of motion), got {n.tolist()}")
        return n.to(self.device)

    def predict_length(self, cond: Conditions) -> torch.Tensor:
        """Token counts ``[B]`` from the text (the estimator's median); mean training length otherwise."""
        if cond.text_embedding is None:
            raise InputError("no motion length given and no text to estimate it from: pass seconds / n_tokens")
        return self.length_estimator.predict(cond.text_embedding.to(self.device).float())

    @abstractmethod
    def loss(self, tokens: torch.Tensor, lengths: torch.Tensor, cond: Conditions, generator: torch.Generator,
             drop: torch.Tensor | None = None, ends: torch.Tensor | None = None) -> dict[str, torch.Tensor]:
        """Training loss on ``tokens [B, N]`` (padded) with valid ``lengths [B]``; returns
        ``{"loss", "accuracy", "count"}`` (accuracy over the predicted positions)."""

    @abstractmethod
    def plan(self, cond: Conditions, n_tokens: int | torch.Tensor | None = None, seed: int = 0,
             cfg_scale: float = 1.0, temperature: float = 1.0, top_k: int | None = None,
             top_p: float | None = None, **kwargs) -> torch.Tensor:
        """Sample tokens ``LongTensor [B, N]`` (N = max of ``n_tokens``; ``-1`` past each sample's length)."""

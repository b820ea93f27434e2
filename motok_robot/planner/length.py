"""Length estimator: text embedding -> distribution over the number of tokens of the motion."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn


class LengthEstimator(nn.Module):
    """MLP classifier over ``1 .. max_tokens`` tokens from a text embedding ``[B, D]``.

    The prediction is the median of the predicted distribution (robust to the long tail of
    clip lengths).
    """

    def __init__(self, text_dim: int, hidden: int, max_tokens: int) -> None:
        super().__init__()
        self.max_tokens = max_tokens
        self.net = nn.Sequential(nn.Linear(text_dim, hidden), nn.GELU(), nn.Linear(hidden, hidden), nn.GELU(),
                                 nn.Linear(hidden, max_tokens))

    def forward(self, text_embedding: torch.Tensor) -> torch.Tensor:
        """``[B, D]`` -> logits ``[B, max_tokens]``; class ``c`` means ``c + 1`` tokens."""
        return self.net(text_embedding)

    def loss(self, text_embedding: torch.Tensor, n_tokens: torch.Tensor) -> torch.Tensor:
        target = n_tokens.clamp(1, self.max_tokens) - 1
        return F.cross_entropy(self(text_embedding), target.long())

    @torch.no_grad()
    def predict(self, text_embedding: torch.Tensor) -> torch.Tensor:
        """``[B, D]`` -> predicted token counts ``[B]`` int64 in ``1 .. max_tokens``."""
        cdf = self(text_embedding).softmax(-1).cumsum(-1)
        return (cdf < 0.5).sum(-1).clamp(max=self.max_tokens - 1) + 1

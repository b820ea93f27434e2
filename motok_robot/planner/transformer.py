"""A small pre-norm transformer used by both planners (bidirectional or causal)."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn


class Block(nn.Module):
    """Pre-norm self-attention + GELU MLP block; input/output ``[B, L, width]``."""

    def __init__(self, width: int, heads: int, ff_width: int, dropout: float) -> None:
        super().__init__()
        self.heads = heads
        self.norm1 = nn.LayerNorm(width)
        self.qkv = nn.Linear(width, 3 * width)
        self.proj = nn.Linear(width, width)
        self.norm2 = nn.LayerNorm(width)
        self.mlp = nn.Sequential(nn.Linear(width, ff_width), nn.GELU(), nn.Linear(ff_width, width))
        self.dropout = dropout
        self.drop = nn.Dropout(dropout)

    def forward(self, x: torch.Tensor, attn_bias: torch.Tensor) -> torch.Tensor:
        """``attn_bias`` ``[B or 1, 1, L, L]`` additive (0 or -inf)."""
        b, length, width = x.shape
        q, k, v = self.qkv(self.norm1(x)).reshape(b, length, 3, self.heads, width // self.heads).permute(2, 0, 3, 1, 4)
        a = F.scaled_dot_product_attention(q, k, v, attn_mask=attn_bias,
                                           dropout_p=self.dropout if self.training else 0.0)
        x = x + self.drop(self.proj(a.transpose(1, 2).reshape(b, length, width)))
        return x + self.drop(self.mlp(self.norm2(x)))

    def step(self, x: torch.Tensor, cache: dict[str, torch.Tensor]) -> torch.Tensor:
        """Causal incremental decoding: ``x [B, 1, width]`` attends to the cached keys/values of
        the earlier positions and itself; the cache is extended in place."""
        b, _, width = x.shape
        q, k, v = self.qkv(self.norm1(x)).reshape(b, 1, 3, self.heads, width // self.heads).permute(2, 0, 3, 1, 4)
        if "k" in cache:
            k = torch.cat([cache["k"], k], dim=2)
            v = torch.cat([cache["v"], v], dim=2)
        cache["k"], cache["v"] = k, v
        a = F.scaled_dot_product_attention(q, k, v)
        x = x + self.proj(a.transpose(1, 2).reshape(b, 1, width))
        return x + self.mlp(self.norm2(x))


class Transformer(nn.Module):
    """Stack of :class:`Block`; ``causal`` selects left-to-right attention."""

    def __init__(self, width: int, layers: int, heads: int, ff_width: int, dropout: float, causal: bool) -> None:
        super().__init__()
        self.blocks = nn.ModuleList(Block(width, heads, ff_width, dropout) for _ in range(layers))
        self.norm = nn.LayerNorm(width)
        self.causal = causal

    def forward(self, x: torch.Tensor, valid: torch.Tensor | None = None) -> torch.Tensor:
        """``x`` ``[B, L, width]``; ``valid`` ``[B, L]`` bool (False = padding, never attended to)."""
        b, length, _ = x.shape
        bias = torch.zeros(1, 1, length, length, device=x.device, dtype=x.dtype)
        if self.causal:
            bias = bias + torch.full((length, length), float("-inf"), device=x.device, dtype=x.dtype).triu(1)
        if valid is not None:
            key_bias = torch.zeros(b, 1, 1, length, device=x.device, dtype=x.dtype)
            key_bias = key_bias.masked_fill(~valid[:, None, None, :], float("-inf"))
            bias = bias + key_bias
        for block in self.blocks:
            x = block(x, bias)
        return self.norm(x)

    def new_cache(self) -> list[dict[str, torch.Tensor]]:
        """Empty key/value cache for :meth:`step` (causal transformers only)."""
        return [{} for _ in self.blocks]

    def step(self, x: torch.Tensor, cache: list[dict[str, torch.Tensor]]) -> torch.Tensor:
        """One new position ``x [B, 1, width]`` -> its output ``[B, 1, width]`` (eval mode)."""
        assert self.causal, "incremental decoding needs a causal transformer"
        for block, block_cache in zip(self.blocks, cache):
            x = block.step(x, block_cache)
        return self.norm(x)

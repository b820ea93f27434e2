"""Single shared codebook vector quantizer with EMA updates and dead-code restarts.

``z_n = argmin_k ||h_n - c_k||^2``, ``q_n = c_{z_n}``; gradients pass straight through
(``q = h + sg(q - h)``); the encoder is pulled to its code by the commitment loss
``||h - sg(q)||^2``; the codebook itself is not trained by gradients but follows an
exponential moving average of the encoder outputs assigned to each code.  A code whose EMA
assignment count drops below ``dead_code_threshold`` times the average count per code
(``M / K`` for ``M`` latents per batch, so the rule does not depend on the batch size) is
restarted at a random encoder output of the current batch (drawn with the caller's
generator, so training stays deterministic).  The codebook is initialised from the first training batch.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import nn


@dataclass
class QuantizerOutput:
    quantized: torch.Tensor  #: [B, N, d] straight-through quantized latents q
    indices: torch.Tensor  #: [B, N] int64 token ids z
    commitment: torch.Tensor  #: scalar, mean ||h - sg(q)||^2 per element
    perplexity: torch.Tensor  #: scalar, exp(entropy) of the code histogram of this batch
    usage: torch.Tensor  #: scalar, fraction of the K codes used in this batch


class VectorQuantizer(nn.Module):
    """Buffers: ``codebook [K, d]``, ``ema_count [K]``, ``ema_sum [K, d]``, ``initialised`` (0/1),
    ``restarts`` (total restarted codes, for logging)."""

    def __init__(self, codebook_size: int, code_dim: int, decay: float = 0.99, dead_code_threshold: float = 0.1, eps: float = 1e-5):
        super().__init__()
        self.codebook_size = int(codebook_size)
        self.code_dim = int(code_dim)
        self.decay = float(decay)
        self.dead_code_threshold = float(dead_code_threshold)
        self.eps = float(eps)
        self.register_buffer("codebook", torch.zeros(self.codebook_size, self.code_dim))
        self.register_buffer("ema_count", torch.ones(self.codebook_size))
        self.register_buffer("ema_sum", torch.zeros(self.codebook_size, self.code_dim))
        self.register_buffer("initialised", torch.zeros((), dtype=torch.int64))
        self.register_buffer("restarts", torch.zeros((), dtype=torch.int64))

    # -- lookup ---------------------------------------------------------------------------
    def nearest(self, h: torch.Tensor) -> torch.Tensor:
        """``h [..., d]`` -> code ids ``[...]`` (int64) of the nearest codebook entries."""
        flat = h.reshape(-1, self.code_dim)
        # ||h||^2 - 2 h.c + ||c||^2 (||h||^2 is constant per row and can be dropped)
        distances = (self.codebook.pow(2).sum(1))[None, :] - 2.0 * flat @ self.codebook.T
        return distances.argmin(dim=1).reshape(h.shape[:-1])

    def lookup(self, indices: torch.Tensor) -> torch.Tensor:
        """Token ids ``[...]`` -> code vectors ``[..., d]``."""
        if indices.numel() and (int(indices.min()) < 0 or int(indices.max()) >= self.codebook_size):
            from motok_robot.errors import InputError

            raise InputError(
                f"token ids must be in 0..{self.codebook_size - 1} (got min {int(indices.min())}, max {int(indices.max())})"
            )
        return F.embedding(indices, self.codebook)

    # -- training -------------------------------------------------------------------------
    @torch.no_grad()
    def _init_from(self, flat: torch.Tensor, generator: torch.Generator | None) -> None:
        picks = _random_rows(flat, self.codebook_size, generator)
        mean_count = flat.shape[0] / self.codebook_size
        self.codebook.copy_(picks)
        self.ema_sum.copy_(picks * mean_count)
        self.ema_count.fill_(mean_count)
        self.initialised.fill_(1)

    @torch.no_grad()
    def _ema_update(self, flat: torch.Tensor, indices: torch.Tensor, generator: torch.Generator | None) -> None:
        onehot = F.one_hot(indices, self.codebook_size).to(flat.dtype)  # [M, K]
        counts = onehot.sum(0)
        sums = onehot.T @ flat
        self.ema_count.mul_(self.decay).add_(counts, alpha=1 - self.decay)
        self.ema_sum.mul_(self.decay).add_(sums, alpha=1 - self.decay)
        total = self.ema_count.sum()
        smoothed = (self.ema_count + self.eps) / (total + self.codebook_size * self.eps) * total  # Laplace smoothing
        self.codebook.copy_(self.ema_sum / smoothed[:, None])
        self.restart_dead_codes(flat, generator)

    @torch.no_grad()
    def restart_dead_codes(self, flat: torch.Tensor, generator: torch.Generator | None = None) -> int:
        """Move every code with ``ema_count < dead_code_threshold * M / K`` onto a random row of
        ``flat [M, d]`` (current encoder outputs), with the average count ``M / K``; return how
        many were restarted."""
        mean_count = flat.shape[0] / self.codebook_size
        dead = self.ema_count < self.dead_code_threshold * mean_count
        n_dead = int(dead.sum())
        if n_dead == 0:
            return 0
        picks = _random_rows(flat, n_dead, generator)
        self.codebook[dead] = picks
        self.ema_sum[dead] = picks * mean_count
        self.ema_count[dead] = mean_count
        self.restarts.add_(n_dead)
        return n_dead

    def forward(self, h: torch.Tensor, generator: torch.Generator | None = None) -> QuantizerOutput:
        """Quantize ``h [B, N, d]``; in training mode also update the codebook (EMA + restarts)."""
        flat = h.reshape(-1, self.code_dim)
        if self.training and not bool(self.initialised):
            self._init_from(flat.detach().float(), generator)
        indices = self.nearest(h.detach())
        if self.training:
            self._ema_update(flat.detach().float(), indices.reshape(-1), generator)
            indices = self.nearest(h.detach())  # restarted codes may now be nearer
        quantized = F.embedding(indices, self.codebook)
        commitment = F.mse_loss(h, quantized.detach())
        quantized = h + (quantized - h).detach()  # straight-through estimator
        stats = code_statistics(indices, self.codebook_size)
        return QuantizerOutput(quantized, indices, commitment, stats["perplexity"], stats["usage"])


def code_statistics(indices: torch.Tensor, codebook_size: int) -> dict[str, torch.Tensor]:
    """Perplexity (exp entropy of the code histogram) and usage (fraction of codes used)."""
    counts = torch.bincount(indices.reshape(-1), minlength=codebook_size).float()
    probs = counts / counts.sum().clamp_min(1.0)
    entropy = -(probs * torch.log(probs.clamp_min(1e-12))).sum()
    return {"perplexity": entropy.exp(), "usage": (counts > 0).float().mean(), "counts": counts}


def _random_rows(flat: torch.Tensor, n: int, generator: torch.Generator | None) -> torch.Tensor:
    """``n`` rows of ``flat [M, d]`` drawn at random (with replacement when M < n), plus a tiny
    jitter so duplicates separate."""
    m = flat.shape[0]
    if generator is None:
        generator = torch.Generator().manual_seed(0)
    if m >= n:
        idx = torch.randperm(m, generator=generator)[:n]
    else:
        idx = torch.randint(0, m, (n,), generator=generator)
    rows = flat[idx.to(flat.device)]
    jitter = torch.randn(rows.shape, generator=generator).to(rows.device) * (1e-3 * (rows.std() + 1e-6))
    return rows + jitter

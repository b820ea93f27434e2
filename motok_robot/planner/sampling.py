"""Sampling helpers shared by the planners: guidance, logit filters, masking schedule."""

from __future__ import annotations

import math

import torch


def guided_logits(cond: torch.Tensor, uncond: torch.Tensor | None, scale: float) -> torch.Tensor:
    """Classifier-free guidance on logits: ``cond + (scale - 1) * (cond - uncond)``.

    Equal to ``uncond + scale * (cond - uncond)``, written so that ``scale == 1`` returns
    ``cond`` exactly (plain conditional sampling) and ``scale == 0`` the unconditional logits.
    """
    if scale == 1.0 or uncond is None:
        return cond
    return cond + (scale - 1.0) * (cond - uncond)


def filter_logits(logits: torch.Tensor, top_k: int | None = None, top_p: float | None = None) -> torch.Tensor:
    """Set logits outside the top-k and outside the nucleus of mass ``top_p`` to ``-inf`` (last axis)."""
    if top_k is not None and 0 < top_k < logits.shape[-1]:
        kth = torch.topk(logits, top_k, dim=-1).values[..., -1:]
        logits = logits.masked_fill(logits < kth, float("-inf"))
    if top_p is not None and 0.0 < top_p < 1.0:
        sorted_logits, order = torch.sort(logits, dim=-1, descending=True)
        probs = sorted_logits.softmax(-1)
        before = probs.cumsum(-1) - probs  # mass strictly before each entry
        drop_sorted = before >= top_p
        drop = torch.zeros_like(drop_sorted).scatter(-1, order, drop_sorted)
        logits = logits.masked_fill(drop, float("-inf"))
    return logits


def sample_logits(
    logits: torch.Tensor, temperature: float, generator: torch.Generator, top_k: int | None = None,
    top_p: float | None = None,
) -> torch.Tensor:
    """Draw ids ``[...]`` from ``logits [..., V]`` (greedy when ``temperature == 0``)."""
    if temperature <= 0:
        return logits.argmax(-1)
    probs = filter_logits(logits / temperature, top_k, top_p).softmax(-1)
    flat = probs.reshape(-1, probs.shape[-1]).to(generator.device)
    ids = torch.multinomial(flat, 1, generator=generator).reshape(probs.shape[:-1])
    return ids.to(logits.device)


def cosine_mask_ratio(progress: torch.Tensor | float) -> torch.Tensor | float:
    """Fraction of tokens still masked at ``progress`` in [0, 1]: ``cos(pi/2 * progress)``."""
    if isinstance(progress, torch.Tensor):
        return torch.cos(progress * math.pi / 2)
    return math.cos(progress * math.pi / 2)


def gumbel_noise(shape, generator: torch.Generator, device) -> torch.Tensor:
    """Standard Gumbel noise drawn on the generator's device, returned on ``device``."""
    u = torch.rand(shape, generator=generator, device=generator.device).clamp(1e-9, 1 - 1e-9)
    return (-torch.log(-torch.log(u))).to(device)

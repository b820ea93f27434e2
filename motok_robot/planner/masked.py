"""Masked discrete-diffusion planner (MaskGIT/MoMask-style, bidirectional).

Sequence: position 0 holds ``M_g``; positions ``1..N`` hold the token embeddings (a [MASK]
embedding where a token is unknown) plus the local features ``M_s[1:N]``; padding past each
sample's length is never attended to.  Training masks a cosine-scheduled fraction of the
tokens and predicts them.  Sampling starts fully masked and, over ``steps`` iterations,
predicts every unknown token, scores every free token by its (guided) log-probability and
re-masks the least confident ones so that ``cos(pi/2 * s/steps)`` of the free tokens stay
masked after step ``s`` -- decided tokens can be re-masked when the model grows unsure of them.
Tokens given in ``keep_tokens`` are never changed (token inpainting for editing).
"""

from __future__ import annotations


import torch
import torch.nn.functional as F
from torch import nn

from motok_robot.errors import InputError
from motok_robot.planner.base import Planner, end_embedding
from motok_robot.planner.conditions import Conditions
from motok_robot.planner.config import PlannerConfig
from motok_robot.planner.sampling import cosine_mask_ratio, guided_logits, gumbel_noise, sample_logits


class MaskedPlanner(Planner):
    """Bidirectional masked-token planner; ids ``K`` = [MASK], ``K + 1`` = [PAD]."""

    causal = False
    n_special = 2

    def __init__(self, config: PlannerConfig) -> None:
        super().__init__(config)
        self.head = nn.Linear(config.width, config.codebook_size)
        k = config.token_conv_kernel
        self.token_conv = nn.Conv1d(config.width, config.width, k, padding=k // 2) if k else None
        # distance to the end 0 .. max_tokens - 1, and max_tokens = "the end is not in this crop"
        self.end_embedding = end_embedding(config.max_tokens + 1, config.width) if config.end_embedding else None

    @property
    def mask_id(self) -> int:
        return self.config.codebook_size

    @property
    def pad_id(self) -> int:
        return self.config.codebook_size + 1

    def logits(self, tokens: torch.Tensor, lengths: torch.Tensor, cond: Conditions,
               drop: torch.Tensor | None = None, ends: torch.Tensor | None = None) -> torch.Tensor:
        """``tokens [B, N]`` (codes, [MASK] or [PAD]) -> logits over the K codes ``[B, N, K]``.
        ``ends [B]`` bool: the sequence ends where the motion ends (default: all True); only
        planners with ``end_embedding`` use it."""
        b, n = tokens.shape
        x = self.token_embedding(tokens)
        if cond.local is not None:
            x = x + self.local_encoder(cond.local, n)
        position = torch.arange(n, device=tokens.device)[None]
        valid = position < lengths[:, None]
        if self.end_embedding is not None:
            to_end = (lengths[:, None] - 1 - position).clamp(min=0)
            if ends is not None:
                to_end = torch.where(ends.to(tokens.device)[:, None], to_end, torch.full_like(to_end, self.config.max_tokens))
            x = x + self.end_embedding(to_end)
        if self.token_conv is not None:  # neighbours' tokens; padding is zero, as past the sequence's ends
            x = x * valid[..., None]
            x = x + self.token_conv(x.transpose(1, 2)).transpose(1, 2)
        g = self.global_encoder(cond, drop)
        seq = torch.cat([g[:, None], x], dim=1) + self.position_embedding[: n + 1]
        valid = torch.cat([torch.ones(b, 1, dtype=torch.bool, device=tokens.device), valid], dim=1)
        return self.head(self.transformer(seq, valid)[:, 1:])

    def loss(self, tokens, lengths, cond, generator, drop=None, ends=None, per_sample: bool = False):
        """Cross-entropy of the masked tokens.  ``per_sample``: the loss is each sample's mean over
        its masked tokens, averaged over samples, so a lightly masked sample (much context, few
        targets) weighs as much as a heavily masked one (the weighting of the masked-diffusion
        ELBO); otherwise the mean over every masked token of the batch, where heavily masked
        samples dominate.  ``accuracy`` is always over all masked tokens."""
        b, n = tokens.shape
        device = tokens.device
        valid = torch.arange(n, device=device)[None] < lengths[:, None]
        u = torch.rand(b, generator=generator, device=generator.device).to(device)
        n_mask = torch.ceil(cosine_mask_ratio(u) * lengths).clamp(min=1).long()
        n_mask = torch.minimum(n_mask, lengths)
        scores = torch.rand(b, n, generator=generator, device=generator.device).to(device)
        scores = scores.masked_fill(~valid, 2.0)
        rank = scores.argsort(1).argsort(1)
        masked = (rank < n_mask[:, None]) & valid
        inputs = torch.where(masked, torch.full_like(tokens, self.mask_id), tokens)
        inputs = inputs.masked_fill(~valid, self.pad_id)
        logits = self.logits(inputs, lengths, cond, drop, ends)
        target = tokens[masked]
        picked = logits[masked]
        if per_sample:
            per_token = F.cross_entropy(logits.transpose(1, 2), tokens.masked_fill(~masked, 0), reduction="none")
            loss = ((per_token * masked).sum(1) / masked.sum(1).clamp(min=1)).mean()
        else:
            loss = F.cross_entropy(picked, target)
        accuracy = (picked.argmax(-1) == target).float().mean()
        return {"loss": loss, "accuracy": accuracy, "count": torch.tensor(float(target.numel()))}

    @torch.no_grad()
    def plan(self, cond: Conditions, n_tokens=None, seed: int = 0, cfg_scale: float = 1.0,
             temperature: float = 1.0, top_k: int | None = None, top_p: float | None = None,
             steps: int = 10, keep_tokens: torch.Tensor | None = None, keep_mask: torch.Tensor | None = None,
             remask_noise: float = 1.0, always_guide: bool = False) -> torch.Tensor:
        """Sample tokens ``LongTensor [B, N]`` (``-1`` past each sample's length).

        Args:
            cond: the conditions (B samples).
            n_tokens: tokens per sample (int or ``[B]``); None = predicted from the text.
            seed: seeds every random draw (same seed -> same tokens).
            cfg_scale: classifier-free guidance scale (1 = conditional only).
            temperature, top_k, top_p: token sampling (temperature 0 = greedy).
            steps: unmasking iterations.
            keep_tokens: ``[B, N]`` or ``[N]`` tokens to keep fixed where ``keep_mask`` (default:
                where ``keep_tokens >= 0``); they are returned unchanged.
            remask_noise: scale of the Gumbel noise added to confidences (annealed to 0).
            always_guide: run the unconditional branch even when ``cfg_scale == 1`` (testing).
        """
        if steps < 1:
            raise InputError(f"steps must be >= 1 (got {steps})")
        b = cond.batch_size
        n = self.predict_length(cond) if n_tokens is None else self._check_n_tokens(n_tokens, b)
        big_n = int(n.max())
        device = self.device
        k = self.config.codebook_size
        valid = torch.arange(big_n, device=device)[None] < n[:, None]
        ids = torch.full((b, big_n), self.mask_id, dtype=torch.long, device=device)
        fixed = torch.zeros(b, big_n, dtype=torch.bool, device=device)
        if keep_tokens is not None:
            keep = torch.as_tensor(keep_tokens, dtype=torch.long, device=device)
            if keep.dim() == 1:
                keep = keep[None].expand(b, -1)
            if keep.shape[1] != big_n or keep.shape[0] != b:
                raise InputError(f"keep_tokens has shape {tuple(keep.shape)}, expected [{b}, {big_n}]")
            fixed = (keep >= 0) if keep_mask is None else torch.as_tensor(keep_mask, device=device).bool()
            fixed = fixed & valid
            if bool(((keep < 0) | (keep >= k))[fixed].any()):
                raise InputError(f"keep_tokens: kept ids must be in 0..{k - 1}")
            ids = torch.where(fixed, keep, ids)
        ids = ids.masked_fill(~valid, self.pad_id)
        free = valid & ~fixed
        n_free = free.sum(1)
        generator = torch.Generator().manual_seed(int(seed))
        guide = always_guide or cfg_scale != 1.0
        if guide:  # conditional and unconditional branches as one batch of 2B
            both = cond.select(torch.cat([torch.arange(b), torch.arange(b)]))
            drop = torch.arange(2 * b, device=device) >= b
            n_both = torch.cat([n, n])
        for step in range(steps):
            if guide:
                out = self.logits(torch.cat([ids, ids]), n_both, both, drop)
                logits = guided_logits(out[:b], out[b:], cfg_scale)
            else:
                logits = self.logits(ids, n, cond)
            sampled = sample_logits(logits, temperature, generator, top_k, top_p)
            candidate = torch.where((ids == self.mask_id) & free, sampled, ids)
            logp = logits.log_softmax(-1).gather(-1, candidate.clamp(0, k - 1)[..., None])[..., 0]
            progress = (step + 1) / steps
            n_masked_next = torch.floor(n_free.float() * cosine_mask_ratio(progress)).long()
            confidence = logp + remask_noise * (1.0 - progress) * gumbel_noise(logp.shape, generator, device)
            confidence = confidence.masked_fill(~free, float("inf"))
            rank = confidence.argsort(1).argsort(1)
            remask = (rank < n_masked_next[:, None]) & free
            ids = torch.where(remask, torch.full_like(ids, self.mask_id), candidate)
        return ids.masked_fill(~valid, -1)

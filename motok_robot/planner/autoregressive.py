"""Autoregressive planner (causal transformer, GPT-style) with an end token.

Sequence: position 0 holds ``M_g``; position ``i >= 1`` holds token ``z_i``.  The output at
position ``i`` predicts ``z_{i+1}`` (or [END] after the last token).  The local feature of token
``z_{i+1}`` is added at position ``i`` -- the PRECEDING position -- so a token is predicted from
its own local condition and earlier tokens only, and causality holds.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from motok_robot.errors import InputError
from motok_robot.planner.base import Planner, end_embedding
from motok_robot.planner.conditions import Conditions
from motok_robot.planner.config import PlannerConfig
from motok_robot.planner.sampling import guided_logits, sample_logits

IGNORE = -100


class ARPlanner(Planner):
    """Causal planner; ids ``K`` = [END], ``K + 1`` = [PAD]; predicts over ``K + 1`` classes."""

    causal = True
    n_special = 2

    def __init__(self, config: PlannerConfig) -> None:
        super().__init__(config)
        self.head = nn.Linear(config.width, config.codebook_size + 1)
        # tokens still to draw at a position, 0 .. max_tokens (0: the [END] position), and
        # max_tokens + 1 = "the end is unknown" (a crop that stops mid-clip, or no length given)
        self.end_embedding = end_embedding(config.max_tokens + 2, config.width) if config.end_embedding else None

    @property
    def unknown_end(self) -> int:
        """The end embedding's "end unknown" entry."""
        return self.config.max_tokens + 1

    def _to_draw(self, lengths: torch.Tensor, positions: int, ends: torch.Tensor | None) -> torch.Tensor:
        """``[B, positions]`` indices of the end embedding: at sequence position ``i`` (which
        predicts token ``i + 1`` or [END]) ``length - i`` tokens are still to draw (capped at
        ``end_horizon``); past the length (padding, never a target) 0; "unknown" where ``ends``
        is False."""
        position = torch.arange(positions, device=lengths.device)[None]
        to_draw = (lengths[:, None] - position).clamp(min=0)
        if self.config.end_horizon:  # "more than end_horizon to go" is one entry
            to_draw = to_draw.clamp(max=self.config.end_horizon + 1)
        if ends is not None:
            to_draw = torch.where(ends.to(lengths.device)[:, None], to_draw, torch.full_like(to_draw, self.unknown_end))
        return to_draw

    @property
    def end_id(self) -> int:
        return self.config.codebook_size

    @property
    def pad_id(self) -> int:
        return self.config.codebook_size + 1

    def logits(self, tokens: torch.Tensor, cond: Conditions, n_local: int | None = None,
               drop: torch.Tensor | None = None, lengths: torch.Tensor | None = None,
               ends: torch.Tensor | None = None) -> torch.Tensor:
        """``tokens [B, L]`` (inputs ``z_1..z_L``) -> logits ``[B, L + 1, K + 1]``; output ``i``
        predicts token ``i + 1`` (1-based) or [END]. ``n_local``: tokens the local conditions cover.
        ``lengths [B]``, ``ends [B]`` bool: only planners with ``end_embedding`` use them (each
        sample's token count, and whether the motion ends there; no lengths = end unknown)."""
        b, length = tokens.shape
        g = self.global_encoder(cond, drop)
        embedded = self.token_embedding(tokens)
        if self.config.global_every_position:
            embedded = embedded + g[:, None]
        seq = torch.cat([g[:, None], embedded], dim=1)
        if cond.local is not None:
            if n_local is None:
                n_local = -(-cond.local.frames // self.config.downsample)
            m_s = self.local_encoder(cond.local, n_local)  # [B, n_local, W]; m_s[:, j] conditions token j+1
            upto = min(length + 1, n_local)
            seq = torch.cat([seq[:, :upto] + m_s[:, :upto], seq[:, upto:]], dim=1)
        seq = seq + self.position_embedding[: length + 1]
        if self.end_embedding is not None:
            if lengths is None:
                to_draw = torch.full((b, length + 1), self.unknown_end, dtype=torch.long, device=tokens.device)
            else:
                to_draw = self._to_draw(lengths.to(tokens.device), length + 1, ends)
            seq = seq + self.end_embedding(to_draw)
        return self.head(self.transformer(seq))

    def loss(self, tokens, lengths, cond, generator, drop=None, ends=None, corruption: float = 0.0):
        """Next-token cross-entropy (teacher forcing). ``corruption``: each sample replaces a
        fraction ``U(0, corruption)`` of its *input* tokens with random codes (targets stay the
        real tokens), so the model learns to continue from its own imperfect samples (the
        exposure-bias remedy of T2M-GPT)."""
        b, n = tokens.shape
        device = tokens.device
        idx = torch.arange(n + 1, device=device)[None]
        valid = idx[:, :n] < lengths[:, None]
        inputs = tokens
        if corruption > 0:
            rate = torch.rand(b, 1, generator=generator, device=generator.device) * corruption
            swap = torch.rand(b, n, generator=generator, device=generator.device) < rate
            random_codes = torch.randint(0, self.config.codebook_size, (b, n), generator=generator, device=generator.device)
            inputs = torch.where(swap.to(device), random_codes.to(device), tokens)
        inputs = inputs.masked_fill(~valid, self.pad_id)
        target = torch.full((b, n + 1), IGNORE, dtype=torch.long, device=device)
        target[:, :n] = torch.where(valid, tokens, torch.full_like(tokens, IGNORE))
        ends = torch.ones(b, dtype=torch.bool, device=device) if ends is None else ends.to(device)
        end_pos = idx == lengths[:, None]
        target = torch.where(end_pos & ends[:, None], torch.full_like(target, self.end_id), target)
        logits = self.logits(inputs, cond, n, drop, lengths, ends)
        loss = F.cross_entropy(logits.reshape(-1, logits.shape[-1]), target.reshape(-1), ignore_index=IGNORE)
        code = (target >= 0) & (target < self.end_id)
        accuracy = (logits.argmax(-1) == target)[code].float().mean()
        return {"loss": loss, "accuracy": accuracy, "count": code.sum().float()}

    @torch.no_grad()
    def plan(self, cond: Conditions, n_tokens=None, seed: int = 0, cfg_scale: float = 1.0,
             temperature: float = 1.0, top_k: int | None = None, top_p: float | None = None,
             always_guide: bool = False, **_ignored) -> torch.Tensor:
        """Sample tokens ``LongTensor [B, N]`` left to right (``-1`` past each sample's end).

        With ``n_tokens`` (int or ``[B]``) the end token is suppressed until exactly that many
        tokens are drawn; with ``n_tokens=None`` a sample stops at its first [END] (at the
        latest after the local conditions' length, or ``max_tokens``).  Uses a key/value cache;
        the conditional and unconditional (guidance) branches run as one batch.
        """
        if _ignored.get("keep_tokens") is not None:
            raise InputError("token inpainting (keep_tokens) needs the masked planner (--planner masked)")
        b = cond.batch_size
        device = self.device
        fixed_length = n_tokens is not None
        if fixed_length:
            n = self._check_n_tokens(n_tokens, b)
            big_n = int(n.max())
        else:
            big_n = self.config.max_tokens
            if cond.local is not None:
                big_n = min(big_n, -(-cond.local.frames // self.config.downsample))
            n = torch.full((b,), big_n, dtype=torch.long, device=device)
        generator = torch.Generator().manual_seed(int(seed))
        guide = always_guide or cfg_scale != 1.0
        g = self.global_encoder(cond)
        if guide:
            g = torch.cat([g, self.global_encoder(cond.without_global())])
        m_s = None
        if cond.local is not None:
            m_s = self.local_encoder(cond.local, big_n)
            if guide:
                m_s = torch.cat([m_s, m_s])
        to_draw = None
        if self.end_embedding is not None:  # tokens still to draw at each position, or "unknown"
            to_draw = self._to_draw(n, big_n + 1, None) if fixed_length else \
                torch.full((b, big_n + 1), self.unknown_end, dtype=torch.long, device=device)
            if guide:
                to_draw = torch.cat([to_draw, to_draw])
        cache = self.transformer.new_cache()
        x = g[:, None]
        out = torch.zeros(b, big_n, dtype=torch.long, device=device)
        for i in range(big_n):
            if m_s is not None:
                x = x + m_s[:, i : i + 1]
            if to_draw is not None:
                x = x + self.end_embedding(to_draw[:, i : i + 1])
            h = self.transformer.step(x + self.position_embedding[i], cache)
            logits = self.head(h[:, 0])
            if guide:
                logits = guided_logits(logits[:b], logits[b:], cfg_scale)
            if fixed_length or i == 0:
                logits[:, self.end_id] = float("-inf")
            token = sample_logits(logits, temperature, generator, top_k, top_p)
            if not fixed_length:
                stop = (token == self.end_id) & (n == big_n)
                n = torch.where(stop, torch.full_like(n, i), n)
                if bool((n < big_n).all()):
                    break
            out[:, i] = token
            inputs = token.masked_fill(token == self.end_id, self.pad_id)
            x = self.token_embedding(torch.cat([inputs, inputs]) if guide else inputs)[:, None]
            if self.config.global_every_position:
                x = x + g[:, None]
        width = int(n.max())
        out = out[:, :width]
        valid = torch.arange(width, device=device)[None] < n[:, None]
        return out.masked_fill(~valid, -1)

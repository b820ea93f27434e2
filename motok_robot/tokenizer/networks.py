"""Networks of the MoTok tokenizer: encoder E, conditioning decoder D and denoiser f_phi.

All modules are 1-D convolutions over frames, so they run on any sequence length that is a
multiple of the downsampling factor (trained on short windows, decoded on whole clips).
Tensors are batch-first ``[B, T, C]`` at the public boundaries (frames on axis 1).
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn


def _conv(cin: int, cout: int, kernel: int, dilation: int = 1) -> nn.Conv1d:
    return nn.Conv1d(cin, cout, kernel, padding=dilation * (kernel - 1) // 2, dilation=dilation, padding_mode="replicate")


class ChannelNorm(nn.Module):
    """LayerNorm over channels of each frame of ``[B, C, T]`` (statistics do not depend on T)."""

    def __init__(self, channels: int):
        super().__init__()
        self.norm = nn.LayerNorm(channels)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.norm(x.transpose(1, 2)).transpose(1, 2)


class ResBlock(nn.Module):
    """``x + conv(act(conv(act(x))))`` with a dilated first convolution, ``[B, C, T]``."""

    def __init__(self, channels: int, kernel: int, dilation: int):
        super().__init__()
        self.conv1 = _conv(channels, channels, kernel, dilation)
        self.conv2 = _conv(channels, channels, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + self.conv2(F.silu(self.conv1(F.silu(x))))


def _stages(downsample: int) -> int:
    stages = int(round(math.log2(downsample)))
    if 2**stages != downsample:
        raise ValueError(f"downsample must be a power of two (got {downsample})")
    return stages


class Encoder(nn.Module):
    """``E``: features ``[B, T, F]`` -> latents ``h [B, T / downsample, code_dim]``.

    Progressive temporal downsampling: ``log2(downsample)`` stages of a strided convolution
    (kernel 4, stride 2) followed by ``depth`` residual blocks (kernel ``kernel_size``,
    dilations 1, 3, 9, ...).
    """

    def __init__(self, feature_dim: int, width: int, code_dim: int, downsample: int, depth: int, kernel_size: int):
        super().__init__()
        layers: list[nn.Module] = [_conv(feature_dim, width, 3), nn.SiLU()]
        for _ in range(max(_stages(downsample), 1)):
            if downsample > 1:
                layers.append(nn.Conv1d(width, width, 4, stride=2, padding=1, padding_mode="replicate"))
            layers += [ResBlock(width, kernel_size, 3**i) for i in range(depth)]
            if downsample == 1:
                break
        layers += [nn.SiLU(), _conv(width, code_dim, 3)]
        self.net = nn.Sequential(*layers)

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        return self.net(features.transpose(1, 2)).transpose(1, 2)


class ConditionDecoder(nn.Module):
    """``D``: quantized latents ``q [B, N, code_dim]`` -> per-frame signal ``[B, N * downsample, out_dim]``.

    Mirrors the encoder: residual blocks then nearest-neighbour x2 upsampling and a
    convolution, per stage.  With ``out_dim = feature_dim`` it is the plain VQ-VAE decoder
    (the convolutional baseline); otherwise ``out_dim`` is the conditioning width.
    """

    def __init__(self, code_dim: int, width: int, out_dim: int, downsample: int, depth: int, kernel_size: int):
        super().__init__()
        layers: list[nn.Module] = [_conv(code_dim, width, 3), nn.SiLU()]
        for _ in range(max(_stages(downsample), 1)):
            layers += [ResBlock(width, kernel_size, 3 ** (depth - 1 - i)) for i in range(depth)]
            if downsample == 1:
                break
            layers += [nn.Upsample(scale_factor=2, mode="nearest"), _conv(width, width, 3)]
        layers += [nn.SiLU(), _conv(width, width, 3), nn.SiLU(), _conv(width, out_dim, 3)]
        self.net = nn.Sequential(*layers)

    def forward(self, q: torch.Tensor) -> torch.Tensor:
        return self.net(q.transpose(1, 2)).transpose(1, 2)


def timestep_embedding(t: torch.Tensor, dim: int) -> torch.Tensor:
    """Sinusoidal embedding of (float) timesteps ``t [B]`` -> ``[B, dim]``."""
    half = dim // 2
    freqs = torch.exp(-math.log(10000.0) * torch.arange(half, device=t.device, dtype=torch.float32) / half)
    args = t.float()[:, None] * freqs[None, :]
    return torch.cat([torch.cos(args), torch.sin(args)], dim=1)


class DenoiserBlock(nn.Module):
    """Residual block with FiLM timestep modulation and the per-frame condition added."""

    def __init__(self, width: int, kernel: int, dilation: int):
        super().__init__()
        self.norm1 = ChannelNorm(width)
        self.conv1 = _conv(width, width, kernel, dilation)
        self.norm2 = ChannelNorm(width)
        self.film = nn.Linear(width, 2 * width)
        self.conv2 = _conv(width, width, kernel)
        nn.init.zeros_(self.conv2.weight)
        nn.init.zeros_(self.conv2.bias)

    def forward(self, h: torch.Tensor, temb: torch.Tensor, cond: torch.Tensor) -> torch.Tensor:
        scale, shift = self.film(temb)[:, :, None].chunk(2, dim=1)
        y = self.conv1(F.silu(self.norm1(h) + cond))
        y = self.norm2(y) * (1.0 + scale) + shift
        return h + self.conv2(F.silu(y))


class Denoiser(nn.Module):
    """``f_phi(x_t, t, s)``: noisy motion ``x_t [B, T, F]``, timesteps ``t [B]`` (0..diffusion_steps-1)
    and the per-frame condition ``s [B, T, cond_dim]`` -> prediction ``[B, T, F]`` (x0 or eps).

    A dilated residual 1-D convolution network (dilations 1, 2, 4, 8 repeating).  With
    ``input_skip`` (used for the eps parameterisation) ``x_t`` is added to the output, scaled
    per feature dim by a learned function of ``t`` (initially 1: at high noise eps ~ x_t).  The
    condition is projected once by :meth:`condition` and added inside every block, so a
    sampler projects it once per decode, not once per step.
    """

    def __init__(self, feature_dim: int, cond_dim: int, width: int, blocks: int, kernel: int, input_skip: bool = False):
        super().__init__()
        self.width = width
        self.input = _conv(feature_dim + cond_dim, width, kernel)
        self.cond_proj = _conv(cond_dim, width, 1)
        self.time_mlp = nn.Sequential(nn.Linear(128, width), nn.SiLU(), nn.Linear(width, width))
        self.blocks = nn.ModuleList(DenoiserBlock(width, kernel, 2 ** (i % 4)) for i in range(blocks))
        self.out_norm = ChannelNorm(width)
        self.output = _conv(width, feature_dim, kernel)
        nn.init.zeros_(self.output.weight)
        nn.init.zeros_(self.output.bias)
        # eps prediction: the noise is white in all feature dims, more than a width-channel network
        # can carry, so x_t reaches the output directly, scaled per dim by a learned function of t
        self.skip_scale = nn.Linear(width, feature_dim) if input_skip else None
        if self.skip_scale is not None:
            nn.init.zeros_(self.skip_scale.weight)
            nn.init.ones_(self.skip_scale.bias)

    def condition(self, s: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Pre-compute what depends only on ``s [B, T, cond_dim]``: (s channels-first, its projection)."""
        s_cf = s.transpose(1, 2)
        return s_cf, self.cond_proj(s_cf)

    def forward(self, x_t: torch.Tensor, t: torch.Tensor, s: torch.Tensor | tuple[torch.Tensor, torch.Tensor]) -> torch.Tensor:
        s_cf, cond = s if isinstance(s, tuple) else self.condition(s)
        if t.dim() == 0:
            t = t.expand(x_t.shape[0])
        temb = F.silu(self.time_mlp(timestep_embedding(t, 128)))
        h = self.input(torch.cat([x_t.transpose(1, 2), s_cf], dim=1))
        for block in self.blocks:
            h = block(h, temb, cond)
        out = self.output(F.silu(self.out_norm(h))).transpose(1, 2)
        if self.skip_scale is not None:
            out = out + self.skip_scale(temb)[:, None, :] * x_t
        return out

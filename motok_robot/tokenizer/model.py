"""The MoTok tokenizer: motion features <-> a single-layer sequence of discrete tokens.

``encode``: raw features ``[B, T, 263]`` -> normalise -> conv encoder ``E`` (``T / downsample``
latents) -> nearest entry of the one shared codebook -> token ids ``[B, N]``.

``decode``: token ids -> codebook vectors ``q`` -> conv decoder ``D`` -> per-frame condition
``s [B, T, width]`` -> DDIM sampling of the denoiser ``f_phi(x_t, t, s)`` from noise (cosine
schedule) -> model space -> (inverse emphasis projection) -> denormalise -> raw features.
With ``decoder="conv"`` the decoder regresses the (normalised) features from ``q`` directly.

Model space = normalised features ``(x - mean) / std``, times the emphasis projection when
``config.emphasis`` is on (the same in training and sampling).
"""

from __future__ import annotations

import hashlib
import json
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from motok_robot.errors import InputError
from motok_robot.tokenizer.config import TokenizerConfig
from motok_robot.tokenizer.emphasis import EmphasisProjection
from motok_robot.tokenizer.networks import ConditionDecoder, Denoiser, Encoder
from motok_robot.tokenizer.quantizer import VectorQuantizer
from motok_robot.tokenizer.sampler import EPS_X0_CLAMP, cosine_alpha_bar, ddim_sample

#: gamma of the Min-SNR loss weighting of the eps parameterisation
MIN_SNR_GAMMA = 5.0

#: minimum std used for normalising (dims that are constant in the training data)
STD_FLOOR = 1e-4

_CONTACT_DIMS = slice(259, 263)


def pad_to_multiple(features: torch.Tensor, multiple: int) -> tuple[torch.Tensor, int]:
    """Pad ``features [..., T, F]`` along frames to a multiple of ``multiple`` by repeating the
    last frame; return ``(padded [..., T', F], T)``.  Crop decoded features back with ``[..., :T, :]``."""
    length = features.shape[-2]
    if length < 1:
        raise InputError("features: the sequence has no frames")
    pad = (-length) % multiple
    if pad:
        last = features[..., -1:, :].expand(*features.shape[:-2], pad, features.shape[-1])
        features = torch.cat([features, last], dim=-2)
    return features, length


def crop_to_multiple(features: torch.Tensor, multiple: int) -> torch.Tensor:
    """Drop trailing frames of ``features [..., T, F]`` so T is a multiple of ``multiple``."""
    keep = features.shape[-2] - features.shape[-2] % multiple
    if keep < 1:
        raise InputError(f"features: {features.shape[-2]} frames is shorter than one token ({multiple} frames)")
    return features[..., :keep, :]


class MoTok(nn.Module):
    """Diffusion-based discrete motion tokenizer.

    Parameters
    ----------
    config: the architecture (:class:`TokenizerConfig`).
    mean, std: ``[feature_dim]`` per-dimension statistics of the raw training features
        (the prepared dataset's ``mean.npy`` / ``std.npy``); stored in the checkpoint.
    """

    def __init__(self, config: TokenizerConfig | None = None, mean: Any = None, std: Any = None):
        super().__init__()
        self.config = config = config or TokenizerConfig()
        dim = config.feature_dim
        mean_t = torch.zeros(dim) if mean is None else torch.as_tensor(np.asarray(mean), dtype=torch.float32).reshape(-1)
        std_t = torch.ones(dim) if std is None else torch.as_tensor(np.asarray(std), dtype=torch.float32).reshape(-1)
        if mean_t.shape != (dim,) or std_t.shape != (dim,):
            raise InputError(f"tokenizer: mean/std must have {dim} entries (got {tuple(mean_t.shape)}, {tuple(std_t.shape)})")
        if not (torch.isfinite(mean_t).all() and torch.isfinite(std_t).all()):
            raise InputError("tokenizer: mean/std contain NaN or inf")
        self.register_buffer("mean", mean_t.clone())
        self.register_buffer("std", std_t.clone().clamp_min(STD_FLOOR))
        self.register_buffer("alpha_bar", cosine_alpha_bar(config.diffusion_steps).float(), persistent=False)

        self.encoder = Encoder(dim, config.width, config.code_dim, config.downsample, config.depth, config.kernel_size)
        self.quantizer = VectorQuantizer(config.codebook_size, config.code_dim, config.ema_decay, config.dead_code_threshold)
        if config.decoder == "diffusion":
            self.cond_decoder = ConditionDecoder(config.code_dim, config.width, config.width, config.downsample, config.depth, config.kernel_size)
            self.denoiser: Denoiser | None = Denoiser(
                dim, config.width, config.denoiser_width, config.denoiser_blocks, config.denoiser_kernel,
                input_skip=config.parameterisation == "eps",
            )
        else:
            self.cond_decoder = ConditionDecoder(config.code_dim, config.width, dim, config.downsample, config.depth, config.kernel_size)
            self.denoiser = None
        self.projection: EmphasisProjection | None = (
            EmphasisProjection(dim, config.emphasis_dims, config.emphasis_c, config.emphasis_seed) if config.emphasis else None
        )

    # -- properties -----------------------------------------------------------------------
    @property
    def frames_per_token(self) -> int:
        """Frames represented by one token (= ``config.downsample``)."""
        return self.config.downsample

    @property
    def device(self) -> torch.device:
        return self.mean.device

    @property
    def codebook(self) -> torch.Tensor:
        """``[K, code_dim]`` codebook vectors (read-only view)."""
        return self.quantizer.codebook

    # -- the token vocabulary -------------------------------------------------------------
    #: configuration fields that decide which token a motion gets (with the tensors below)
    TOKEN_FIELDS = ("feature_dim", "downsample", "codebook_size", "code_dim", "width", "depth", "kernel_size")

    def token_tensors(self) -> dict[str, torch.Tensor]:
        """The tensors that decide ``encode``: normalisation, encoder weights and codebook."""
        state = self.state_dict()
        return {k: v for k, v in state.items() if k in ("mean", "std", "quantizer.codebook") or k.startswith("encoder.")}

    def tokens_digest(self) -> str:
        """SHA-256 (first 16 hex digits) of what decides the tokens (:meth:`token_tensors` and
        :data:`TOKEN_FIELDS`): equal digests give equal ``encode`` results, whatever the decoder."""
        h = hashlib.sha256()
        h.update(json.dumps({k: getattr(self.config, k) for k in self.TOKEN_FIELDS}, sort_keys=True).encode())
        for name, tensor in sorted(self.token_tensors().items()):
            h.update(name.encode())
            h.update(str(tuple(tensor.shape)).encode())
            h.update(tensor.detach().to("cpu", torch.float32).contiguous().numpy().tobytes())
        return h.hexdigest()[:16]

    def freeze_tokens(self) -> None:
        """Fix the encoder and the codebook (no gradients, no EMA updates or restarts, also in
        training mode); only the decoder side stays trainable."""
        self.encoder.requires_grad_(False)
        self._tokens_frozen = True
        self.train(self.training)

    def train(self, mode: bool = True) -> "MoTok":
        super().train(mode)
        if getattr(self, "_tokens_frozen", False):
            self.encoder.eval()
            self.quantizer.eval()
        return self

    # -- spaces ---------------------------------------------------------------------------
    def normalise(self, x: torch.Tensor) -> torch.Tensor:
        """Raw features ``[..., F]`` -> ``(x - mean) / std`` (differentiable)."""
        return (x - self.mean) / self.std

    def denormalise(self, x: torch.Tensor) -> torch.Tensor:
        """Normalised features ``[..., F]`` -> raw (differentiable)."""
        return x * self.std + self.mean

    def to_model_space(self, features: torch.Tensor) -> torch.Tensor:
        """Raw features -> diffusion space (normalised, then emphasis-projected if enabled)."""
        x = self.normalise(features)
        return self.projection.project(x) if self.projection is not None else x

    def from_model_space(self, x: torch.Tensor) -> torch.Tensor:
        """Diffusion space -> raw features (inverse of :meth:`to_model_space`)."""
        if self.projection is not None:
            x = self.projection.unproject(x)
        return self.denormalise(x)

    def pad(self, features: torch.Tensor) -> tuple[torch.Tensor, int]:
        """:func:`pad_to_multiple` with this tokenizer's ``frames_per_token``."""
        return pad_to_multiple(features, self.frames_per_token)

    # -- encode ---------------------------------------------------------------------------
    def _check_features(self, features: Any) -> torch.Tensor:
        features = torch.as_tensor(features)
        if features.dim() != 3 or features.shape[-1] != self.config.feature_dim:
            raise InputError(f"encode: features must be [B, T, {self.config.feature_dim}] (got {tuple(features.shape)})")
        length = features.shape[1]
        if length == 0 or length % self.frames_per_token:
            raise InputError(
                f"encode: T = {length} frames is not a positive multiple of {self.frames_per_token} frames per token; "
                "pad with motok_robot.tokenizer.pad_to_multiple (or tok.pad) first"
            )
        if not torch.isfinite(features).all():
            bad = (~torch.isfinite(features)).nonzero()[0].tolist()
            raise InputError(f"encode: features contain NaN/inf (first at batch {bad[0]}, frame {bad[1]}, dim {bad[2]})")
        return features.to(device=self.device, dtype=torch.float32)

    def latents(self, features: torch.Tensor) -> torch.Tensor:
        """Encoder output ``h [B, N, code_dim]`` of raw features ``[B, T, F]`` (differentiable)."""
        return self.encoder(self.normalise(features))

    @torch.no_grad()
    def encode(self, features: torch.Tensor) -> torch.Tensor:
        """Raw (unnormalised) features ``[B, T, F]`` (T a multiple of ``frames_per_token``) ->
        token ids ``LongTensor [B, T / frames_per_token]`` in ``0 .. codebook_size - 1``."""
        features = self._check_features(features)
        return self.quantizer.nearest(self.latents(features))

    # -- decode ---------------------------------------------------------------------------
    def _check_tokens(self, tokens: Any) -> torch.Tensor:
        tokens = torch.as_tensor(tokens)
        if tokens.dim() != 2 or tokens.shape[1] == 0:
            raise InputError(f"decode: tokens must be [B, N] with N >= 1 (got {tuple(tokens.shape)})")
        if tokens.dtype.is_floating_point or tokens.dtype == torch.bool:
            raise InputError(f"decode: tokens must be integers (got {tokens.dtype})")
        return tokens.to(device=self.device, dtype=torch.int64)

    def _length(self, tokens: torch.Tensor, length: int | None) -> int:
        full = tokens.shape[1] * self.frames_per_token
        if length is None:
            return full
        length = int(length)
        if not 1 <= length <= full:
            raise InputError(f"decode: length must be in 1..{full} for {tokens.shape[1]} tokens (got {length})")
        return length

    def condition(self, tokens: torch.Tensor, length: int | None = None) -> torch.Tensor:
        """Token ids ``[B, N]`` -> decoder output ``[B, length, C]`` (differentiable w.r.t. the
        network): the per-frame condition ``s`` (C = width) for the diffusion decoder, the
        normalised motion (C = feature_dim) for the conv baseline."""
        tokens = self._check_tokens(tokens)
        length = self._length(tokens, length)
        return self.cond_decoder(self.quantizer.lookup(tokens))[:, :length]

    @torch.no_grad()
    def decode(
        self,
        tokens: torch.Tensor,
        length: int | None = None,
        steps: int | None = None,
        seed: int = 0,
        guidance: Any = None,
        eta: float = 0.0,
        noise: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """Token ids ``[B, N]`` -> raw features ``[B, length, F]`` (float32, on ``self.device``).

        ``length`` defaults to ``N * frames_per_token`` and may be shorter (the last token then
        covers fewer frames).  ``steps`` DDIM steps (default ``config.sample_steps``), initial
        noise from ``seed`` (or the given ``noise [B, length, F]``), ``eta`` DDIM stochasticity
        (0 = deterministic).  ``guidance``: see :mod:`motok_robot.tokenizer.sampler`.
        """
        tokens = self._check_tokens(tokens)
        length = self._length(tokens, length)
        s = self.condition(tokens, length)
        if self.denoiser is None:
            if guidance is not None:
                raise InputError("decode: guidance needs the diffusion decoder (this tokenizer uses decoder='conv')")
            return self.denormalise(s)
        steps = int(steps or self.config.sample_steps)
        cond = self.denoiser.condition(s)
        denoiser = self.denoiser

        def model_fn(x_t: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
            return denoiser(x_t, t, cond)

        x0 = ddim_sample(
            model_fn,
            (tokens.shape[0], length, self.config.feature_dim),
            self.alpha_bar,
            steps=steps,
            parameterisation=self.config.parameterisation,
            seed=seed,
            eta=eta,
            device=self.device,
            guidance=guidance,
            noise=noise,
            state_extras=dict(
                projection=self.projection,
                normalise=self.normalise,
                denormalise=self.denormalise,
                to_features=self.from_model_space,
                from_features=self.to_model_space,
                condition=s,
            ),
        )
        return self.from_model_space(x0)

    def reconstruct(self, features: torch.Tensor, steps: int | None = None, seed: int = 0) -> torch.Tensor:
        """``decode(encode(features))`` for raw features ``[B, T, F]`` of any length T (padded and
        cropped internally) -> ``[B, T, F]``."""
        padded, length = self.pad(torch.as_tensor(features, dtype=torch.float32))
        return self.decode(self.encode(padded), length=length, steps=steps, seed=seed)

    # -- training -------------------------------------------------------------------------
    def training_losses(
        self, features: torch.Tensor, generator: torch.Generator | None = None, mask: torch.Tensor | None = None
    ) -> dict[str, torch.Tensor]:
        """Losses on a batch of raw features ``[B, T, F]`` (T a multiple of frames_per_token).

        ``mask [B, T]`` (bool, optional) marks the real frames of clips padded to T; padded
        frames are encoded (they repeat the last frame) but excluded from the losses.

        Returns a dict of scalars: ``loss`` (total to minimise), ``reconstruction`` (diffusion
        MSE on x0 or eps in model space, or the conv decoder's MSE), ``commitment``, the
        geometric terms that are enabled (``joints``, ``velocity``, ``foot``), and the codebook
        statistics ``perplexity`` / ``usage`` of this batch (no gradient).  Random draws
        (timesteps, noise, code restarts) use ``generator`` (a CPU generator).
        """
        cfg = self.config
        if generator is None:
            generator = torch.Generator().manual_seed(0)
        x = self.normalise(features)
        h = self.encoder(x)
        vq = self.quantizer(h, generator)
        s = self.cond_decoder(vq.quantized)
        out: dict[str, torch.Tensor] = {}
        if self.denoiser is None:
            x0_hat_model = s
            reconstruction = _masked_mse(s, x, mask)
        else:
            x0 = self.projection.project(x) if self.projection is not None else x
            batch = x0.shape[0]
            t = torch.randint(0, cfg.diffusion_steps, (batch,), generator=generator).to(self.device)
            noise = torch.randn(x0.shape, generator=generator).to(self.device)
            ab = self.alpha_bar[t][:, None, None]
            x_t = ab.sqrt() * x0 + (1 - ab).sqrt() * noise
            pred = self.denoiser(x_t, t, s)
            if cfg.parameterisation == "x0":
                reconstruction = _masked_mse(pred, x0, mask)
                x0_hat_model = pred
            else:
                # Min-SNR weighting (weight min(SNR, 5) / SNR): at low noise the eps target is
                # dominated by noise the network cannot see; down-weight it so it does not swamp
                # the steps that decide the motion
                snr = ab / (1 - ab).clamp_min(1e-12)
                weight = (snr.clamp(max=MIN_SNR_GAMMA) / snr)
                reconstruction = _masked_mse(pred * weight.sqrt(), noise * weight.sqrt(), mask)
                x0_hat_model = ((x_t - (1 - ab).sqrt() * pred) / ab.sqrt().clamp_min(1e-6)).clamp(-EPS_X0_CLAMP, EPS_X0_CLAMP)
        out["reconstruction"] = reconstruction
        out["commitment"] = vq.commitment
        loss = reconstruction + cfg.commitment * vq.commitment
        if cfg.joint_weight or cfg.velocity_weight or cfg.foot_weight:
            predicted = self.from_model_space(x0_hat_model) if self.denoiser is not None else self.denormalise(x0_hat_model)
            geometric = self.geometric_losses(predicted, features, mask)
            for name, weight in (("joints", cfg.joint_weight), ("velocity", cfg.velocity_weight), ("foot", cfg.foot_weight)):
                if weight:
                    out[name] = geometric[name]
                    loss = loss + weight * geometric[name]
        out["loss"] = loss
        out["perplexity"] = vq.perplexity.detach()
        out["usage"] = vq.usage.detach()
        return out

    def geometric_losses(self, predicted: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None = None) -> dict[str, torch.Tensor]:
        """MDM's geometric losses between raw feature batches ``[B, T, F]``: joint positions
        (m^2), joint velocities (m^2 / frame^2) and predicted foot velocity where the target's
        contact bit is set (m^2 / frame^2); ``mask [B, T]`` excludes padded frames."""
        from motok_robot.motion.features_torch import foot_contact_velocity, joints_from_features

        valid = torch.ones(target.shape[:2], dtype=torch.bool, device=target.device) if mask is None else mask.bool()
        step_valid = (valid[:, 1:] & valid[:, :-1]).float()  # [B, T-1]
        j_hat = joints_from_features(predicted)
        j = joints_from_features(target)
        v_hat = j_hat[:, 1:] - j_hat[:, :-1]
        v = j[:, 1:] - j[:, :-1]
        contacts = target[..., _CONTACT_DIMS]
        foot_velocity = foot_contact_velocity(j_hat, contacts)  # [B, T-1, 4, 3], zero where no contact
        on = (contacts[:, :-1] > 0.5).float() * step_valid[..., None]
        frame_err = (j_hat - j).pow(2).sum(-1).mean(-1)  # [B, T]
        step_err = (v_hat - v).pow(2).sum(-1).mean(-1)  # [B, T-1]
        return {
            "joints": (frame_err * valid.float()).sum() / valid.float().sum().clamp_min(1.0),
            "velocity": (step_err * step_valid).sum() / step_valid.sum().clamp_min(1.0),
            "foot": (foot_velocity.pow(2).sum(-1) * on).sum() / on.sum().clamp_min(1.0),
        }

    def extra_repr(self) -> str:
        n = sum(p.numel() for p in self.parameters())
        return f"decoder={self.config.decoder}, downsample={self.config.downsample}, K={self.config.codebook_size}, params={n / 1e6:.2f}M"


def _masked_mse(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None) -> torch.Tensor:
    """Mean squared error over ``[B, T, F]``, counting only frames where ``mask [B, T]`` is set."""
    if mask is None:
        return F.mse_loss(pred, target)
    weight = mask.to(pred.dtype)[..., None]
    return ((pred - target).pow(2) * weight).sum() / (weight.sum() * pred.shape[-1]).clamp_min(1.0)


def parameter_count(model: nn.Module) -> int:
    return int(sum(p.numel() for p in model.parameters()))


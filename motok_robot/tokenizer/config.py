"""Configuration of the MoTok tokenizer and of its training (defaults live here only).

No torch import: the CLI reads and validates these before any heavy module loads.

A run directory stores the two configs in ``config.json``::

    {"format": "motok-tokenizer", "version": 1,
     "tokenizer": {...TokenizerConfig...}, "train": {...TrainConfig...}}

A ``--config FILE.json`` given to ``motok-robot train tokenizer`` has the same
``"tokenizer"`` / ``"train"`` sections; each key overrides the default, and an unknown
key is an :class:`~motok_robot.errors.InputError` naming the key.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from motok_robot.config_utils import dataclass_from_dict, dataclass_to_dict
from motok_robot.config_utils import read_json_object
from motok_robot.data.groups import check_action_shares, check_balance
from motok_robot.errors import InputError

FORMAT = "motok-tokenizer"
FORMAT_VERSION = 1

#: HumanML3D feature layout: dims 0..3 are the root trajectory (rotational velocity about
#: up, planar velocity x/z in the root frame, root height) - the dims GMD's emphasis
#: projection up-weights.
ROOT_TRAJECTORY_DIMS: tuple[int, ...] = (0, 1, 2, 3)


@dataclass
class TokenizerConfig:
    """Architecture of a MoTok tokenizer.

    Token rate is ``fps / downsample`` tokens per second of motion (5 at the defaults).
    """

    feature_dim: int = 263  #: per-frame motion feature size (HumanML3D layout)
    fps: int = 20  #: frames per second of the feature sequences
    downsample: int = 4  #: temporal downsampling of the encoder: 2, 4 or 8 frames per token
    kernel_size: int = 3  #: kernel size (frames) of the residual convolutions of encoder/decoder
    width: int = 256  #: channels of the encoder / conditioning decoder
    depth: int = 2  #: residual blocks per resolution stage
    codebook_size: int = 512  #: K, entries of the single shared codebook
    code_dim: int = 256  #: d, size of a codebook entry (latent dimension)
    commitment: float = 0.02  #: weight of the commitment loss ||h - sg(q)||^2
    ema_decay: float = 0.99  #: EMA decay of the codebook updates
    dead_code_threshold: float = 0.1  #: restart codes whose EMA count < this x the mean count per code
    decoder: str = "diffusion"  #: "diffusion" (MoTok) or "conv" (plain VQ-VAE regression baseline)
    denoiser_width: int = 256  #: channels of the denoiser
    denoiser_blocks: int = 8  #: residual blocks of the denoiser (dilations 1, 2, 4, 8 repeating)
    denoiser_kernel: int = 3  #: kernel size of the denoiser convolutions
    parameterisation: str = "x0"  #: the denoiser predicts "x0" (clean motion, MDM) or "eps" (noise, GMD)
    diffusion_steps: int = 1000  #: discrete training timesteps of the cosine schedule
    sample_steps: int = 20  #: default number of DDIM steps at decoding
    emphasis: bool = False  #: GMD emphasis projection of the (normalised) motion, train and sample
    emphasis_c: float = 5.0  #: emphasis factor c on the root-trajectory dims
    emphasis_dims: tuple[int, ...] = ROOT_TRAJECTORY_DIMS  #: dims multiplied by c
    emphasis_seed: int = 0  #: seed of the fixed standard-normal matrix A'
    joint_weight: float = 1.0  #: MDM geometric loss: joint positions (m^2), through features_torch
    velocity_weight: float = 1.0  #: MDM geometric loss: joint velocities (m^2/frame^2)
    foot_weight: float = 1.0  #: MDM geometric loss: foot velocity where the contact bit is set

    def __post_init__(self) -> None:
        self.emphasis_dims = tuple(int(d) for d in self.emphasis_dims)
        self.validate()

    def validate(self) -> None:
        if self.downsample not in (1, 2, 4, 8, 16):
            raise InputError(f"tokenizer config: downsample must be 2, 4 or 8 (got {self.downsample})")
        if self.kernel_size < 1 or self.kernel_size % 2 == 0:
            raise InputError(f"tokenizer config: kernel_size must be odd and >= 1 (got {self.kernel_size})")
        if self.denoiser_kernel < 1 or self.denoiser_kernel % 2 == 0:
            raise InputError(f"tokenizer config: denoiser_kernel must be odd and >= 1 (got {self.denoiser_kernel})")
        if self.decoder not in ("diffusion", "conv"):
            raise InputError(f"tokenizer config: decoder must be 'diffusion' or 'conv' (got {self.decoder!r})")
        if self.parameterisation not in ("x0", "eps"):
            raise InputError(f"tokenizer config: parameterisation must be 'x0' or 'eps' (got {self.parameterisation!r})")
        if self.codebook_size < 2:
            raise InputError(f"tokenizer config: codebook_size must be >= 2 (got {self.codebook_size})")
        for name in ("width", "depth", "code_dim", "denoiser_width", "denoiser_blocks", "diffusion_steps", "sample_steps", "feature_dim", "fps"):
            if int(getattr(self, name)) < 1:
                raise InputError(f"tokenizer config: {name} must be >= 1 (got {getattr(self, name)})")
        if not 0.0 < self.ema_decay < 1.0:
            raise InputError(f"tokenizer config: ema_decay must be in (0, 1) (got {self.ema_decay})")
        bad = [d for d in self.emphasis_dims if not 0 <= d < self.feature_dim]
        if bad:
            raise InputError(f"tokenizer config: emphasis_dims {bad} outside 0..{self.feature_dim - 1}")

    @property
    def frames_per_token(self) -> int:
        return self.downsample

    @property
    def tokens_per_second(self) -> float:
        return self.fps / self.downsample


@dataclass
class TrainConfig:
    """Optimisation of a tokenizer (``motok-robot train tokenizer``)."""

    seed: int = 0  #: seeds initialisation, window sampling, noise and codebook restarts
    batch_size: int = 64  #: windows per step
    window: int = 64  #: frames per training window (rounded down to a multiple of downsample)
    lr: float = 3e-4  #: peak AdamW learning rate
    weight_decay: float = 0.0
    warmup_steps: int = 300  #: linear warm-up, then cosine decay to lr_min_ratio * lr
    lr_min_ratio: float = 0.05
    grad_clip: float = 1.0  #: max global gradient norm (0 = off)
    epochs: int = 100  #: used when steps is 0
    steps: int = 5000  #: total optimiser steps (overrides epochs when > 0; 0 = use epochs)
    steps_per_epoch: int = 500  #: steps between validations (0 = ceil(train clips / batch_size))
    checkpoint_every: int = 500  #: steps between checkpoints (also at each epoch end)
    val_clips: int = 64  #: validation windows decoded each epoch (fixed, seeded)
    val_sample_steps: int = 10  #: DDIM steps for the validation decode
    device: str = "cpu"
    num_threads: int = 0  #: torch CPU threads (0 = torch default)
    #: tokenizer run whose weights (and architecture) start this run ("" = random initialisation)
    init_from: str = ""
    #: keep the encoder, codebook and normalisation of ``init_from`` fixed and train only the
    #: decoder side (conditioning decoder + denoiser): every clip keeps its tokens, so planners
    #: trained on the ``init_from`` tokens stay valid with the new decoder
    freeze_tokens: bool = False
    #: how training draws windows: every frame equally often (0), or a group of ``n`` clips with
    #: the same action label (else the same first caption) weighed down by ``n ** balance_groups``
    #: (1 = every group by its mean clip length, 0.5 = square-root balancing); the shared data's
    #: train split holds 888 "raise the left hand" clips (mirrors included) against 28 bows
    balance_groups: float = 0.0
    #: hard-example sampling: at the start and after every epoch, each train clip's error is
    #: measured (root-relative joint error of a one-step decode of its tokens, cm) and its draw
    #: weight multiplied by ``(error / mean error) ** focus_errors``, clamped to
    #: ``[1 / focus_cap, focus_cap]`` (0 = off).  Rare motions the tokenizer reconstructs badly
    #: (the shared data's bows, cartwheels, crawls) are then drawn more often
    focus_errors: float = 0.0
    focus_cap: float = 10.0  #: bound of the focus factor (>= 1)
    #: train (and validate) only on the clips of these action labels (empty = every clip): a
    #: tokenizer specialised to a motion family, or a check of whether the architecture can
    #: represent an action at all when it sees enough of it
    only_actions: tuple[str, ...] = ()
    #: draw the clips of these action labels with this share of all windows, e.g.
    #: ``{"bow": 0.05}`` (after balance_groups, before focus_errors; empty = off).  Balancing
    #: cannot lift a rare action far: the shared data's 28 train bows get at most 0.9 % of the
    #: windows with any balance_groups, as there are 109 groups
    action_share: dict[str, float] = field(default_factory=dict)

    def validate(self) -> None:
        check_balance(self.balance_groups, "train config")
        self.action_share = check_action_shares(self.action_share, "train config")
        if self.action_share and self.only_actions:
            raise InputError("train config: action_share and only_actions exclude each other "
                             "(only_actions already draws nothing else)")
        if isinstance(self.only_actions, str) or not all(isinstance(a, str) and a.strip() for a in self.only_actions):
            raise InputError(f"train config: only_actions must be a list of action labels (got {self.only_actions!r})")
        self.only_actions = tuple(self.only_actions)
        if not 0.0 <= self.focus_errors <= 4.0:
            raise InputError(f"train config: focus_errors must be within 0..4 (got {self.focus_errors})")
        if self.focus_cap < 1.0:
            raise InputError(f"train config: focus_cap must be >= 1 (got {self.focus_cap})")
        if self.freeze_tokens and not self.init_from:
            raise InputError("train config: freeze_tokens needs init_from (the run whose tokens to keep)")
        for name in ("batch_size", "window"):
            if int(getattr(self, name)) < 1:
                raise InputError(f"train config: {name} must be >= 1 (got {getattr(self, name)})")
        if self.lr <= 0:
            raise InputError(f"train config: lr must be > 0 (got {self.lr})")
        if self.steps < 0 or self.epochs < 0 or self.steps_per_epoch < 0:
            raise InputError("train config: steps, epochs and steps_per_epoch must be >= 0")
        if self.steps == 0 and self.epochs == 0:
            raise InputError("train config: one of steps or epochs must be > 0")
        if self.checkpoint_every < 1:
            raise InputError(f"train config: checkpoint_every must be >= 1 (got {self.checkpoint_every})")

    def __post_init__(self) -> None:
        self.validate()


def _from_dict(cls, data: dict[str, Any], where: str):
    return dataclass_from_dict(cls, data, where, noun="key")


def tokenizer_config_from_dict(data: dict[str, Any], where: str = "tokenizer config") -> TokenizerConfig:
    return _from_dict(TokenizerConfig, data, where)


def train_config_from_dict(data: dict[str, Any], where: str = "train config") -> TrainConfig:
    return _from_dict(TrainConfig, data, where)


def to_dict(config) -> dict[str, Any]:
    """The config as a JSON-ready dict (tuples as lists)."""
    return dataclass_to_dict(config)


def read_config_file(path: str | Path) -> tuple[dict[str, Any], dict[str, Any]]:
    """Read a JSON config file -> (tokenizer section, train section), both possibly empty."""
    path = Path(path)
    data = read_json_object(path, "config file")
    unknown = sorted(set(data) - {"tokenizer", "train", "format", "version"})
    if unknown:
        raise InputError(f"{path}: unknown section(s) {unknown}; expected 'tokenizer' and/or 'train'")
    return dict(data.get("tokenizer") or {}), dict(data.get("train") or {})


__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "ROOT_TRAJECTORY_DIMS",
    "TokenizerConfig",
    "TrainConfig",
    "read_config_file",
    "to_dict",
    "tokenizer_config_from_dict",
    "train_config_from_dict",
]

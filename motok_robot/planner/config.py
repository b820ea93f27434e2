"""Planner configurations (dataclasses; every default lives here).

* :class:`PlannerConfig` -- the architecture of one planner (masked or autoregressive) and its
  condition encoders; saved as JSON next to the weights.
* :class:`ControlConfig` -- how training derives coarse local conditions from the ground truth.
* :class:`PlannerTrainConfig` -- optimisation, batching, validation, seeds.
* :class:`SampleConfig` -- sampling defaults (guidance, steps, temperature, top-k / top-p).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from motok_robot.config_utils import dataclass_from_dict, dataclass_to_dict
from motok_robot.data.groups import check_action_shares, check_balance
from motok_robot.errors import InputError

PLANNER_KINDS = ("masked", "ar")
#: ``PlannerConfig.token_conv_kernel`` of a masked planner when not set
MASKED_TOKEN_CONV_KERNEL = 5
#: ``PlannerTrainConfig.end_unknown_prob`` of an AR planner when not set
AR_END_UNKNOWN_PROB = 0.1
FORMAT = "motok-planner"
FORMAT_VERSION = 1


@dataclass
class PlannerConfig:
    """Architecture of a planner.

    Token rate: ``fps / downsample`` tokens per second (5 at the defaults); the longest plan is
    ``max_frames // downsample`` tokens (``max_frames / fps`` seconds).
    """

    kind: str = "masked"  #: "masked" (discrete diffusion) or "ar" (autoregressive)
    codebook_size: int = 512  #: K, must equal the tokenizer's
    downsample: int = 4  #: frames per token, must equal the tokenizer's
    fps: int = 20  #: frames per second of the motion
    max_frames: int = 240  #: longest motion the planner handles, frames (12 s at 20 fps)
    width: int = 192  #: transformer width
    layers: int = 4  #: transformer blocks
    heads: int = 4  #: attention heads
    ff_mult: int = 4  #: feed-forward width = ff_mult * width
    dropout: float = 0.1
    text_encoder: str = "minilm"  #: "minilm" or "clip:/path"
    text_dim: int = 384  #: size of the text encoder's embedding (set from the encoder at training)
    action_labels: list[str] = field(default_factory=list)  #: action classes with a learned embedding
    local_hidden: int = 128  #: hidden width of the local-condition conv encoder
    length_hidden: int = 256  #: hidden width of the length estimator MLP
    #: masked planner: kernel of a convolution over the token embeddings before the transformer
    #: (odd; 0 = none), so that every position sees its neighbours' tokens from the first layer.
    #: None = the kind's default: 5 for the masked planner, 0 for the AR planner (which decodes
    #: one token at a time).  Without it the masked planner trained on the shared data ignored
    #: the tokens around a gap in locomotion (docs/planner.md, "What the planners learned").
    token_conv_kernel: int | None = None
    #: AR planner: also add the global condition feature ``M_g`` to every token embedding, not only
    #: at the first position, so that late tokens do not have to find the caption through
    #: attention alone.  False = ``M_g`` at the first position only (the runs shipped so far).
    global_every_position: bool = False
    #: add a learned embedding of each position's distance to the sequence end (in tokens; a
    #: separate "end unknown" entry for training crops that stop mid-clip), so that the planner
    #: knows where a motion has to be finished.  Masked planner: every token gets its distance
    #: to the last token.  AR planner: the position that predicts token ``i`` (or [END]) gets the
    #: count of tokens still to draw there, from the length asked for at sampling ("end
    #: unknown" when it stops at its own [END]).  False = no such embedding (the AR planners
    #: shipped before 2026-11-27, and the masked planners before 2026-11-26).
    end_embedding: bool = False
    #: AR planner with ``end_embedding``: counts of tokens still to draw above this all share one
    #: entry ("more than ``end_horizon`` to go"), so the planner is told where the motion ends
    #: only once the end is near, not the clip's whole length from the first position.  AR
    #: planners with the exact count matched texts worse; the shipped one has 8
    #: (models/MODEL_CARD.md, "The AR planner with a capped end embedding").  0 = the exact count
    #: everywhere.  Not for the masked planner: it attends to every position, so it sees the
    #: length anyway.
    end_horizon: int = 0

    @property
    def max_tokens(self) -> int:
        return self.max_frames // self.downsample

    @property
    def max_seconds(self) -> float:
        return self.max_tokens * self.downsample / self.fps

    def validate(self) -> "PlannerConfig":
        if self.kind not in PLANNER_KINDS:
            raise InputError(f"planner config: kind must be one of {PLANNER_KINDS} (got {self.kind!r})")
        for name in ("codebook_size", "downsample", "fps", "max_frames", "width", "layers", "heads", "ff_mult",
                     "text_dim", "local_hidden", "length_hidden"):
            if int(getattr(self, name)) < 1:
                raise InputError(f"planner config: {name} must be >= 1 (got {getattr(self, name)})")
        if self.width % self.heads:
            raise InputError(f"planner config: width {self.width} is not divisible by heads {self.heads}")
        if self.max_tokens < 1:
            raise InputError(f"planner config: max_frames {self.max_frames} < downsample {self.downsample}")
        if not 0.0 <= self.dropout < 1.0:
            raise InputError(f"planner config: dropout must be in [0, 1) (got {self.dropout})")
        if self.token_conv_kernel is None:
            self.token_conv_kernel = MASKED_TOKEN_CONV_KERNEL if self.kind == "masked" else 0
        if self.token_conv_kernel < 0 or (self.token_conv_kernel and self.token_conv_kernel % 2 == 0):
            raise InputError(f"planner config: token_conv_kernel must be 0 or odd (got {self.token_conv_kernel})")
        if self.token_conv_kernel and self.kind != "masked":
            raise InputError("planner config: token_conv_kernel is for the masked planner only (the AR planner "
                             "decodes one token at a time)")
        if self.global_every_position and self.kind != "ar":
            raise InputError("planner config: global_every_position is for the AR planner (the masked planner's "
                             "positions all attend to M_g)")
        if self.end_horizon and self.kind != "ar":
            raise InputError("planner config: end_horizon is for the AR planner (the masked planner attends to "
                             "every position, so it sees the length anyway)")
        if self.end_horizon and not self.end_embedding:
            raise InputError("planner config: end_horizon needs end_embedding (it caps the distances that embedding shows)")
        if not 0 <= self.end_horizon < self.max_tokens - 1:
            raise InputError(f"planner config: end_horizon must be in 0..{self.max_tokens - 2} (0 = no cap; got "
                             f"{self.end_horizon})")
        if len(set(self.action_labels)) != len(self.action_labels):
            raise InputError("planner config: action_labels contains duplicates")
        return self


@dataclass
class ControlConfig:
    """Coarse control in training: which local conditions are derived from the ground truth.

    Each training sample draws one mode with these probabilities (normalised): no local
    condition, the root trajectory on the ground (with its height with ``height_prob``), a few
    random joints on every frame, or random sparse keyframes of random joints.
    """

    none_prob: float = 0.4
    root_prob: float = 0.3
    joints_prob: float = 0.1
    keyframes_prob: float = 0.2
    height_prob: float = 0.5
    max_random_joints: int = 3
    max_keyframes: int = 5


@dataclass
class PlannerTrainConfig:
    """Optimisation of a planner (``motok-robot train planner``)."""

    seed: int = 0
    steps: int = 5000  #: optimiser steps in total
    batch_size: int = 32
    lr: float = 3e-4
    weight_decay: float = 0.01
    warmup_steps: int = 200
    grad_clip: float = 1.0
    cond_drop_prob: float = 0.1  #: classifier-free guidance: global condition dropped for this fraction
    action_prob: float = 0.2  #: clips with both texts and an action label train the action path this often
    length_loss_weight: float = 0.1  #: weight of the length estimator's loss
    #: AR planner: each sample replaces a fraction U(0, this) of its input tokens with random
    #: codes (targets unchanged; T2M-GPT's remedy for exposure bias). 0 = plain teacher forcing.
    #: The masked planner has no input tokens to corrupt and must leave it at 0.
    input_corruption: float = 0.0
    #: masked planner: "token" averages the loss over every masked token of a batch (heavily
    #: masked samples dominate); "sample" averages each sample's masked tokens first, so a
    #: lightly masked sample, where the neighbours decide the answer, counts as much as a
    #: heavily masked one (the masked-diffusion ELBO's weighting).
    masked_loss_average: str = "token"
    #: each training clip is also tokenised from frames 1 .. token_phases - 1 on (at most the
    #: tokenizer's frames per token): the same motion through shifted token grids, so the
    #: planner sees ``token_phases`` token sequences per clip.  1 = the clip's own grid only.
    token_phases: int = 1
    #: how training draws clips: a group of ``n`` clips with the same action label (or, without
    #: one, the same first caption) is drawn with total weight ``n ** (1 - balance_groups)``.
    #: 0 = every clip equally often (the train split holds 888 "raise the left hand" clips
    #: against 28 bows and 2 kicks); 1 = every group equally often; 0.5 = square-root balancing
    #: (both shipped planners).  Weights from :func:`motok_robot.data.groups.balanced_weights`.
    balance_groups: float = 0.0
    #: action labels whose clips together hold a fixed share of the draws, e.g. ``{"bow": 0.05}``
    #: (the 28 bow sequences get 1.3 % under ``balance_groups`` 0.5); the other clips keep their
    #: relative weights in the rest.  Empty = off.  As the tokenizer's ``action_share``
    #: (:func:`motok_robot.data.groups.with_action_shares`).
    action_share: dict[str, float] = field(default_factory=dict)
    #: ids of train-split clips to leave out of training (a data choice, e.g. clips whose motion
    #: the tokenizer cannot reproduce, so that their token sequences teach the planner something
    #: other than their captions say).  A clip's mirrored copy (``mirror_of`` in index.jsonl)
    #: and its token-phase copies go with it.  An id not in the train split is an error.
    exclude_clips: list[str] = field(default_factory=list)
    #: planners with ``end_embedding``: this fraction of the training samples gets the "end
    #: unknown" entry although its crop ends with the clip, so the AR planner also learns to
    #: close a motion with [END] when no length is given (``plan(n_tokens=None)``).  None = the
    #: kind's default: 0.1 for the AR planner, 0 for the masked one (which always plans a length).
    end_unknown_prob: float | None = None
    val_every: int = 500  #: steps between validation + checkpoint
    #: True: model.safetensors keeps the weights of the validation with the lowest val loss
    #: (early stopping); False: the latest weights. Resuming always continues from the latest
    #: state (checkpoint.safetensors).  Off by default: the AR planner's val loss is lowest at
    #: 2,000 of 5,000 steps on the shared data, yet those weights generate worse motion by the
    #: evaluator (FID 0.195 vs 0.170, R-precision top-1 0.232 vs 0.244 for the 5,000-step
    #: weights, 2026-11-23); token loss is not the quality that matters.  (The masked
    #: planner's best val loss is at its last step, so the switch changes nothing there.)
    keep_best: bool = False
    val_batches: int = 20
    device: str = "cpu"
    control: ControlConfig = field(default_factory=ControlConfig)

    def validate(self, kind: str) -> "PlannerTrainConfig":
        """Checks of the options that only one planner kind (``"masked"`` / ``"ar"``) uses."""
        if not 0.0 <= self.input_corruption < 1.0:
            raise InputError(f"train config: input_corruption must be in [0, 1) (got {self.input_corruption})")
        if kind == "masked" and self.input_corruption > 0:
            raise InputError("train config: input_corruption is for the AR planner (the masked planner already "
                             "trains on masked inputs)")
        if self.masked_loss_average not in ("token", "sample"):
            raise InputError(f"train config: masked_loss_average must be 'token' or 'sample' (got {self.masked_loss_average!r})")
        if kind == "ar" and self.masked_loss_average != "token":
            raise InputError("train config: masked_loss_average is for the masked planner")
        check_balance(self.balance_groups, "train config")
        self.action_share = check_action_shares(self.action_share, "train config")
        if not isinstance(self.exclude_clips, (list, tuple)) or not all(
                isinstance(c, str) and c.strip() for c in self.exclude_clips):
            raise InputError(f"train config: exclude_clips must be a list of clip ids (got {self.exclude_clips!r})")
        self.exclude_clips = [c.strip() for c in self.exclude_clips]
        repeated = sorted({c for c in self.exclude_clips if self.exclude_clips.count(c) > 1})
        if repeated:
            raise InputError(f"train config: exclude_clips lists {repeated[0]!r} more than once")
        if self.end_unknown_prob is None:
            self.end_unknown_prob = AR_END_UNKNOWN_PROB if kind == "ar" else 0.0
        if not 0.0 <= self.end_unknown_prob <= 1.0:
            raise InputError(f"train config: end_unknown_prob must be in [0, 1] (got {self.end_unknown_prob})")
        return self


@dataclass
class SampleConfig:
    """Sampling defaults of :meth:`Planner.plan` and ``motok-robot generate``."""

    cfg_scale: float = 2.5  #: classifier-free guidance scale (1 = plain conditional)
    steps: int = 10  #: masked planner: unmasking iterations
    temperature: float = 1.0  #: 0 = greedy
    top_k: int | None = None
    top_p: float | None = None
    remask_noise: float = 1.0  #: masked planner: Gumbel noise on the re-masking confidence (annealed)
    decoder_steps: int | None = None  #: tokenizer decoder DDIM steps (None = the tokenizer's default)


def to_dict(cfg: Any) -> dict[str, Any]:
    """The config as a JSON-ready dict."""
    return dataclass_to_dict(cfg)


def _from_dict(cls, data: dict[str, Any], where: str):
    return dataclass_from_dict(cls, data, where, noun="field")


def planner_config_from_dict(data: dict[str, Any], where: str = "planner config") -> PlannerConfig:
    return _from_dict(PlannerConfig, data, where).validate()


def saved_planner_config(data: dict[str, Any], where: str) -> PlannerConfig:
    """The architecture saved in a run's ``config.json``.  Runs written before a field existed
    were built without what it adds: a missing ``token_conv_kernel`` means no convolution."""
    return planner_config_from_dict({"token_conv_kernel": 0, **data}, where)


def train_config_from_dict(data: dict[str, Any], where: str = "train config") -> PlannerTrainConfig:
    data = dict(data)
    control = _from_dict(ControlConfig, data.pop("control", {}) or {}, where + " 'control'")
    cfg = _from_dict(PlannerTrainConfig, data, where)
    cfg.control = control
    return cfg

"""Text -> motion: the planner writes MoTok tokens, the tokenizer's diffusion decoder turns them
into features, and ``joints_from_features`` into joint positions.

```python
from motok_robot import generate
motion = generate("a person walks forward", seconds=6, seed=0)        # GeneratedMotion
motion.save("motion.npz")                                              # or generate(..., out="motion.npz")
motion.joints   # float32 [T, 22, 3] metres, z up;  motion.features [T, 263];  motion.tokens [N]
```

Models are read from ``models/`` at the repository root by default (``models/tokenizer``,
``models/planner_masked``, ``models/planner_ar``; override the folder with the environment
variable ``MOTOK_ROBOT_MODELS`` or pass run directories).  Loaded models are kept per process,
so repeated calls pay only for generation.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from motok_robot.errors import InputError
from motok_robot.motion.skeleton import FPS
from motok_robot.paths import models_dir
from motok_robot.planner.config import PLANNER_KINDS, SampleConfig
from motok_robot.text import validate
from motok_robot.text.vocabulary import VocabularyCheck, check_prompt, vocabulary_for_planner, warn_if_far

TRAIN_HINT = {
    "tokenizer": "motok-robot train tokenizer --data DIR --out {path}",
    "masked": "motok-robot train planner --data DIR --tokenizer models/tokenizer --kind masked --out {path}",
    "ar": "motok-robot train planner --data DIR --tokenizer models/tokenizer --kind ar --out {path}",
}




def default_run(what: str) -> Path:
    """Default run directory of ``"tokenizer"``, ``"masked"`` or ``"ar"``."""
    return models_dir() / ("tokenizer" if what == "tokenizer" else f"planner_{what}")


def _require_run(path: Path, what: str) -> None:
    if not (path / "model.safetensors").is_file() or not (path / "config.json").is_file():
        raise InputError(
            f"no trained {'tokenizer' if what == 'tokenizer' else what + ' planner'} in {path} "
            f"(config.json + model.safetensors); train one with: {TRAIN_HINT[what].format(path=path)}"
        )


@dataclass
class GeneratedMotion:
    """One generated clip.

    Attributes:
        joints: float32 ``[T, 22, 3]`` metres, z up, body starting at the origin facing +x.
        features: float32 ``[T, 263]`` raw HumanML3D features.
        tokens: int64 ``[N]`` MoTok token ids.
        text: the prompt ("" for action/unconditional; ``"action:LABEL"`` for an action).
        seed: the seed used.
        model: identifiers of the models used.
        fps: frames per second (20).
        timings: seconds spent per stage (``text``, ``plan``, ``decode``, ``joints``).
        decoder_seed: the seed of the decoder's noise when it was not ``seed`` (None: ``seed``).
        vocabulary: how near the prompt is to the planner's training captions
            (:class:`~motok_robot.text.vocabulary.VocabularyCheck`; None when not checked: no text,
            or no vocabulary file for this planner).
    """

    joints: np.ndarray
    features: np.ndarray
    tokens: np.ndarray
    text: str
    seed: int
    model: str
    fps: int = FPS
    timings: dict[str, float] = field(default_factory=dict)
    decoder_seed: int | None = None
    vocabulary: VocabularyCheck | None = None

    @property
    def seconds(self) -> float:
        return self.joints.shape[0] / self.fps

    def save(self, path: str | Path) -> Path:
        """Write ``motion.npz`` (see :mod:`motok_robot.planner.motion_file`)."""
        from motok_robot.planner.motion_file import save_motion

        return save_motion(path, self.joints, self.features, self.tokens, self.text, self.seed, self.model, self.fps,
                           decoder_seed=self.decoder_seed,
                           vocabulary_check=None if self.vocabulary is None else self.vocabulary.to_json())


def check_text(text: str) -> str:
    """The prompt with whitespace collapsed (:func:`motok_robot.text.validate.check_text`)."""
    return validate.check_text(text, hint=" (or use --unconditional)")


class MotionGenerator:
    """Loaded tokenizer + planner + text encoder; call :meth:`generate` repeatedly.

    Args:
        planner: ``"masked"`` or ``"ar"`` (used when ``planner_run`` is None).
        tokenizer_run, planner_run: run directories (default: ``models/``).
        device: torch device.
    """

    def __init__(self, planner: str = "masked", tokenizer_run: str | Path | None = None,
                 planner_run: str | Path | None = None, device: str = "cpu") -> None:
        from motok_robot.planner.checkpoint import load_planner, tokenizer_mismatch
        from motok_robot.planner.data import file_digest
        from motok_robot.text import load_text_encoder
        from motok_robot.tokenizer import load_tokenizer

        if planner not in PLANNER_KINDS:
            raise InputError(f"planner must be one of {PLANNER_KINDS}, got {planner!r}")
        tok_path = Path(tokenizer_run) if tokenizer_run else default_run("tokenizer")
        plan_path = Path(planner_run) if planner_run else default_run(planner)
        if tokenizer_run is None:
            _require_run(tok_path, "tokenizer")
        elif not tok_path.exists():
            raise InputError(f"tokenizer run {tok_path} does not exist")
        if planner_run is None:
            _require_run(plan_path, planner)
        elif not plan_path.exists():
            raise InputError(f"planner run {plan_path} does not exist")
        self.device = torch.device(device)
        self.tokenizer = load_tokenizer(tok_path, device=self.device)
        self.planner, run = load_planner(plan_path, device=self.device)
        mismatch = tokenizer_mismatch(run.get("tokenizer") or {}, tok_path, self.tokenizer)
        if mismatch:
            raise InputError(f"planner {plan_path} was trained with another tokenizer: {mismatch}; "
                             "pass the matching --tokenizer or retrain the planner")
        cfg = self.planner.config
        if cfg.codebook_size != self.tokenizer.config.codebook_size or cfg.downsample != self.tokenizer.frames_per_token:
            raise InputError(f"planner {plan_path} (K={cfg.codebook_size}, downsample={cfg.downsample}) does not match "
                             f"tokenizer {tok_path} (K={self.tokenizer.config.codebook_size}, "
                             f"downsample={self.tokenizer.frames_per_token})")
        self.text_encoder = load_text_encoder(cfg.text_encoder, device=str(self.device))
        if self.text_encoder.dim != cfg.text_dim:
            raise InputError(f"text encoder {cfg.text_encoder!r} gives {self.text_encoder.dim}-d embeddings, "
                             f"the planner expects {cfg.text_dim}")
        self.kind = cfg.kind
        tok_hash = file_digest((tok_path if tok_path.is_dir() else tok_path.parent) / "model.safetensors")
        plan_hash = file_digest(plan_path / "model.safetensors")
        self.model_id = (f"tokenizer={tok_path.name}@{tok_hash[:12]};"
                         f"planner={cfg.kind}:{plan_path.name}@{plan_hash[:12]};"
                         f"text={self.text_encoder.name}")
        # the planner's training captions (models/vocabulary.json for the shipped planners); a
        # prompt far from all of them is warned about and the check recorded in motion.npz
        self.vocabulary, self.vocabulary_status = vocabulary_for_planner(plan_path, plan_hash)

    def check_vocabulary(self, text: str, embedding=None) -> VocabularyCheck | None:
        """How near ``text`` is to the planner's training captions (None without a vocabulary, or
        when its text encoder cannot be loaded: then ``vocabulary_status`` says why).
        ``embedding``: the prompt's embedding by the planner's text encoder, when at hand."""
        vocab = self.vocabulary
        if vocab is None:
            return None
        encoder = self.text_encoder
        if encoder.name != vocab.encoder_name:
            from motok_robot.text import load_text_encoder

            embedding = None
            try:
                encoder = load_text_encoder(vocab.encoder_spec)
            except InputError as exc:
                self.vocabulary = None  # not tried again for every prompt
                self.vocabulary_status = f"prompts are not checked against the training captions: {exc}"
                return None
        return check_prompt(text, vocab, encoder, embedding)

    @property
    def max_seconds(self) -> float:
        return self.planner.config.max_seconds

    def frames_for(self, seconds: float) -> int:
        if not isinstance(seconds, (int, float)) or isinstance(seconds, bool) or not math.isfinite(seconds):
            raise InputError(f"seconds must be a number, got {seconds!r}")
        if seconds <= 0:
            raise InputError(f"seconds must be positive, got {seconds:g}")
        if seconds > self.max_seconds + 1e-9:
            raise InputError(f"seconds must be at most {self.max_seconds:g} for this planner, got {seconds:g}")
        return max(1, round(seconds * self.planner.config.fps))

    def generate(
        self,
        text: str | None = None,
        seconds: float | None = None,
        seed: int = 0,
        cfg_scale: float | None = None,
        action: str | None = None,
        unconditional: bool = False,
        steps: int | None = None,
        decoder_steps: int | None = None,
        temperature: float | None = None,
        top_k: int | None = None,
        top_p: float | None = None,
        trajectory: np.ndarray | None = None,
        keep_tokens: np.ndarray | None = None,
        local=None,
        decode=None,
        decoder_seed: int | None = None,
    ) -> GeneratedMotion:
        """Generate one motion; see :func:`generate` for the arguments.

        Extra hooks for the control stage: ``local`` -- ready-made
        :class:`~motok_robot.planner.conditions.LocalConditions` (B = 1, T frames; sets T when
        ``seconds`` is None); ``decode(tokenizer, tokens [1, N], length, steps, seed) -> features
        [1, T, 263]`` replaces the plain ``tokenizer.decode`` (e.g. decoding with guidance);
        ``keep_tokens`` ``[N]`` (``-1`` = free) fixes tokens (masked planner: inpainting).
        """
        from motok_robot.motion.features import joints_from_features
        from motok_robot.planner.conditions import Conditions, LocalConditions

        defaults = SampleConfig()
        cfg = self.planner.config
        noise_seed = seed if decoder_seed is None else decoder_seed
        for name, value in (("seed", seed), ("decoder_seed", noise_seed)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
                raise InputError(f"{name} must be a non-negative integer, got {value!r}")
        seed, noise_seed = int(seed), int(noise_seed)
        for name, value, low in (("steps", steps, 1), ("decoder_steps", decoder_steps, 1), ("top_k", top_k, 1)):
            if value is not None and (isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low):
                raise InputError(f"{name} must be an integer >= {low}, got {value!r}")
        if temperature is not None and not (math.isfinite(temperature) and temperature >= 0):
            raise InputError(f"temperature must be >= 0 (0 = greedy), got {temperature!r}")
        if top_p is not None and not 0.0 < top_p <= 1.0:
            raise InputError(f"top_p must be in (0, 1], got {top_p!r}")
        if cfg_scale is not None and not math.isfinite(cfg_scale):
            raise InputError(f"cfg_scale must be a finite number, got {cfg_scale!r}")
        given = sum(x for x in (text is not None, action is not None, bool(unconditional)))
        if given != 1:
            raise InputError("give exactly one of: a text prompt, an action label (--action), or --unconditional")
        timings: dict[str, float] = {}
        t0 = time.perf_counter()
        cond = Conditions(batch=1)
        label = ""
        if text is not None:
            label = check_text(text)
            cond.text_embedding = self.text_encoder.encode([label]).to(self.device)
        elif action is not None:
            if action not in cfg.action_labels:
                known = ", ".join(cfg.action_labels) or "none (this planner was trained without action labels)"
                raise InputError(f"unknown action label {action!r}; known labels: {known}")
            cond.action = torch.tensor([cfg.action_labels.index(action)], device=self.device)
            label = f"action:{action}"
        timings["text"] = time.perf_counter() - t0
        check = None
        if text is not None and self.vocabulary is not None:
            t_vocab = time.perf_counter()
            check = self.check_vocabulary(label, cond.text_embedding[0].cpu())
            timings["vocabulary"] = time.perf_counter() - t_vocab
            warn_if_far(check)

        ds = cfg.downsample
        if trajectory is not None and local is not None:
            raise InputError("give either a trajectory or local conditions, not both")
        if seconds is None and trajectory is not None:
            seconds = int(np.asarray(trajectory).shape[0]) / cfg.fps
        if seconds is None and local is not None:
            seconds = local.frames / cfg.fps
        if seconds is not None:
            frames = self.frames_for(seconds)
            n_tokens = -(-frames // ds)
        elif cond.text_embedding is not None:
            n_tokens = int(self.planner.predict_length(cond)[0])
            frames = n_tokens * ds
        else:
            frames = self.frames_for(6.0)
            n_tokens = -(-frames // ds)
        if trajectory is not None:
            cond.local = LocalConditions.from_arrays(frames, trajectory=trajectory).to(self.device)
        if local is not None:
            if local.batch_size != 1 or local.frames != frames:
                raise InputError(f"local conditions cover {local.batch_size} x {local.frames} frames, "
                                 f"expected 1 x {frames} ({frames / cfg.fps:g} s)")
            cond.local = local.to(self.device)

        t1 = time.perf_counter()
        scale = defaults.cfg_scale if cfg_scale is None else float(cfg_scale)
        if unconditional:
            scale = 1.0  # both guidance branches would be the null condition
        tokens = self.planner.plan(
            cond, n_tokens, seed=seed,
            cfg_scale=scale,
            temperature=defaults.temperature if temperature is None else float(temperature),
            top_k=top_k if top_k is not None else defaults.top_k,
            top_p=top_p if top_p is not None else defaults.top_p,
            steps=defaults.steps if steps is None else steps,
            keep_tokens=None if keep_tokens is None else torch.as_tensor(keep_tokens)[None],
            remask_noise=defaults.remask_noise,
        )
        timings["plan"] = time.perf_counter() - t1
        t2 = time.perf_counter()
        steps_dec = defaults.decoder_steps if decoder_steps is None else decoder_steps
        if decode is None:
            features = self.tokenizer.decode(tokens, length=frames, steps=steps_dec, seed=noise_seed)
        else:
            features = decode(self.tokenizer, tokens, frames, steps_dec, noise_seed)
            if tuple(features.shape) != (1, frames, 263):
                raise InputError(f"decode hook returned shape {tuple(features.shape)}, expected (1, {frames}, 263)")
        timings["decode"] = time.perf_counter() - t2
        t3 = time.perf_counter()
        feats = features[0].detach().cpu().numpy().astype(np.float32)
        joints = joints_from_features(feats).astype(np.float32)
        timings["joints"] = time.perf_counter() - t3
        return GeneratedMotion(joints=joints, features=feats, tokens=tokens[0].cpu().numpy().astype(np.int64),
                               text=label, seed=seed, model=self.model_id, fps=int(cfg.fps), timings=timings,
                               decoder_seed=None if noise_seed == seed else noise_seed, vocabulary=check)


_GENERATORS: dict[tuple, MotionGenerator] = {}


def load_generator(planner: str = "masked", tokenizer_run=None, planner_run=None, device: str = "cpu") -> MotionGenerator:
    """A :class:`MotionGenerator`, reused per process for the same model files and device.

    The key holds the resolved run directories, so changing ``$MOTOK_ROBOT_MODELS`` between
    calls loads the models it points to instead of reusing the previous ones."""
    tok_path = Path(tokenizer_run) if tokenizer_run else default_run("tokenizer")
    plan_path = Path(planner_run) if planner_run else default_run(planner)
    key = (planner, str(tok_path.resolve()), str(plan_path.resolve()), str(device))
    if key not in _GENERATORS:
        _GENERATORS[key] = MotionGenerator(planner, tokenizer_run, planner_run, device)
    return _GENERATORS[key]


def generate(
    text: str | None = None,
    seconds: float | None = None,
    seed: int = 0,
    planner: str = "masked",
    cfg_scale: float | None = None,
    action: str | None = None,
    unconditional: bool = False,
    out: str | Path | None = None,
    tokenizer_run: str | Path | None = None,
    planner_run: str | Path | None = None,
    steps: int | None = None,
    decoder_steps: int | None = None,
    temperature: float | None = None,
    top_k: int | None = None,
    top_p: float | None = None,
    trajectory: np.ndarray | None = None,
    device: str = "cpu",
    decoder_seed: int | None = None,
) -> GeneratedMotion:
    """Generate a motion from a sentence (or an action label, or unconditionally).

    Args:
        text: the prompt (at most 500 characters).
        seconds: duration (0 < seconds <= the planner's maximum, 12 s by default); None = estimated
            from the text by the length estimator (6 s without text).
        seed: seeds planning and decoding; the same seed gives the same motion (and file).
        decoder_seed: seeds the decoder's noise instead of ``seed`` (the tokens stay those of
            ``seed``): another rendering of the same token plan. The noise sets part of the motion
            (a bow's depth by tens of degrees; docs/evaluation.md).
        planner: "masked" (default) or "ar".
        cfg_scale: classifier-free guidance scale (default 2.5; 1 = plain conditional).
        action: an action label the planner was trained with (instead of text).
        unconditional: generate without any global condition.
        out: write ``motion.npz`` here as well.
        tokenizer_run, planner_run: run directories (default ``models/``).
        steps: masked planner unmasking steps (default 10); decoder_steps: DDIM steps of the decoder.
        temperature, top_k, top_p: token sampling.
        trajectory: ``[T, 2]`` or ``[T, 3]`` root path x, y (, height) in metres to follow coarsely (its
            length sets T when ``seconds`` is None); NaN = free.
        device: torch device.
    Returns:
        :class:`GeneratedMotion`.
    """
    gen = load_generator(planner, tokenizer_run, planner_run, device)
    motion = gen.generate(text=text, seconds=seconds, seed=seed, cfg_scale=cfg_scale, action=action,
                          unconditional=unconditional, steps=steps, decoder_steps=decoder_steps,
                          temperature=temperature, top_k=top_k, top_p=top_p, trajectory=trajectory,
                          decoder_seed=decoder_seed)
    if out is not None:
        motion.save(out)
    return motion

"""Batched text -> features generation with the trained planners, for the evaluation protocol.

:func:`planner_generate_fn` wraps a loaded :class:`motok_robot.planner.generate.MotionGenerator`
as a :data:`motok_robot.eval.protocol.GenerateFn`: the texts of one call are encoded together,
grouped by token count (so every sample gets exactly its requested length), planned as one
batch per group with the planner's ``plan`` and decoded as one batch by the tokenizer.
:func:`resolve_models` turns ``--model`` / ``--planner`` arguments into run directories.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from motok_robot.errors import InputError
from motok_robot.paths import models_dir

PLANNER_KINDS = ("masked", "ar")


def train_hint(kind: str, path: Path | str) -> str:
    if kind == "tokenizer":
        return f"motok-robot train tokenizer --data DIR --out {path}"
    return f"motok-robot train planner --data DIR --tokenizer models/tokenizer --kind {kind} --out {path}"


def _is_run(path: Path) -> bool:
    return (path / "config.json").is_file() and (path / "model.safetensors").is_file()


@dataclass
class ModelSpec:
    """One generator to evaluate: a planner run, the tokenizer run it decodes with, a row name."""

    name: str
    kind: str
    planner_run: Path
    tokenizer_run: Path


def _planner_kind(run: Path) -> str:
    try:
        config = json.loads((run / "config.json").read_text())
        kind = config["planner"]["kind"]
    except (OSError, json.JSONDecodeError, KeyError, TypeError):
        raise InputError(f"{run / 'config.json'}: not a planner run config (no planner.kind)") from None
    if kind not in PLANNER_KINDS:
        raise InputError(f"{run / 'config.json'}: unknown planner kind {kind!r}")
    return kind


def _tokenizer_of(run: Path, tokenizer: Path | None) -> Path:
    if tokenizer is not None:
        candidate = Path(tokenizer)
    else:
        try:
            recorded = json.loads((run / "config.json").read_text()).get("tokenizer", {}).get("path")
        except (OSError, json.JSONDecodeError, AttributeError):
            recorded = None
        candidate = Path(recorded) if recorded and _is_run(Path(recorded)) else models_dir() / "tokenizer"
    if not _is_run(candidate):
        raise InputError(f"no trained tokenizer in {candidate} (config.json + model.safetensors); "
                         f"train one with: {train_hint('tokenizer', candidate)} (or pass --tokenizer RUN)")
    return candidate


def resolve_models(models: list[Path] | None, kinds: list[str], tokenizer: Path | None = None) -> list[ModelSpec]:
    """``--model`` entries (planner runs, or folders holding ``tokenizer/`` + ``planner_<kind>/``;
    none = the default ``models/`` folder) and ``--planner`` kinds -> the generators to evaluate."""
    for kind in kinds:
        if kind not in PLANNER_KINDS:
            raise InputError(f"--planner must be one of {PLANNER_KINDS}, got {kind!r}")
    specs: list[ModelSpec] = []
    for entry in models or [None]:
        folder = models_dir() if entry is None else Path(entry)
        if entry is not None and not folder.exists():
            raise InputError(f"--model {folder} does not exist")
        if _is_run(folder):
            kind = _planner_kind(folder)
            specs.append(ModelSpec(f"{kind} ({folder.name})", kind, folder, _tokenizer_of(folder, tokenizer)))
            continue
        for kind in kinds:
            run = folder / f"planner_{kind}"
            if not _is_run(run):
                raise InputError(f"no trained {kind} planner in {run} (config.json + model.safetensors); train one "
                                 f"with: {train_hint(kind, run)} (or pass --model RUN)")
            tok = Path(tokenizer) if tokenizer is not None else folder / "tokenizer"
            if not _is_run(tok):
                raise InputError(f"no trained tokenizer in {tok} (config.json + model.safetensors); train one "
                                 f"with: {train_hint('tokenizer', tok)}")
            name = kind if entry is None else f"{kind} ({folder.name})"
            specs.append(ModelSpec(name, kind, run, tok))
    names = [s.name for s in specs]
    if len(set(names)) != len(names):
        raise InputError(f"the models to evaluate have repeated names {names}: give distinct --model folders")
    return specs


def planner_generate_fn(generator, cfg_scale: float | None = None, steps: int | None = None,
                        decoder_steps: int | None = None, temperature: float | None = None):
    """A ``GenerateFn(texts, lengths, seed) -> [features [length_i, 263]]`` over a loaded
    :class:`~motok_robot.planner.generate.MotionGenerator` (see the module docstring)."""
    import torch

    from motok_robot.planner.conditions import Conditions
    from motok_robot.planner.config import SampleConfig

    defaults = SampleConfig()
    planner, tokenizer = generator.planner, generator.tokenizer
    ds = planner.config.downsample
    max_frames = planner.config.max_tokens * ds

    @torch.no_grad()
    def generate(texts: list[str], lengths: list[int], seed: int) -> list[np.ndarray]:
        lengths = [int(n) for n in lengths]
        too_long = [n for n in lengths if not 1 <= n <= max_frames]
        if too_long:
            raise InputError(f"the planner generates 1..{max_frames} frames; asked for {too_long[0]}")
        embeddings = generator.text_encoder.encode(texts).to(generator.device)
        n_tokens = np.array([-(-n // ds) for n in lengths])
        out: list[np.ndarray | None] = [None] * len(texts)
        for group, n in enumerate(np.unique(n_tokens)):
            idx = np.flatnonzero(n_tokens == n)
            cond = Conditions(text_embedding=embeddings[torch.as_tensor(idx)])
            tokens = planner.plan(
                cond, int(n), seed=seed * 1_000 + group,
                cfg_scale=defaults.cfg_scale if cfg_scale is None else float(cfg_scale),
                temperature=defaults.temperature if temperature is None else float(temperature),
                top_k=defaults.top_k, top_p=defaults.top_p, steps=steps or defaults.steps,
                remask_noise=defaults.remask_noise,
            )
            feats = tokenizer.decode(tokens, length=int(n) * ds, steps=decoder_steps or defaults.decoder_steps,
                                     seed=seed * 1_000 + group)
            feats = feats.float().cpu().numpy()
            for row, i in enumerate(idx):
                out[i] = feats[row, : lengths[i]]
        return out  # type: ignore[return-value]

    return generate

"""Planner run directories: safetensors weights + JSON config (never pickle).

::

    RUN/config.json              {"format": "motok-planner", "version": 1, "planner": {...},
                                  "train": {...}, "tokenizer": {"path": ..., "sha256": ..., "tokens_sha256": ...},
                                  "text_encoder": "<encoder name>"}
    RUN/model.safetensors        weights for generation (written at every validation)
    RUN/checkpoint.safetensors   weights + optimiser state + step (resuming)
    RUN/train_state.json         numpy RNG state and progress counters (resuming)
    RUN/metrics.csv              validation loss / token accuracy per evaluation
    RUN/cache/                   token and text-embedding caches (see planner/data.py)
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import torch

from motok_robot import checkpoint as _shared
from motok_robot.checkpoint import CONFIG_FILE, WEIGHTS_FILE, atomic_save_tensors, atomic_write_text, load_checked_weights
from motok_robot.errors import InputError
from motok_robot.planner.base import Planner
from motok_robot.planner.config import FORMAT, FORMAT_VERSION, PlannerConfig, saved_planner_config, to_dict

__all__ = ["CONFIG_FILE", "WEIGHTS_FILE", "atomic_write_text", "build_planner", "load_planner", "read_run_config",
           "save_planner_weights", "write_run_config"]


def build_planner(config: PlannerConfig) -> Planner:
    """A fresh planner of ``config.kind``."""
    config.validate()
    if config.kind == "masked":
        from motok_robot.planner.masked import MaskedPlanner

        return MaskedPlanner(config)
    from motok_robot.planner.autoregressive import ARPlanner

    return ARPlanner(config)


def write_run_config(run_dir: Path, config: PlannerConfig, extra: dict[str, Any]) -> None:
    data = {"format": FORMAT, "version": FORMAT_VERSION, "planner": to_dict(config), **extra}
    run_dir.mkdir(parents=True, exist_ok=True)
    atomic_write_text(run_dir / CONFIG_FILE, json.dumps(data, indent=2) + "\n")


def read_run_config(run_dir: str | Path) -> dict[str, Any]:
    """Parsed ``config.json`` of a planner run (InputError naming the file when bad)."""
    return _shared.read_run_config(run_dir, stage="planner", fmt=FORMAT, version=FORMAT_VERSION, name_section=False)


def save_planner_weights(model: Planner, run_dir: str | Path) -> Path:
    """Write the weights of ``model`` to ``RUN/model.safetensors`` atomically."""
    path = Path(run_dir) / WEIGHTS_FILE
    atomic_save_tensors(model.state_dict(), path, metadata={"format": FORMAT, "version": str(FORMAT_VERSION)})
    return path


def load_planner(run_dir: str | Path, device: str | torch.device = "cpu") -> tuple[Planner, dict[str, Any]]:
    """Load ``(planner in eval mode, run config dict)`` from a run directory."""
    run_dir = Path(run_dir)
    if run_dir.is_file():
        run_dir = run_dir.parent
    data = read_run_config(run_dir)
    config = saved_planner_config(data["planner"], where=f"{run_dir / CONFIG_FILE} 'planner'")
    weights = run_dir / WEIGHTS_FILE
    if not weights.is_file():
        raise InputError(f"{weights}: planner weights not found (training has not written a checkpoint yet?)")
    model = build_planner(config)
    load_checked_weights(model, weights)
    return model.to(device).eval(), data


# -- which tokenizer a planner belongs to -----------------------------------------------------
def tokenizer_record(tokenizer_dir: str | Path, tokenizer) -> dict[str, str]:
    """What a planner run stores about its tokenizer: the path (provenance), the SHA-256 of its
    weights file, and ``tokens_sha256``, the digest of what decides the tokens (normalisation,
    encoder, codebook; :meth:`MoTok.tokens_digest`).  A decoder trained further with
    ``--freeze-tokens`` keeps ``tokens_sha256``, so the planner stays valid with it."""
    from motok_robot.planner.data import file_digest

    tokenizer_dir = Path(tokenizer_dir)
    run = tokenizer_dir if tokenizer_dir.is_dir() else tokenizer_dir.parent
    return {"path": str(run.resolve()), "sha256": file_digest(run / WEIGHTS_FILE), "tokens_sha256": tokenizer.tokens_digest()}


def tokenizer_mismatch(saved: dict[str, Any], tokenizer_dir: str | Path, tokenizer) -> str | None:
    """Why ``tokenizer`` (loaded from ``tokenizer_dir``) cannot serve a planner whose run config
    holds ``saved`` as its tokenizer record, or None when it can.  Records with
    ``tokens_sha256`` compare token digests; older ones (weights SHA-256 only) the weights file."""
    if not saved:
        return None
    if saved.get("tokens_sha256"):
        have = tokenizer.tokens_digest()
        if have != saved["tokens_sha256"]:
            return f"its tokens differ (token digest {saved['tokens_sha256']} expected, {tokenizer_dir} gives {have})"
        return None
    if saved.get("sha256"):
        have = tokenizer_record(tokenizer_dir, tokenizer)["sha256"]
        if have != saved["sha256"]:
            return f"weights sha256 {saved['sha256']} expected, {tokenizer_dir} has {have}"
    return None


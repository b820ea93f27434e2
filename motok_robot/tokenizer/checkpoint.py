"""Tokenizer run directories: safetensors weights + JSON config (never pickle).

A run directory holds::

    RUN/config.json             {"format": "motok-tokenizer", "version": 1, "tokenizer": {...}, "train": {...}}
    RUN/model.safetensors       all weights and buffers (codebook + EMA state, mean/std, emphasis A, A^-1)
    RUN/train_state.safetensors optimiser moments, RNG state, step/epoch (training only, see train.py)
    RUN/metrics.csv             validation metrics per epoch (training only)

Files are written to a temporary name and renamed, so a kill never leaves a torn file.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import torch

from motok_robot import checkpoint as _shared
from motok_robot.checkpoint import CONFIG_FILE, WEIGHTS_FILE, atomic_save_tensors, atomic_write_text, load_checked_weights
from motok_robot.errors import InputError
from motok_robot.tokenizer.config import FORMAT, FORMAT_VERSION, TokenizerConfig, to_dict, tokenizer_config_from_dict
from motok_robot.tokenizer.model import MoTok

__all__ = ["CONFIG_FILE", "WEIGHTS_FILE", "atomic_save_tensors", "atomic_write_text", "load_tokenizer",
           "read_run_config", "save_tokenizer", "write_config"]


def write_config(run_dir: Path, config: TokenizerConfig, train: dict[str, Any] | None = None) -> None:
    data: dict[str, Any] = {"format": FORMAT, "version": FORMAT_VERSION, "tokenizer": to_dict(config)}
    if train is not None:
        data["train"] = train
    atomic_write_text(run_dir / CONFIG_FILE, json.dumps(data, indent=2) + "\n")


def read_run_config(run_dir: str | Path) -> dict[str, Any]:
    """The parsed ``config.json`` of a run directory (InputError naming the file if bad)."""
    return _shared.read_run_config(run_dir, stage="tokenizer", fmt=FORMAT, version=FORMAT_VERSION)


def save_tokenizer(tokenizer: MoTok, run_dir: str | Path, train: dict[str, Any] | None = None, step: int | None = None) -> Path:
    """Write ``config.json`` and ``model.safetensors`` of ``tokenizer`` into ``run_dir`` (created).

    ``train`` (the training config as a dict) goes into config.json; ``step`` (training step of
    these weights) into the safetensors metadata, where resuming checks it against the state."""
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    if train is None and (run_dir / CONFIG_FILE).is_file():
        try:
            train = json.loads((run_dir / CONFIG_FILE).read_text()).get("train")
        except (json.JSONDecodeError, AttributeError):
            train = None
    metadata = {"format": FORMAT, "version": str(FORMAT_VERSION)}
    if step is not None:
        metadata["step"] = str(int(step))
    atomic_save_tensors(tokenizer.state_dict(), run_dir / WEIGHTS_FILE, metadata=metadata)
    write_config(run_dir, tokenizer.config, train)
    return run_dir


def load_tokenizer(run_dir: str | Path, device: str | torch.device | None = None) -> MoTok:
    """Load a tokenizer from a run directory (or its ``model.safetensors``) in eval mode.

    ``device`` defaults to CUDA when available, else CPU.
    """
    run_dir = Path(run_dir)
    if run_dir.is_file():
        run_dir = run_dir.parent
    if not run_dir.exists():
        raise InputError(f"{run_dir}: tokenizer run directory not found")
    data = read_run_config(run_dir)
    config = tokenizer_config_from_dict(data["tokenizer"], where=f"{run_dir / CONFIG_FILE} 'tokenizer'")
    weights = run_dir / WEIGHTS_FILE
    if not weights.is_file():
        raise InputError(f"{weights}: tokenizer weights not found")
    model = MoTok(config)
    load_checked_weights(model, weights)
    if device is None:
        device = "cuda" if torch.cuda.is_available() else "cpu"
    if str(device).startswith("cuda") and not torch.cuda.is_available():
        raise InputError(f"device {device!r} requested but CUDA is not available")
    return model.to(device).eval()

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
import os
from pathlib import Path
from typing import Any

import torch
from safetensors import SafetensorError
from safetensors.torch import load_file, save_file

from motok_robot.errors import InputError
from motok_robot.tokenizer.config import FORMAT, FORMAT_VERSION, TokenizerConfig, to_dict, tokenizer_config_from_dict
from motok_robot.tokenizer.model import MoTok

CONFIG_FILE = "config.json"
WEIGHTS_FILE = "model.safetensors"


def atomic_write_text(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def atomic_save_tensors(tensors: dict[str, torch.Tensor], path: Path, metadata: dict[str, str] | None = None) -> None:
    tmp = path.with_name(path.name + ".tmp")
    save_file({k: v.detach().contiguous().cpu() for k, v in tensors.items()}, str(tmp), metadata=metadata)
    os.replace(tmp, path)


def write_config(run_dir: Path, config: TokenizerConfig, train: dict[str, Any] | None = None) -> None:
    data: dict[str, Any] = {"format": FORMAT, "version": FORMAT_VERSION, "tokenizer": to_dict(config)}
    if train is not None:
        data["train"] = train
    atomic_write_text(run_dir / CONFIG_FILE, json.dumps(data, indent=2) + "\n")


def read_run_config(run_dir: str | Path) -> dict[str, Any]:
    """The parsed ``config.json`` of a run directory (InputError naming the file if bad)."""
    path = Path(run_dir) / CONFIG_FILE
    if not path.is_file():
        raise InputError(f"{path}: tokenizer config not found (is {run_dir} a tokenizer run directory?)")
    try:
        data = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: not valid JSON ({exc})") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT or "tokenizer" not in data:
        raise InputError(f"{path}: not a motok tokenizer config (expected format {FORMAT!r} and a 'tokenizer' section)")
    if int(data.get("version", 0)) > FORMAT_VERSION:
        raise InputError(f"{path}: format version {data['version']} is newer than this motok-robot ({FORMAT_VERSION})")
    return data


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
    try:
        state = load_file(str(weights))
    except (SafetensorError, OSError) as exc:
        raise InputError(f"{weights}: cannot read safetensors file ({exc})") from None
    model = MoTok(config)
    expected = model.state_dict()
    missing = sorted(set(expected) - set(state))
    unexpected = sorted(set(state) - set(expected))
    if missing or unexpected:
        raise InputError(f"{weights}: weights do not match {CONFIG_FILE} (missing {missing[:5]}, unexpected {unexpected[:5]})")
    for key, value in state.items():
        if value.shape != expected[key].shape:
            raise InputError(f"{weights}: tensor {key} has shape {tuple(value.shape)}, config expects {tuple(expected[key].shape)}")
    model.load_state_dict(state)
    if device is None:
        device = "cuda" if torch.cuda.is_available() else "cpu"
    if str(device).startswith("cuda") and not torch.cuda.is_available():
        raise InputError(f"device {device!r} requested but CUDA is not available")
    return model.to(device).eval()

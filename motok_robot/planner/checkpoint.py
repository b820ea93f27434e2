"""Planner run directories: safetensors weights + JSON config (never pickle).

::

    RUN/config.json              {"format": "motok-planner", "version": 1, "planner": {...},
                                  "train": {...}, "tokenizer": {"path": ..., "sha256": ...},
                                  "text_encoder": "<encoder name>"}
    RUN/model.safetensors        weights for generation (written at every validation)
    RUN/checkpoint.safetensors   weights + optimiser state + step (resuming)
    RUN/train_state.json         numpy RNG state and progress counters (resuming)
    RUN/metrics.csv              validation loss / token accuracy per evaluation
    RUN/cache/                   token and text-embedding caches (see planner/data.py)
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import torch

from motok_robot.errors import InputError
from motok_robot.planner.base import Planner
from motok_robot.planner.config import FORMAT, FORMAT_VERSION, PlannerConfig, planner_config_from_dict, to_dict

CONFIG_FILE = "config.json"
WEIGHTS_FILE = "model.safetensors"


def build_planner(config: PlannerConfig) -> Planner:
    """A fresh planner of ``config.kind``."""
    config.validate()
    if config.kind == "masked":
        from motok_robot.planner.masked import MaskedPlanner

        return MaskedPlanner(config)
    from motok_robot.planner.autoregressive import ARPlanner

    return ARPlanner(config)


def atomic_write_text(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def write_run_config(run_dir: Path, config: PlannerConfig, extra: dict[str, Any]) -> None:
    data = {"format": FORMAT, "version": FORMAT_VERSION, "planner": to_dict(config), **extra}
    run_dir.mkdir(parents=True, exist_ok=True)
    atomic_write_text(run_dir / CONFIG_FILE, json.dumps(data, indent=2) + "\n")


def read_run_config(run_dir: str | Path) -> dict[str, Any]:
    """Parsed ``config.json`` of a planner run (InputError naming the file when bad)."""
    path = Path(run_dir) / CONFIG_FILE
    if not path.is_file():
        raise InputError(f"{path}: planner config not found (is {run_dir} a planner run directory?)")
    try:
        data = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: not valid JSON ({exc})") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT or "planner" not in data:
        raise InputError(f"{path}: not a motok planner config (expected format {FORMAT!r})")
    if int(data.get("version", 0)) > FORMAT_VERSION:
        raise InputError(f"{path}: format version {data['version']} is newer than this motok-robot ({FORMAT_VERSION})")
    return data


def save_planner_weights(model: Planner, run_dir: str | Path) -> Path:
    from safetensors.torch import save_file

    path = Path(run_dir) / WEIGHTS_FILE
    tmp = path.with_name(path.name + ".tmp")
    save_file({k: v.detach().cpu().contiguous() for k, v in model.state_dict().items()}, str(tmp),
              metadata={"format": FORMAT, "version": str(FORMAT_VERSION)})
    os.replace(tmp, path)
    return path


def load_planner(run_dir: str | Path, device: str | torch.device = "cpu") -> tuple[Planner, dict[str, Any]]:
    """Load ``(planner in eval mode, run config dict)`` from a run directory."""
    from safetensors import SafetensorError
    from safetensors.torch import load_file

    run_dir = Path(run_dir)
    if run_dir.is_file():
        run_dir = run_dir.parent
    data = read_run_config(run_dir)
    config = planner_config_from_dict(data["planner"], where=f"{run_dir / CONFIG_FILE} 'planner'")
    weights = run_dir / WEIGHTS_FILE
    if not weights.is_file():
        raise InputError(f"{weights}: planner weights not found (training has not written a checkpoint yet?)")
    try:
        state = load_file(str(weights))
    except (SafetensorError, OSError) as exc:
        raise InputError(f"{weights}: cannot read safetensors file ({exc})") from None
    model = build_planner(config)
    expected = model.state_dict()
    missing = sorted(set(expected) - set(state))
    unexpected = sorted(set(state) - set(expected))
    if missing or unexpected:
        raise InputError(f"{weights}: weights do not match {CONFIG_FILE} (missing {missing[:5]}, unexpected {unexpected[:5]})")
    for key, value in state.items():
        if value.shape != expected[key].shape:
            raise InputError(f"{weights}: tensor {key} has shape {tuple(value.shape)}, config expects {tuple(expected[key].shape)}")
    model.load_state_dict(state)
    return model.to(device).eval(), data

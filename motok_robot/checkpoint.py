"""Run directories and training checkpoints as safetensors + JSON (never pickle).

Used by every trainer (tokenizer, planners, evaluator):

- :func:`atomic_write_text` / :func:`atomic_save_tensors` write to ``NAME.tmp`` and rename, so a
  run killed at any moment never leaves a torn file;
- :func:`read_run_config` parses and checks a run directory's ``config.json``;
- :func:`load_checked_weights` loads ``model.safetensors`` into a model, naming the file and the
  tensor when names or shapes do not match;
- :func:`save_training_state` / :func:`load_training_state`: weights, optimiser state and step in
  one ``.safetensors`` file, for resuming.

Imports torch: only the learning stages use it.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import torch
from safetensors import SafetensorError
from safetensors.torch import load_file, save_file

from motok_robot.config_utils import read_json_object
from motok_robot.errors import InputError

CONFIG_FILE = "config.json"
WEIGHTS_FILE = "model.safetensors"


def atomic_write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` via ``path.tmp`` + rename (never a half-written file)."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def atomic_save_tensors(tensors: dict[str, torch.Tensor], path: Path, metadata: dict[str, str] | None = None) -> None:
    """Save ``tensors`` (detached, contiguous, on the CPU) as safetensors via ``path.tmp`` + rename."""
    tmp = path.with_name(path.name + ".tmp")
    save_file({k: v.detach().contiguous().cpu() for k, v in tensors.items()}, str(tmp), metadata=metadata)
    os.replace(tmp, path)


def read_run_config(run_dir: str | Path, *, stage: str, fmt: str, version: int, name_section: bool = True) -> dict[str, Any]:
    """The parsed ``config.json`` of a ``stage`` run directory (``stage`` also names its section).

    Raises InputError naming the file when it is missing, not JSON, not of format ``fmt`` or
    lacking the ``stage`` section, or newer than ``version``. ``name_section`` adds
    "and a '<stage>' section" to the wrong-format message.
    """
    path = Path(run_dir) / CONFIG_FILE
    if not path.is_file():
        raise InputError(f"{path}: {stage} config not found (is {run_dir} a {stage} run directory?)")
    data = read_json_object(path, f"{stage} config")
    if data.get("format") != fmt or stage not in data:
        section = f" and a '{stage}' section" if name_section else ""
        raise InputError(f"{path}: not a motok {stage} config (expected format {fmt!r}{section})")
    if int(data.get("version", 0)) > version:
        raise InputError(f"{path}: format version {data['version']} is newer than this motok-robot ({version})")
    return data


def load_checked_weights(model: torch.nn.Module, weights: Path, may_lack: tuple[str, ...] = ()) -> None:
    """Load the safetensors file ``weights`` into ``model`` (strict: same names and shapes).

    ``may_lack``: name prefixes of tensors the file may lack; those keep the model's values (a
    module added to a trained model for a fine-tune).  Raises InputError naming the file (and the
    tensor) when it cannot be read or does not match the model built from ``config.json``.
    """
    try:
        state = load_file(str(weights))
    except (SafetensorError, OSError) as exc:
        raise InputError(f"{weights}: cannot read safetensors file ({exc})") from None
    expected = model.state_dict()
    missing = sorted(k for k in set(expected) - set(state) if not k.startswith(may_lack))
    unexpected = sorted(set(state) - set(expected))
    if missing or unexpected:
        raise InputError(f"{weights}: weights do not match {CONFIG_FILE} (missing {missing[:5]}, unexpected {unexpected[:5]})")
    for key, value in state.items():
        if value.shape != expected[key].shape:
            raise InputError(f"{weights}: tensor {key} has shape {tuple(value.shape)}, config expects {tuple(expected[key].shape)}")
    model.load_state_dict(state, strict=not may_lack)


def save_training_state(path: str | Path, model: torch.nn.Module, optimiser: torch.optim.Optimizer, step: int, extra: dict[str, torch.Tensor] | None = None) -> None:
    """Write model weights, optimiser state and ``step`` to ``path`` atomically."""
    state = {f"model.{k}": v.detach().cpu().contiguous() for k, v in model.state_dict().items()}
    for pid, values in optimiser.state_dict()["state"].items():
        for key, value in values.items():
            state[f"optim.{pid}.{key}"] = torch.as_tensor(value).detach().cpu().clone().contiguous()
    state["step"] = torch.tensor(int(step))
    for key, value in (extra or {}).items():
        state[f"extra.{key}"] = value.detach().cpu().contiguous()
    atomic_save_tensors(state, Path(path))


def load_training_state(path: str | Path, model: torch.nn.Module, optimiser: torch.optim.Optimizer | None = None) -> tuple[int, dict[str, torch.Tensor]]:
    """Restore what :func:`save_training_state` wrote; returns ``(step, extra tensors)``."""
    path = Path(path)
    if not path.exists():
        raise InputError(f"checkpoint {path} does not exist")
    flat = load_file(str(path))
    weights = {k[6:]: v for k, v in flat.items() if k.startswith("model.")}
    missing, unexpected = model.load_state_dict(weights, strict=False)
    if missing or unexpected:
        raise InputError(f"checkpoint {path} does not match the model: missing {missing[:5]}, unexpected {unexpected[:5]}")
    if optimiser is not None:
        state = optimiser.state_dict()
        restored: dict[int, dict] = {}
        for key, value in flat.items():
            if key.startswith("optim."):
                _, pid, name = key.split(".", 2)
                restored.setdefault(int(pid), {})[name] = value
        state["state"] = restored
        optimiser.load_state_dict(state)
    extra = {k[6:]: v for k, v in flat.items() if k.startswith("extra.")}
    return int(flat["step"].item()), extra

"""Training checkpoints as safetensors (never pickle): weights, optimiser state, step.

Used by every trainer (tokenizer, planners, evaluator). A checkpoint is one
``.safetensors`` file written atomically (temp file + rename), so a run killed at any
moment resumes from the last complete checkpoint. Imports torch: only the learning
stages use it.
"""

from __future__ import annotations

from pathlib import Path

import torch
from safetensors.torch import load_file, save_file

from motok_robot.errors import InputError


def save_training_state(path: str | Path, model: torch.nn.Module, optimiser: torch.optim.Optimizer, step: int, extra: dict[str, torch.Tensor] | None = None) -> None:
    """Write model weights, optimiser state and ``step`` to ``path`` atomically."""
    state = {f"model.{k}": v.detach().cpu().contiguous() for k, v in model.state_dict().items()}
    for pid, values in optimiser.state_dict()["state"].items():
        for key, value in values.items():
            state[f"optim.{pid}.{key}"] = torch.as_tensor(value).detach().cpu().clone().contiguous()
    state["step"] = torch.tensor(int(step))
    for key, value in (extra or {}).items():
        state[f"extra.{key}"] = value.detach().cpu().contiguous()
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    save_file(state, str(tmp))
    tmp.replace(path)


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

"""MoTok: the diffusion-based discrete motion tokenizer (issue 11).

```python
from motok_robot.tokenizer import MoTok, TokenizerConfig, load_tokenizer, save_tokenizer
tok = load_tokenizer(run_dir)                 # config.json + model.safetensors (mean/std inside)
tokens = tok.encode(features)                 # raw [B, T, 263], T % tok.frames_per_token == 0 -> int64 [B, T / 4]
feats = tok.decode(tokens, length=T, steps=20, seed=0, guidance=None)   # -> raw [B, T, 263]
padded, T = tok.pad(features)                 # repeat the last frame up to a multiple of frames_per_token
```

Attributes resolve lazily, so ``import motok_robot.tokenizer`` (and its CLI module) does
not import torch; :class:`TokenizerConfig` and :class:`TrainConfig` are torch-free.
"""

from __future__ import annotations

import importlib

from motok_robot.tokenizer.config import TokenizerConfig, TrainConfig

_LAZY = {
    "MoTok": "motok_robot.tokenizer.model",
    "pad_to_multiple": "motok_robot.tokenizer.model",
    "crop_to_multiple": "motok_robot.tokenizer.model",
    "load_tokenizer": "motok_robot.tokenizer.checkpoint",
    "save_tokenizer": "motok_robot.tokenizer.checkpoint",
    "EmphasisProjection": "motok_robot.tokenizer.emphasis",
    "Guidance": "motok_robot.tokenizer.sampler",
    "GuidanceState": "motok_robot.tokenizer.sampler",
    "VectorQuantizer": "motok_robot.tokenizer.quantizer",
}


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'motok_robot.tokenizer' has no attribute {name!r}")


__all__ = ["TokenizerConfig", "TrainConfig", *_LAZY]

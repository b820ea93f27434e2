"""motok-robot: a sentence -> a physics-checked humanoid robot trajectory -> Dynamixel servos.

This module stays light: importing :mod:`motok_robot` does not import torch, so the
robot-side stages (``retarget``, :mod:`motok_robot.robots`, :mod:`motok_robot.sim`,
:mod:`motok_robot.servo`) run without the learning stack. Heavy entry points are
resolved lazily on first attribute access.
"""

from __future__ import annotations

import importlib

__version__ = "0.1.0"

_LAZY = {
    "generate": ("motok_robot.planner.generate", "generate"),
    "Pipeline": ("motok_robot.pipeline", "Pipeline"),
}


def __getattr__(name: str):
    if name in _LAZY:
        module, attr = _LAZY[name]
        return getattr(importlib.import_module(module), attr)
    raise AttributeError(f"module 'motok_robot' has no attribute {name!r}")


__all__ = ["__version__", *_LAZY]

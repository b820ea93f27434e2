"""Where motok-robot finds its shipped files (light: no heavy imports).

``$MOTOK_ROBOT_MODELS`` replaces ``<repo>/models`` for everything at once: trained weights
in ``models/{tokenizer,planner_masked,planner_ar,evaluator}/`` and robot descriptions in
``models/mjcf/``.
"""

from __future__ import annotations

import os
from pathlib import Path

MODELS_ENV = "MOTOK_ROBOT_MODELS"


def models_dir() -> Path:
    """``$MOTOK_ROBOT_MODELS`` or ``models/`` at the repository root."""
    override = os.environ.get(MODELS_ENV)
    if override:
        return Path(override).expanduser()
    return Path(__file__).resolve().parents[1] / "models"


def robots_dir() -> Path:
    """The folder of robot descriptions (``NAME.xml`` + ``NAME.toml``): ``models_dir() / "mjcf"``."""
    return models_dir() / "mjcf"

"""One sentence -> human motion -> robot trajectory -> MuJoCo validation -> servo playback.

The Python API behind ``motok-robot run`` (docs/pipeline.md)::

    from motok_robot import Pipeline

    pipe = Pipeline()                                   # models are loaded once, on first use
    result = pipe.run("a person waves the right hand", robot="op3", seconds=6, out_dir="wave/")
    result.passed, result.failed_checks                 # the validation verdict
    result.files["video"], result.timings["retarget"]   # paths and per-stage seconds

Each stage writes into ``out_dir`` (formats: docs/CONTRACTS.md): generate ``motion.npz``,
retarget ``robot.npz``, validate ``report.json`` (and plots, ``video.mp4``), playback
``playback.csv`` and ``playback.stats.json``; always ``summary.md`` and ``pipeline.json``.
Playback is ``"dry-run"`` (an emulated Dynamixel chain, simulated time; default), ``"sim"`` (the
MuJoCo model) or ``"port"`` (real servos, only after a passing validation or with ``force``).
A failed validation is not an error: every file is written and the verdict says FAIL.  After one,
the balance repair and the slow-down may be tried (:mod:`~motok_robot.pipeline.repairs`).

Output is atomic: a hidden partial folder is renamed ``out_dir`` when every stage finished, or
``OUT.failed/`` (with ``FAILED.txt``) when one raised.  Invalid input raises
:class:`~motok_robot.errors.InputError` before any work and leaves nothing.

The modules, one idea each: :mod:`~.request` (argument checks), :mod:`~.source` (``--motion``
files), :mod:`~.config`, :mod:`~.result`, :mod:`~.run` (:class:`Pipeline`), :mod:`~.stages` (the
stage sequence), :mod:`~.repairs`, :mod:`~.playback`, :mod:`~.output` (the atomic folder),
:mod:`~.summary` (summary.md, pipeline.json, summary.csv), :mod:`~.batch` (prompt lists) and
:mod:`~.cli` (``motok-robot run``).  Importing the package does not import torch, MuJoCo or
matplotlib.
"""

from motok_robot.pipeline.batch import slug
from motok_robot.pipeline.config import PipelineConfig
from motok_robot.pipeline.repairs import BALANCE_CHECKS, RETIME_STEPS, SPEED_CHECKS, balance_retargeter
from motok_robot.pipeline.request import (
    DEFAULT_CONSTRAINED_SECONDS, PLAYBACK_MODES, check_out_dir, check_playback, check_robot,
)
from motok_robot.pipeline.result import STAGES, PipelineResult, PlaybackSummary
from motok_robot.pipeline.run import Pipeline, load_robot_stages
from motok_robot.pipeline.source import SourceMotion, load_source_motion
from motok_robot.pipeline.stages import PLOT_FILES
from motok_robot.pipeline.summary import summary_markdown
from motok_robot.text.prompts import MAX_SEED, PromptSpec, check_seconds, check_seed, read_prompts
from motok_robot.text.validate import MAX_TEXT_CHARS, check_text

__all__ = [
    "BALANCE_CHECKS", "DEFAULT_CONSTRAINED_SECONDS", "MAX_SEED", "MAX_TEXT_CHARS", "PLAYBACK_MODES", "PLOT_FILES",
    "RETIME_STEPS", "SPEED_CHECKS", "STAGES", "Pipeline", "PipelineConfig", "PipelineResult", "PlaybackSummary",
    "PromptSpec", "SourceMotion", "balance_retargeter", "check_out_dir", "check_playback", "check_robot",
    "check_seconds", "check_seed", "check_text", "load_robot_stages", "load_source_motion", "read_prompts", "slug",
    "summary_markdown",
]

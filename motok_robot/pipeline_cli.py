"""Deprecated: ``motok-robot run`` lives in :mod:`motok_robot.pipeline.cli`; this old name still imports it."""
from motok_robot.pipeline.cli import format_result, register, run_command

__all__ = ["format_result", "register", "run_command"]

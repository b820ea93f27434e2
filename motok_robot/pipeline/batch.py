"""Batch runs: many prompts into one folder with the models loaded once, and ``summary.csv``."""

from __future__ import annotations

import re
from pathlib import Path

from motok_robot.errors import InputError
from motok_robot.pipeline.request import check_out_dir, check_playback, check_robot
from motok_robot.pipeline.result import STAGES
from motok_robot.pipeline.summary import write_summary_csv
from motok_robot.robots.robot import DEFAULT_ROBOT
from motok_robot.text.prompts import PromptSpec, check_seconds, check_seed
from motok_robot.text.validate import check_text


def slug(text: str, limit: int = 40) -> str:
    """A folder-name-safe short form of ``text``."""
    return re.sub(r"[^a-z0-9]+", "_", text.lower()).strip("_")[:limit].rstrip("_") or "prompt"


def run_batch(pipe, prompts: list[PromptSpec], out_dir, robot: str = DEFAULT_ROBOT, playback: str = "dry-run",
              render: bool = False, overwrite: bool = False, progress: bool | None = None) -> Path:
    """Run every prompt with ``pipe`` (a :class:`~motok_robot.pipeline.Pipeline`) into
    ``out_dir/NNN_slug/`` and write ``out_dir/summary.csv``.

    A prompt whose run fails is recorded (``error`` column, ``NNN_slug.failed/``) and the
    batch goes on.  Returns the path of ``summary.csv``.
    """
    from tqdm import tqdm

    if not prompts:
        raise InputError("no prompts to run")
    if playback == "port":
        raise InputError("a prompt list cannot play on hardware; run one prompt with --port")
    check_robot(robot)
    check_playback(playback, None)
    out = check_out_dir(out_dir, overwrite)
    for spec in prompts:
        check_text(spec.text), check_seconds(spec.seconds), check_seed(spec.seed)
    pipe.load_models()
    for spec in prompts:
        if spec.seconds is not None:
            try:
                pipe.generator.frames_for(spec.seconds)
            except InputError as exc:
                raise InputError(f"prompt on line {spec.line}: {exc}") from None
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    try:
        for i, spec in enumerate(tqdm(prompts, desc="prompts", unit="prompt", disable=None if progress is None
                                      else not progress)):
            folder = f"{i:03d}_{slug(spec.text)}"
            row = {"index": i, "text": spec.text, "seed": spec.seed, "folder": folder}
            try:
                res = pipe.run(spec.text, robot=robot, seconds=spec.seconds, seed=spec.seed,
                               out_dir=out / folder, playback=playback, render=render, overwrite=True)
            except Exception as exc:  # noqa: BLE001 - record it and go on with the list
                failed = out / f"{folder}.failed"
                row.update(passed=False, error=str(exc), seconds=spec.seconds,
                           folder=failed.name if failed.is_dir() else "")
            else:
                row.update(seconds=round(res.seconds, 3), passed=res.passed,
                           failed_checks=";".join(res.failed_checks), playback=res.playback.status,
                           vocabulary_far=bool((res.report.get("vocabulary") or {}).get("far", False)),
                           **{f"{k}_s": round(v, 3) for k, v in res.timings.items() if k in (*STAGES, "total")})
            rows.append(row)
    finally:  # also after Ctrl-C: the rows of the prompts that ran
        write_summary_csv(out, rows)
    return out / "summary.csv"

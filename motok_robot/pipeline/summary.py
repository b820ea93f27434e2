"""What a run writes about itself: ``summary.md`` (verdict, failing checks, stage times, a link to
every file), ``pipeline.json`` (the same, machine-readable) and a batch's ``summary.csv``."""

from __future__ import annotations

import csv
import io
import json
import os
from pathlib import Path

from motok_robot.pipeline.result import STAGES, PipelineResult, relative

_FILE_LABELS = {
    "motion": "human motion (joints, features, tokens)",
    "robot": "robot trajectory (qpos, contacts, keypoint errors)",
    "servo_goals": "servo goals the physics rollout tracked and playback streams (feedforward)",
    "report": "validation report",
    "video": "validation video (reference | physics rollout)",
    "playback_log": "playback log (one row per control tick)",
    "playback_stats": "playback loop statistics",
    "playback_video": "simulated playback video",
    "result": "this summary, machine-readable",
}


def summary_markdown(result: PipelineResult) -> str:
    """``summary.md``: verdict, failing checks, per-stage times and links to every file."""
    root = result.out_dir
    verdict = "PASS" if result.passed else "FAIL"
    lines = [f"# {verdict}: \"{result.text}\"", "",
             f"* robot: `{result.robot}`; clip: {result.seconds:.2f} s; seed: {result.seed}"
             + (f"; the robot plays it {result.retime_factor:g}x slower (servo limits)" if result.retime_factor != 1.0 else "")
             + (f"; retargeted with the ZMP term (weight {result.zmp_weight:g}, acceleration weight "
                f"{result.acceleration_weight:g})" if result.zmp_weight > 0 else ""),
             f"* models: `{result.model}`" if result.model else "* models: -",
             f"* validation: **{verdict}**"
             + (f" - failing checks: {', '.join(f'`{c}`' for c in result.failed_checks)}" if result.failed_checks else
                " - every check passed"),
             f"* playback ({result.playback.mode}): **{result.playback.status}**"
             + (f" - {result.playback.line}" if result.playback.line else "")
             + (f" - {result.playback.error}" if result.playback.error else ""), ""]
    if result.playback.gate:
        lines += [f"Hardware playback would be refused: {result.playback.gate}.", ""]
    if result.report:
        from motok_robot.sim.report import summary_text

        lines += ["## Validation", "", "```", summary_text(result.report), "```", ""]
    lines += ["## Stage times", "", "| stage | seconds |", "|---|---:|"]
    for key in ("load", "setup", *STAGES, "total"):
        if key in result.timings:
            lines.append(f"| {key} | {result.timings[key]:.3f} |")
    lines += ["", "## Files", ""]
    for key, path in result.files.items():
        if key == "summary":
            continue
        name = relative(path, root)
        label = _FILE_LABELS.get(key) or ("plot: " + key[5:].replace("_", " ") if key.startswith("plot_") else key)
        lines.append(f"* [{name}]({name}) - {label}")
    for key in [k for k in result.files if k.startswith("plot_")]:
        name = relative(result.files[key], root)
        lines += ["", f"![{key[5:]}]({name})"]
    if result.notes:
        lines += ["", "## Notes", ""] + [f"* {n}" for n in result.notes]
    return "\n".join(lines) + "\n"


def write_summary(result: PipelineResult, tmp: Path) -> None:
    """Write ``summary.md`` and ``pipeline.json`` into the run folder ``tmp`` (paths relative to it)."""
    result.files["summary"] = tmp / "summary.md"
    result.files["result"] = tmp / "pipeline.json"
    result.out_dir = tmp
    (tmp / "summary.md").write_text(summary_markdown(result), encoding="utf-8")
    data = result.to_dict()
    data["out_dir"] = "."
    (tmp / "pipeline.json").write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")


def write_summary_csv(out: Path, rows: list[dict]) -> None:
    """Write ``out/summary.csv`` (one row per prompt of a batch), atomically."""
    columns = ["index", "text", "seconds", "seed", "folder", "passed", "failed_checks", "vocabulary_far", "playback",
               *(f"{s}_s" for s in (*STAGES, "total")), "error"]
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=columns, extrasaction="ignore")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: "" if row.get(k) is None else row.get(k, "") for k in columns})
    path = out / "summary.csv"
    part = out / ".summary.csv.partial"
    part.write_text(buffer.getvalue(), encoding="utf-8")
    os.replace(part, path)

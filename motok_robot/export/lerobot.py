"""The passing robot trajectories of a folder tree as a LeRobot-style episode dataset.

Input: any folder tree of run folders, each holding ``robot.npz`` and the ``report.json`` that
validated it (``motok-robot run --prompts`` batches, sweep cells, ``validate --out`` folders
next to the trajectory).  A folder becomes an episode when its report passed, records this
very ``robot.npz`` (``input.sha256``) and names its servo goals (``servo_goals.npz``, checked
against the report's digest); every other folder is skipped with its reason.

Output (the layout of LeRobot's dataset format ``v2.1``; docs/export.md says what matches)::

    OUT/data/chunk-000/episode_000000.parquet   one row per frame (npz without pyarrow)
    OUT/meta/info.json                          codebase_version, robot_type, fps, counts,
                                                data_path, features (dtype, shape, names)
    OUT/meta/episodes.jsonl                     {"episode_index", "tasks": [prompt], "length"}
    OUT/meta/tasks.jsonl                        {"task_index", "task"}: the distinct prompts
    OUT/meta/episodes_stats.jsonl               per episode and feature: min, max, mean, std, count
    OUT/meta/motok_export.json                  where each episode came from, skipped folders

Columns: ``observation.state`` float32 [nj] joint angles (rad, robot.npz ``qpos`` joint
columns), ``observation.base_pose`` float32 [7] (free base x, y, z in m and quaternion w, x, y,
z), ``action`` float32 [nj] the validated servo goals (rad), ``timestamp`` float32 (s),
``frame_index``, ``episode_index``, ``index`` (over the dataset), ``task_index`` (int64).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from motok_robot.errors import InputError
from motok_robot.export.robot_csv import FREE_BASE, RobotTable, read_goals_for, read_robot_table

CODEBASE_VERSION = "v2.1"
CHUNK_SIZE = 1000
DATA_PATH = "data/chunk-{episode_chunk:03d}/episode_{episode_index:06d}.{ext}"
#: folders visited at most while looking for run folders (a bound on a mistaken root such as /)
MAX_FOLDERS = 100_000
BASE_NAMES = ("x", "y", "z", "qw", "qx", "qy", "qz")


@dataclass
class Episode:
    """One passing run folder: its trajectory, validated goals [T, nj] and prompt."""

    folder: Path
    table: RobotTable
    goals: np.ndarray
    task: str


@dataclass
class Scan:
    """What :func:`find_episodes` found: the episodes and ``skipped`` ``(folder, reason)``."""

    episodes: list[Episode] = field(default_factory=list)
    skipped: list[tuple[str, str]] = field(default_factory=list)


def run_folders(root: str | Path) -> list[Path]:
    """Folders under ``root`` (itself included) that hold both robot.npz and report.json, sorted."""
    root = Path(root)
    if not root.is_dir():
        raise InputError(f"{root}: not a folder (export --lerobot reads a folder tree of run folders)")
    found, visited = [], 0
    for here, dirs, files in os.walk(root):
        visited += 1
        if visited > MAX_FOLDERS:
            raise InputError(f"{root}: more than {MAX_FOLDERS:,} folders below it; point export at the batch folder")
        dirs[:] = sorted(d for d in dirs if not d.startswith("."))  # .partial-* folders of unfinished runs
        if "robot.npz" in files and "report.json" in files:
            found.append(Path(here))
    return sorted(found)


def _prompt(folder: Path) -> str:
    """The sentence of a run folder: pipeline.json's ``text``, else motion.npz's ``text``, else ""."""
    try:
        text = json.loads((folder / "pipeline.json").read_text(encoding="utf-8")).get("text")
        if isinstance(text, str) and text.strip():
            return text.strip()
    except (OSError, ValueError, AttributeError):
        pass
    motion = folder / "motion.npz"
    if motion.is_file():
        from motok_robot.npz_files import read_npz_fields

        try:
            fields = read_npz_fields(motion, "motion file")
        except InputError:
            return ""
        value = np.asarray(fields.get("text", ""))
        if value.size == 1 and value.dtype.kind in "US":
            return str(value.reshape(())).strip()
    return ""


def read_episode(folder: Path) -> Episode | str:
    """The episode of ``folder``, or the reason it is not one (a one-line string)."""
    report_path = folder / "report.json"
    try:
        report = json.loads(report_path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        return f"{report_path} is unreadable ({exc})"
    if not isinstance(report, dict):
        return f"{report_path} is not a JSON object"
    if report.get("passed") is not True:
        failed = report.get("failed_checks") or []
        return "validation failed" + (f" ({', '.join(map(str, failed))})" if failed else "")
    table = read_robot_table(folder / "robot.npz")
    recorded = (report.get("input") or {}).get("sha256") if isinstance(report.get("input"), dict) else None
    if not isinstance(recorded, str) or recorded.lower() != table.sha256:
        return f"{report_path} did not validate this robot.npz (input.sha256 differs or is missing)"
    record = report.get("servo_goals")
    if not isinstance(record, dict) or not record.get("file"):
        return f"{report_path} records no servo goals (validated without physics)"
    goals = read_goals_for(table, folder / str(record["file"]), record.get("sha256"))
    return Episode(folder=folder, table=table, goals=goals, task=_prompt(folder))


def find_episodes(root: str | Path, robot: str | None = None, progress=None) -> Scan:
    """Every passing run folder under ``root`` (of ``robot`` when given); ``progress(done, total)``."""
    scan = Scan()
    folders = run_folders(root)
    for k, folder in enumerate(folders):
        try:
            episode = read_episode(folder)
        except InputError as exc:
            episode = str(exc)
        if isinstance(episode, str):
            scan.skipped.append((str(folder), episode))
        elif robot and episode.table.robot != robot:
            scan.skipped.append((str(folder), f"robot {episode.table.robot!r}, not {robot!r}"))
        else:
            scan.episodes.append(episode)
        if progress is not None:
            progress(k + 1, len(folders))
    return scan


def check_consistent(episodes: list[Episode], root: Path) -> None:
    """One robot, joint order and fps across the episodes (one LeRobot dataset has one of each)."""
    first = episodes[0]
    for ep in episodes[1:]:
        if ep.table.robot != first.table.robot or ep.table.joint_names != first.table.joint_names:
            raise InputError(f"{root}: episodes of different robots or joint orders ({first.table.robot!r} in "
                             f"{first.folder}, {ep.table.robot!r} in {ep.folder}); pass --robot NAME")
        if abs(ep.table.fps - first.table.fps) > 1e-9:
            raise InputError(f"{root}: episodes at different frame rates ({first.table.fps:g} fps in "
                             f"{first.folder}, {ep.table.fps:g} in {ep.folder}); a dataset has one fps")


def _columns(episode: Episode, episode_index: int, start_index: int, task_index: int) -> dict[str, np.ndarray]:
    T = episode.table.qpos.shape[0]
    frames = np.arange(T, dtype=np.int64)
    return {
        "observation.state": episode.table.joints.astype(np.float32),
        "observation.base_pose": episode.table.qpos[:, :FREE_BASE].astype(np.float32),
        "action": episode.goals.astype(np.float32),
        "timestamp": (frames / episode.table.fps).astype(np.float32),
        "frame_index": frames,
        "episode_index": np.full(T, episode_index, dtype=np.int64),
        "index": start_index + frames,
        "task_index": np.full(T, task_index, dtype=np.int64),
    }


def _features(joint_names: list[str]) -> dict:
    scalar = {"shape": [1], "names": None}
    return {
        "observation.state": {"dtype": "float32", "shape": [len(joint_names)], "names": list(joint_names),
                              "unit": "rad"},
        "observation.base_pose": {"dtype": "float32", "shape": [FREE_BASE], "names": list(BASE_NAMES),
                                  "unit": "m (x, y, z), unit quaternion w x y z"},
        "action": {"dtype": "float32", "shape": [len(joint_names)], "names": list(joint_names),
                   "unit": "rad (validated servo goals)"},
        "timestamp": {"dtype": "float32", **scalar, "unit": "s"},
        "frame_index": {"dtype": "int64", **scalar},
        "episode_index": {"dtype": "int64", **scalar},
        "index": {"dtype": "int64", **scalar},
        "task_index": {"dtype": "int64", **scalar},
    }


def _stats(columns: dict[str, np.ndarray]) -> dict:
    out = {}
    for name, values in columns.items():
        v = values.astype(np.float64).reshape(len(values), -1)
        out[name] = {"min": v.min(axis=0).tolist(), "max": v.max(axis=0).tolist(), "mean": v.mean(axis=0).tolist(),
                     "std": v.std(axis=0).tolist(), "count": [int(len(v))]}
    return out


def parquet_available() -> bool:
    import importlib

    try:
        importlib.import_module("pyarrow.parquet")
    except ImportError:
        return False
    return True


def _write_parquet(path: Path, columns: dict[str, np.ndarray]) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    arrays = {}
    for name, values in columns.items():
        if values.ndim == 2:  # a vector per frame: a fixed-size list column
            flat = pa.array(values.reshape(-1), type=pa.float32())
            arrays[name] = pa.FixedSizeListArray.from_arrays(flat, values.shape[1])
        else:
            arrays[name] = pa.array(values)
    pq.write_table(pa.table(arrays), path)


def write_dataset(episodes: list[Episode], out: str | Path, *, source: str = "", skipped=(), use_parquet=None,
                  progress=None) -> dict:
    """Write ``episodes`` as a dataset in ``out`` (see the module docstring); returns info.json.

    ``use_parquet`` None: Parquet when pyarrow is installed, npz otherwise (info.json and
    motok_export.json say which).  ``progress(done, total)`` after each episode."""
    if not episodes:
        raise InputError(f"{source or out}: no passing trajectory to export")
    out = Path(out)
    check_consistent(episodes, Path(source or out))
    parquet = parquet_available() if use_parquet is None else use_parquet
    ext = "parquet" if parquet else "npz"
    (out / "meta").mkdir(parents=True, exist_ok=True)
    tasks: dict[str, int] = {}
    episode_rows, stats_rows, origins = [], [], []
    total = 0
    for e, episode in enumerate(episodes):
        task_index = tasks.setdefault(episode.task, len(tasks))
        columns = _columns(episode, e, total, task_index)
        path = out / DATA_PATH.format(episode_chunk=e // CHUNK_SIZE, episode_index=e, ext=ext)
        path.parent.mkdir(parents=True, exist_ok=True)
        if parquet:
            _write_parquet(path, columns)
        else:
            np.savez(path, **columns)
        length = int(len(columns["frame_index"]))
        total += length
        episode_rows.append({"episode_index": e, "tasks": [episode.task], "length": length})
        stats_rows.append({"episode_index": e, "stats": _stats(columns)})
        origins.append({"episode_index": e, "folder": str(episode.folder), "robot_npz_sha256": episode.table.sha256})
        if progress is not None:
            progress(e + 1, len(episodes))
    first = episodes[0].table
    info = {
        "codebase_version": CODEBASE_VERSION, "robot_type": first.robot, "total_episodes": len(episodes),
        "total_frames": total, "total_tasks": len(tasks), "total_videos": 0,
        "total_chunks": (len(episodes) - 1) // CHUNK_SIZE + 1, "chunks_size": CHUNK_SIZE, "fps": first.fps,
        "splits": {"train": f"0:{len(episodes)}"}, "data_path": DATA_PATH.replace("{ext}", ext),
        "video_path": None, "features": _features(first.joint_names),
    }
    _write_json(out / "meta" / "info.json", info)
    _write_jsonl(out / "meta" / "episodes.jsonl", episode_rows)
    _write_jsonl(out / "meta" / "tasks.jsonl", [{"task_index": i, "task": t} for t, i in tasks.items()])
    _write_jsonl(out / "meta" / "episodes_stats.jsonl", stats_rows)
    _write_json(out / "meta" / "motok_export.json", {
        "source": source, "format": ext, "episodes": origins,
        "skipped": [{"folder": f, "reason": r} for f, r in skipped],
        "note": "" if parquet else "pyarrow is not installed: episode files are npz (same columns), which LeRobot "
                                   "does not read; install pyarrow and export again for Parquet"})
    return info


def _write_json(path: Path, value) -> None:
    path.write_text(json.dumps(value, indent=2) + "\n", encoding="utf-8")


def _write_jsonl(path: Path, rows) -> None:
    path.write_text("".join(json.dumps(row) + "\n" for row in rows), encoding="utf-8")

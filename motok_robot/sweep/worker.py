"""One sweep worker: runs cells on :class:`~motok_robot.pipeline.Pipeline` s it keeps.

A :class:`CellRunner` is what a Ray actor holds (:mod:`motok_robot.sweep.engine`); with
``--workers 1`` the sweep calls the same class in process.  It keeps one ``Pipeline`` per
variant's settings, so the generation models and each robot's compiled retargeting problems are
loaded once per worker.  A cell runs into a scratch folder of the worker; its files come back to
the driver as bytes with its result row, so the driver is the only writer of ``--out`` (also when
the workers run on other machines without a shared filesystem).

Torch runs on one thread in every worker, so a cell gives the same report in process and on Ray.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import re
import shutil
import signal
import socket
import tempfile
import threading
import time
from pathlib import Path

#: environment variables the driver hands its workers (limits, model folder, retargeting cache)
FORWARDED_ENV_PREFIXES = ("MOTOK_",)
#: report fields left out of the report hash: the timings, and the sha256 of robot.npz (that file
#: records the retargeting solver's wall seconds per window, so its bytes differ from run to run)
UNHASHED_REPORT_FIELDS = ("timing_s", "input.sha256")


class CellTimeout(BaseException):
    """Raised inside a cell when its time budget is spent (a BaseException: the pipeline re-raises it as is)."""


def worker_env() -> dict[str, str]:
    """The driver's environment that workers take over: ``MOTOK_*`` variables and one thread."""
    env = {k: v for k, v in os.environ.items() if k.startswith(FORWARDED_ENV_PREFIXES)}
    env["OMP_NUM_THREADS"] = "1"
    return env


def report_sha(report: dict) -> str:
    """sha256 of a validation report without :data:`UNHASHED_REPORT_FIELDS`: equal for equal results."""
    kept = json.loads(json.dumps(report))
    for dotted in UNHASHED_REPORT_FIELDS:
        *parents, name = dotted.split(".")
        table = kept
        for parent in parents:
            table = table.get(parent) if isinstance(table, dict) else None
        if isinstance(table, dict):
            table.pop(name, None)
    return hashlib.sha256(json.dumps(kept, sort_keys=True).encode("utf-8")).hexdigest()


def qpos_sha(robot_npz: Path) -> str:
    """sha256 of the robot trajectory (``qpos``, its shape and dtype) in ``robot.npz``."""
    import numpy as np

    with np.load(robot_npz, allow_pickle=False) as data:
        qpos = np.ascontiguousarray(data["qpos"])
    return hashlib.sha256(f"{qpos.dtype}{qpos.shape}".encode("ascii") + qpos.tobytes()).hexdigest()


@contextlib.contextmanager
def time_budget(seconds: float | None):
    """Raise :class:`CellTimeout` in this thread after ``seconds`` (only in the main thread of a POSIX
    process, where SIGALRM can be caught; elsewhere the driver's deadline stops the cell)."""
    usable = (seconds is not None and hasattr(signal, "setitimer")
              and threading.current_thread() is threading.main_thread())
    if not usable:
        yield
        return

    def expire(_signum, _frame):
        raise CellTimeout(f"over its time budget of {seconds:g} s")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, float(seconds))
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


class CellRunner:
    """Runs cells (plain dicts from :meth:`motok_robot.sweep.driver.task_of`); keeps the pipelines."""

    def __init__(self, env: dict[str, str] | None = None) -> None:
        os.environ.update(env or {})
        import torch

        torch.set_num_threads(1)
        self.worker = f"{socket.gethostname()}:{os.getpid()}"
        self._scratch = Path(tempfile.mkdtemp(prefix="motok-sweep-"))
        self._pipelines: dict[tuple, tuple] = {}
        self._motions: dict[str, Path] = {}

    def name(self) -> str:
        """``host:pid`` of this worker."""
        return self.worker

    def _pipeline(self, argv: tuple, plots: bool):
        from motok_robot.pipeline import Pipeline
        from motok_robot.sweep.run_options import parse, pipeline_config

        key = (tuple(argv), plots)
        if key not in self._pipelines:
            args = parse(argv)
            self._pipelines[key] = (Pipeline(pipeline_config(args, plots)), args)
        return self._pipelines[key]

    def _motion(self, task: dict, blobs: tuple[bytes, ...]) -> Path | None:
        """The cell's motion file on this worker (written once per content from the bytes sent)."""
        if task["motion_names"] is None:
            return None
        digest = task["motion_sha"]
        if digest not in self._motions:
            folder = self._scratch / "motions" / digest[:16]
            folder.mkdir(parents=True, exist_ok=True)
            for name, blob in zip(task["motion_names"], blobs):
                (folder / name).write_bytes(blob)
            self._motions[digest] = folder / task["motion_names"][0]
        return self._motions[digest]

    def run_cell(self, task: dict, *motion_blobs: bytes) -> dict:
        """Run one cell; returns ``{"row": {...}, "files": {relative path: bytes}}``.  Never raises for a
        failing cell: its error (or its time-out) is in the row."""
        start = time.perf_counter()
        row: dict = {"worker": self.worker}
        out = self._scratch / "cells" / task["cell_id"]
        folder = out
        try:
            with time_budget(task["budget_s"]):
                from motok_robot.sweep.run_options import run_arguments

                pipe, args = self._pipeline(task["argv"], task["plots"])
                result = pipe.run(task["prompt"], robot=task["robot"], seed=task["seed"], out_dir=out, overwrite=True,
                                  progress=False, motion=self._motion(task, motion_blobs), **run_arguments(args))
            row.update(result_fields(result, out))
        except CellTimeout as exc:
            row.update(status="timeout", error=f"cancelled: {exc}")
            folder = out.with_name(out.name + ".failed")
        except Exception as exc:  # noqa: BLE001 - a failing cell is a result: record it and go on
            row.update(status="error", error=one_line(exc))
            folder = out.with_name(out.name + ".failed")
        files = read_folder(folder)
        for left in (out, out.with_name(out.name + ".failed")):
            shutil.rmtree(left, ignore_errors=True)
        row["cell_s"] = time.perf_counter() - start
        return {"row": row, "files": files}

    def close(self) -> None:
        shutil.rmtree(self._scratch, ignore_errors=True)


def one_line(exc: BaseException) -> str:
    """The error of a cell as one line (the pipeline's note on its partial files left out: the
    driver keeps them in the cell's folder)."""
    from motok_robot.errors import MotokError

    text = re.sub(r"\s*\(partial files in [^)]*\)", "", " ".join(str(exc).split()))
    if not isinstance(exc, MotokError):
        text = f"{type(exc).__name__}: {text}" if text else type(exc).__name__
    return text


def read_folder(folder: Path) -> dict[str, bytes]:
    """``{relative path: bytes}`` of every file under ``folder`` (empty when it does not exist)."""
    if not folder.is_dir():
        return {}
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def result_fields(result, out: Path) -> dict:
    """The row fields of a finished :class:`~motok_robot.pipeline.PipelineResult` (written to ``out``)."""
    report = json.loads((out / "report.json").read_text(encoding="utf-8"))
    row = {"status": "passed" if result.passed else "failed", "passed": bool(result.passed),
           "failed_checks": ";".join(result.failed_checks), "n_failed_checks": len(result.failed_checks),
           "error": "", "report_sha": report_sha(report), "qpos_sha": qpos_sha(out / "robot.npz"),
           "clip_s": float(result.seconds), "retime_factor": float(result.retime_factor),
           "zmp_weight": float(result.zmp_weight), "playback": result.playback.status, "model": result.model}
    for name, value in report.get("metrics", {}).items():
        if name != "passed" and (value is None or isinstance(value, (bool, int, float))):
            row[f"metric_{name}"] = value
    for name, check in report.get("checks", {}).items():
        if name.startswith("fidelity_"):
            row[name] = check.get("value")
    feasibility = out / "feasibility.json"
    if feasibility.is_file():
        record = json.loads(feasibility.read_text(encoding="utf-8"))
        row["feasibility_time_warp"] = record.get("time_warp")
        row["feasibility_fell"] = (record.get("executed") or {}).get("fell")
        row["feasibility_com_shift_max_m"] = (record.get("zmp_shift") or {}).get("com_shift_m_max")
    for stage, seconds in result.timings.items():
        row[f"time_{stage}_s"] = float(seconds)
    return row

"""Helpers shared by the benchmark scripts in ``benchmarks/``.

* :func:`machine_description`: what the numbers were measured on (CPU model, cores, RAM, load,
  library versions read from package metadata so nothing heavy is imported, git commit);
* :func:`time_median`: median (and min / max / CPU time) of N timed runs after warm-up;
* :class:`PeakMemory` / :func:`measure_peak_memory`: peak resident memory while a block runs
  (RSS sampled by a thread, which also sees torch's CPU allocations), optionally the Python heap
  peak (``tracemalloc``) and the CUDA peak (``torch.cuda.max_memory_allocated``);
* :func:`write_json` (adds the machine description) and :func:`markdown_table`;
* :func:`random_model_runs`: default-size tokenizer + planner runs with random weights, for
  timing generation when no trained models exist (latency depends on sizes, not weights).

Used as ``from common import ...`` by a script run as ``python benchmarks/NAME.py`` (Python
puts the script's folder first on ``sys.path``), or ``from benchmarks.common import ...``.
"""

from __future__ import annotations

import json
import math
import os
import platform
import statistics
import subprocess
import threading
import time
import tracemalloc
from collections.abc import Callable, Sequence
from importlib import metadata
from pathlib import Path
from typing import Any

REPO_ROOT = Path(__file__).resolve().parents[1]
RESULTS_DIR = REPO_ROOT / "benchmarks" / "results"
VERSIONED = ("numpy", "scipy", "torch", "mujoco", "casadi", "dynamixel-sdk", "sentence-transformers")


# -- machine ----------------------------------------------------------------------------------------
def cpu_model() -> str:
    """CPU model name (``/proc/cpuinfo`` on Linux, ``platform.processor()`` elsewhere)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def total_ram_gb() -> float | None:
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30
    except (ValueError, OSError, AttributeError):
        return None


def package_version(name: str) -> str | None:
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return None


def git_commit() -> dict[str, Any]:
    """``{"commit": sha or None, "dirty": bool or None}`` of the repository."""
    try:
        sha = subprocess.run(["git", "rev-parse", "HEAD"], cwd=REPO_ROOT, capture_output=True, text=True,
                             timeout=10, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=REPO_ROOT,
                               capture_output=True, text=True, timeout=10, check=True).stdout.strip() != ""
        return {"commit": sha, "dirty": dirty}
    except (OSError, subprocess.SubprocessError):
        return {"commit": None, "dirty": None}


def machine_description(threads: int | None = None) -> dict[str, Any]:
    """What a benchmark ran on. ``threads``: the torch/BLAS threads the benchmark used."""
    usable = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    info: dict[str, Any] = {
        "cpu": cpu_model(),
        "logical_cores": os.cpu_count(),
        "usable_cores": usable,
        "ram_gb": None if total_ram_gb() is None else round(total_ram_gb(), 1),
        "load_average_1_5_15": [round(x, 2) for x in os.getloadavg()] if hasattr(os, "getloadavg") else None,
        "os": platform.platform(),
        "python": platform.python_version(),
        "versions": {name: package_version(name) for name in VERSIONED},
        "threads": threads,
        "omp_num_threads": os.environ.get("OMP_NUM_THREADS"),
        "date_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        **git_commit(),
    }
    import sys

    if "torch" in sys.modules:  # only describe the GPU when the benchmark already uses torch
        torch = sys.modules["torch"]
        info["torch_threads"] = torch.get_num_threads()
        if torch.cuda.is_available():
            info["gpu"] = torch.cuda.get_device_name(0)
    return info


def machine_summary(machine: dict[str, Any]) -> str:
    """One line: ``CPU, N usable cores (of M), R GB RAM, load a/b/c, torch x, mujoco y, commit``."""
    v = machine.get("versions", {})
    load = machine.get("load_average_1_5_15")
    parts = [str(machine.get("cpu"))]
    if machine.get("usable_cores") is not None:
        parts.append(f"{machine['usable_cores']} usable cores (of {machine.get('logical_cores')})")
    if machine.get("ram_gb") is not None:
        parts.append(f"{machine['ram_gb']} GB RAM")
    if machine.get("gpu"):
        parts.append(str(machine["gpu"]))
    if load:
        parts.append("load " + "/".join(f"{x:g}" for x in load))
    parts += [f"{k} {v[k]}" for k in ("torch", "mujoco", "casadi") if v.get(k)]
    if machine.get("python"):
        parts.append(f"python {machine['python']}")
    if machine.get("commit"):
        parts.append(f"commit {machine['commit'][:10]}{' (dirty)' if machine.get('dirty') else ''}")
    return ", ".join(parts)


# -- timing -----------------------------------------------------------------------------------------
def time_median(fn: Callable[[], Any], repeat: int = 5, warmup: int = 1, sync: Callable[[], Any] | None = None) -> dict[str, Any]:
    """Time ``fn()`` ``repeat`` times after ``warmup`` untimed calls.

    Returns ``median_s``, ``min_s``, ``max_s``, ``cpu_median_s`` (process CPU time: on a shared,
    loaded machine it shows what the work costs apart from waiting for a core), ``runs_s`` and
    ``repeat``. ``sync`` (e.g. ``torch.cuda.synchronize``) is called before every clock read.
    """
    if repeat < 1:
        raise ValueError("repeat must be >= 1")
    for _ in range(warmup):
        fn()
    wall, cpu = [], []
    for _ in range(repeat):
        if sync:
            sync()
        w0, c0 = time.perf_counter(), time.process_time()
        fn()
        if sync:
            sync()
        wall.append(time.perf_counter() - w0)
        cpu.append(time.process_time() - c0)
    return {"median_s": statistics.median(wall), "min_s": min(wall), "max_s": max(wall),
            "cpu_median_s": statistics.median(cpu), "runs_s": wall, "repeat": repeat}


# -- memory -----------------------------------------------------------------------------------------
def _rss_bytes() -> tuple[int, int] | None:
    """``(resident set size, its anonymous part)`` in bytes, or None where /proc is missing.

    The anonymous part (heap, numpy and torch buffers) is what a block of code allocates; the
    rest is mapped files (shared libraries), which the kernel drops and reloads under memory
    pressure, so the total can fall while a block allocates (CI saw 24 MB of a 40 MB array).
    """
    try:
        total = int(Path("/proc/self/statm").read_text().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return None
    anon = None
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("RssAnon:"):
                anon = int(line.split()[1]) * 1024  # kB
                break
    except (OSError, ValueError, IndexError):
        pass
    return total, (total if anon is None else anon)


def max_rss_mb() -> float:
    """Peak resident set size of this process so far (``resource.getrusage``), MB."""
    import resource
    import sys

    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / 2**20 if sys.platform == "darwin" else peak / 2**10  # bytes on macOS, KiB on Linux


class PeakMemory:
    """Context manager measuring peak memory while its block runs.

    Attributes after exit (MB): ``rss_peak_mb`` (highest resident set size sampled every
    ``interval`` s, including torch's CPU allocations), ``rss_increase_mb`` (highest anonymous
    resident memory minus that at entry: what the block itself allocated; mapped files are left
    out because the kernel may drop them meanwhile), ``python_peak_mb`` (``tracemalloc`` peak of
    Python allocations, when ``python_heap=True``; it slows Python-heavy code), ``cuda_peak_mb``
    (``torch.cuda.max_memory_allocated``, when torch is loaded with CUDA).
    """

    def __init__(self, interval: float = 0.002, python_heap: bool = False):
        self.interval = interval
        self.python_heap = python_heap
        self.rss_peak_mb: float | None = None
        self.rss_increase_mb: float | None = None
        self.python_peak_mb: float | None = None
        self.cuda_peak_mb: float | None = None

    def _sample(self) -> None:
        while not self._stop.is_set():
            self._update()
            self._stop.wait(self.interval)

    def _update(self) -> None:
        now = _rss_bytes()
        if now is not None:
            self._peak = max(self._peak, now[0])
            self._anon_peak = max(self._anon_peak, now[1])

    def __enter__(self) -> "PeakMemory":
        import sys

        self._torch = sys.modules.get("torch")
        if self._torch is not None and self._torch.cuda.is_available():
            self._torch.cuda.reset_peak_memory_stats()
        if self.python_heap:
            tracemalloc.start()
        start = _rss_bytes()
        self._start = start is not None
        self._peak, self._anon_start = start if start is not None else (0, 0)
        self._anon_peak = self._anon_start
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._sample, daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()
        self._update()
        if self._start:
            self.rss_peak_mb = self._peak / 2**20
            self.rss_increase_mb = (self._anon_peak - self._anon_start) / 2**20
        if self.python_heap:
            self.python_peak_mb = tracemalloc.get_traced_memory()[1] / 2**20
            tracemalloc.stop()
        if self._torch is not None and self._torch.cuda.is_available():
            self.cuda_peak_mb = self._torch.cuda.max_memory_allocated() / 2**20

    def to_dict(self) -> dict[str, float | None]:
        return {"rss_peak_mb": self.rss_peak_mb, "rss_increase_mb": self.rss_increase_mb,
                "python_peak_mb": self.python_peak_mb, "cuda_peak_mb": self.cuda_peak_mb}


def measure_peak_memory(fn: Callable[[], Any], python_heap: bool = False) -> tuple[Any, dict[str, float | None]]:
    """``(fn(), PeakMemory(...).to_dict())``."""
    with PeakMemory(python_heap=python_heap) as mem:
        out = fn()
    return out, mem.to_dict()


# -- models -----------------------------------------------------------------------------------------
def random_model_runs(kind: str, root: Path) -> tuple[Path, Path]:
    """Write default-size tokenizer and ``kind`` planner runs with random weights (seed 0) into
    ``root/tokenizer`` and ``root/planner``; returns those two run directories. Imports torch."""
    import torch

    from motok_robot.planner.checkpoint import build_planner, save_planner_weights, tokenizer_record, write_run_config
    from motok_robot.planner.config import PlannerConfig
    from motok_robot.tokenizer import MoTok, TokenizerConfig, save_tokenizer

    torch.manual_seed(0)
    tok = MoTok(TokenizerConfig())
    save_tokenizer(tok, root / "tokenizer")
    cfg = PlannerConfig(kind=kind, codebook_size=tok.config.codebook_size, downsample=tok.frames_per_token)
    planner = build_planner(cfg)
    write_run_config(root / "planner", cfg, {"tokenizer": tokenizer_record(root / "tokenizer", tok)})
    save_planner_weights(planner, root / "planner")
    return root / "tokenizer", root / "planner"


# -- output -----------------------------------------------------------------------------------------
def write_json(path: str | Path, payload: dict[str, Any], threads: int | None = None) -> Path:
    """Write ``payload`` as indented JSON, adding ``machine`` (and ``date_utc``) when absent."""
    path = Path(path)
    payload = dict(payload)
    payload.setdefault("machine", machine_description(threads))
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(payload, indent=2, default=_json_default) + "\n")
    tmp.replace(path)
    return path


def _json_default(value: Any) -> Any:
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"cannot write {type(value).__name__} as JSON")


def format_cell(value: Any, digits: int = 3) -> str:
    """A table cell: floats rounded by magnitude (1,234 / 12.35 / 0.1235 / 1.23e-05), None -> '-'."""
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        if not math.isfinite(value):
            return str(value)
        a = abs(value)
        if a >= 1000:
            return f"{value:,.0f}"
        if a >= 1:
            return f"{value:.2f}"
        if a == 0:
            return "0"
        return f"{value:.{digits + 1}f}" if a >= 10 ** -digits else f"{value:.{digits}g}"
    if isinstance(value, (list, tuple)):
        return ", ".join(format_cell(v, digits) for v in value)
    return str(value).replace("|", "\\|")


def markdown_table(rows: Sequence[dict[str, Any]], columns: Sequence[str] | None = None,
                   headers: dict[str, str] | None = None, digits: int = 3) -> str:
    """Rows (dicts) -> a markdown table; ``columns`` default to the keys in first-seen order
    (nested dicts and long lists are left out)."""
    if not rows:
        return "(no rows)"
    if columns is None:
        columns = []
        for row in rows:
            for key, value in row.items():
                if key not in columns and not isinstance(value, dict) and not (isinstance(value, list) and len(value) > 4):
                    columns.append(key)
    headers = headers or {}
    head = [headers.get(c, c) for c in columns]
    numeric = [all(isinstance(r.get(c), (int, float)) and not isinstance(r.get(c), bool) for r in rows if r.get(c) is not None)
               for c in columns]
    lines = ["| " + " | ".join(head) + " |",
             "|" + "|".join("---:" if n else "---" for n in numeric) + "|"]
    for row in rows:
        lines.append("| " + " | ".join(format_cell(row.get(c), digits) for c in columns) + " |")
    return "\n".join(lines)


def print_table(rows: Sequence[dict[str, Any]], columns: Sequence[str] | None = None, title: str | None = None, **kw) -> None:
    if title:
        print(title)
    print(markdown_table(rows, columns, **kw))

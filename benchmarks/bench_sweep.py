"""Benchmark of ``motok-robot sweep``: throughput on Ray vs in process, per-cell overhead, faults.

    python benchmarks/bench_sweep.py                    # 200 cells; writes benchmarks/results/bench_sweep.json
    python benchmarks/bench_sweep.py --cells 20 --out /tmp/bench_sweep.json     # a quick look
    python benchmarks/bench_sweep.py --cell prompt --out benchmarks/results/bench_sweep_prompts.json

Two kinds of cell (``--cell``):

* ``stand`` (default): tiny cells, a 1 s standing clip (a motion file, no trained model) on
  humanoid25 (no servos, so no playback), two setting variants, seeds 0..N/2-1 (a motion file
  ignores the seed: every cell does the same work); the engine's own costs at their largest share;
* ``prompt``: real cells, what a campaign runs: the four gesture prompts of
  ``examples/prompts_eight.txt`` (wave, raise both hands, bow, punch), 3 s, seeds 0..N/4-1, on
  the default robot (``op3``) with every default: generate with the shipped models, retarget,
  the pipeline's repairs, validate (no render, no plots, no playback).

Measured:

1. throughput: the same sweep with ``--workers 1`` (in process) and ``--workers 2`` (local Ray),
   cells per second over the whole call (Ray start included) and from the first to the last
   result (steady state);
2. per-cell overhead on Ray: hand-over to result back in the driver minus the cell's own time
   (the first cell of each worker, which waits for the worker to start, left out), plus the
   driver's writing, as a share of the mean cell time; and the share of worker time not spent in
   cells (``1 - sum(cell time) / (wall x workers)``: start, tail and scheduling together);
3. kill one worker mid-sweep: every cell ends with a row, the lost cell is retried once;
4. kill the driver (SIGKILL) mid-sweep, then ``--resume``: the rest is run, no finished cell
   again.

The machine load (``uptime``) is recorded before and after: other work on the 2 cores slows
the 2-worker run more than the in-process one.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
import threading
import time
from datetime import datetime
from pathlib import Path

BENCH = Path(__file__).resolve().parent
REPO = BENCH.parent


def worker_pids(busy: bool = False) -> list[int]:
    """Process ids of this machine's sweep workers (Ray actors holding a CellRunner); ``busy``: only
    those running a cell.  Reads ``/proc`` (Linux)."""
    pids = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            title = (entry / "cmdline").read_bytes().split(b"\0")[0].decode(errors="replace")
        except OSError:
            continue
        if title.startswith("ray::CellRunner") and (not busy or title.startswith("ray::CellRunner.run_cell")):
            pids.append(int(entry.name))
    return sorted(pids)


def ray_processes() -> dict[int, str]:
    """``{pid: command}`` of Ray's own processes (raylet, gcs_server, agents, workers) on this machine."""
    found = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            cmd = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace").strip()
        except OSError:
            continue
        if cmd.startswith("ray::") or "/site-packages/ray/" in cmd:
            found[int(entry.name)] = cmd[:120]
    return found


def uptime() -> str:
    try:
        return subprocess.run(["uptime"], capture_output=True, text=True, timeout=5).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "load average: " + ", ".join(f"{x:.2f}" for x in os.getloadavg())


GESTURES = ["a person waves the right hand", "a person raises both hands", "a person bows",
            "a person punches forward with the right hand"]
CELLS = {"stand": "1 s standing clip (motion file) on humanoid25, no render, no plots, no playback (no servos)",
         "prompt": "the 4 gesture prompts of examples/prompts_eight.txt, 3 s, seeds 0..N/4-1, on op3 with every "
                   "default (generate, retarget, repairs, validate), no render, no plots, no playback"}


def write_inputs(root: Path, cells: int, kind: str = "stand") -> Path:
    """The spec of ``cells`` cells of kind ``kind`` (see the module docstring) under ``root``."""
    import numpy as np

    if kind == "prompt":
        spec = root / "bench.toml"
        prompts = ", ".join(f'"{p}"' for p in GESTURES)
        spec.write_text(f"""prompts = [{prompts}]
seeds = {{ start = 0, count = {max(1, cells // len(GESTURES))} }}
robots = ["op3"]
[run]
seconds = 3
""", encoding="utf-8")
        return spec

    from motok_robot.motion.features import features_from_joints, joints_from_features
    from motok_robot.motion.synthetic import standing_clip

    features = features_from_joints(standing_clip(frames=21))
    np.savez(root / "stand.npz", joints=joints_from_features(features).astype(np.float32), features=features,
             fps=20, text="stand")
    spec = root / "bench.toml"
    spec.write_text(f"""motions = ["stand.npz"]
seeds = {{ start = 0, count = {max(1, cells // 2)} }}
robots = ["humanoid25"]
[variants.plain]
[variants.slow_limit]
max-retime = 1.5
""", encoding="utf-8")
    return spec


def rows_of(out: Path) -> list[dict]:
    from motok_robot.sweep.results import read_table

    return read_table(out)


def throughput(spec: Path, root: Path, workers: int) -> dict:
    from motok_robot.sweep.driver import run_sweep

    out = root / f"workers{workers}"
    load_before = os.getloadavg()
    outcome = run_sweep(spec, out, workers=workers, progress=True)
    rows = rows_of(out)
    finished = sorted(r["finished_at"] for r in rows)
    cell_s = [float(r["cell_s"]) for r in rows]
    first_per_worker = {}
    for r in sorted(rows, key=lambda r: r["finished_at"]):
        first_per_worker.setdefault(r["worker"], r["cell_id"])
    steady = [r for r in rows if r["cell_id"] not in set(first_per_worker.values())]
    handover = [float(r["roundtrip_s"]) - float(r["cell_s"]) for r in steady]
    write_per_cell = outcome.write_s / max(1, outcome.ran)
    mean_cell = statistics.fmean(cell_s)
    result = {
        "workers": outcome.workers, "cells": outcome.ran, "statuses": outcome.counts,
        "wall_s": round(outcome.wall_s, 2), "engine_start_s": round(outcome.startup_s, 2),
        "cells_per_s": round(outcome.ran / outcome.wall_s, 3),
        "first_result_utc": finished[0], "last_result_utc": finished[-1],
        "cell_s_mean": round(mean_cell, 4), "cell_s_median": round(statistics.median(cell_s), 4),
        "cell_s_sum": round(sum(cell_s), 2),
        "handover_s_mean": round(statistics.fmean(handover), 4) if handover else None,
        "handover_s_median": round(statistics.median(handover), 4) if handover else None,
        "write_s_per_cell": round(write_per_cell, 4),
        "overhead_share_per_cell": round(((statistics.fmean(handover) if handover else 0.0) + write_per_cell)
                                         / mean_cell, 4),
        "idle_share_of_worker_time": round(1 - sum(cell_s) / (outcome.wall_s * outcome.workers), 4),
        "distinct_workers": len({r["worker"] for r in rows}),
        "load_average_before": [round(x, 2) for x in load_before],
        "load_average_after": [round(x, 2) for x in os.getloadavg()],
    }
    # steady state: from the first result to the last (Ray start and the workers' model loading left out)
    stamps = [datetime.fromisoformat(f).timestamp() for f in finished]
    if len(stamps) > 1 and stamps[-1] > stamps[0]:
        result["steady_cells_per_s"] = round((len(stamps) - 1) / (stamps[-1] - stamps[0]), 3)
    return result


def start_worker_killer(journal: Path, after_rows: int, timeout_s: float = 600) -> tuple[threading.Thread, list[int]]:
    """A thread that SIGKILLs one sweep worker running a cell once ``journal`` holds ``after_rows``
    rows; returns it and the list its pid goes into."""
    killed: list[int] = []

    def killer():
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline and not killed:
            if journal.is_file() and journal.read_text().count("\n") >= after_rows:
                busy = worker_pids(busy=True)
                if busy:
                    os.kill(busy[0], signal.SIGKILL)
                    killed.append(busy[0])
            time.sleep(0.02)

    thread = threading.Thread(target=killer, daemon=True)
    thread.start()
    return thread, killed


def kill_one_worker(spec: Path, root: Path, after_rows: int = 5) -> dict:
    from motok_robot.sweep.driver import run_sweep
    from motok_robot.sweep.results import JOURNAL

    out = root / "kill_worker"
    thread, killed = start_worker_killer(out / JOURNAL, after_rows)
    outcome = run_sweep(spec, out, workers=2, progress=False)
    thread.join(timeout=1)
    rows = rows_of(out)
    retried = [r for r in rows if r["attempts"] > 1]
    return {"cells": outcome.total, "rows": len(rows), "killed_pid": killed[0] if killed else None,
            "retried_cells": len(retried), "retried_statuses": [r["status"] for r in retried],
            "statuses": outcome.counts, "every_cell_has_a_row": len(rows) == outcome.total,
            "notes": [r["engine_notes"] for r in retried]}


def kill_the_driver(spec: Path, root: Path, after_rows: int = 10) -> dict:
    from motok_robot.sweep.results import JOURNAL

    out = root / "kill_driver"
    command = [sys.executable, "-m", "motok_robot.cli", "sweep", str(spec), "--out", str(out), "--workers", "2"]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    others = set(ray_processes())  # Ray processes that are not this driver's
    driver = subprocess.Popen(command, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=REPO)
    journal = out / JOURNAL
    deadline = time.monotonic() + 600
    while time.monotonic() < deadline and driver.poll() is None:
        if journal.is_file() and journal.read_text().count("\n") >= after_rows:
            break
        time.sleep(0.05)
    os.kill(driver.pid, signal.SIGKILL)
    driver.wait()
    left: dict[int, str] = {}
    for _ in range(30):  # do the killed driver's Ray processes go away by themselves?
        time.sleep(1)
        left = {pid: cmd for pid, cmd in ray_processes().items() if pid not in others}
        if not left:
            break
    for pid in left:  # they are the killed driver's: stop them by their id
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    before = {json.loads(line)["cell_id"]: json.loads(line) for line in journal.read_text().splitlines() if line.strip()}
    table_readable = True
    try:
        table_rows = len(rows_of(out))
    except Exception:  # noqa: BLE001 - the point is to record whether it could be read
        table_readable, table_rows = False, None
    t = time.monotonic()
    resumed = subprocess.run([*command, "--resume"], env=env, capture_output=True, text=True, cwd=REPO)
    resume_s = time.monotonic() - t
    rows = rows_of(out)
    kept = [r for r in rows if r["cell_id"] in before and r["run_id"] == before[r["cell_id"]]["run_id"]
            and r["finished_at"] == before[r["cell_id"]]["finished_at"]]
    journal_ids = [json.loads(line)["cell_id"] for line in journal.read_text().splitlines() if line.strip()]
    return {"cells": len(rows), "rows_before_kill": len(before), "table_rows_after_kill": table_rows,
            "table_readable_after_kill": table_readable,
            "ray_processes_left_30s_after_kill": sorted(left.values()),
            "resume_exit_status": resumed.returncode, "resume_s": round(resume_s, 1),
            "resume_last_line": resumed.stdout.strip().splitlines()[0] if resumed.stdout.strip() else resumed.stderr[-300:],
            "kept_from_before": len(kept), "run_after_resume": len(rows) - len(kept),
            "no_cell_twice_in_journal": len(journal_ids) == len(set(journal_ids))}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, default=200, help="cells of the throughput sweep (default 200)")
    parser.add_argument("--fault-cells", type=int, default=40, help="cells of each fault check (default 40)")
    parser.add_argument("--cell", choices=sorted(CELLS), default="stand",
                        help="stand: tiny motion-file cells (default); prompt: real prompt cells (module docstring)")
    parser.add_argument("--no-faults", action="store_true", help="throughput only, without the two fault checks")
    parser.add_argument("--out", type=Path, default=BENCH / "results" / "bench_sweep.json")
    parser.add_argument("--work", type=Path, default=None, help="scratch folder (default: a temporary one)")
    args = parser.parse_args(argv)
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    os.environ.setdefault("MOTOK_ROBOT_CACHE", "off")
    os.environ.setdefault("RAY_AUTH_MODE", "disabled")
    sys.path.insert(0, str(BENCH))
    import tempfile

    from common import write_json

    root = args.work or Path(tempfile.mkdtemp(prefix="bench_sweep_"))
    root.mkdir(parents=True, exist_ok=True)
    spec = write_inputs(root, args.cells, args.cell)
    report: dict = {"benchmark": "bench_sweep", "command": " ".join(["python", "benchmarks/bench_sweep.py", *(argv or sys.argv[1:])]),
                    "cell": CELLS[args.cell], "uptime_before": uptime()}
    t = time.monotonic()
    serial = throughput(spec, root, 1)
    ray2 = throughput(spec, root, 2)
    report["throughput"] = {"workers_1": serial, "workers_2": ray2,
                            "speedup_whole_call": round(ray2["cells_per_s"] / serial["cells_per_s"], 3)}
    if "steady_cells_per_s" in serial and "steady_cells_per_s" in ray2:
        report["throughput"]["speedup_steady"] = round(ray2["steady_cells_per_s"] / serial["steady_cells_per_s"], 3)
    report["uptime_after_throughput"] = uptime()
    if not args.no_faults:
        fault_root = root / "faults"
        fault_root.mkdir(exist_ok=True)
        fault_spec = write_inputs(fault_root, args.fault_cells)
        report["kill_one_worker"] = kill_one_worker(fault_spec, fault_root)
        report["kill_driver_then_resume"] = kill_the_driver(fault_spec, fault_root)
    report["uptime_after"] = uptime()
    report["total_s"] = round(time.monotonic() - t, 1)
    report["targets"] = {"speedup_at_least": 1.7, "overhead_share_at_most": 0.05}
    write_json(args.out, report)
    print(json.dumps({k: report[k] for k in ("throughput", "kill_one_worker", "kill_driver_then_resume") if k in report},
                     indent=2))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

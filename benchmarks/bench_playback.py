"""Playback loop benchmark: a 10 s clip streamed to 20 emulated servos at 125 Hz in real time.

Measures loop rate, jitter (|interval between tick starts - period|) p50/p99/max, per-tick work
(sync write + fast sync read through dynamixel_sdk + emulated servos + log row) and overruns,
then checks that every Goal Position the emulated servos decoded equals the expected ticks
(interpolated trajectory converted independently of the streamer).  Prints a table and writes
JSON with a description of the machine.

    python benchmarks/bench_playback.py [--seconds 10] [--rate 125] [--repeats 3] [--fifo]
        [--out benchmarks/results/bench_playback.json]

``--fifo`` runs the loop with SCHED_FIFO priority 50 when the OS allows it (Linux, root or
CAP_SYS_NICE), as ``motok-robot play`` does by default (``PlaybackConfig.realtime_priority``);
without it the loop runs at normal priority.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine_description, machine_summary, print_table, write_json  # noqa: E402

from motok_robot.errors import HardwareError
from motok_robot.servo.config import PlaybackConfig
from motok_robot.servo.convert import ServoMap
from motok_robot.servo.playback_log import read_log
from motok_robot.servo.streamer import Streamer
from motok_robot.servo.testing import emulated_bus, sine_trajectory, synthetic_specs
from motok_robot.servo.timing import RealClock, realtime_priority


def servo_map() -> tuple[ServoMap, str]:
    try:
        from motok_robot.robots import load

        robot = load("op3_like")
        return ServoMap.from_specs(robot.servos), "op3_like"
    except Exception:  # robots not importable: the same number of synthetic servos
        return ServoMap.from_specs(synthetic_specs(20)), "synthetic-20"


def expected_goals(smap: ServoMap, traj, rate: float) -> np.ndarray:
    """Independent expectation of the trajectory-phase goals: int [ticks, n]."""
    n_play = int(np.floor(traj.duration_s * rate + 1e-9)) + 1
    t = np.arange(n_play) / rate
    frame_t = np.arange(len(traj.q)) / traj.fps
    q = np.stack([np.interp(t, frame_t, traj.q[:, k]) for k in range(smap.n)], axis=1)
    return np.rint(smap.zero_offset + smap.sign * q * 4096 / (2 * np.pi)).astype(np.int64)


def run_once(smap: ServoMap, seconds: float, rate: float, ramp: float, spin_s: float, log_dir: Path,
             fifo: bool) -> dict:
    traj = sine_trajectory(smap, seconds=seconds)
    bus, chain = emulated_bus(smap)
    log_path = log_dir / "bench_playback.csv"
    config = PlaybackConfig(rate_hz=rate, ramp_s=ramp, spin_s=spin_s, realtime_priority=50 if fifo else 0)
    streamer = Streamer(bus, smap, config, clock=RealClock(spin_s), log_path=log_path)
    wall = time.perf_counter()
    try:
        result = streamer.play(traj)
        stopped = None
    except HardwareError as exc:  # e.g. the host stalled past the bus watchdog: reported, not hidden
        stopped = str(exc)
        result = None
    wall = time.perf_counter() - wall
    bus.close()
    if result is None:
        stats = json.loads(log_path.with_name(log_path.stem + ".stats.json").read_text())
        return {"stopped": stopped, "wall_s": wall, "stats": stats, "log_rows": int(len(read_log(log_path)["tick"]))}
    expected = expected_goals(smap, traj, rate)
    mismatches = 0
    for k, servo_id in enumerate(smap.ids):
        decoded = np.asarray(chain.servos[int(servo_id)].goal_history[-len(expected):])
        if decoded.shape != expected[:, k].shape:
            mismatches += len(expected)
            continue
        mismatches += int(np.sum(decoded != expected[:, k]))
    rejected = sum(servo.rejected_goals for servo in chain.servos.values())
    rows = read_log(log_path)
    s = result.stats
    return {
        "stopped": None,
        "rejected_goals": rejected,
        "ticks": result.ticks,
        "wall_s": wall,
        "loop_rate_hz": s.rate_hz,
        "jitter_p50_ms": s.jitter_p50_ms,
        "jitter_p99_ms": s.jitter_p99_ms,
        "jitter_max_ms": s.jitter_max_ms,
        "lateness_p99_ms": s.lateness_p99_ms,
        "work_p50_ms": s.work_p50_ms,
        "work_p99_ms": s.work_p99_ms,
        "overruns": s.overruns,
        "failed_ticks": result.failed_ticks,
        "goals_checked": int(expected.size),
        "goal_mismatches": mismatches,
        "log_rows": int(len(rows["tick"])),
        "stats_line": result.line(),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--rate", type=float, default=125.0)
    parser.add_argument("--ramp", type=float, default=1.0)
    parser.add_argument("--spin-ms", type=float, default=0.5, help="final part of each wait spent spinning")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--fifo", action="store_true", help="SCHED_FIFO priority 50 if permitted")
    parser.add_argument("--out", default="benchmarks/results/bench_playback.json")
    args = parser.parse_args(argv)

    smap, robot = servo_map()
    runs = []
    fifo = "normal"
    if args.fifo:  # probe whether the OS grants it (the streamer asks for it around its loop)
        with realtime_priority(50) as fifo:
            pass
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(args.repeats):
            runs.append(run_once(smap, args.seconds, args.rate, args.ramp, args.spin_ms / 1e3, Path(tmp), args.fifo))

    keys = ["loop_rate_hz", "jitter_p50_ms", "jitter_p99_ms", "jitter_max_ms", "work_p50_ms", "work_p99_ms",
            "overruns", "goal_mismatches"]
    print(f"playback benchmark: {args.seconds:g} s clip (+{args.ramp:g} s ramp), {smap.n} emulated servos "
          f"({robot}), {args.rate:g} Hz, spin {args.spin_ms:g} ms, scheduler {fifo}")
    for i, r in enumerate(runs):
        if r["stopped"]:
            print(f"run {i} STOPPED: {r['stopped']}")
    print_table([{"run": i, **r} for i, r in enumerate(runs) if not r["stopped"]], ["run", *keys])
    done = [r for r in runs if not r["stopped"]]
    if done:
        print(f"goals checked per run: {done[0]['goals_checked']} (trajectory phase, all servos)")
    summary = {
        "benchmark": "playback",
        "clip_s": args.seconds,
        "ramp_s": args.ramp,
        "rate_hz": args.rate,
        "servos": smap.n,
        "servo_map": robot,
        "spin_ms": args.spin_ms,
        "scheduler": fifo,
        "runs": runs,
        "machine": machine_description(),
        "acceptance": {
            "runs_completed": len(done),
            "all_goals_exact": bool(done) and all(r["goal_mismatches"] == 0 and r["rejected_goals"] == 0 for r in done),
            "jitter_p99_ms_le_2": bool(done) and len(done) == len(runs) and all(r["jitter_p99_ms"] <= 2.0 for r in done),
        },
    }
    print(machine_summary(summary["machine"]))
    out = write_json(args.out, summary)
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

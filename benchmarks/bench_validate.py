"""Real-time factors of `motok-robot validate` on a 10 s clip (issue 7 targets).

Targets: kinematic + physics (no render) >= 50x real time on 2 cores; a 10 s render at 30 fps
<= 20 s.  Columns: kinematic replay and physics rollout alone (and the real-time factor of
their sum, by wall and by CPU time), then ``validate`` without plots or render as the CLI runs
it (replay and rollout overlapped on two threads; the real-time factor that counts), then
the render.  The clip is the procedural walk of ``motok_robot.sim.synthetic`` (feet planted,
both feet stepping), resampled to exactly 10 s at 20 fps.  Each stage is timed ``--repeat``
times and the median is reported, as wall time and as this process's CPU time (the stages
are single-threaded, so on a shared, overloaded machine the CPU time is what an idle core
would take); the load average is recorded with the numbers.

    python benchmarks/bench_validate.py [--robot op3_like|humanoid25|all] [--repeat 3]
                                        [--no-render] [--json benchmarks/results/bench_validate.json]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from motok_robot.robots import list_robots, load  # noqa: E402
from motok_robot.sim import synthetic  # noqa: E402
from motok_robot.sim.config import ValidationConfig  # noqa: E402
from motok_robot.sim.kinematic import replay  # noqa: E402
from motok_robot.sim.model_index import index_robot  # noqa: E402
from motok_robot.sim.rollout import simulate  # noqa: E402
from motok_robot.sim.trajectory import RobotTrajectory  # noqa: E402
from motok_robot.sim.validate import validate_trajectory  # noqa: E402

CLIP_S = 10.0
FPS = 20.0


def machine() -> dict:
    cpu = ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"cpu": cpu, "cores": os.cpu_count(), "load_average_1m": os.getloadavg()[0],
            "python": platform.python_version(), "mujoco": mujoco.__version__, "platform": platform.platform(),
            "mujoco_gl": os.environ.get("MUJOCO_GL"), "omp_num_threads": os.environ.get("OMP_NUM_THREADS")}


def ten_second_walk(index) -> np.ndarray:
    qpos = synthetic.walk(index, steps=2, step_period_s=CLIP_S / 3, fps=FPS)
    frames = int(CLIP_S * FPS) + 1
    return qpos[:frames] if len(qpos) >= frames else np.vstack([qpos, np.tile(qpos[-1], (frames - len(qpos), 1))])


def timed(fn, repeat: int) -> tuple[float, float, object]:
    """Median wall time, median CPU time of this process (s), and the last result."""
    walls, cpus, out = [], [], None
    for _ in range(repeat):
        start, cpu = time.perf_counter(), time.process_time()
        out = fn()
        walls.append(time.perf_counter() - start)
        cpus.append(time.process_time() - cpu)
    return statistics.median(walls), statistics.median(cpus), out


def bench_robot(name: str, repeat: int, render: bool) -> dict:
    config = ValidationConfig()
    start = time.perf_counter()
    index = index_robot(load(name))
    setup = time.perf_counter() - start
    qpos = ten_second_walk(index)
    kin_s, kin_cpu, _ = timed(lambda: replay(index, qpos, FPS, config), repeat)
    phys_s, phys_cpu, roll = timed(lambda: simulate(index, qpos, FPS, config), repeat)
    row = {"robot": name, "clip_s": CLIP_S, "frames": len(qpos), "nq": index.model.nq,
           "physics_timestep_s": roll.timestep, "physics_steps": int(roll.step_qpos.shape[0] - 1),
           "setup_s": setup, "kinematic_s": kin_s, "physics_s": phys_s,
           "kinematic_rtf": CLIP_S / kin_s, "physics_rtf": CLIP_S / phys_s,
           "kinematic_plus_physics_rtf": CLIP_S / (kin_s + phys_s), "kinematic_cpu_s": kin_cpu,
           "physics_cpu_s": phys_cpu, "kinematic_plus_physics_cpu_rtf": CLIP_S / (kin_cpu + phys_cpu),
           "fell": roll.fell}
    trajectory = RobotTrajectory(qpos, FPS, index.joint_names, name, source=f"walk10s_{name}.npz")
    # what `motok-robot validate --no-render --no-plots` does: replay and rollout overlapped in 2 threads
    both_s, both_cpu, _ = timed(lambda: validate_trajectory(trajectory, index, config, plots=False), repeat)
    row.update(validate_no_render_s=both_s, validate_no_render_cpu_s=both_cpu, validate_no_render_rtf=CLIP_S / both_s)
    with tempfile.TemporaryDirectory() as tmp:
        plots_s, _, _ = timed(lambda: validate_trajectory(trajectory, index, config, out_dir=tmp, plots=True), 1)
        row["validate_with_plots_s"] = plots_s
        if render:
            from motok_robot.sim.render import render_video

            result = validate_trajectory(trajectory, index, config, physics=True, plots=False)
            render_s, render_cpu, _ = timed(lambda: render_video(result, trajectory, Path(tmp) / "v.mp4", config), 1)
            row.update(render_s=render_s, render_cpu_s=render_cpu, render_frames=int(CLIP_S * config.render_fps) + 1,
                       render_size=f"{config.render_width}x{config.render_height}", render_rtf=CLIP_S / render_s)
    return row


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robot", default="all", help="robot name or 'all'")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--no-render", action="store_true")
    parser.add_argument("--json", default=str(Path(__file__).parent / "results" / "bench_validate.json"))
    args = parser.parse_args(argv)
    robots = list_robots() if args.robot == "all" else [args.robot]
    info = machine()
    rows = [bench_robot(name, args.repeat, not args.no_render) for name in robots]
    info["load_average_1m_end"] = os.getloadavg()[0]
    header = (f"{'robot':<12}{'kin s':>8}{'phys s':>8}{'sum RTF':>9}{'CPU RTF':>9}{'validate s':>12}{'RTF':>6}"
              f"{'render s':>10}{'(CPU s)':>9}{'fell':>6}")
    print(f"10 s clip ({int(CLIP_S * FPS) + 1} frames), median of {args.repeat}; cpu {info['cpu']} x{info['cores']}, "
          f"load {info['load_average_1m']:.1f}")
    print(header)
    for r in rows:
        print(f"{r['robot']:<12}{r['kinematic_s']:>8.3f}{r['physics_s']:>8.3f}{r['kinematic_plus_physics_rtf']:>9.1f}"
              f"{r['kinematic_plus_physics_cpu_rtf']:>9.1f}{r['validate_no_render_s']:>12.3f}{r['validate_no_render_rtf']:>6.1f}"
              f"{r.get('render_s', float('nan')):>10.2f}{r.get('render_cpu_s', float('nan')):>9.2f}{str(r['fell']):>6}")
    path = Path(args.json)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"benchmark": "bench_validate", "machine": info, "results": rows}, indent=2) + "\n")
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

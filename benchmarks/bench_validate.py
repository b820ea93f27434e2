"""Real-time factors of `motok-robot validate` on a 10 s clip (issue 7 targets).

Targets: kinematic + physics (no render) >= 50x real time on 2 cores; a 10 s render at 30 fps
<= 20 s.  Columns: kinematic replay and physics rollout alone (and the real-time factor of
their sum, by wall and by CPU time), then ``validate`` without plots or render as the CLI runs
it (the replay, then the rollout tracking the feedforward servo goals computed from the
replay's torques; the real-time factor that counts), then the render.  The clip is the procedural walk of ``motok_robot.sim.synthetic`` (feet planted,
both feet stepping), resampled to exactly 10 s at 20 fps.  Each stage is timed ``--repeat``
times and the median is reported, as wall time and as this process's CPU time (the stages
are single-threaded, so on a shared, overloaded machine the CPU time is what an idle core
would take); the load average is recorded with the numbers.

    python benchmarks/bench_validate.py [--robot op3_like|humanoid25|all] [--repeat 3]
                                        [--no-render] [--json benchmarks/results/bench_validate.json]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine_description, machine_summary, print_table, time_median, write_json  # noqa: E402

from motok_robot.robots import list_robots, load  # noqa: E402
from motok_robot.sim import synthetic  # noqa: E402
from motok_robot.sim.config import ValidationConfig  # noqa: E402
from motok_robot.sim.kinematic import replay  # noqa: E402
from motok_robot.robots.index import index_robot  # noqa: E402
from motok_robot.sim.rollout import simulate  # noqa: E402
from motok_robot.sim.trajectory import RobotTrajectory  # noqa: E402
from motok_robot.sim.validate import validate_trajectory  # noqa: E402

CLIP_S = 10.0
FPS = 20.0


def ten_second_walk(index) -> np.ndarray:
    qpos = synthetic.walk(index, steps=2, step_period_s=CLIP_S / 3, fps=FPS)
    frames = int(CLIP_S * FPS) + 1
    return qpos[:frames] if len(qpos) >= frames else np.vstack([qpos, np.tile(qpos[-1], (frames - len(qpos), 1))])


def timed(fn, repeat: int) -> tuple[float, float, object]:
    """Median wall time, median CPU time of this process (s) of ``repeat`` runs (no warm-up),
    and the last result."""
    box = {}

    def run():
        box["out"] = fn()

    t = time_median(run, repeat=repeat, warmup=0)
    return t["median_s"], t["cpu_median_s"], box["out"]


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
    # what `motok-robot validate --no-render --no-plots` does: replay, feedforward goals, rollout
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
    info = machine_description()
    info["mujoco_gl"] = os.environ.get("MUJOCO_GL")
    rows = []
    for name in robots:
        try:
            rows.append(bench_robot(name, args.repeat, not args.no_render))
        except ValueError as exc:  # the procedural walk is sized for small humanoids (G1, T1 are not)
            if args.robot != "all":
                raise
            print(f"skipping {name}: {exc}")
    info["load_average_1m_end"] = os.getloadavg()[0]
    print(f"10 s clip ({int(CLIP_S * FPS) + 1} frames), median of {args.repeat}; {machine_summary(info)}")
    print_table(rows, ["robot", "kinematic_s", "physics_s", "kinematic_plus_physics_rtf", "kinematic_plus_physics_cpu_rtf",
                       "validate_no_render_s", "validate_no_render_rtf", "render_s", "render_cpu_s", "fell"],
                headers={"kinematic_s": "kin s", "physics_s": "phys s", "kinematic_plus_physics_rtf": "sum RTF",
                         "kinematic_plus_physics_cpu_rtf": "CPU RTF", "validate_no_render_s": "validate s",
                         "validate_no_render_rtf": "RTF", "render_s": "render s", "render_cpu_s": "(CPU s)"})
    path = write_json(args.json, {"benchmark": "bench_validate", "machine": info, "results": rows})
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

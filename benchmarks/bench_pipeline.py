"""Per-stage times of ``motok-robot run`` for a 6 s clip, models loaded (issue 9 targets).

Targets on 2 CPU cores: generation <= 1 s, retargeting <= 1 s, validation <= 1 s (medians).

    python benchmarks/bench_pipeline.py [--robot op3_like] [--seconds 6] [--repeat 5] [--threads 2]
        [--tokenizer RUN --planner-run RUN] [--random-init] [--motion motion.npz]
        [--outputs] [--balance [--balance-repeat N]] [--profile generate|retarget|validate]
        [--json benchmarks/results/bench_pipeline.json]

Each stage runs exactly as :class:`motok_robot.pipeline.Pipeline` runs it, after one warm-up:

* **generate**: text -> motion (text encoding, planning, token decoding, joints) with the
  configured models (``models/tokenizer`` + ``models/planner_masked`` or the runs given).
  Without trained models this stage is skipped with a message, unless ``--random-init`` times
  default-size models with random weights (latency depends on the architecture, not the
  weights).
* **retarget**: the CasADi/IPOPT trajectory optimisation of the clip (problems compiled
  beforehand: ``setup`` is reported once, apart).
* **validate**: kinematic checks, inverse dynamics, balance and the physics rollout (no plots,
  no video; ``--outputs`` times those once, apart).
* **balance** (``--balance``): the re-solve of the pipeline's balance repair (ZMP term at
  ``PipelineConfig.balance_zmp_weight``, joint-acceleration weight at
  ``PipelineConfig.balance_acceleration_weight``, a foot planted in every frame, self-collision
  avoidance) of the same clip, as ``run`` performs it for a clip that loses balance; its first
  run (problem compiles included) is reported apart as ``balance_setup``.  It has no target:
  clips that keep their balance never pay it.

The motion retargeted and validated is the generated one with trained models; otherwise (or
with ``--motion``) the procedural 6 s walk of :mod:`motok_robot.motion.synthetic` or the given
``motion.npz``.  Wall-clock and process-CPU medians are reported (on a shared, overloaded
machine the CPU time is what an idle core would take), with the machine description and load.
"""

from __future__ import annotations

import argparse
import cProfile
import io
import os
import pstats
import statistics
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import (  # noqa: E402
    RESULTS_DIR, machine_description, machine_summary, markdown_table, random_model_runs, time_median, write_json,
)

PROMPT = "a person walks forward and waves the right hand"
TARGET_S = {"generate": 1.0, "retarget": 1.0, "validate": 1.0}


def _have_trained(kind: str) -> bool:
    from motok_robot.planner.generate import default_run

    return all((default_run(w) / f).is_file() for w in ("tokenizer", kind) for f in ("config.json", "model.safetensors"))


def _profile(fn, top: int = 20) -> str:
    prof = cProfile.Profile()
    prof.enable()
    fn()
    prof.disable()
    out = io.StringIO()
    pstats.Stats(prof, stream=out).sort_stats("cumulative").print_stats(top)
    return out.getvalue()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    from motok_robot.robots.robot import DEFAULT_ROBOT

    parser.add_argument("--robot", default=DEFAULT_ROBOT, help=f"default {DEFAULT_ROBOT}, the pipeline's")
    parser.add_argument("--seconds", type=float, default=6.0)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--threads", type=int, default=2, help="torch threads for generation (default 2)")
    parser.add_argument("--planner", choices=("masked", "ar"), default="masked")
    parser.add_argument("--tokenizer", type=Path, default=None, help="tokenizer run (default models/tokenizer)")
    parser.add_argument("--planner-run", type=Path, default=None, help="planner run (default models/planner_<kind>)")
    parser.add_argument("--random-init", action="store_true",
                        help="time generation with default-size models of random weights (no trained models needed)")
    parser.add_argument("--motion", type=Path, default=None, help="retarget/validate this motion.npz instead")
    parser.add_argument("--outputs", action="store_true", help="also time the plots and the video once")
    parser.add_argument("--balance", action="store_true",
                        help="also time the balance repair's re-solve of the clip (slow: tens of seconds a run)")
    parser.add_argument("--balance-repeat", type=int, default=3, metavar="N",
                        help="runs of the balance re-solve after its first (default 3)")
    parser.add_argument("--profile", choices=("generate", "retarget", "validate"), action="append", default=[],
                        help="print a cProfile of one run of this stage (repeatable)")
    parser.add_argument("--json", type=Path, default=RESULTS_DIR / "bench_pipeline.json")
    args = parser.parse_args()

    import numpy as np
    import torch

    torch.set_num_threads(args.threads)
    from motok_robot.motion.skeleton import FPS
    from motok_robot.pipeline import BALANCE_CHECKS, PipelineConfig, balance_retargeter, load_robot_stages
    from motok_robot.sim.trajectory import RobotTrajectory
    from motok_robot.sim.validate import validate_trajectory

    frames = int(round(args.seconds * FPS))
    results: dict[str, dict] = {}
    notes: list[str] = []
    profiles: dict[str, str] = {}

    # ---- generation
    gen = None
    tmp = None
    tok_run, plan_run = args.tokenizer, args.planner_run
    if args.random_init:
        tmp = tempfile.TemporaryDirectory()
        tok_run, plan_run = random_model_runs(args.planner, Path(tmp.name))
    trained = args.random_init is False and (plan_run is not None or _have_trained(args.planner))
    if args.random_init or trained:
        from motok_robot.planner.generate import MotionGenerator

        t = time.perf_counter()
        gen = MotionGenerator(args.planner, tok_run, plan_run)
        results["load"] = {"median_s": time.perf_counter() - t, "repeat": 1, "note": "once"}
        seeds = iter(range(10_000))

        parts: dict[str, list[float]] = {}

        def generate():
            gen.text_encoder.clear_cache()
            motion = gen.generate(PROMPT, seconds=args.seconds, seed=next(seeds))
            for key, value in motion.timings.items():
                parts.setdefault(key, []).append(value)
            return motion

        results["generate"] = time_median(generate, repeat=args.repeat, warmup=1)
        results["generate"]["parts_median_s"] = {k: round(statistics.median(v[1:] or v), 4) for k, v in parts.items()}
        results["generate"]["decoder_steps"] = gen.tokenizer.config.sample_steps
        if "generate" in args.profile:
            profiles["generate"] = _profile(generate)
        if args.random_init:
            notes.append("generation timed with RANDOM weights of the default model sizes (no trained models)")
    else:
        print("bench_pipeline: no trained models in models/ (models/tokenizer and models/planner_"
              f"{args.planner} with config.json + model.safetensors): generation SKIPPED. Train them (docs/planner.md) "
              "or pass --tokenizer/--planner-run, or --random-init to time default-size random weights.")
        notes.append("generation skipped: no trained models")

    # ---- the motion retargeted and validated
    if args.motion is not None:
        with np.load(args.motion, allow_pickle=False) as z:
            joints, fps = np.asarray(z["joints"], dtype=np.float32), float(z["fps"]) if "fps" in z.files else FPS
        motion_source = str(args.motion)
    elif trained:
        m = gen.generate(PROMPT, seconds=args.seconds, seed=0)
        joints, fps, motion_source = m.joints, float(m.fps), f"generated: {PROMPT!r}, seed 0"
    else:
        from motok_robot.motion.synthetic import walking_clip

        joints, fps = walking_clip(frames=frames, speed=1.0, turn_rate=0.2).astype(np.float32), float(FPS)
        motion_source = f"procedural walk (motok_robot.motion.synthetic.walking_clip, {frames} frames)"
    print(f"motion retargeted/validated: {motion_source}")

    # ---- retargeting
    t = time.perf_counter()
    entry = load_robot_stages(args.robot)
    entry["retargeter"].prepare(len(joints))
    results["setup"] = {"median_s": time.perf_counter() - t, "repeat": 1,
                        "note": "once: robot load, retargeting problem compile, validation index"}
    box = {}

    def retarget():
        box["rt"] = entry["retargeter"].run(joints, fps, progress=False)

    results["retarget"] = time_median(retarget, repeat=args.repeat, warmup=1)
    if "retarget" in args.profile:
        profiles["retarget"] = _profile(retarget)
    rt = box["rt"]
    windows = rt.windows
    results["retarget"]["windows"] = len(windows)
    results["retarget"]["ipopt_iterations"] = [w.iterations for w in windows]
    results["retarget"]["solver_s"] = [round(w.seconds, 4) for w in windows]
    results["retarget"]["converged"] = bool(rt.success)

    # ---- validation
    trajectory = RobotTrajectory(qpos=rt.qpos, fps=rt.fps, joint_names=list(rt.joint_names), robot=rt.robot,
                                 contacts=rt.contacts, source="robot.npz")

    def validate():
        box["val"] = validate_trajectory(trajectory, entry["index"], None, out_dir=None)

    results["validate"] = time_median(validate, repeat=args.repeat, warmup=1)
    if "validate" in args.profile:
        profiles["validate"] = _profile(validate)
    val = box["val"]
    results["validate"]["stage_s"] = {k: round(v, 4) for k, v in val.report.get("timing_s", {}).items()}
    results["validate"]["passed"] = val.passed
    results["validate"]["failed_checks"] = val.report["failed_checks"]

    if args.balance:
        balanced = balance_retargeter(entry, PipelineConfig.balance_zmp_weight,
                                      PipelineConfig.balance_acceleration_weight)
        t = time.perf_counter()
        balanced.run(joints, fps, progress=False)
        results["balance_setup"] = {"median_s": time.perf_counter() - t, "repeat": 1,
                                    "note": "once: the first balance re-solve, its problem compiles included"}

        def rebalance():
            box["balanced"] = balanced.run(joints, fps, progress=False)

        results["balance"] = time_median(rebalance, repeat=args.balance_repeat, warmup=0)
        b = box["balanced"]
        results["balance"].update(ipopt_iterations=[w.iterations for w in b.windows], converged=bool(b.success),
                                  collision_pairs=len(b.collision_pairs),
                                  zmp_weight=PipelineConfig.balance_zmp_weight,
                                  acceleration_weight=PipelineConfig.balance_acceleration_weight,
                                  needed_by_this_clip=bool(set(val.report["failed_checks"]) & BALANCE_CHECKS))

    if args.outputs:
        from motok_robot.sim.plots import save_plots
        from motok_robot.sim.render import render_video

        with tempfile.TemporaryDirectory() as folder:
            t = time.perf_counter()
            save_plots(val, Path(folder))
            results["plots"] = {"median_s": time.perf_counter() - t, "repeat": 1, "note": "once"}
            t = time.perf_counter()
            render_video(val, trajectory, Path(folder) / "video.mp4")
            results["render"] = {"median_s": time.perf_counter() - t, "repeat": 1, "note": "once"}

    # ---- report
    rows = []
    for stage in ("load", "setup", "generate", "retarget", "validate", "balance_setup", "balance", "plots", "render"):
        if stage not in results:
            continue
        r = results[stage]
        target = TARGET_S.get(stage)
        rows.append({"stage": stage, "median_s": r["median_s"], "cpu_median_s": r.get("cpu_median_s"),
                     "min_s": r.get("min_s"), "max_s": r.get("max_s"), "runs": r["repeat"],
                     "target_s": target,
                     "meets": None if target is None else (r.get("cpu_median_s", r["median_s"]) <= target,
                                                           r["median_s"] <= target)})
    machine = machine_description(args.threads)
    clip_s = round(len(joints) / fps, 3)  # --motion: the file's length, not --seconds
    print(f"\n{clip_s:g} s clip ({len(joints)} frames) on {args.robot}; torch threads {args.threads}; "
          f"median of {args.repeat}")
    print(machine_summary(machine))
    table_rows = [{**r, "meets": "" if r["meets"] is None else
                   ("yes" if all(r["meets"]) else "cpu only" if r["meets"][0] else "NO")} for r in rows]
    print(markdown_table(table_rows, ["stage", "median_s", "cpu_median_s", "min_s", "max_s", "runs", "target_s", "meets"],
                         headers={"median_s": "wall median s", "cpu_median_s": "CPU median s"}))
    if "generate" in results:
        print(f"generate parts (median s): {results['generate']['parts_median_s']}; "
              f"decoder steps {results['generate']['decoder_steps']}")
    rtr = results["retarget"]
    print(f"retarget: {rtr['windows']} IPOPT windows, iterations {rtr['ipopt_iterations']}, "
          f"converged {rtr['converged']}")
    print(f"validate: {results['validate']['stage_s']} (last run); passed {val.passed}, "
          f"failed {', '.join(val.report['failed_checks']) or 'none'}")
    if "balance" in results:
        bal = results["balance"]
        print(f"balance: iterations {bal['ipopt_iterations']}, converged {bal['converged']}, "
              f"{bal['collision_pairs']} pairs kept apart; run would "
              f"{'' if bal['needed_by_this_clip'] else 'NOT '}perform it for this clip (validation above)")
    for note in notes:
        print(f"note: {note}")
    for stage, text in profiles.items():
        print(f"\n--- cProfile of one {stage} run (cumulative) ---\n{text}")
    write_json(args.json, {"benchmark": "bench_pipeline", "seconds": clip_s, "frames": int(len(joints)),
                           "robot": args.robot, "prompt": PROMPT, "motion": motion_source, "statistic": "median",
                           "repeat": args.repeat, "targets_s": TARGET_S, "stages": results, "notes": notes,
                           "machine": machine, "date_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())})
    print(f"written {args.json}")
    if tmp is not None:
        tmp.cleanup()
    return 0


if __name__ == "__main__":
    sys.exit(main())

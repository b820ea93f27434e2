"""``motok-robot train tokenizer`` / ``eval reconstruct`` on a tiny prepared dataset written here."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
import torch

from motok_robot.cli import main
from motok_robot.errors import InputError
from motok_robot.motion.features import features_from_joints
from motok_robot.motion.synthetic import walking_clip

TINY = {"width": 32, "code_dim": 16, "codebook_size": 16, "denoiser_width": 32, "denoiser_blocks": 2, "depth": 1, "sample_steps": 3}


def write_prepared(root, splits={"train": 4, "val": 1, "test": 2}):  # noqa: B006 - read only
    """A prepared dataset in the layout of docs/CONTRACTS.md (walking clips of 33..57 frames)."""
    (root / "features").mkdir(parents=True)
    (root / "joints").mkdir()
    (root / "texts").mkdir()
    (root / "splits").mkdir()
    records, train_feats, n = [], [], 0
    for split, count in splits.items():
        ids = []
        for _ in range(count):
            cid = f"walk{n:03d}"
            joints = walking_clip(frames=33 + 8 * (n % 4), speed=0.8 + 0.1 * n, turn_rate=0.2 * (n % 3 - 1)).astype(np.float32)
            feats = features_from_joints(joints)
            np.save(root / "features" / f"{cid}.npy", feats)
            np.save(root / "joints" / f"{cid}.npy", joints)
            (root / "texts" / f"{cid}.txt").write_text("a person walks\n")
            records.append({"id": cid, "source": "synthetic", "licence": "MIT", "fps": 20, "frames": len(joints),
                            "seconds": len(joints) / 20, "texts": ["a person walks"], "split": split,
                            "file": "synthetic", "mirror_of": None, "derived_joints": []})
            if split == "train":
                train_feats.append(feats)
            ids.append(cid)
            n += 1
        (root / "splits" / f"{split}.txt").write_text("\n".join(ids) + "\n")
    (root / "index.jsonl").write_text("".join(json.dumps(r) + "\n" for r in records))
    flat = np.concatenate(train_feats)
    np.save(root / "mean.npy", flat.mean(0).astype(np.float32))
    np.save(root / "std.npy", flat.std(0).astype(np.float32))
    (root / "summary.json").write_text("{}")
    return root


def test_train_resume_and_reconstruct(tmp_path, capsys):
    torch.set_num_threads(1)
    data = write_prepared(tmp_path / "prepared")
    config = tmp_path / "tiny.json"
    config.write_text(json.dumps({"tokenizer": TINY, "train": {"window": 48, "batch_size": 2, "warmup_steps": 1,
                                                                "steps_per_epoch": 2, "val_clips": 2, "val_sample_steps": 2}}))
    run = tmp_path / "run"
    assert main(["train", "tokenizer", "--data", str(data), "--out", str(run), "--config", str(config), "--steps", "4"]) == 0
    for name in ("config.json", "model.safetensors", "train_state.safetensors", "metrics.csv"):
        assert (run / name).is_file(), name
    rows = list(csv.DictReader((run / "metrics.csv").open()))
    assert [int(r["step"]) for r in rows] == [2, 4]
    assert all(np.isfinite(float(r["val_mpjpe_cm"])) for r in rows)
    # an existing run is not overwritten; --resume extends it
    assert main(["train", "tokenizer", "--data", str(data), "--out", str(run), "--config", str(config), "--steps", "4"]) == 2
    assert "--resume" in capsys.readouterr().err
    # --resume keeps the run's config: a setting that differs from it is refused by name (it used to
    # be dropped without a word for --seed and --batch-size), the same settings repeated are accepted
    assert main(["train", "tokenizer", "--data", str(data), "--out", str(run), "--resume", "--steps", "6",
                 "--seed", "3", "--config", str(config)]) == 2
    err = capsys.readouterr().err
    assert "train.seed is 0 (asked 3)" in err and "window" not in err and "Traceback" not in err
    other = tmp_path / "other.json"
    other.write_text(json.dumps({"tokenizer": {**TINY, "codebook_size": TINY["codebook_size"] * 2},
                                 "train": {"lr": 0.5, "action_share": {"bow": 0.1}}}))
    assert main(["train", "tokenizer", "--data", str(data), "--out", str(run), "--resume", "--config", str(other)]) == 2
    err = capsys.readouterr().err
    assert f"tokenizer.codebook_size is {TINY['codebook_size']} (asked {TINY['codebook_size'] * 2})" in err
    assert "train.lr is" in err and "train.action_share is {} (asked {'bow': 0.1})" in err
    assert [int(r["step"]) for r in csv.DictReader((run / "metrics.csv").open())] == [2, 4]
    assert main(["train", "tokenizer", "--data", str(data), "--out", str(run), "--resume", "--steps", "6",
                 "--config", str(config)]) == 0
    rows = list(csv.DictReader((run / "metrics.csv").open()))
    assert [int(r["step"]) for r in rows] == [2, 4, 6]

    out = tmp_path / "rec.json"
    assert main(["eval", "reconstruct", "--data", str(data), "--tokenizer", str(run), "--split", "all",
                 "--device", "cpu", "--json", str(out), "--plot", str(tmp_path / "rec.png")]) == 0
    assert (tmp_path / "rec.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    result = json.loads(out.read_text())
    assert result["clips"] == 7 and result["split"] == "all" and len(result["clip_errors"]) == 7
    for key in ("mpjpe_cm", "mpjpe_root_aligned_cm", "root_trajectory_error_cm", "foot_skating_ratio_reconstructed",
                "foot_skating_ratio_original", "codebook_usage", "perplexity", "tokens_per_second"):
        assert np.isfinite(result[key]), key
    assert 0 < result["codebook_usage"] <= 1 and result["token_rate_hz"] == 5.0
    assert "mpjpe_cm" in capsys.readouterr().out


def test_decoder_stage_recipe_keeps_the_tokens(tmp_path):
    """The optional second stage of models/train_default_models.sh (TOKENIZER_STAGE2=1):
    --init-from RUN --freeze-tokens --config models/tokenizer_finetune.json trains the decoder
    side with the recipe's settings and leaves the tokens (and so the planners) as they were."""
    from motok_robot.tokenizer.checkpoint import load_tokenizer

    torch.set_num_threads(1)
    recipe = Path(__file__).resolve().parents[1] / "models" / "tokenizer_finetune.json"
    data = write_prepared(tmp_path / "prepared")
    config = tmp_path / "tiny.json"
    config.write_text(json.dumps({"tokenizer": TINY, "train": {"window": 48, "batch_size": 2, "warmup_steps": 1,
                                                                "val_clips": 1, "val_sample_steps": 2}}))
    base, stage2 = tmp_path / "base", tmp_path / "stage2"
    assert main(["train", "tokenizer", "--data", str(data), "--out", str(base), "--config", str(config), "--steps", "3"]) == 0
    assert main(["train", "tokenizer", "--data", str(data), "--out", str(stage2), "--init-from", str(base), "--freeze-tokens",
                 "--config", str(recipe), "--steps", "3", "--batch-size", "2", "--device", "cpu"]) == 0
    train = json.loads((stage2 / "config.json").read_text())["train"]
    wanted = json.loads(recipe.read_text())["train"]
    assert train["freeze_tokens"] and train["init_from"] == str(base)
    assert train["lr"] == wanted["lr"] and train["steps_per_epoch"] == wanted["steps_per_epoch"]
    a, b = load_tokenizer(base, device="cpu"), load_tokenizer(stage2, device="cpu")
    assert a.tokens_digest() == b.tokens_digest()
    changed = [k for k, v in a.state_dict().items() if not torch.equal(v, b.state_dict()[k])]
    assert changed and all(k.startswith(("cond_decoder.", "denoiser.")) for k in changed), changed


def test_cli_errors_are_one_line(tmp_path, capsys):
    data = write_prepared(tmp_path / "prepared", {"train": 1, "val": 0, "test": 1})
    assert main(["eval", "reconstruct", "--data", str(data), "--tokenizer", str(tmp_path / "none")]) == 2
    assert "no trained tokenizer" in capsys.readouterr().err
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"tokenizer": {"codebook": 3}}))
    assert main(["train", "tokenizer", "--data", str(data), "--out", str(tmp_path / "r"), "--config", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "unknown key" in err and "codebook" in err and "Traceback" not in err
    short = tmp_path / "short.json"
    short.write_text(json.dumps({"tokenizer": {"downsample": 3}}))
    assert main(["train", "tokenizer", "--data", str(data), "--out", str(tmp_path / "r2"), "--config", str(short)]) == 2
    assert "downsample must be 2, 4 or 8" in capsys.readouterr().err
    # the synthetic clips carry captions, no action labels
    assert main(["train", "tokenizer", "--data", str(data), "--out", str(tmp_path / "r3"), "--only-actions", "bow"]) == 2
    assert "train split has no clip of action ['bow'] (labels there: none)" in capsys.readouterr().err
    assert main(["train", "tokenizer", "--data", str(data), "--out", str(tmp_path / "r3"), "--resume",
                 "--only-actions", "bow"]) == 2
    assert "r3: nothing to resume (train_state.safetensors not found)" in capsys.readouterr().err
    assert main(["train", "tokenizer", "--data", str(data), "--out", str(tmp_path / "r4"), "--action-share", "bow"]) == 2
    assert "--action-share: expected LABEL=SHARE such as bow=0.05 (got 'bow')" in capsys.readouterr().err
    assert main(["train", "tokenizer", "--data", str(data), "--out", str(tmp_path / "r4"), "--action-share", "bow=0.1"]) == 2
    assert "train split: action_share names 'bow', which no clip has (labels there: none)" in capsys.readouterr().err


def test_action_share_flag_parses_label_equals_share():
    from motok_robot.data.groups import parse_action_shares

    assert parse_action_shares(["bow=0.05", "walk-left=0.1"]) == {"bow": 0.05, "walk-left": 0.1}
    for bad in ("=0.1", "bow=", "bow=a lot", "bow"):
        with pytest.raises(InputError, match="expected LABEL=SHARE"):
            parse_action_shares([bad])


@pytest.mark.parametrize("split", ["test"])
def test_reconstruct_default_split(tmp_path, split):
    from motok_robot.tokenizer import MoTok, TokenizerConfig, save_tokenizer
    from motok_robot.tokenizer.evaluate import reconstruct_dataset

    data = write_prepared(tmp_path / "prepared", {"train": 1, "val": 0, "test": 2})
    tok = MoTok(TokenizerConfig(**{**TINY, "decoder": "conv"}), np.load(data / "mean.npy"), np.load(data / "std.npy"))
    save_tokenizer(tok, tmp_path / "run")
    result = reconstruct_dataset(tok.eval(), data, split, progress=False)
    assert result["clips"] == 2 and result["steps"] == 0 and result["decoder"] == "conv"


def test_cli_module_and_configs_do_not_import_torch():
    import subprocess
    import sys

    code = ("import sys, motok_robot.tokenizer.cli, motok_robot.tokenizer\n"
            "from motok_robot.tokenizer import TokenizerConfig, TrainConfig\n"
            "TokenizerConfig(); TrainConfig()\n"
            "assert 'torch' not in sys.modules, 'torch imported'\n")
    subprocess.run([sys.executable, "-c", code], check=True)

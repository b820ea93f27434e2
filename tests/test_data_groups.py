"""Balancing groups of training clips (motok_robot.data.groups) and their use by the tokenizer's
window sampler and the planner's clip draw."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from motok_robot.data.groups import balanced_weights, clip_group
from motok_robot.errors import InputError


def test_clip_group_prefers_the_action_label_then_the_first_sentence():
    bandai = {"source": "bandai", "file": "x.tar.xz:d/dataset-1_bow_angry_001.bvh", "texts": ["An angry bow."]}
    assert clip_group(bandai, "bandai/dataset-1_bow_angry_001") == ("action", "bow")
    assert clip_group({"source": "cmu", "texts": ["  a person   jumps "]}, "cmu/01_01") == ("text", "a person jumps")
    assert clip_group({"source": "deepmimic", "texts": []}, "deepmimic/spin") == ("clip", "deepmimic/spin")


def test_balanced_weights_divide_each_group_by_its_size_to_the_power():
    groups = ["walk"] * 9 + ["bow"]
    plain = balanced_weights(groups, 0.0)
    assert np.allclose(plain, 0.1)
    full = balanced_weights(groups, 1.0)
    assert np.isclose(full[groups.index("bow")], 0.5) and np.isclose(full[:9].sum(), 0.5)
    root = balanced_weights(groups, 0.5)  # walk 9 / 3 = 3 : bow 1
    assert np.isclose(root[-1], 0.25) and np.isclose(root.sum(), 1.0)
    # base weights (clip lengths) scale within and across groups
    based = balanced_weights(["a", "a", "b"], 1.0, base=[1.0, 3.0, 2.0])
    assert np.allclose(based, np.array([0.5, 1.5, 2.0]) / 4.0)


@pytest.mark.parametrize("args, match", [((["a"], 1.5), "balance_groups must be in"), (([], 0.5), "no items"),
                                         ((["a", "b"], 0.5, [1.0]), "2 positive weights"),
                                         ((["a", "b"], 0.5, [1.0, 0.0]), "positive weights")])
def test_balanced_weights_errors(args, match):
    with pytest.raises(InputError, match=match):
        balanced_weights(*args)


def test_tokenizer_window_sampler_balances_groups():
    from motok_robot.tokenizer.train import Clips, WindowSampler

    # nine walks and one bow, all 40 frames, each clip filled with its index
    features = [np.full((40, 263), i, dtype=np.float32) for i in range(10)]
    groups = [("action", "walk")] * 9 + [("action", "bow")]
    ids = [f"c{i}" for i in range(10)]
    gen = torch.Generator().manual_seed(0)
    share = {}
    for balance in (0.0, 1.0):
        sampler = WindowSampler(Clips(ids, features, groups), window=32, balance=balance)
        x, _ = sampler.sample(2000, gen)
        share[balance] = float((x[:, 0, 0] == 9).float().mean())
    assert abs(share[0.0] - 0.1) < 0.03 and abs(share[1.0] - 0.5) < 0.04
    # without groups every clip is its own group: balancing changes nothing
    ungrouped = WindowSampler(Clips(ids, features), window=32, balance=1.0)
    assert torch.allclose(ungrouped.weights, torch.full((10,), 0.1, dtype=torch.float64))


def test_tokenizer_config_rejects_a_bad_balance():
    from motok_robot.tokenizer.config import train_config_from_dict

    with pytest.raises(InputError, match="balance_groups must be in"):
        train_config_from_dict({"balance_groups": -0.1}, where="cfg.json 'train'").validate()


def test_load_split_gives_each_clip_its_group(tmp_path):
    import json

    from test_tokenizer_cli import write_prepared

    from motok_robot.tokenizer.train import load_split

    data = write_prepared(tmp_path / "prepared", {"train": 3, "val": 1, "test": 0})
    records = [json.loads(line) for line in (data / "index.jsonl").read_text().splitlines()]
    records[0].update(source="bandai", file="d.tar.xz:x/dataset-1_bow_sad_001.bvh")
    (data / "index.jsonl").write_text("".join(json.dumps(r) + "\n" for r in records))
    clips = load_split(data, "train")
    assert clips.groups == [("action", "bow"), ("text", "a person walks"), ("text", "a person walks")]

"""Balancing groups of training clips (motok_robot.data.groups) and their use by the tokenizer's
window sampler and the planner's clip draw."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from motok_robot.data.groups import balanced_weights, check_action_shares, clip_group, with_action_shares
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


def test_with_action_shares_gives_each_label_its_share_and_keeps_relative_weights():
    groups = [("action", "walk")] * 6 + [("action", "bow"), ("action", "bow"), ("text", "a person jumps")]
    weights = np.array([1.0] * 6 + [1.0, 3.0, 2.0])
    out = with_action_shares(weights, groups, {"bow": 0.2}, "train split")
    assert np.isclose(out.sum(), 1.0)
    assert np.allclose(out[6:8], [0.05, 0.15])  # 0.2 split 1 : 3 as the bows were
    rest = 0.8 * np.array([1.0] * 6 + [2.0]) / 8.0  # walks and the caption keep their 1 : 2
    assert np.allclose(out[[0, 1, 2, 3, 4, 5, 8]], rest)
    two = with_action_shares(weights, groups, {"bow": 0.1, "walk": 0.6}, "train split")
    assert np.isclose(two[6:8].sum(), 0.1) and np.isclose(two[:6].sum(), 0.6) and np.isclose(two[8], 0.3)
    assert np.allclose(with_action_shares(weights, groups, {}, "x"), weights / weights.sum())


def test_with_action_shares_errors_name_the_label_and_the_labels_there():
    groups = [("action", "walk"), ("action", "bow"), ("text", "a person jumps")]
    with pytest.raises(InputError, match=r"train split: action_share names 'kick', which no clip has "
                                         r"\(labels there: bow, walk\)"):
        with_action_shares([1.0, 1.0, 1.0], groups, {"kick": 0.1}, "train split")
    with pytest.raises(InputError, match="every clip is of an action in action_share"):
        with_action_shares([1.0, 1.0], groups[:2], {"walk": 0.5, "bow": 0.4}, "train split")


@pytest.mark.parametrize("shares, match", [(["bow"], "must map action labels to shares"),
                                           ({"bow": 0.0}, r"action_share\['bow'\] must be a number in \(0, 1\)"),
                                           ({"bow": 1.0}, "must be a number in"), ({"bow": True}, "must be a number in"),
                                           ({"bow": "0.1"}, "must be a number in"), ({" ": 0.1}, "empty or non-text label"),
                                           ({"bow": 0.6, "walk": 0.4}, "adds up to 1; it must stay below 1")])
def test_check_action_shares_errors(shares, match):
    with pytest.raises(InputError, match=match):
        check_action_shares(shares, "cfg.json 'train'")
    assert check_action_shares({" bow ": 0.05}, "x") == {"bow": 0.05}


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
    # an action share overrides what balancing gives the label
    shared = WindowSampler(Clips(ids, features, groups), window=32, balance=1.0, shares={"bow": 0.25})
    x, _ = shared.sample(4000, gen)
    assert abs(float((x[:, 0, 0] == 9).float().mean()) - 0.25) < 0.03
    with pytest.raises(InputError, match="train split: action_share names 'kick'"):
        WindowSampler(Clips(ids, features, groups), window=32, shares={"kick": 0.1})


def test_tokenizer_config_rejects_a_bad_balance():
    from motok_robot.tokenizer.config import train_config_from_dict

    with pytest.raises(InputError, match="balance_groups must be in"):
        train_config_from_dict({"balance_groups": -0.1}, where="cfg.json 'train'").validate()
    with pytest.raises(InputError, match=r"train config: action_share\['bow'\] must be a number"):
        train_config_from_dict({"action_share": {"bow": 2}}, where="cfg.json 'train'")
    with pytest.raises(InputError, match="action_share and only_actions exclude each other"):
        train_config_from_dict({"action_share": {"bow": 0.1}, "only_actions": ["bow"]}, where="cfg.json 'train'")


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

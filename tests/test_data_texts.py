"""Clip texts: Bandai content x style, CMU descriptions, DeepMimic names, acRNN, user index, mirroring."""

from __future__ import annotations

import json

import pytest

from motok_robot.data import texts as T
from motok_robot.errors import InputError

README_CONTENTS = (
    "walk walk-left walk-right walk-back run dash guide bow bye byebye call respond punch kick slash dance-short "
    "walk-turn-left walk-turn-right raise-up-left-hand raise-up-right-hand raise-up-both-hands wave-left-hand "
    "wave-right-hand wave-both-hands dance-long"
).split()
README_STYLES = (
    "normal happy sad angry proud tired old giant childish feminine masculinity musical not-confident active "
    "chimpira exhausted youthful masculine elderly"
).split()


def test_every_bandai_content_and_style_gives_distinct_sentences():
    for c in README_CONTENTS:
        for s in README_STYLES:
            out = T.bandai_texts(c, s, f"bandai/x_{c}_{s}")
            assert len(out) >= 3, (c, s, out)
            assert len(set(out)) == len(out)
            assert all(t[0].isupper() and t.endswith(".") for t in out)
    # deterministic per clip id, different across ids
    assert T.bandai_texts("walk", "happy", "a") == T.bandai_texts("walk", "happy", "a")
    many = {tuple(T.bandai_texts("walk", "happy", f"id{i}")) for i in range(20)}
    assert len(many) > 5
    assert any("happ" in t or "cheerful" in t or "joyful" in t for t in T.bandai_texts("walk", "happy", "a"))
    assert all("right hand" in t for t in T.bandai_texts("wave-right-hand", "normal", "b"))
    with pytest.raises(InputError, match="unknown Bandai content 'fly'"):
        T.bandai_texts("fly", "normal", "c")


@pytest.mark.parametrize(
    "text, mirrored",
    [
        ("a person waves the left hand", "a person waves the right hand"),
        ("Someone turns right, then left.", "Someone turns left, then right."),
        ("Left foot forward", "Right foot forward"),
        ("spins clockwise", "spins counterclockwise"),
        ("spins counterclockwise", "spins clockwise"),
        ("walks leftward", "walks rightward"),
        ("stands up right away and waves the right arm", "stands up right away and waves the left arm"),
        ("bright lights", "bright lights"),
    ],
)
def test_mirror_text_swaps_sides(text, mirrored):
    assert T.mirror_text(text) == mirrored
    assert T.mirror_text(T.mirror_text(text)) == text or "anticlockwise" in text


def test_cmu_descriptions(tmp_path):
    f = tmp_path / "cmu.csv"
    f.write_text(
        '"Subject","Trial #","Motion Description","framerate"\n'
        '2,3,"run/jog",120\n1,1,"playground - forward jumps, turn around",120\n5,2,"swordplay",60\n'
    )
    d = T.load_cmu_descriptions(f)
    assert d["02_03"] == {"description": "run/jog", "fps": 120.0}
    assert d["05_02"]["fps"] == 60.0
    out = T.description_texts("run/jog", "cmu/02_03")
    assert any(t.endswith("runs.") for t in out) and any(t.endswith("jogs.") for t in out)
    assert "Run/jog." in out
    assert T.description_texts("swordplay", "x") == ["A person performs swordplay.", "Swordplay."]
    assert T.description_texts("forward jump", "x") == ["A person performs a forward jump.", "Forward jump."]
    assert T.description_texts("JumpTwist", "x") == ["A person performs a jump twist.", "Jump twist."]


def test_deepmimic_and_acrnn_names():
    assert any("backflip" in t or "flips" in t for t in T.deepmimic_texts("humanoid3d_backflip", "d/1"))
    assert any("spin" in t for t in T.deepmimic_texts("humanoid3d_spinkick", "d/2"))
    assert any("zombie" in t for t in T.deepmimic_texts("humanoid3d_long_zombie", "d/3"))
    assert any("walk" in t for t in T.deepmimic_texts("humanoid3d_long_walk2_mirror", "d/4"))
    assert T.deepmimic_texts("02_01", "d/5") == []  # a bare CMU number is no description
    assert any("salsa" in t for t in T.acrnn_texts("salsa", "a/1"))
    assert any("Indian" in t for t in T.acrnn_texts("indian", "a/2"))
    assert any("martial" in t for t in T.acrnn_texts("martial", "a/3"))


def test_user_text_index_csv_and_json(tmp_path):
    c = tmp_path / "t.csv"
    c.write_text("file,text\nsub/walk01.bvh,a person walks\nsub/walk01.bvh,someone strolls\njump,a person jumps\n")
    idx = T.load_text_index(c)
    assert T.lookup_texts(idx, "bvh/sub/walk01", "/data/sub/walk01.bvh") == ["a person walks", "someone strolls"]
    assert T.lookup_texts(idx, "bvh/jump", "/data/jump.bvh") == ["a person jumps"]
    assert T.lookup_texts(idx, "bvh/other", "/data/other.bvh") == []
    j = tmp_path / "t.json"
    j.write_text(json.dumps({"walk01.bvh": "a walk", "bvh/jump": ["a jump", "a hop"]}))
    idx = T.load_text_index(j)
    assert T.lookup_texts(idx, "bvh/sub/walk01", "x.tar.xz:sub/walk01.bvh") == ["a walk"]
    assert T.lookup_texts(idx, "bvh/jump", "/d/jump.bvh") == ["a jump", "a hop"]
    bad = tmp_path / "bad.csv"
    bad.write_text("name,caption\na,b\n")
    with pytest.raises(InputError, match=r"needs a 'file' \(or clip/id/path\) column and a 'text' column"):
        T.load_text_index(bad)

"""``motok-robot data prepare`` end to end on small folders and archives the test writes."""

from __future__ import annotations

import json
import tarfile
import zipfile

import numpy as np
import pytest
from test_data_fixtures import (
    BANDAI_NAMES,
    canonical_bvh_text,
    cmu_like_amc,
    cmu_like_asf,
    deepmimic_json,
    identity_map,
)

from motok_robot.cli import main
from motok_robot.data.dataset import PreparedDataset
from motok_robot.data.prepare import split_of
from motok_robot.errors import InputError
from motok_robot.motion import features as F
from motok_robot.motion import skeleton

BANDAI_FILES = [
    "dataset-1_walk_happy_001", "dataset-1_walk_happy_002", "dataset-2_wave-left-hand_normal_001",
    "dataset-1_bow_sad_001", "dataset-2_run_active_003",
]


def _bandai_folder(root):
    data = root / "Bandai-Namco-Research-Motiondataset-1" / "data"
    data.mkdir(parents=True)
    names = BANDAI_NAMES | {"spine3": "unused"}
    for k, stem in enumerate(BANDAI_FILES):
        (data / f"{stem}.bvh").write_text(canonical_bvh_text(frames=24 + 3 * k, names=names, skip=("spine3",)))
        (data / f"{stem}.json").write_text('{"content": 0, "style": 0}')
    good = canonical_bvh_text(frames=12, names=names, skip=("spine3",))
    (data / "dataset-1_kick_angry_001.bvh").write_text(good.replace("Frames: 12", "Frames: 40"))  # truncated
    (data / "dataset-1_fly_normal_001.bvh").write_text(good)  # unknown content
    (root / "README.md").write_text("not motion")
    return root


def _run(*argv):
    return main(["data", "prepare", *argv])


def test_prepare_bandai_folder_end_to_end(tmp_path, capsys):
    src = _bandai_folder(tmp_path / "bandai")
    out = tmp_path / "out"
    # the folder holds two bad files on purpose (listed, then accepted with --allow-skips)
    assert _run("--source", f"bandai={src}", "--out", str(out), "--workers", "1", "--allow-skips") == 0
    printed = capsys.readouterr()
    assert "dataset-1_kick_angry_001.bvh: truncated motion: header says 40 frames, file has 12" in printed.err
    assert "skipped 2 file(s)" in printed.out

    index = [json.loads(line) for line in (out / "index.jsonl").read_text().splitlines()]
    ids = [r["id"] for r in index]
    assert len(ids) == 10 and len(set(ids)) == 10  # 5 clips + 5 mirrors
    rec = {r["id"]: r for r in index}
    r = rec["bandai/dataset-2_wave-left-hand_normal_001"]
    assert set(r) == {"id", "source", "licence", "fps", "frames", "seconds", "texts", "split", "file", "mirror_of",
                      "derived_joints"}
    assert r["fps"] == 20 and r["source"] == "bandai" and "CC BY-NC" in r["licence"]
    assert r["derived_joints"] == ["spine3"] and r["mirror_of"] is None
    assert all("left hand" in t for t in r["texts"])
    m = rec["mirror/bandai/dataset-2_wave-left-hand_normal_001"]
    assert m["mirror_of"] == r["id"] and m["split"] == r["split"]
    assert all("right hand" in t and "left" not in t for t in m["texts"])
    # takes of one content/style stay in one split
    assert rec["bandai/dataset-1_walk_happy_001"]["split"] == rec["bandai/dataset-1_walk_happy_002"]["split"]

    splits = {s: (out / "splits" / f"{s}.txt").read_text().split() for s in ("train", "val", "test")}
    assert sorted(sum(splits.values(), [])) == sorted(ids)
    for r in index:
        assert r["id"] in splits[r["split"]]

    summary = json.loads((out / "summary.json").read_text())
    assert summary["sources"]["bandai"]["clips"] == 5 and summary["sources"]["bandai"]["mirrored_clips"] == 5
    reasons = {s["file"].rsplit("/", 1)[-1]: s["reason"] for s in summary["skipped"]}
    assert set(reasons) == {"dataset-1_kick_angry_001.bvh", "dataset-1_fly_normal_001.bvh"}
    assert "unknown Bandai content 'fly'" in reasons["dataset-1_fly_normal_001.bvh"]
    assert summary["total_hours"] == pytest.approx(sum(r["frames"] for r in index if not r["mirror_of"]) / 20 / 3600, abs=1e-4)

    ds = PreparedDataset(out, "all")
    train = PreparedDataset(out, "train")
    feats = np.concatenate([train.features(i) for i in train.clip_ids]).astype(np.float64)
    np.testing.assert_allclose(ds.mean, feats.mean(0), atol=1e-5)
    np.testing.assert_allclose(ds.std, np.maximum(feats.std(0), 1e-4), rtol=1e-3, atol=1e-5)
    for cid in ds.clip_ids:
        j, f = ds.joints(cid), ds.features(cid)
        assert j.dtype == np.float32 and f.dtype == np.float32
        assert f.shape == (j.shape[0] - 1, 263) and j.shape[1:] == (22, 3)
        assert ds.texts(cid) == ds.record(cid)["texts"]
        # round trip: features -> joints reproduces the stored skeleton-normalised joints
        err = np.abs(F.joints_from_features(f) - j[:-1]).max()
        assert err < 1e-3, (cid, err)
        # normalised: canonical bone lengths, feet on the floor, upright
        bones = np.linalg.norm(j[:, 1:] - j[:, list(skeleton.PARENTS[1:])], axis=-1)
        np.testing.assert_allclose(bones, np.broadcast_to(skeleton.BONE_LENGTHS[1:], bones.shape), atol=1e-4)
        assert j[..., 2].min() == pytest.approx(0.0, abs=1e-5)

    # deterministic: the same folder as a .tar.xz and a .zip archive gives the same index
    tar = tmp_path / "bandai.tar.xz"
    with tarfile.open(tar, "w:xz") as tf:
        tf.add(src, arcname="bandai")
    zp = tmp_path / "bandai.zip"
    with zipfile.ZipFile(zp, "w") as zf:
        for p in sorted(src.rglob("*")):
            zf.write(p, p.relative_to(src.parent).as_posix())
    for arch, name in ((tar, "t"), (zp, "z")):
        o = tmp_path / name
        assert _run("--source", f"bandai={arch}", "--out", str(o), "--workers", "2", "--allow-skips") == 0
        other = [json.loads(line) for line in (o / "index.jsonl").read_text().splitlines()]
        assert sorted((r["id"], r["split"], r["frames"], tuple(r["texts"])) for r in other) == sorted(
            (r["id"], r["split"], r["frames"], tuple(r["texts"])) for r in index
        )
        np.testing.assert_allclose(np.load(o / "mean.npy"), np.load(out / "mean.npy"), atol=1e-6)


def test_prepare_mixed_sources_user_map_texts_and_limits(tmp_path, capsys):
    bvh_dir = tmp_path / "bvh"
    (bvh_dir / "sub").mkdir(parents=True)
    for k in range(3):
        (bvh_dir / "sub" / f"walk{k}.bvh").write_text(canonical_bvh_text(frames=20 + k))
    mp = identity_map(tmp_path / "map.json")
    idx = tmp_path / "texts.csv"
    idx.write_text("file,text\nsub/walk0.bvh,a person walks to the left\n")
    asf_dir = tmp_path / "asf" / "07"
    asf_dir.mkdir(parents=True)
    (asf_dir / "07.asf").write_text(cmu_like_asf())
    (asf_dir / "07_01.amc").write_text(cmu_like_amc(frames=60))
    (asf_dir / "08_01.amc").write_text(cmu_like_amc(frames=50))  # pairs with the only ASF of the folder
    (tmp_path / "asf" / "lonely").mkdir()
    (tmp_path / "asf" / "lonely" / "09_01.amc").write_text(cmu_like_amc(frames=30))
    dm = tmp_path / "dm"
    (dm / "humanoid3d").mkdir(parents=True)
    (dm / "humanoid3d" / "humanoid3d_backflip.txt").write_text(deepmimic_json(frames=20))
    (dm / "humanoid3d" / "humanoid3d_copy.txt").write_text(deepmimic_json(frames=20))  # same motion
    out = tmp_path / "out"
    code = _run(
        "--source", f"bvh={bvh_dir}", "--source", f"asf={tmp_path / 'asf'}", "--source", f"deepmimic={dm}",
        "--out", str(out), "--map", f"bvh={mp}", "--texts", str(idx), "--no-mirror", "--workers", "1",
        "--allow-skips",  # lonely/09_01.amc has no skeleton: 1 of 8 files skipped, on purpose
    )
    assert code == 0
    ds = PreparedDataset(out, "all")
    assert not any(c.startswith("mirror/") for c in ds.clip_ids)
    assert ds.texts("bvh/sub/walk0") == ["a person walks to the left"]
    assert ds.texts("bvh/sub/walk1") == []
    assert "asf/07/07_01" in ds and "asf/07/08_01" in ds
    assert "deepmimic/humanoid3d/humanoid3d_backflip" in ds
    summary = ds.summary()
    assert summary["sources"]["deepmimic"]["duplicate_clips"] == 1
    assert summary["duplicates"][0]["duplicate_of"] == "deepmimic/humanoid3d/humanoid3d_backflip"
    assert any("09_01.amc" in s["file"] and "no .asf skeleton file" in s["reason"] for s in summary["skipped"])
    # --limit: at most N files per source; an existing dataset needs --overwrite
    assert _run("--source", f"bvh={bvh_dir}", "--out", str(out), "--map", str(mp), "--workers", "1") == 2
    assert "--overwrite" in capsys.readouterr().err
    assert _run("--source", f"bvh={bvh_dir}", "--out", str(out), "--map", str(mp), "--limit", "1",
                "--workers", "1", "--overwrite") == 0
    assert len(PreparedDataset(out, "all")) == 2  # one clip + its mirror


def test_prepare_fails_only_when_nothing_is_usable(tmp_path, capsys):
    src = tmp_path / "broken"
    src.mkdir()
    (src / "a.bvh").write_text("HIERARCHY\nROOT Hips\n{\n OFFSET 0 0 0\n")
    mp = identity_map(tmp_path / "map.json")
    code = _run("--source", f"bvh={src}", "--out", str(tmp_path / "o"), "--map", str(mp), "--workers", "1")
    assert code == 2
    err = capsys.readouterr().err
    assert "nothing usable: 0 clips prepared" in err and "a.bvh" in err
    assert _run("--source", f"bvh={src}", "--out", str(tmp_path / "o2"), "--workers", "1") == 2
    assert "needs --map" in capsys.readouterr().err
    assert _run("--source", f"bandai={tmp_path / 'missing'}", "--out", str(tmp_path / "o3")) == 2
    assert "no such file or folder" in capsys.readouterr().err


def test_prepare_humanml3d_keeps_features_splits_and_stats(tmp_path):
    from test_data_deepmimic_humanml3d import _humanml_folder

    root = _humanml_folder(tmp_path / "HumanML3D")
    out = tmp_path / "out"
    assert _run("--source", f"humanml3d={root}", "--out", str(out), "--workers", "1") == 0
    ds = PreparedDataset(out, "all")
    assert "humanml3d/M000001" in ds and "mirror/humanml3d/000001" not in ds
    assert ds.record("humanml3d/000002")["split"] == "test"
    assert ds.summary()["split_by"] == "given"  # HumanML3D's own split, whatever --split-by says
    assert ds.record("humanml3d/M000001")["mirror_of"] == "humanml3d/000001"
    np.testing.assert_array_equal(ds.features("humanml3d/000001"), np.load(root / "new_joint_vecs" / "000001.npy"))
    np.testing.assert_array_equal(ds.std, np.ones(263, np.float32))  # HumanML3D's own Std.npy
    # the same folder as an archive: extracted to a temporary folder that is removed afterwards
    import tempfile
    from pathlib import Path

    arch = tmp_path / "HumanML3D.tar.gz"
    with tarfile.open(arch, "w:gz") as tf:
        tf.add(root, arcname="HumanML3D")
    before = set(Path(tempfile.gettempdir()).glob("motok-prepare-*"))
    assert _run("--source", f"humanml3d={arch}", "--out", str(tmp_path / "o2"), "--workers", "1") == 0
    assert set(Path(tempfile.gettempdir()).glob("motok-prepare-*")) == before
    assert PreparedDataset(tmp_path / "o2", "all").clip_ids == ds.clip_ids


def test_split_is_deterministic_and_roughly_85_5_10():
    groups = [f"g{i}" for i in range(4000)]
    s = [split_of(g) for g in groups]
    assert s == [split_of(g) for g in groups]
    frac = {k: s.count(k) / len(s) for k in ("train", "val", "test")}
    assert abs(frac["train"] - 0.85) < 0.03 and abs(frac["val"] - 0.05) < 0.015 and abs(frac["test"] - 0.10) < 0.02
    assert [split_of(g, seed=1) for g in groups] != s


def test_dataset_reader_errors(tmp_path):
    with pytest.raises(InputError, match="not a prepared dataset"):
        PreparedDataset(tmp_path)


def test_show_renders_a_prepared_clip(tmp_path, capsys):
    src = tmp_path / "bvh"
    src.mkdir()
    (src / "walk.bvh").write_text(canonical_bvh_text(frames=12))
    out = tmp_path / "out"
    assert _run("--source", f"bvh={src}", "--out", str(out), "--map", str(identity_map(tmp_path / "m.json")),
                "--workers", "1") == 0
    gif = tmp_path / "walk.gif"
    assert main(["data", "show", str(out), "--clip", "bvh/walk", "--out", str(gif)]) == 0
    assert gif.stat().st_size > 1000 and gif.read_bytes()[:3] == b"GIF"
    capsys.readouterr()
    assert main(["data", "show", str(out), "--clip", "walk", "--out", str(gif)]) == 2
    assert "no clip 'walk'; did you mean ['bvh/walk', 'mirror/bvh/walk']" in capsys.readouterr().err
    assert main(["data", "show", str(out), "--clip", "bvh/walk", "--out", str(tmp_path / "x.avi")]) == 2


def test_data_modules_do_not_import_torch():
    import subprocess
    import sys

    code = ("import sys, motok_robot.data.prepare, motok_robot.data.dataset, motok_robot.data.cli, "
            "motok_robot.data.sources, motok_robot.data.humanml3d; print('torch' in sys.modules)")
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip() == "False"


ACRNN_NAMES = {
    "pelvis": "hip", "left_hip": "lThigh", "right_hip": "rThigh", "left_knee": "lShin", "right_knee": "rShin",
    "spine2": "abdomen", "left_ankle": "lFoot", "right_ankle": "rFoot", "spine3": "chest", "neck": "neck",
    "left_collar": "lCollar", "right_collar": "rCollar", "head": "head", "left_shoulder": "lShldr",
    "right_shoulder": "rShldr", "left_elbow": "lForeArm", "right_elbow": "rForeArm", "left_wrist": "lHand",
    "right_wrist": "rHand",
}


def test_prepare_acrnn_uses_readme_frame_rate_and_drops_first_frame(tmp_path):
    root = tmp_path / "acrnn-bvh"
    (root / "salsa").mkdir(parents=True)
    (root / "martial").mkdir()
    (root / "readme.txt").write_text("indian framerate 120\nsalsa  framerate 60\nmartial framerate 120\n")
    skip = ("spine1", "left_foot", "right_foot")  # toes come from lFoot's End Site
    for genre in ("salsa", "martial"):  # both headers claim 120 fps
        (root / genre / "01.bvh").write_text(canonical_bvh_text(frames=61, fps=120.0, names=ACRNN_NAMES, skip=skip))
    out = tmp_path / "out"
    assert _run("--source", f"acrnn={root}", "--out", str(out), "--workers", "1") == 0
    ds = PreparedDataset(out, "all")
    # 52 frames after the 9-frame lead-in: 51/60 s at 60 fps -> 18 frames at 20 fps; at 120 fps -> 9
    assert ds.record("acrnn/salsa/01")["frames"] == 18
    assert ds.record("acrnn/martial/01")["frames"] == 9
    assert any("salsa" in t for t in ds.texts("acrnn/salsa/01"))
    assert ds.record("acrnn/salsa/01")["derived_joints"] == ["spine1"]
    assert "MIT" in ds.record("acrnn/salsa/01")["licence"]


def test_cmu_trial_and_its_deepmimic_conversion_share_a_split(tmp_path):
    cmu = tmp_path / "cmu" / "subjects" / "02"
    cmu.mkdir(parents=True)
    (cmu / "02.asf").write_text(cmu_like_asf())
    dm = tmp_path / "dm" / "cmu" / "cmu01-09" / "02"
    dm.mkdir(parents=True)
    (tmp_path / "cmu-descriptions.csv").write_text('"Subject","Trial #","Motion Description","framerate"\n')
    with (tmp_path / "cmu-descriptions.csv").open("a") as fh:
        for t in range(1, 9):
            fh.write(f'2,{t},"walk",120\n')
            (cmu / f"02_0{t}.amc").write_text(cmu_like_amc(frames=30 + 6 * t))
            (dm / f"02_0{t}.txt").write_text(deepmimic_json(frames=10 + 3 * t))
    out = tmp_path / "out"
    assert _run("--source", f"cmu={tmp_path / 'cmu'}", "--source", f"deepmimic={tmp_path / 'dm'}",
                "--out", str(out), "--workers", "1") == 0
    ds = PreparedDataset(out, "all")
    splits = set()
    for t in range(1, 9):
        a, b = ds.record(f"cmu/02_0{t}"), ds.record(f"deepmimic/cmu/02_0{t}")
        assert a["split"] == b["split"] == split_of(f"cmu/02_0{t}")
        assert any("walks" in s for s in b["texts"])  # DeepMimic's CMU clips get the CMU description
        splits.add(a["split"])
    assert len(splits) > 1


def test_split_by_clip_spreads_takes_and_keeps_mirrors_with_their_original(tmp_path, capsys):
    data = tmp_path / "bandai" / "Bandai-Namco-Research-Motiondataset-1" / "data"
    data.mkdir(parents=True)
    stems = [f"dataset-1_walk_happy_{k:03d}" for k in range(1, 9)]
    for k, stem in enumerate(stems):
        bvh = canonical_bvh_text(frames=24 + 3 * k, speed=1 + 0.1 * k, names=BANDAI_NAMES | {"spine3": "unused"},
                                 skip=("spine3",))
        (data / f"{stem}.bvh").write_text(bvh)
    ids = [f"bandai/{s}" for s in stems]
    # a salt under which a per-clip hash puts the eight takes into more than one split
    seed = next(s for s in range(100) if len({split_of(i, s) for i in ids}) > 1)

    by_clip, by_group = tmp_path / "by_clip", tmp_path / "by_group"
    for out, unit in ((by_clip, "clip"), (by_group, "group")):
        assert _run("--source", f"bandai={tmp_path / 'bandai'}", "--out", str(out), "--workers", "1",
                    "--seed", str(seed), "--split-by", unit) == 0
    assert "splits (by clip)" in capsys.readouterr().out
    clip_rec = {r["id"]: r for r in map(json.loads, (by_clip / "index.jsonl").read_text().splitlines())}
    group_rec = {r["id"]: r for r in map(json.loads, (by_group / "index.jsonl").read_text().splitlines())}
    assert len(clip_rec) == len(group_rec) == 16  # eight takes and their mirrors
    assert len({group_rec[i]["split"] for i in ids}) == 1  # one content+style group: one split
    assert len({clip_rec[i]["split"] for i in ids}) > 1
    for i in ids:
        assert clip_rec[i]["split"] == split_of(i, seed)
        assert clip_rec[f"mirror/{i}"]["split"] == clip_rec[i]["split"]
    summary = json.loads((by_clip / "summary.json").read_text())
    assert summary["command"]["split_by"] == "clip" and summary["split_by"] == "clip"
    # mean/std follow the split: over the train clips of this split only
    train = PreparedDataset(by_clip, "train")
    if train.clip_ids:
        feats = np.concatenate([train.features(c) for c in train.clip_ids]).astype(np.float64)
        np.testing.assert_allclose(np.load(by_clip / "mean.npy"), feats.mean(0), atol=1e-4)

    with pytest.raises(SystemExit):
        _run("--source", f"bandai={tmp_path / 'bandai'}", "--out", str(tmp_path / "x"), "--split-by", "take")
    assert "invalid choice: 'take'" in capsys.readouterr().err
    from motok_robot.data.prepare import PrepareConfig, prepare

    with pytest.raises(InputError, match="split_by 'take'"):
        prepare(PrepareConfig(sources=[("bandai", str(tmp_path / "bandai"))], out=str(tmp_path / "y"), split_by="take"))
    assert not (tmp_path / "y").exists()

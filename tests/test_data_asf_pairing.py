"""Issue 46 item 11: an AMC takes the ASF whose name is the longest prefix of its own; skipped
files are listed with the reason; ``data prepare`` fails when too many are skipped."""

import json

import pytest

from motok_robot.cli import main
from motok_robot.data.sources import skeleton_for
from test_data_fixtures import cmu_like_amc, cmu_like_asf


@pytest.mark.parametrize("amc, asfs, expected", [
    ("HDM_tr_squat1Reps_001_120", {"HDM_tr", "HDM_bd", "HDM_mm"}, "HDM_tr"),
    ("HDM_tr_squat1Reps_001_120", {"HDM", "HDM_tr"}, "HDM_tr"),  # the longest prefix
    ("07_01", {"07", "08"}, "07"),
    ("10_01", {"1", "2"}, None),  # a prefix must end at a separator
    ("10_01", {"1"}, "1"),  # the only skeleton of the folder
    ("walk", {"walk"}, "walk"),
    ("HDM_xx_walk", {"HDM_tr", "HDM_bd"}, None),
])
def test_skeleton_is_the_longest_prefix(amc, asfs, expected):
    assert skeleton_for(amc, asfs) == expected


def hdm_folder(root, orphans=0):
    folder = root / "hdm"
    folder.mkdir(parents=True)
    for s, subject in enumerate(("HDM_tr", "HDM_bd")):
        (folder / f"{subject}.asf").write_text(cmu_like_asf())
        for take in (1, 2):  # different lengths: not duplicates of each other
            (folder / f"{subject}_squat1Reps_00{take}_120.amc").write_text(cmu_like_amc(frames=60 + 9 * (2 * s + take)))
    for k in range(orphans):
        (folder / f"XYZ_walk_00{k}_120.amc").write_text(cmu_like_amc(frames=50 + k))
    return root


def test_prepare_pairs_multi_part_subject_prefixes(tmp_path, capsys):
    # before: every AMC here was skipped with "several .asf files and none named after it"
    src = hdm_folder(tmp_path / "src")
    out = tmp_path / "out"
    assert main(["data", "prepare", "--source", f"asf={src}", "--out", str(out), "--workers", "1",
                 "--no-mirror"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["total_clips"] == 4 and summary["skipped"] == []


def test_too_many_skips_fail_unless_allowed(tmp_path, capsys):
    src = hdm_folder(tmp_path / "src", orphans=1)
    out = tmp_path / "out"
    assert main(["data", "prepare", "--source", f"asf={src}", "--out", str(out), "--workers", "1",
                 "--no-mirror"]) == 2
    captured = capsys.readouterr()
    errors = [line for line in captured.err.splitlines() if line.startswith("motok-robot: error:")]
    assert len(errors) == 1 and "1 of 5 files skipped (20%" in errors[0] and "--allow-skips" in errors[0]
    assert "XYZ_walk_000_120.amc" in captured.err and "none whose name is a prefix of its own" in captured.err
    assert not (out / "summary.json").exists()  # nothing that looks like a finished dataset
    assert main(["data", "prepare", "--source", f"asf={src}", "--out", str(out), "--workers", "1",
                 "--no-mirror", "--allow-skips", "--overwrite"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["total_clips"] == 4
    assert [s["reason"] for s in summary["skipped"]] == [
        "several .asf files (['HDM_bd', 'HDM_tr']) and none whose name is a prefix of its own"]


def test_retarget_input_picks_the_prefixed_skeleton(tmp_path):
    from retarget.io import read_mocap

    src = hdm_folder(tmp_path / "src")
    motion = read_mocap(src / "hdm" / "HDM_tr_squat1Reps_001_120.amc")
    assert motion.joints.shape[1:] == (22, 3)

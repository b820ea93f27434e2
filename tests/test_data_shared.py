"""A few real clips from every source in ../shared/datasets (skipped when that folder is absent)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from motok_robot.cli import main
from motok_robot.data import sources as S
from motok_robot.data.clip import stature
from motok_robot.data.texts import load_cmu_descriptions
from motok_robot.motion import features as F
from motok_robot.motion import skeleton

SHARED = Path(__file__).resolve().parents[2] / "shared" / "datasets"
ARCHIVES = {
    "bandai": "bandai-namco-bvh.tar.xz",
    "cmu": "cmu-asf-amc.tar.xz",
    "deepmimic": "deepmimic.tar.xz",
    "acrnn": "acrnn-bvh.tar.xz",
}
J = skeleton.JOINT_INDEX

pytestmark = [
    pytest.mark.shared,
    pytest.mark.skipif(not (SHARED / "README.md").exists(), reason=f"shared datasets not found at {SHARED}"),
]


def _clips(kind: str, n: int, want=lambda job: True):
    options = S.SourceOptions(cmu_descriptions=load_cmu_descriptions(SHARED / "cmu-descriptions.csv"))
    out = []
    for job in S.iter_jobs(kind, SHARED / ARCHIVES[kind], options):
        if isinstance(job, S.Job) and want(job):
            out += S.run_job(job, options)
        if len(out) >= n:
            break
    return out


@pytest.mark.parametrize(
    "kind, want",
    [
        ("bandai", lambda job: True),
        ("cmu", lambda job: True),
        ("acrnn", lambda job: True),
        ("deepmimic", lambda job: any(k in job.file for k in ("humanoid3d_walk.txt", "humanoid3d_run.txt", "cmu01-09/02/"))),
    ],
)
def test_real_clips_are_people_standing_on_the_floor(kind, want):
    clips = _clips(kind, 3, want)
    assert len(clips) == 3
    for c in clips:
        j = c.joints
        assert j.dtype == np.float32 and j.shape[1:] == (22, 3) and c.fps == 20
        assert c.texts, c.id
        assert 1.4 <= stature(j) <= 2.0, (c.id, stature(j))
        feet = j[:, [J["left_ankle"], J["right_ankle"], J["left_foot"], J["right_foot"]], 2]
        upright = (j[:, J["head"], 2] > j[:, J["pelvis"], 2]) & (j[:, J["pelvis"], 2] > feet.max(1))
        assert upright.mean() >= 0.9, (c.id, upright.mean())
        assert abs(np.percentile(feet.min(1), 5)) < 0.2, (c.id, np.percentile(feet.min(1), 5))


def test_prepare_real_archives_round_trip_below_1mm(tmp_path, capsys):
    out = tmp_path / "prepared"
    argv = ["data", "prepare", "--out", str(out), "--limit", "2", "--workers", "1"]
    for kind, name in ARCHIVES.items():
        argv += ["--source", f"{kind}={SHARED / name}"]
    assert main(argv) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary["sources"]) == set(ARCHIVES)
    assert all(s["clips"] >= 1 for s in summary["sources"].values())
    for line in (out / "index.jsonl").read_text().splitlines():
        rec = json.loads(line)
        name = rec["id"].replace("/", "__")
        j = np.load(out / "joints" / f"{name}.npy")
        f = np.load(out / "features" / f"{name}.npy")
        assert rec["texts"], rec["id"]
        err = np.abs(F.joints_from_features(f.astype(np.float64)) - j[:-1]).max()
        assert err < 1e-3, (rec["id"], err)

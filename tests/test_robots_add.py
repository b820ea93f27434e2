"""``motok-robot robots add MJCF --out NAME.toml``: a robot description drafted from an MJCF alone.

The shipped Booster T1 (models/mjcf/t1.xml) with its keypoint and sole sites stripped stands for an
unknown humanoid: the draft must load, agree with the hand-written t1.toml, and retarget a walk.
"""

from __future__ import annotations

import hashlib
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import mujoco
import numpy as np
import pytest

from motok_robot.cli import main
from motok_robot.motion import skeleton as sk
from motok_robot.motion.synthetic import walking_clip
from motok_robot.robots import load, models_dir
from motok_robot.robots.draft import draft

SHARED_T1 = Path(__file__).resolve().parents[1] / ".." / "shared" / "robots" / "booster_t1.tar.xz"


def strip_sites(src: Path, dest: Path, keep=("imu",)) -> Path:
    """A copy of ``src`` without its sites (except ``keep`` and those sensors use), asset folders
    pointing back at ``src``'s."""
    tree = ET.parse(src)
    root = tree.getroot()
    keep = set(keep) | {e.get(k) for e in root.iter() if e.tag != "site" for k in ("site", "objname") if e.get(k)}
    for parent in root.iter():
        for child in list(parent):
            if child.tag == "site" and child.get("name") not in keep:
                parent.remove(child)
    comp = root.find("compiler")
    for key in ("meshdir", "texturedir"):
        if comp is not None and comp.get(key):
            comp.set(key, str((src.parent / comp.get(key)).resolve()))
    dest.parent.mkdir(parents=True, exist_ok=True)
    tree.write(dest)
    return dest


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def t1_draft(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("t1")
    bare = strip_sites(models_dir() / "t1.xml", tmp / "src" / "t1_bare.xml")
    before = digest(bare)
    result = draft(bare, tmp / "out" / "mybot.toml")
    assert digest(bare) == before  # the user's file is never written
    return result


def test_t1_draft_loads_with_all_keypoints_and_soles(t1_draft):
    assert t1_draft.load_error is None and t1_draft.copied
    robot = load(t1_draft.toml_path)
    assert robot.mjcf_path == t1_draft.toml_path.with_suffix(".xml")
    assert robot.torso_body == "Trunk" and robot.nj == 23
    human = {k.human_joint for k in robot.keypoints}
    assert human == {k.human_joint for k in load("t1").keypoints}
    assert robot.soles["left"].body == "left_foot_link" and robot.soles["right"].body == "right_foot_link"
    np.testing.assert_allclose(robot.soles["left"].half_size, (0.1115, 0.05), atol=1e-4)
    lo, hi = robot.description.mass_range
    assert lo <= robot.total_mass() <= hi
    lo, hi = robot.description.height_range
    assert lo <= robot.height() <= hi
    # only the velocity limits (not in the MJCF) and the wrist-less hands are named for editing
    whats = " | ".join(u.what for u in t1_draft.unsure)
    assert len(t1_draft.unsure) == 3 and "velocity" in whats and whats.count("hand site is a guess") == 2
    for u in t1_draft.unsure:
        path = t1_draft.toml_path.parent / u.file
        assert path.read_text().splitlines()[u.line - 1].strip() == u.text.strip()


def test_t1_draft_sites_agree_with_the_hand_written_description(t1_draft):
    draft_robot, shipped = load(t1_draft.toml_path), load("t1")

    def sites(robot, qpos):
        d = mujoco.MjData(robot.model)
        d.qpos[:] = qpos
        mujoco.mj_kinematics(robot.model, d)
        out = {k.human_joint: d.site(k.site).xpos.copy() for k in robot.keypoints}
        out.update({f"{side}_{i}": d.site(c).xpos.copy() for side, s in robot.soles.items()
                    for i, c in enumerate(s.corner_sites)})
        return out

    zero = np.zeros(23)
    a, b = sites(draft_robot, draft_robot.qpos_from_joints(zero)), sites(shipped, shipped.qpos_from_joints(zero))
    tolerance = {"pelvis": 0.03, "spine3": 0.03, "neck": 0.07, "head": 0.04, "left_wrist": 0.03, "right_wrist": 0.03}
    for name in a:
        assert np.linalg.norm(a[name] - b[name]) < tolerance.get(name, 0.012), name
    for limb, value in shipped.limb_scale.items():
        assert draft_robot.limb_scale[limb] == pytest.approx(value, rel=0.06), limb
    # the drafted nominal pose: knees bent, soles flat on the floor, ankles under the hips, arms lowered
    q = draft_robot.nominal_qpos()
    d = mujoco.MjData(draft_robot.model)
    d.qpos[:] = q
    mujoco.mj_kinematics(draft_robot.model, d)
    for side, sole in draft_robot.soles.items():
        z = [d.site(s).xpos[2] for s in (sole.site, *sole.corner_sites)]
        np.testing.assert_allclose(z, 0.0, atol=1e-4, err_msg=side)
    nominal = draft_robot.description.nominal_pose
    assert nominal["Left_Knee_Pitch"] == pytest.approx(0.4) and nominal["Right_Knee_Pitch"] == pytest.approx(0.4)
    assert nominal["Left_Shoulder_Roll"] < -1.2 and nominal["Right_Shoulder_Roll"] > 1.2
    assert draft_robot.servos == []


def test_t1_draft_retargets_a_walk(t1_draft, tmp_path, capsys):
    motion = tmp_path / "walk.npz"
    np.savez(motion, joints=walking_clip(frames=30, fps=20.0).astype(np.float32), fps=20)
    errors = {}
    for label, robot in (("draft", str(t1_draft.toml_path)), ("shipped", "t1")):
        out = tmp_path / f"{label}.npz"
        assert main(["retarget", str(motion), "--robot", robot, "--out", str(out), "--window", "15", "--overlap", "5",
                     "--no-self-collision"]) == 0
        text = capsys.readouterr().out
        errors[label] = float(text.split("keypoint error mean ")[1].split(" cm")[0])
    assert errors["draft"] < errors["shipped"] + 1.5, errors


def test_check_image_is_written(t1_draft):
    import imageio.v3 as iio

    image = iio.imread(t1_draft.image_path)
    assert image.shape == (800, 1280, 3) and image.std() > 10


def test_dynamixel_like_actuators_get_a_servo_map_to_verify(tmp_path):
    bare = strip_sites(models_dir() / "op3_like.xml", tmp_path / "src" / "kid.xml")
    result = draft(bare, tmp_path / "kid.toml", render=None)
    assert result.load_error is None
    robot = load(result.toml_path)
    assert len(robot.servos) == 20 and {s.model for s in robot.servos} == {"XM430-W350"}
    assert sorted(s.id for s in robot.servos) == list(range(1, 21))
    text = result.toml_path.read_text()
    assert "VERIFY" in text and "[bus]" in text
    assert any("verify each on the robot" in u.what for u in result.unsure)
    # op3_like's own description: the same feet, nominal flat soles
    assert robot.soles["left"].body == "l_foot" and robot.soles["right"].body == "r_foot"
    assert robot.limb_scale["legs"] == pytest.approx(load("op3_like").limb_scale["legs"], rel=0.03)


def test_cli_add_prints_the_inferred_and_the_lines_to_edit(tmp_path, capsys):
    bare = strip_sites(models_dir() / "t1.xml", tmp_path / "src" / "t1.xml")
    assert main(["robots", "add", str(bare), "--out", str(tmp_path / "bot.toml"), "--no-render"]) == 0
    out = capsys.readouterr().out
    assert "left leg: Hip_Pitch_Left" in out and "could not infer (3)" in out
    assert "bot.toml:" in out and "default = 10.0" in out
    # a second run does not overwrite the draft unless told to
    assert main(["robots", "add", str(bare), "--out", str(tmp_path / "bot.toml"), "--no-render"]) == 2
    assert "exists; pass --force" in capsys.readouterr().err
    assert main(["robots", "add", str(bare), "--out", str(tmp_path / "bot.toml"), "--no-render", "--force"]) == 0


def test_the_copy_never_replaces_the_input(tmp_path, capsys):
    bare = strip_sites(models_dir() / "t1.xml", tmp_path / "bot.xml")
    before = digest(bare)
    assert main(["robots", "add", str(bare), "--out", str(tmp_path / "bot.toml"), "--no-render", "--force"]) == 2
    assert "would overwrite the input" in capsys.readouterr().err
    assert digest(bare) == before


BAD = {
    "no-free-joint": ("<mujoco><worldbody><body name='a'><joint name='j' type='hinge'/><geom size='0.1'/></body>"
                      "</worldbody></mujoco>", r"no free joint"),
    "one-leg": ("<mujoco><worldbody><body name='base' pos='0 0 1'><freejoint/><geom size='0.1'/>"
                "<body name='leg' pos='0 0.1 -0.3'><joint name='hip' axis='0 1 0' range='-1 1'/>"
                "<geom type='capsule' fromto='0 0 0 0 0 -0.3' size='0.03'/>"
                "<body name='foot' pos='0 0 -0.35'><joint name='ankle' axis='0 1 0' range='-1 1'/>"
                "<geom type='box' size='0.08 0.04 0.01'/></body></body></body></worldbody></mujoco>",
                r"found one leg only"),
    "unparsable": ("<mujoco><worldbody><body>", r"not valid XML"),
    "not-mujoco": ("<mujoco><worldbody><body><geom type='box'/></worldbody></mujoco>", r"not valid XML|cannot compile"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_mjcf_is_one_line_naming_the_file(case, tmp_path, capsys):
    text, pattern = BAD[case]
    path = tmp_path / f"{case}.xml"
    path.write_text(text)
    assert main(["robots", "add", str(path), "--out", str(tmp_path / "x.toml"), "--no-render"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith(f"motok-robot: error: {case}.xml"), err
    import re

    assert re.search(pattern, err), err


def test_missing_file(tmp_path, capsys):
    assert main(["robots", "add", str(tmp_path / "nope.xml"), "--out", str(tmp_path / "x.toml")]) == 2
    assert "nope.xml: MJCF file not found" in capsys.readouterr().err


@pytest.mark.skipif(not SHARED_T1.is_file(), reason="needs ../shared/robots/booster_t1.tar.xz")
def test_menagerie_t1_as_published(tmp_path):
    subprocess.run(["tar", "-xJf", str(SHARED_T1), "-C", str(tmp_path)], check=True)
    src = tmp_path / "booster_t1" / "t1.xml"
    result = draft(src, tmp_path / "out" / "t1m.toml", render=None)
    assert result.load_error is None
    robot = load(result.toml_path)
    assert len(robot.keypoints) == 18
    assert robot.model.geom("floor").type == mujoco.mjtGeom.mjGEOM_PLANE and robot.model.camera("track")
    assert abs(robot.lowest_sole_height(robot.nominal_qpos())) < 1e-9
    assert {k.human_joint for k in robot.keypoints} >= {"pelvis", "neck", "head", "left_wrist", "right_foot"}
    assert sk.JOINT_NAMES  # canonical names only (checked by load)

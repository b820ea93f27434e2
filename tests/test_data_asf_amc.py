"""Acclaim ASF/AMC reader: units, axes, FK against hand-computed points, malformed files."""

from __future__ import annotations

import numpy as np
import pytest
from test_data_fixtures import cmu_like_amc, cmu_like_asf

from motok_robot.data import asf_amc
from motok_robot.errors import InputError
from motok_robot.motion import skeleton

TWO_BONES = """:version 1.10
:units
  mass 1.0
  length 0.45
  angle deg
:root
   order TX TY TZ RX RY RZ
   axis XYZ
   position 0 0 0
   orientation 0 0 0
:bonedata
  begin
     id 1
     name a
     direction 0 1 0
     length 0.45
     axis 0 0 90 XYZ
    dof rx
  end
  begin
     id 2
     name b
     direction 1 0 0
     length 0.9
     axis 0 0 0 XYZ
    dof rz
  end
:hierarchy
  begin
    root a
    a b
  end
"""


def test_fk_hand_computed_and_inch_units(tmp_path):
    asf = tmp_path / "t.asf"
    asf.write_text(TWO_BONES)
    amc = tmp_path / "t_01.amc"
    amc.write_text(":FULLY-SPECIFIED\n:DEGREES\n1\nroot 0 0 0 0 0 0\na 90\nb 0\n2\nroot 0 0 0 0 0 0\na 0\nb 90\n")
    skel = asf_amc.read_asf(asf)
    assert skel.units_to_m == pytest.approx(0.0254 / 0.45)
    pos = asf_amc.forward_kinematics(skel, asf_amc.read_amc(amc, skel))
    # bone a: 1 inch (0.45 units) up; its frame C = Rz(90) so "rx 90" turns about world y
    np.testing.assert_allclose(pos["a_end"][0], [0, 0.45, 0], atol=1e-9)
    np.testing.assert_allclose(pos["b"][0], [0, 0.45, 0], atol=1e-9)
    # bone b (2 inches along +x) turned 90 deg about world y -> along -z
    np.testing.assert_allclose(pos["b_end"][0], [0, 0.45, -0.9], atol=1e-9)
    # frame 1: b turned 90 deg about z -> along +y
    np.testing.assert_allclose(pos["b_end"][1], [0, 1.35, 0], atol=1e-9)


def test_cmu_like_pair_gives_upright_body_in_metres(tmp_path):
    asf = tmp_path / "07.asf"
    asf.write_text(cmu_like_asf())
    amc = tmp_path / "07_01.amc"
    amc.write_text(cmu_like_amc(frames=121, knee_deg=0.0, speed=1.0))
    clip = asf_amc.load_clip(asf, amc, fps=120.0, source="asf")
    assert clip.joints.shape == (21, 22, 3)  # 1 s at 120 fps -> 21 frames at 20 fps
    assert clip.derived_joints == ["left_collar", "right_collar"]
    J = skeleton.JOINT_INDEX
    rest = skeleton.rest_pose()
    # legs straight at frame 0 -> exactly the canonical leg; metres, z up, forward +x
    for name in ("left_hip", "left_knee", "left_ankle", "right_ankle", "head", "left_wrist"):
        np.testing.assert_allclose(clip.joints[0, J[name]], rest[J[name]], atol=2e-4)
    np.testing.assert_allclose(clip.joints[-1, 0] - clip.joints[0, 0], [1.0, 0, 0], atol=1e-4)


def test_untracked_leading_frames_are_trimmed(tmp_path):
    asf = tmp_path / "07.asf"
    asf.write_text(cmu_like_asf())
    amc = tmp_path / "07_02.amc"
    amc.write_text(cmu_like_amc(frames=121, untracked_lead=24))
    skel = asf_amc.read_asf(asf)
    assert asf_amc.untracked_ends(asf_amc.read_amc(amc, skel)) == (24, 0)
    clip = asf_amc.load_clip(asf, amc, fps=120.0)
    assert clip.labels["trimmed_untracked_frames"] == [24, 0]
    assert clip.joints.shape[0] == 17  # (120 - 24) / 120 s -> 96/6 + 1 frames at 20 fps
    amc.write_text(cmu_like_amc(frames=121))
    assert asf_amc.untracked_ends(asf_amc.read_amc(amc, skel)) == (0, 0)


def test_amc_errors_name_frame_and_bone(tmp_path):
    asf = tmp_path / "s.asf"
    asf.write_text(cmu_like_asf())
    skel = asf_amc.read_asf(asf)
    good = cmu_like_amc(frames=3)
    cases = [
        (good.replace("ltibia 30.0000", "ltibia 30.0000 5", 1), r"frame 0: bone 'ltibia' has 2 values, the ASF declares 1 dof"),
        (good.replace("ltibia 30.0000", "ltibia nan", 1), r"frame 0: bone 'ltibia' has a NaN"),
        (good.replace("rhumerus 0.0001 0 0", "rtail 0 0 0", 1), r"frame 0: unknown bone 'rtail'"),
        (good.rsplit("\n", 3)[0] + "\n", r"frame 2: bone '.*' missing \(truncated motion\?\)"),
        (":FULLY-SPECIFIED\n:DEGREES\n", r"AMC has zero frames"),
    ]
    for i, (text, pattern) in enumerate(cases):
        f = tmp_path / f"bad{i}.amc"
        f.write_text(text)
        with pytest.raises(InputError, match=rf"bad{i}\.amc: {pattern}"):
            asf_amc.read_amc(f, skel)


def test_asf_errors(tmp_path):
    f = tmp_path / "x.asf"
    f.write_text(TWO_BONES.replace("    a b\n", "    a c\n"))
    with pytest.raises(InputError, match=r"x\.asf: :hierarchy names unknown bone 'c'"):
        asf_amc.read_asf(f)
    f.write_text(TWO_BONES.split(":hierarchy")[0])
    with pytest.raises(InputError, match=r"no :hierarchy section"):
        asf_amc.read_asf(f)
    f.write_text(TWO_BONES.replace("angle deg", "angle grad"))
    with pytest.raises(InputError, match=r":units angle must be deg or rad"):
        asf_amc.read_asf(f)


def test_radians_and_length_scale(tmp_path):
    asf = tmp_path / "r.asf"
    text = TWO_BONES.replace("angle deg", "angle rad").replace("length 0.45\n  angle", "length 1.0\n  angle")
    asf.write_text(text.replace("axis 0 0 90 XYZ", f"axis 0 0 {np.pi / 2} XYZ"))  # axis angles are radians too
    amc = tmp_path / "r.amc"
    amc.write_text(f"1\nroot 0 0 0 0 0 0\na {np.pi / 2}\nb 0\n")
    skel = asf_amc.read_asf(asf)
    assert skel.units_to_m == pytest.approx(0.0254)
    pos = asf_amc.forward_kinematics(skel, asf_amc.read_amc(amc, skel))
    np.testing.assert_allclose(pos["b_end"][0], [0, 0.45, -0.9], atol=1e-9)

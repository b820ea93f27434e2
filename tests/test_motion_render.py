"""Stick-figure renderer: files are written, readable, and have one frame per pose."""

from __future__ import annotations

import imageio.v2 as imageio2
import imageio.v3 as iio
import numpy as np
import pytest

from motok_robot.errors import InputError
from motok_robot.motion import render, synthetic


@pytest.fixture(scope="module")
def clip():
    return synthetic.walking_clip(6)


def test_mp4_has_one_frame_per_pose(tmp_path, clip):
    out = render.render_stick_figure(clip, tmp_path / "walk.mp4", fps=20, title="walk")
    reader = imageio2.get_reader(out, format="FFMPEG")
    try:
        assert reader.count_frames() == 6
        assert reader.get_meta_data()["fps"] == pytest.approx(20)
        frame = reader.get_data(0)
    finally:
        reader.close()
    assert frame.shape == (480, 480, 3)
    assert frame.std() > 1  # not a blank image


def test_gif_side_by_side_uses_the_longest_motion(tmp_path, clip):
    still = synthetic.standing_clip(3)  # shorter: holds its last pose
    out = render.render_stick_figure([clip, still], tmp_path / "two.gif", labels=["walk", "stand"], trail=False)
    frames = iio.imread(out, index=None)
    assert frames.shape[0] == 6
    assert frames.shape[1:3] == (480, 960)
    # the figure moves between frames in the left panel
    assert np.abs(frames[0, :, :480].astype(int) - frames[5, :, :480].astype(int)).sum() > 0


def test_summary_png(tmp_path, clip):
    out = render.plot_motion_summary(synthetic.walking_clip(40), tmp_path / "sub" / "summary.png", title="walk")
    image = iio.imread(out)
    assert image.shape[0] == 420 and image.shape[1] == 1000


def test_render_errors(tmp_path, clip):
    with pytest.raises(InputError, match=r"\.mp4 or \.gif"):
        render.render_stick_figure(clip, tmp_path / "x.avi")
    with pytest.raises(InputError, match=r"joints\[1\]"):
        render.render_stick_figure([clip, np.zeros((3, 21, 3))], tmp_path / "x.gif")
    with pytest.raises(InputError, match="labels"):
        render.render_stick_figure([clip], tmp_path / "x.gif", labels=["a", "b"])
    with pytest.raises(InputError, match=r"\.png"):
        render.plot_motion_summary(clip, tmp_path / "x.jpg")

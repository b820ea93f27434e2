"""Issue 46 items 4, 6, 10: a motion file's fps is honoured by ``run --motion``; prompt files
are read as documented; error messages point at the user's problem, not at unsafe options."""

import numpy as np
import pytest

from motok_robot.errors import InputError
from motok_robot.motion.features import features_from_joints
from motok_robot.motion.synthetic import walking_clip


# ---------------------------------------------------------------------------------- item 4
def test_run_motion_honours_the_fps_of_a_motion_npz_with_features(tmp_path):
    from motok_robot.pipeline import load_source_motion

    joints = walking_clip(frames=181, fps=60).astype(np.float32)  # 3 s at 60 fps
    features = features_from_joints(joints).astype(np.float32)
    np.savez(tmp_path / "m60.npz", joints=joints, features=features, fps=np.float64(60.0), text="a walk")
    source = load_source_motion(tmp_path / "m60.npz")
    # before: the 181 frames were taken as 20 fps (9 s, three times slower)
    assert abs(source.seconds - 3.0) < 0.1 and source.fps == 20
    assert source.text == "a walk"
    np.savez(tmp_path / "m20.npz", joints=joints[::3], features=features[::3], fps=np.float64(20.0))
    assert len(load_source_motion(tmp_path / "m20.npz").joints) == len(joints[::3])


def test_run_motion_checks_the_fields_of_a_motion_npz(tmp_path):
    from motok_robot.pipeline import load_source_motion

    joints = walking_clip(frames=21).astype(np.float32)
    np.savez(tmp_path / "bad.npz", joints=joints, features=np.zeros((20, 7), np.float32), fps=20.0)
    with pytest.raises(InputError, match=r"bad.npz: field 'features' must be a float array \[T, 263\]"):
        load_source_motion(tmp_path / "bad.npz")
    np.savez(tmp_path / "fps.npz", joints=joints, features=features_from_joints(joints), fps=np.array([20.0, 30.0]))
    with pytest.raises(InputError, match=r"fps.npz: field 'fps' must be one number"):
        load_source_motion(tmp_path / "fps.npz")

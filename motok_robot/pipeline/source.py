"""A motion read from a file instead of generated (``run --motion``)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from motok_robot.errors import InputError


@dataclass
class SourceMotion:
    """A motion read from a file instead of generated (``run --motion``): a ``motion.npz``, or a
    mocap file (BVH / ASF+AMC / DeepMimic JSON) put on the canonical skeleton with its features."""

    joints: np.ndarray  #: float32 [T, 22, 3] metres, z up
    features: np.ndarray  #: float32 [T, 263]
    text: str
    model: str
    fps: int = 20
    seed: int = 0

    @property
    def seconds(self) -> float:
        return self.joints.shape[0] / self.fps

    def save(self, path) -> Path:
        from motok_robot.planner.motion_file import save_motion

        return save_motion(path, self.joints, self.features, np.zeros(0, np.int64), self.text, self.seed,
                           self.model, self.fps)


def load_source_motion(path, skeleton: str = "bandai", asf=None) -> SourceMotion:
    """Read ``--motion``: ``motion.npz`` as it is; a mocap file through the data importers
    (20 fps) and :func:`~motok_robot.motion.features.normalise_joints` (canonical bones, floor at
    z = 0, facing +x), with joints recovered from its features so the two agree frame by frame."""
    from motok_robot.motion.features import features_from_joints, joints_from_features
    from retarget.io import read_input

    p = Path(path)
    text, model = f"motion:{p.name}", f"file:{p.name}"
    if p.suffix.lower() == ".npz":
        from motok_robot.npz_files import read_npz_fields
        from retarget.io import read_motion_npz

        data = read_npz_fields(p, "motion file")
        human = read_motion_npz(p)  # joints [T, 22, 3], fps and the size bounds checked, as retarget does
        text = str(data["text"]) if "text" in data and data["text"].size == 1 and str(data["text"]) else text
        model = str(data["model"]) if "model" in data and data["model"].size == 1 and str(data["model"]) else model
        features = np.asarray(data["features"]) if "features" in data else None
        if features is not None and abs(human.fps - 20.0) <= 1e-6:  # as generated: used as it is
            if features.ndim != 2 or features.shape[1] != 263 or features.dtype.kind != "f":
                raise InputError(f"{p}: field 'features' must be a float array [T, 263], got shape {features.shape} "
                                 f"({features.dtype})")
            if not np.isfinite(features).all():
                frame = int(np.argwhere(~np.isfinite(features))[0][0])
                raise InputError(f"{p}: field 'features' is not finite (NaN or inf) at frame {frame}: fix the file")
            return SourceMotion(np.asarray(human.joints, np.float32), features.astype(np.float32), text, model)
        # at another frame rate the saved features (defined at 20 fps) do not apply: resample the
        # joints (the file's fps is honoured, as retarget honours it) and recompute them
    else:
        human = read_input(p, skeleton=skeleton, asf=asf)
    if abs(human.fps - 20.0) > 1e-6:
        from motok_robot.motion.features import resample

        human.joints = resample(human.joints, human.fps, 20.0)
    features = features_from_joints(human.joints)
    joints = joints_from_features(features).astype(np.float32)
    return SourceMotion(joints, features.astype(np.float32), text, model)

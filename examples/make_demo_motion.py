"""Write ``examples/wave_demo.npz``: a procedural 6 s "stand and wave the right hand" motion.

It is built by forward kinematics on the canonical body (no motion capture and no trained
model involved), so ``motok-robot run --motion examples/wave_demo.npz`` exercises
retargeting, validation and playback on a fresh clone. Run ``python examples/make_demo_motion.py``
to rebuild it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from motok_robot.motion import skeleton
from motok_robot.motion.features import features_from_joints, joints_from_features
from motok_robot.motion.rotations import rotation_about_axis
from motok_robot.motion.synthetic import forward_kinematics

J = skeleton.JOINT_INDEX


def wave_motion(seconds: float = 6.0, fps: int = skeleton.FPS) -> np.ndarray:
    """Joints ``[T + 1, 22, 3]`` (metres, z up): stand, raise the right arm, wave, lower it."""
    frames = int(round(seconds * fps)) + 1
    t = np.arange(frames) / fps
    rot = np.tile(np.eye(3), (frames, skeleton.NUM_JOINTS, 1, 1))
    # arms hang by the sides (the rest pose is a T-pose with the arms along +-y)
    rot[:, J["left_shoulder"]] = rotation_about_axis(np.full(frames, -1.25), 0)
    # the right arm rises to ~60 deg above horizontal over 1 s, waves for 4 s, comes down over 1 s
    envelope = np.clip(np.minimum(t / 1.0, (seconds - t) / 1.0), 0.0, 1.0)
    envelope = 0.5 - 0.5 * np.cos(np.pi * envelope)  # smooth in and out
    shoulder = 1.25 - envelope * (1.25 + 1.0)  # +1.25 hangs down, -1.0 raises the arm
    rot[:, J["right_shoulder"]] = rotation_about_axis(shoulder, 0)
    wave = envelope * (0.9 + 0.45 * np.sin(2 * np.pi * 1.2 * t))  # forearm swings side to side
    rot[:, J["right_elbow"]] = rotation_about_axis(-wave, 0)
    # a little weight shift and breathing
    rot[:, J["spine3"]] = rotation_about_axis(0.03 * np.sin(2 * np.pi * 0.25 * t), 1)
    root = np.tile(skeleton.rest_pose()[0], (frames, 1))
    root[:, 1] += 0.01 * np.sin(2 * np.pi * 0.3 * t)
    return forward_kinematics(rot, root)


def main() -> None:
    features = features_from_joints(wave_motion())
    joints = joints_from_features(features).astype(np.float32)
    out = Path(__file__).resolve().parent / "wave_demo.npz"
    np.savez_compressed(out, joints=joints, features=features.astype(np.float32), fps=np.int64(20),
                        text=np.str_("a person waves the right hand (procedural demo)"), tokens=np.zeros(0, np.int64),
                        seed=np.int64(0), model=np.str_("procedural:examples/make_demo_motion.py"))
    print(f"wrote {out} ({len(joints)} frames)")


if __name__ == "__main__":
    main()

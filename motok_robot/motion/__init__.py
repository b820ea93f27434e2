"""Motion representation: the canonical 22-joint body and HumanML3D's 263-d features.

``features_from_joints`` and the numpy ``joints_from_features`` need only numpy;
``joints_from_features_torch`` (batched, differentiable) imports torch on first use.
"""

from motok_robot.motion.skeleton import (  # noqa: F401
    FPS,
    JOINT_INDEX,
    JOINT_NAMES,
    NUM_JOINTS,
    PARENTS,
)

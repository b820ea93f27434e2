"""Motion representation: the canonical 22-joint body and HumanML3D's 263-d features.

Everything exported here needs only numpy. The batched, differentiable torch decoder lives in
:mod:`motok_robot.motion.features_torch` (import it explicitly; it is not imported here).
"""

from motok_robot.motion.features import (  # noqa: F401
    FEATURE_DIM,
    FEATURE_SLICES,
    features_from_joints,
    joints_from_features,
    normalise_joints,
    resample,
    root_from_features,
)
from motok_robot.motion.skeleton import (  # noqa: F401
    FPS,
    JOINT_INDEX,
    JOINT_NAMES,
    NUM_JOINTS,
    PARENTS,
)

"""Validation of robot trajectories in MuJoCo (issue 7): kinematic checks, inverse dynamics,
balance, a physics rollout, a pass/fail report with plots and a side-by-side video.

Entry points: :func:`motok_robot.sim.validate.validate_file`,
:func:`motok_robot.sim.validate.validate_trajectory`, the CLI ``motok-robot validate``
(:mod:`motok_robot.sim.cli`).  Thresholds: :class:`motok_robot.sim.config.ValidationConfig`.
No torch.
"""

import os as _os

# MuJoCo picks its OpenGL backend when first imported; the video is rendered headless.
_os.environ.setdefault("MUJOCO_GL", "egl")

"""Stage 5, feasibility: make a kinematic robot trajectory executable in physics.

* :mod:`~motok_robot.feasibility.balance`: the closed-loop balance controller (torso IMU
  feedback at the servo rate) and its per-trajectory plan; the same code runs in the
  validation rollout and in playback on a rig.
* :mod:`~motok_robot.feasibility.physics`: the robot with its servos and IMU, stepped tick by
  tick with the controller in the loop.
* :mod:`~motok_robot.feasibility.zmp_shift`, :mod:`~motok_robot.feasibility.refine`,
  :mod:`~motok_robot.feasibility.stage`: the CoM path, the sampling-based refinement and the
  stage that chains them (``motok-robot feasible``).
* :mod:`~motok_robot.feasibility.config`: settings.

Imports robots (stage 4's robot models) and nothing from validation or playback.  The names
below load on first use, so importing the package (the CLI does) does not import MuJoCo: a
command may still choose the headless renderer (``MUJOCO_GL``) before MuJoCo loads.
"""

import importlib

_WHERE = {
    "BalanceConfig": "config",
    "BalanceController": "balance",
    "BalancePlan": "balance",
    "build_plan": "balance",
}

__all__ = sorted(_WHERE)


def __getattr__(name: str):
    if name in _WHERE:
        return getattr(importlib.import_module(f"motok_robot.feasibility.{_WHERE[name]}"), name)
    raise AttributeError(f"module 'motok_robot.feasibility' has no attribute {name!r}")

"""Stage 5, feasibility: make a kinematic robot trajectory executable in physics.

* :mod:`~motok_robot.feasibility.balance`: the closed-loop balance controller (torso IMU
  feedback at the servo rate) and its per-trajectory plan; the same code runs in the
  validation rollout and in playback on a rig.
* :mod:`~motok_robot.feasibility.physics`: the robot with its servos and IMU, stepped tick by
  tick with the controller in the loop.
* :mod:`~motok_robot.feasibility.config`: settings.

Imports robots (stage 4's robot models) and nothing from validation or playback.
"""

from motok_robot.feasibility.balance import BalanceController, BalancePlan, build_plan
from motok_robot.feasibility.config import BalanceConfig

__all__ = ["BalanceConfig", "BalanceController", "BalancePlan", "build_plan"]

"""Robot models: MJCF + description (keypoint map, soles, nominal pose, servo map). No torch.

>>> from motok_robot.robots import load, list_robots
>>> robot = load("op3_like")   # models/mjcf/op3_like.{xml,toml}
"""

from motok_robot.robots.description import (
    BusSpec,
    Keypoint,
    RobotDescription,
    ServoSpec,
    Sole,
    check_against_model,
    parse_description,
)
from motok_robot.robots.robot import DEFAULT_ROBOT, MODELS_ENV, Robot, list_robots, load, models_dir

__all__ = [
    "BusSpec",
    "DEFAULT_ROBOT",
    "Keypoint",
    "MODELS_ENV",
    "Robot",
    "RobotDescription",
    "ServoSpec",
    "Sole",
    "check_against_model",
    "list_robots",
    "load",
    "models_dir",
    "parse_description",
]

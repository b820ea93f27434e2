"""The state of one draft: the compiled model and everything inferred from it, put together from
the body plan, site placement, joint limits and nominal pose (one module each)."""

from __future__ import annotations

from pathlib import Path

from motok_robot.robots.draft.body import BodyPlan
from motok_robot.robots.draft.limits import JointLimits
from motok_robot.robots.draft.model import MjcfModel
from motok_robot.robots.draft.pose import KNEE_BEND, NominalPose
from motok_robot.robots.draft.sites import Site, SitePlacement


class Drafter(BodyPlan, SitePlacement, JointLimits, NominalPose):
    """One MJCF being drafted: :meth:`analyse`, :meth:`place_sites`, :meth:`joint_limits`,
    :meth:`fill_missing_ranges`, :meth:`nominal_pose`, :meth:`limb_scales`, :meth:`servo_guess`."""

    def __init__(self, mjcf: Path, name: str, knee_bend: float = KNEE_BEND):
        self.src = mjcf
        self.name = name
        self.knee_bend = knee_bend
        self.M = MjcfModel(mjcf)
        self.sites: dict[str, Site] = {}
        self.keypoints: list[tuple[str, str, float]] = []  # human joint, site, weight
        self.summary: list[str] = []
        self.unsure_xml: list[tuple[str, str]] = []  # (what, a marker to find the line in the copy)
        self.unsure_toml: list[tuple[str, str]] = []  # (what, TOML key marker)
        self.added_ranges: dict[int, tuple[float, float]] = {}
        self.comments: dict[str, list[str]] = {}

    def height(self) -> float:
        z = min(z for _, _, z in self.soles.values())
        return self.top - z

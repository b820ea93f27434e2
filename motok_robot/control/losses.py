"""Differentiable control losses on joint positions (torch).

Every loss takes joints ``[B, T, 22, 3]`` (metres, z up, from
:func:`motok_robot.motion.features_torch.joints_from_features`) and a
:class:`ConstraintTensors` and returns one value per batch element ``[B]`` in m^2 (squared
errors summed over the constrained entries and divided by their count, so terms are
comparable whatever the number of keyframes).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from motok_robot.control.constraints import Constraints
from motok_robot.motion.skeleton import JOINT_INDEX, PARENTS

FOOT_JOINTS = (JOINT_INDEX["left_foot"], JOINT_INDEX["right_foot"])
#: a foot is in contact below this height (m), the metric's threshold
FOOT_CONTACT_HEIGHT = 0.05
#: softness of the contact weight around the threshold (m)
FOOT_CONTACT_SOFTNESS = 0.01
#: joints whose lowest one carries the body (ankles and feet, as the floating metric)
SUPPORT_JOINTS = tuple(JOINT_INDEX[n] for n in ("left_ankle", "left_foot", "right_ankle", "right_foot"))
#: below this height (m) the lowest foot joint is pulled to the floor; above, the body is airborne
STANDING_HEIGHT = 0.15
#: height (m) of the lowest foot joint that counts as standing (the metric's float tolerance)
FLOAT_TOLERANCE = 0.005


@dataclass
class ConstraintTensors:
    """:class:`Constraints` as tensors on one device, broadcast over the batch."""

    targets: torch.Tensor  # [T, 22, 3]
    weight: torch.Tensor  # [T, 22, 3] 1 where a coordinate is constrained
    count: float
    circles: torch.Tensor  # [Nc, 3] cx, cy, r
    boxes: torch.Tensor  # [Nb, 5] cx, cy, sx/2, sy/2, yaw
    margin: float
    foot_physics: bool

    @classmethod
    def from_constraints(cls, c: Constraints, device: torch.device | str = "cpu", dtype: torch.dtype = torch.float32) -> "ConstraintTensors":
        weight = np.repeat(c.joint_mask[..., None], 3, axis=-1).astype(np.float32)
        # the root's height counts only where it was given
        weight[:, 0, 2] = (c.joint_mask[:, 0] & c.root_height_mask).astype(np.float32)
        circles = [(o.center[0], o.center[1], o.radius) for o in c.obstacles if o.kind == "circle"]
        boxes = [(o.center[0], o.center[1], o.size[0] / 2, o.size[1] / 2, o.yaw) for o in c.obstacles if o.kind == "box"]
        as_t = lambda a, width: torch.as_tensor(np.asarray(a, np.float32).reshape(-1, width), device=device, dtype=dtype)  # noqa: E731
        return cls(
            targets=torch.as_tensor(c.joint_targets, device=device, dtype=dtype),
            weight=torch.as_tensor(weight, device=device, dtype=dtype),
            count=float(max(weight.sum(), 1.0)),
            circles=as_t(circles, 3),
            boxes=as_t(boxes, 5),
            margin=c.obstacle_margin,
            foot_physics=c.foot_physics,
        )


def position_loss(joints: torch.Tensor, ct: ConstraintTensors) -> torch.Tensor:
    """Squared error of keyframes / root trajectory / kept joints, ``[B]``."""
    diff = (joints - ct.targets) * ct.weight
    return diff.pow(2).sum(dim=(1, 2, 3)) / ct.count


def obstacle_distance(xy: torch.Tensor, ct: ConstraintTensors) -> torch.Tensor:
    """Signed distance (m, negative inside) of points ``[..., 2]`` to the nearest obstacle ``[...]``."""
    dists = []
    if len(ct.circles):
        d = torch.linalg.norm(xy[..., None, :] - ct.circles[:, :2], dim=-1) - ct.circles[:, 2]
        dists.append(d)
    if len(ct.boxes):
        rel = xy[..., None, :] - ct.boxes[:, :2]
        c, s = torch.cos(ct.boxes[:, 4]), torch.sin(ct.boxes[:, 4])
        local = torch.stack([c * rel[..., 0] + s * rel[..., 1], -s * rel[..., 0] + c * rel[..., 1]], dim=-1)
        q = local.abs() - ct.boxes[:, 2:4]
        outside = torch.linalg.norm(q.clamp(min=0.0), dim=-1)
        inside = q.max(dim=-1).values.clamp(max=0.0)
        dists.append(outside + inside)
    if not dists:
        return torch.full(xy.shape[:-1], math.inf, device=xy.device, dtype=xy.dtype)
    return torch.cat(dists, dim=-1).min(dim=-1).values


def obstacle_loss(joints: torch.Tensor, ct: ConstraintTensors) -> torch.Tensor:
    """Squared penetration (m^2) of every joint into obstacles grown by the margin, ``[B]``."""
    if not (len(ct.circles) or len(ct.boxes)):
        return joints.new_zeros(joints.shape[0])
    depth = (ct.margin - obstacle_distance(joints[..., :2], ct)).clamp(min=0.0)
    return depth.pow(2).sum(dim=(1, 2)) / joints.shape[1]


def foot_loss(joints: torch.Tensor) -> torch.Tensor:
    """Physics terms, ``[B]``: feet in contact do not slide, feet never go below the floor
    (z = 0), and a body standing near the floor stands on it.

    The last term pulls the lowest of the four foot joints (ankles, feet) of every frame where
    it is lower than :data:`STANDING_HEIGHT` down to :data:`FLOAT_TOLERANCE` above the floor;
    higher frames (jumps) are left alone.
    """
    feet = joints[:, :, list(FOOT_JOINTS), :]
    height = feet[..., 2]
    # the contact weight is a label, not something to optimise: with its gradient the cheapest
    # way to "stop sliding" is lifting the feet above the contact height (floating feet)
    contact = torch.sigmoid((FOOT_CONTACT_HEIGHT - height.detach()) / FOOT_CONTACT_SOFTNESS)
    both = contact[:, 1:] * contact[:, :-1]
    slide = (feet[:, 1:, :, :2] - feet[:, :-1, :, :2]).pow(2).sum(-1)
    below = (-height).clamp(min=0.0).pow(2)
    lowest = joints[:, :, list(SUPPORT_JOINTS), 2].min(dim=-1).values  # [B, T]
    standing = torch.sigmoid((STANDING_HEIGHT - lowest.detach()) / FOOT_CONTACT_SOFTNESS)
    floating = standing * (lowest - FLOAT_TOLERANCE).clamp(min=0.0).pow(2)
    return (both * slide).mean(dim=(1, 2)) + below.mean(dim=(1, 2)) + floating.mean(dim=1)


_CHILDREN = list(range(1, len(PARENTS)))
_PARENTS = [PARENTS[c] for c in _CHILDREN]


def bone_loss(joints: torch.Tensor) -> torch.Tensor:
    """Squared change (m^2) of the 21 bone lengths around their per-clip median, ``[B]``.

    Joint positions from features are not tied by bones, so pulling a foot or a wrist towards
    a target could stretch the limb; the median (no gradient) is the skeleton the decoder made.
    """
    lengths = torch.linalg.norm(joints[:, :, _CHILDREN] - joints[:, :, _PARENTS], dim=-1)  # [B, T, 21]
    reference = lengths.detach().median(dim=1, keepdim=True).values
    return (lengths - reference).pow(2).mean(dim=(1, 2))


def control_loss(joints: torch.Tensor, ct: ConstraintTensors, obstacle_weight: float = 1.0, foot_weight: float = 1.0,
                 bone_weight: float = 0.0) -> torch.Tensor:
    """Sum of all active terms, ``[B]``."""
    loss = position_loss(joints, ct) + obstacle_weight * obstacle_loss(joints, ct)
    if ct.foot_physics:
        loss = loss + foot_weight * foot_loss(joints)
    if bone_weight > 0:
        loss = loss + bone_weight * bone_loss(joints)
    return loss

"""The body plan of an unknown humanoid: its size, the feet (the lowest collision bodies on each
side), the legs down to them, the arms (the deepest other chains on each side) and the head."""

from __future__ import annotations

import re

import numpy as np

from motok_robot.errors import InputError
from motok_robot.robots.draft.axes import joint_groups

#: sole points lie within this distance of the foot's lowest point, m
SOLE_TOL = 0.002
#: hinges whose axes pass within this fraction of the robot's height of each other form one group
GROUP_TOL = 0.04

_LEFT = re.compile(r"(^|[^a-z])(l|left|lft)([^a-z]|$)|left", re.I)
_RIGHT = re.compile(r"(^|[^a-z])(r|right|rgt)([^a-z]|$)|right", re.I)


def name_side(name: str) -> str | None:
    """'left' / 'right' from a name (``l_knee``, ``Left_Hip``, ``knee_L``, ``leftFoot``), else None."""
    snake = re.sub(r"([a-z])([A-Z])", r"\1_\2", name or "")
    left, right = bool(_LEFT.search(snake)), bool(_RIGHT.search(snake))
    return "left" if left and not right else "right" if right and not left else None


class BodyPlan:
    """:meth:`analyse` of a :class:`~motok_robot.robots.draft.drafter.Drafter` (a mixin: it reads
    ``self.M`` and sets ``top``, ``tol``, ``feet``, ``pelvis_body``, ``legs``, ``arms``,
    ``upper_body``, ``head_body``, ``head_chain``, ``head_joints``)."""

    def analyse(self) -> None:
        M, m, d = self.M, self.M.m, self.M.d
        fname = self.src.name
        # the robot's size: the geoms' vertical extent at the zero pose
        allpts = [M.body_points(b, collision_only=False) for b in range(1, m.nbody)]
        allpts = np.vstack([p for p in allpts if len(p)] or [np.zeros((1, 3))])
        self.top = float(allpts[:, 2].max())
        bottom = float(allpts[:, 2].min())
        H = self.top - bottom
        if not H > 0:
            raise InputError(f"{fname}: the robot has no geoms to measure")
        self.tol = GROUP_TOL * H

        # feet: the lowest collision geoms on each side
        low = {}
        for b in M.subtree(M.base):
            pts = M.body_points(b)
            if len(pts) == 0:
                continue
            z = pts[:, 2].min()
            sole = pts[pts[:, 2] < z + SOLE_TOL]
            y = float(sole[:, 1].mean())
            side = "left" if y > 0 else "right"
            if side not in low or z < low[side][0] - 1e-9:
                low[side] = (z, b)
        if set(low) != {"left", "right"} or low["left"][1] == low["right"][1]:
            have = ", ".join(f"{s} {M.body_name(b)!r}" for s, (_, b) in low.items()) or "none"
            raise InputError(f"{fname}: found one leg only (lowest bodies: {have}): a humanoid needs two feet, one "
                             f"at y > 0 (left) and one at y < 0 (right), each the lowest body of its own chain")
        feet = {s: low[s][1] for s in ("left", "right")}
        lf, rf = feet["left"], feet["right"]
        if lf in M.ancestors(rf) or rf in M.ancestors(lf):
            raise InputError(f"{fname}: found one leg only: the lowest bodies {M.body_name(lf)!r} and "
                             f"{M.body_name(rf)!r} lie on the same chain")
        if abs(low["left"][0] - low["right"][0]) > 0.05 * H:
            self.summary.append(f"warning: the feet are {abs(low['left'][0] - low['right'][0]) * 100:.1f} cm apart in "
                                f"height at the zero pose")
        self.feet = feet
        self.pelvis_body = M.lca(lf, rf)
        legs = {}
        for side, foot in feet.items():
            chain = M.path(self.pelvis_body, foot)
            joints = M.chain_joints(chain)
            groups = joint_groups(M, joints, self.tol)
            if len(groups) < 3:
                raise InputError(f"{fname}: the {side} leg ({' -> '.join(M.body_name(b) for b in chain)}) has "
                                 f"{len(joints)} hinge(s) in {len(groups)} group(s): hip, knee and ankle joints are "
                                 f"needed")
            legs[side] = (chain, groups)
        self.legs = legs
        self.leg_bodies = {b for chain, _ in legs.values() for b in chain}
        self._name_check("leg", feet)

        # arms: the deepest other body on each side
        other = [b for b in range(1, m.nbody) if b not in self.leg_bodies and b != self.pelvis_body
                 and M.base in M.ancestors(b) and b != M.base]
        ends = {}
        for side, sign in (("left", 1), ("right", -1)):
            cands = [b for b in other if sign * d.xpos[b, 1] > 0.04 * H]
            if cands:
                ends[side] = max(cands, key=lambda b: (M.hinge_depth(b), abs(d.xpos[b, 1])))
        self.arms = {}
        if set(ends) == {"left", "right"}:
            self.upper_body = M.lca(ends["left"], ends["right"])
            for side, end in ends.items():
                chain = M.path(self.upper_body, end)
                joints = M.chain_joints(chain)
                groups = joint_groups(M, joints, self.tol)
                if len(groups) >= 2:
                    self.arms[side] = (chain, groups)
            if set(self.arms) != {"left", "right"}:
                self.arms = {}
            else:
                self._name_check("arm", ends)
        if not self.arms:
            self.upper_body = M.base
            self.summary.append("no arms found (two chains of at least 2 joint groups, one per side)")
            self.unsure_toml.append(("no arms found: the shoulder, elbow and wrist keypoints are left out; add sites "
                                     "and [keypoints] entries by hand", "[keypoints]"))
        self.arm_bodies = {b for chain, _ in self.arms.values() for b in chain}

        # head: the highest remaining body
        rest = [b for b in range(1, m.nbody) if b not in self.leg_bodies and b not in self.arm_bodies
                and M.base in M.ancestors(b)]
        tops = {b: M.body_points(b, collision_only=False)[:, 2].max() for b in rest if len(M.geoms(b, False))}
        self.head_body = max(tops, key=tops.get) if tops else M.base
        self.head_chain = []
        if self.head_body != self.upper_body and self.upper_body in M.ancestors(self.head_body):
            self.head_chain = M.path(self.upper_body, self.head_body)
        self.head_joints = M.chain_joints(self.head_chain)

    def _name_check(self, what: str, ends: dict[str, int]) -> None:
        M = self.M
        for side, b in ends.items():
            chain_names = [M.body_name(x) for x in M.ancestors(b)[:3]] + [M.joint_name(j) for j in M.chain_joints([b])]
            said = [s for s in (name_side(n) for n in chain_names) if s]
            if said and said[0] != side:
                self.unsure_toml.append((f"the {side} {what} (by y sign) ends in body {M.body_name(b)!r}, whose name "
                                         f"says {said[0]}: does the model face +x with +y to its left?",
                                         f"[soles.{side}]" if what == "leg" else "[keypoints]"))

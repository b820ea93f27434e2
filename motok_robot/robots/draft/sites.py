"""Where the description's sites go: hip, knee, ankle, shoulder, elbow and wrist keypoints at the
centres of the joint groups, the soles (centre, corners, half size) from each foot's lowest faces,
pelvis, chest, neck and head; and the limb scales measured between them."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from motok_robot.errors import InputError
from motok_robot.motion import skeleton
from motok_robot.robots.draft.axes import point_on_line_nearest
from motok_robot.robots.draft.body import SOLE_TOL


@dataclass
class Site:
    name: str
    body: int
    pos: np.ndarray  # world, at the analysis pose
    kind: str = "kp"  # kp or corner
    note: str = ""  # a reason to check it (becomes an Unsure entry)


class SitePlacement:
    """Site placement of a :class:`~motok_robot.robots.draft.drafter.Drafter` (a mixin: it reads
    the body plan :meth:`~motok_robot.robots.draft.body.BodyPlan.analyse` found and sets
    ``sites``, ``keypoints``, ``points``, ``soles``, ``sole_kind``, ``roles``)."""

    def add_site(self, name: str, body: int, pos, kind: str = "kp", note: str = "") -> str:
        self.sites[name] = Site(name, body, np.asarray(pos, float).copy(), kind, note)
        return name

    def keypoint(self, human: str, name: str, body: int, pos, weight: float, note: str = "") -> None:
        self.add_site(name, body, pos, "kp", note)
        self.keypoints.append((human, name, weight))

    def place_sites(self) -> None:
        M = self.M
        self.points: dict[str, np.ndarray] = {}
        self.soles = {}
        for side, (chain, groups) in self.legs.items():
            s = side[0]
            hip_g, ankle_g = groups[0], groups[-1]
            middle = groups[1:-1]
            hip = hip_g.centre
            ankle = ankle_g.centre
            knee_g = max(middle, key=lambda g: np.linalg.norm(np.cross(ankle - hip, g.centre - hip)))
            ka, ku = M.joint_line(knee_g.joints[0])
            knee = point_on_line_nearest(ka, ku, hip) if len(knee_g.joints) == 1 else knee_g.centre
            self.keypoint(f"{side}_hip", f"{s}_hip", M.m.jnt_bodyid[hip_g.joints[-1]], hip, 0.5)
            self.keypoint(f"{side}_knee", f"{s}_knee", M.m.jnt_bodyid[knee_g.joints[-1]], knee, 1.0)
            self.keypoint(f"{side}_ankle", f"{s}_ankle", M.m.jnt_bodyid[ankle_g.joints[-1]], ankle, 1.0)
            self.points.update({f"{side}_hip": hip, f"{side}_knee": knee, f"{side}_ankle": ankle})
            self.leg_joint_roles(side, hip_g, knee_g, ankle_g)

            foot = self.feet[side]
            pts = M.body_points(foot)
            z = pts[:, 2].min()
            sole = pts[pts[:, 2] < z + SOLE_TOL]
            x0, x1 = sole[:, 0].min(), sole[:, 0].max()
            y0, y1 = sole[:, 1].min(), sole[:, 1].max()
            if x1 - x0 < 1e-3 or y1 - y0 < 1e-3:
                raise InputError(f"{self.src.name}: the {side} foot {M.body_name(foot)!r} has no flat sole at the zero "
                                 f"pose (its lowest collision points span {x1 - x0:.4f} x {y1 - y0:.4f} m)")
            centre = np.array([(x0 + x1) / 2, (y0 + y1) / 2, z])
            corners = {"fl": (x1, y1), "fr": (x1, y0), "rr": (x0, y0), "rl": (x0, y1)}
            self.add_site(f"{s}_sole", foot, centre)
            for k, (x, y) in corners.items():
                self.add_site(f"{s}_sole_{k}", foot, (x, y, z), "corner")
            half = ((x1 - x0) / 2, (y1 - y0) / 2)
            toe = np.array([centre[0] + 0.7 * half[0], ankle[1], z + 0.2 * max(ankle[2] - z, 0.0)])
            self.keypoint(f"{side}_foot", f"{s}_toe", foot, toe, 0.5)
            self.soles[side] = (foot, half, z)
            self.sole_kind = self._sole_description(foot)

        pelvis = (self.points["left_hip"] + self.points["right_hip"]) / 2
        self.points["pelvis"] = pelvis

        # arms
        for side, (chain, groups) in self.arms.items():
            s = side[0]
            sh_g, el_g = groups[0], groups[1]
            shoulder = sh_g.centre
            ea, eu = M.joint_line(el_g.joints[0])
            elbow = point_on_line_nearest(ea, eu, shoulder) if len(el_g.joints) == 1 else el_g.centre
            self.keypoint(f"{side}_shoulder", f"{s}_shoulder", M.m.jnt_bodyid[sh_g.joints[-1]], shoulder, 0.5)
            self.keypoint(f"{side}_elbow", f"{s}_elbow", M.m.jnt_bodyid[el_g.joints[-1]], elbow, 1.0)
            if len(groups) >= 3:
                wg = groups[2]
                wa, wu = M.joint_line(wg.joints[0])
                wrist = point_on_line_nearest(wa, wu, elbow) if len(wg.joints) == 1 else wg.centre
                self.keypoint(f"{side}_wrist", f"{s}_wrist", M.m.jnt_bodyid[wg.joints[-1]], wrist, 1.0)
            else:
                # no wrist joint: the hand 0.9 of the way along the distal link's geoms
                end = chain[-1]
                pts = M.body_points(end, collision_only=False)
                if len(pts) == 0:
                    pts = np.vstack([M.body_points(b, False) for b in chain[1:] if len(M.geoms(b, False))] or [[elbow]])
                u = pts.mean(axis=0) - elbow
                u = u / max(np.linalg.norm(u), 1e-9)
                reach = float(((pts - elbow) @ u).max())
                wrist = elbow + 0.9 * reach * u
                self.keypoint(f"{side}_wrist", f"{s}_hand", end, wrist, 1.0,
                              note=f"no wrist joint: the {side} hand site is a guess, 0.9 of the distal link's reach "
                                   f"({0.9 * reach:.3f} m from the elbow); move it to the palm centre")
            self.points.update({f"{side}_shoulder": shoulder, f"{side}_elbow": elbow, f"{side}_wrist": wrist})

        # neck and head
        head_pts = M.body_points(self.head_body, collision_only=False)
        if self.head_joints:
            neck = M.joint_line(self.head_joints[0])[0]
            neck_body = M.m.jnt_bodyid[self.head_joints[0]]
            head = (head_pts.min(axis=0) + head_pts.max(axis=0)) / 2
            head_body, note_n, note_h = self.head_body, "", ""
            self.summary.append(f"head: {' -> '.join(M.body_name(b) for b in self.head_chain)} "
                                f"({', '.join(M.joint_name(j) for j in self.head_joints)})")
        else:
            top = self.top
            if self.arms:
                sh = (self.points["left_shoulder"] + self.points["right_shoulder"]) / 2
            else:
                sh = pelvis + [0, 0, 0.6 * (top - pelvis[2])]
            neck = np.array([sh[0], 0.0, sh[2] + 0.3 * (top - sh[2])])
            head = np.array([sh[0], 0.0, sh[2] + 0.65 * (top - sh[2])])
            neck_body = head_body = self.upper_body if self.head_body == M.base else self.head_body
            if M.base not in M.ancestors(neck_body):
                neck_body = head_body = self.upper_body
            note_n = ("no head joint: the neck site is a guess (30 % of the way from the shoulders to the top of the "
                      "robot); move it to the base of the head")
            note_h = "no head joint: the head site is a guess (65 % of the way up from the shoulders); move it to the head's centre"
            self.summary.append("head: no head joints (the head is part of the torso)")
        self.points.update({"neck": neck, "head": head})

        rest = skeleton.rest_pose()
        J = skeleton.JOINT_INDEX
        f = (rest[J["spine3"], 2] - rest[J["pelvis"], 2]) / (rest[J["neck"], 2] - rest[J["pelvis"], 2])
        chest = pelvis + f * (neck - pelvis)
        self.keypoint("pelvis", "pelvis", self.pelvis_body, pelvis, 1.0)
        self.keypoint("spine3", "chest", self.upper_body, chest, 0.2)
        self.keypoint("neck", "neck", neck_body, neck, 0.5, note_n)
        self.keypoint("head", "head", head_body, head, 0.5, note_h)
        self.points["spine3"] = chest
        self.chest_ratio = f
        # the order of the shipped descriptions
        order = ["pelvis", "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle", "left_foot",
                 "right_foot", "spine3", "neck", "head", "left_shoulder", "right_shoulder", "left_elbow", "right_elbow",
                 "left_wrist", "right_wrist"]
        self.keypoints.sort(key=lambda k: order.index(k[0]))

    def _sole_description(self, foot: int) -> str:
        M = self.M
        kinds = sorted({self.M.mj.mjtGeom(M.m.geom_type[g]).name.replace("mjGEOM_", "").lower() for g in M.geoms(foot)})
        return "/".join(kinds)

    def leg_joint_roles(self, side, hip_g, knee_g, ankle_g) -> None:
        M = self.M

        def pitch(g):
            return max(g.joints, key=lambda j: abs(M.joint_line(j)[1][1]))

        self.roles = getattr(self, "roles", {})
        self.roles[side] = {"hip": pitch(hip_g), "knee": pitch(knee_g), "ankle": pitch(ankle_g)}

    def limb_scales(self) -> dict[str, tuple[float, float, float]]:
        rest = skeleton.rest_pose()
        J = skeleton.JOINT_INDEX
        p = self.points
        chains = {"legs": ("left_hip", "left_knee", "left_ankle"), "arms": ("left_shoulder", "left_elbow", "left_wrist"),
                  "torso": ("pelvis", "neck"), "head": ("neck", "head")}
        out = {}
        for limb, chain in chains.items():
            if any(c not in p for c in chain):
                continue
            robot = sum(np.linalg.norm(p[b] - p[a]) for a, b in zip(chain, chain[1:]))
            human = sum(np.linalg.norm(rest[J[b]] - rest[J[a]]) for a, b in zip(chain, chain[1:]))
            out[limb] = (robot / human, robot, human)
        return out

    def _local(self, body: int, p_world_at_zero: np.ndarray) -> np.ndarray:
        # body frames at the zero pose (the analysis pose); cached
        cache = getattr(self, "_frames0", None)
        if cache is None:
            q = self.M.d.qpos.copy()
            self.M.set_pose(self.M.q0)
            cache = self._frames0 = (self.M.d.xpos.copy(), self.M.d.xmat.copy())
            self.M.set_pose(q)
        pos, mat = cache
        return mat[body].reshape(3, 3).T @ (p_world_at_zero - pos[body])

    def _world(self, site: str) -> np.ndarray:
        s = self.sites[site]
        return self.M.d.xmat[s.body].reshape(3, 3) @ self._local(s.body, s.pos) + self.M.d.xpos[s.body]

    def _world_of(self, what: str, side: str) -> np.ndarray:
        return self._world(f"{side[0]}_{what}")

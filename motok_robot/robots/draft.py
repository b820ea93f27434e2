"""Draft a robot description (``NAME.toml``) for an unknown humanoid from its MJCF alone.

``motok-robot robots add MJCF --out NAME.toml`` (see ``docs/robots.md``, "Adding a robot").
What is inferred, and how (all measured on the compiled model at its zero pose, in the frame of
the free base body, which must face +x with +y to its left and +z up):

* **free base**: the body carrying the free joint; it is the ``torso_body``.
* **feet**: the body with the lowest collision geom on each side (``y > 0`` left, ``y < 0``
  right); they must hang from two different chains. The legs are the paths from the feet's common
  ancestor (the pelvis) down to them; the arms end in the deepest (most hinges from the base)
  other body on each side, and the head is the highest remaining body.
* **joint groups**: along a chain, consecutive hinges whose axes (nearly) meet form one group
  (hip pitch, roll and yaw; shoulder pitch, roll and the upper-arm twist; ankle pitch and roll);
  a group's centre is the point nearest to all its axes. Hips, knees, ankles, shoulders, elbows
  and wrists are the centres of the 1st, 2nd and last groups of a leg, and of the 1st, 2nd and 3rd
  groups of an arm; the neck is the anchor of the first head joint, the head the centre of the
  head body's geoms, the pelvis the middle of the hips, the chest on the pelvis-neck line at the
  canonical human's ratio.
* **soles**: the lowest faces of each foot's collision geoms (box corners, sphere bottoms,
  cylinder rims, mesh vertices within 2 mm of the lowest point): their bounding rectangle gives
  the sole centre and 4 corner sites and ``half_size``; the toe keypoint sits 0.7 of the half
  length ahead of the sole centre.
* **limb scales**: robot chain length / canonical human length (``skeleton.rest_pose()``).
* **nominal pose**: a knee bend (``knee_bend`` rad, default 0.4) with hip and ankle pitch solved
  so the ankles stay under the hips and the soles flat; arms lowered to hang 0.15 rad from the
  body when the zero pose holds them out.
* **limits**: joint ranges and torque limits are the MJCF's (listed in the TOML's comments); the
  MJCF holds no joint speeds, so ``[velocity_limits]`` is a placeholder (or, for robots whose
  actuators look like Dynamixel position servos, the servo datasheet's no-load speed).

Sites the description needs and the MJCF lacks go into a copy of the MJCF (``NAME.xml`` beside
the TOML; the user's file is never written), together with what loading and rendering need
(a ``floor`` plane, a ``track`` camera, an offscreen buffer, joint ranges from the actuators'
``ctrlrange`` where a hinge has none). Everything the draft could not infer comes back as
:class:`Unsure` entries naming the file and line to edit. No torch; mujoco is imported lazily.
"""

from __future__ import annotations

import math
import os
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from motok_robot.errors import InputError
from motok_robot.motion import skeleton

#: knee bend of the drafted nominal pose, rad
KNEE_BEND = 0.4
#: angle between a lowered upper arm and the vertical, rad (outwards)
ARM_HANG = 0.15
#: sole points lie within this distance of the foot's lowest point, m
SOLE_TOL = 0.002
#: hinges whose axes pass within this fraction of the robot's height of each other form one group
GROUP_TOL = 0.04
#: the velocity limit written when the MJCF says nothing about joint speeds, rad/s (a placeholder)
VELOCITY_PLACEHOLDER = 10.0


@dataclass
class Unsure:
    """Something the draft could not infer: what, and the file + line to edit."""

    what: str
    file: str
    line: int | None
    text: str  # the line as written

    def format(self) -> str:
        where = f"{self.file}:{self.line}" if self.line else self.file
        return f"{where}: {self.what}\n      {self.text.strip()}"


@dataclass
class DraftResult:
    toml_path: Path
    mjcf_path: Path  # the MJCF the TOML names (the copy, or the user's file when nothing was added)
    copied: bool
    image_path: Path | None
    summary: list[str]  # what was inferred, one line each
    unsure: list[Unsure] = field(default_factory=list)
    load_error: str | None = None  # the draft does not load (after the listed edits it should)


# --------------------------------------------------------------------------------------------
# geometry helpers


def _lines_centre(anchors: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """The point nearest (least squares) to the lines ``anchor + t * axis``; a single line (or
    parallel lines): the mean anchor."""
    A = np.zeros((3, 3))
    b = np.zeros(3)
    for a, u in zip(anchors, axes):
        P = np.eye(3) - np.outer(u, u)
        A += P
        b += P @ a
    if np.linalg.matrix_rank(A, tol=1e-6) < 3:
        return anchors.mean(axis=0)
    return np.linalg.solve(A, b)


def _line_distance(p: np.ndarray, a: np.ndarray, u: np.ndarray) -> float:
    v = p - a
    return float(np.linalg.norm(v - np.dot(v, u) * u))


def _lines_distance(a1, u1, a2, u2) -> float:
    n = np.cross(u1, u2)
    if np.linalg.norm(n) < 1e-6:
        return _line_distance(a2, a1, u1)
    return float(abs(np.dot(a2 - a1, n)) / np.linalg.norm(n))


def _point_on_line_nearest(a: np.ndarray, u: np.ndarray, p: np.ndarray) -> np.ndarray:
    return a + np.dot(p - a, u) * u


_LEFT = re.compile(r"(^|[^a-z])(l|left|lft)([^a-z]|$)|left", re.I)
_RIGHT = re.compile(r"(^|[^a-z])(r|right|rgt)([^a-z]|$)|right", re.I)


def _name_side(name: str) -> str | None:
    """'left' / 'right' from a name (``l_knee``, ``Left_Hip``, ``knee_L``, ``leftFoot``), else None."""
    snake = re.sub(r"([a-z])([A-Z])", r"\1_\2", name or "")
    left, right = bool(_LEFT.search(snake)), bool(_RIGHT.search(snake))
    return "left" if left and not right else "right" if right and not left else None


# --------------------------------------------------------------------------------------------
# the model analysis


class _Model:
    """The compiled MJCF at its zero pose with the base at the origin, and tree queries."""

    def __init__(self, path: Path):
        import warnings

        import mujoco

        self.mj = mujoco
        self.file = path
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                self.m = mujoco.MjModel.from_xml_path(str(path))
        except ValueError as exc:
            msg = " ".join(str(exc).split())
            raise InputError(f"{path.name}: MuJoCo cannot compile it: {msg}") from None
        m = self.m
        free = [j for j in range(m.njnt) if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE]
        if not free:
            raise InputError(f"{path.name}: no free joint: a humanoid needs a floating base "
                             f"(a <freejoint/> in its root body)")
        if len(free) > 1:
            raise InputError(f"{path.name}: {len(free)} free joints: one robot with one floating base is supported")
        if free[0] != 0 or m.jnt_qposadr[0] != 0:
            raise InputError(f"{path.name}: the free joint must be the first joint (its body the first body with joints)")
        for j in range(1, m.njnt):
            if m.jnt_type[j] != mujoco.mjtJoint.mjJNT_HINGE:
                kind = mujoco.mjtJoint(m.jnt_type[j]).name.replace("mjJNT_", "").lower()
                raise InputError(f"{path.name}: joint {self.joint_name(j)!r} is a {kind} joint: only a free base "
                                 f"and hinges are supported")
        if m.njnt < 2:
            raise InputError(f"{path.name}: no hinge joints")
        self.base = int(m.jnt_bodyid[0])
        self.d = mujoco.MjData(m)
        q = m.qpos0.copy()
        q[0:3] = 0.0
        q[3:7] = (1.0, 0.0, 0.0, 0.0)
        self.q0 = q
        self.set_pose(q)
        self.children: dict[int, list[int]] = {b: [] for b in range(m.nbody)}
        for b in range(1, m.nbody):
            self.children[int(m.body_parentid[b])].append(b)
        self.hinges = sorted(range(1, m.njnt), key=lambda j: m.jnt_qposadr[j])

    # names
    def body_name(self, b: int) -> str:
        return self.mj.mj_id2name(self.m, self.mj.mjtObj.mjOBJ_BODY, b) or ""

    def joint_name(self, j: int) -> str:
        return self.mj.mj_id2name(self.m, self.mj.mjtObj.mjOBJ_JOINT, j) or ""

    def set_pose(self, q) -> None:
        self.d.qpos[:] = q
        self.mj.mj_kinematics(self.m, self.d)

    # tree
    def ancestors(self, b: int) -> list[int]:
        """``b`` and its ancestors up to (excluding) the world, leaf first."""
        out = []
        while b > 0:
            out.append(b)
            b = int(self.m.body_parentid[b])
        return out

    def lca(self, a: int, b: int) -> int:
        anc = set(self.ancestors(a))
        for x in self.ancestors(b):
            if x in anc:
                return x
        return 0

    def path(self, top: int, bottom: int) -> list[int]:
        """Bodies from below ``top`` down to ``bottom`` (``top`` excluded)."""
        chain = []
        for b in self.ancestors(bottom):
            if b == top:
                return chain[::-1]
            chain.append(b)
        raise ValueError("not an ancestor")

    def subtree(self, b: int) -> list[int]:
        out, stack = [], [b]
        while stack:
            x = stack.pop()
            out.append(x)
            stack.extend(self.children[x])
        return out

    def chain_joints(self, bodies: list[int]) -> list[int]:
        js = []
        for b in bodies:
            start, n = self.m.body_jntadr[b], self.m.body_jntnum[b]
            js.extend(range(start, start + n) if start >= 0 else [])
        return [j for j in js if j != 0]

    def hinge_depth(self, b: int) -> int:
        return len(self.chain_joints(self.ancestors(b))) if b > 0 else 0

    # geoms
    def geoms(self, b: int, collision_only: bool = True) -> list[int]:
        m = self.m
        gs = [g for g in range(m.ngeom) if m.geom_bodyid[g] == b and m.geom_type[g] != self.mj.mjtGeom.mjGEOM_PLANE]
        if collision_only:
            hit = [g for g in gs if m.geom_contype[g] or m.geom_conaffinity[g]]
            return hit
        return gs

    def geom_points(self, g: int) -> np.ndarray:
        """Points on geom ``g``'s surface (world) that bound it, incl. its lowest points."""
        m, d, G = self.m, self.d, self.mj.mjtGeom
        c = d.geom_xpos[g].copy()
        R = d.geom_xmat[g].reshape(3, 3)
        s = m.geom_size[g]
        t = m.geom_type[g]
        down = np.array([0.0, 0.0, -1.0])
        ring = np.array([[math.cos(a), math.sin(a), 0.0] for a in np.linspace(0, 2 * math.pi, 16, endpoint=False)])
        if t == G.mjGEOM_BOX:
            corners = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float) * s
            return c + corners @ R.T
        if t == G.mjGEOM_SPHERE:
            return c + s[0] * np.vstack([down, -down, [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]]])
        if t in (G.mjGEOM_CAPSULE, G.mjGEOM_CYLINDER):
            ends = [c + R[:, 2] * s[1], c - R[:, 2] * s[1]]
            if t == G.mjGEOM_CAPSULE:
                return np.vstack([e + s[0] * np.vstack([down, -down]) for e in ends] + [ends])
            return np.vstack([e + s[0] * ring @ R.T for e in ends])
        if t == G.mjGEOM_ELLIPSOID:
            pts = np.vstack([ring * [s[0], s[1], 0], [[0, 0, s[2]], [0, 0, -s[2]]]])
            pts = c + pts @ R.T
            # the lowest point of the ellipsoid
            low = c - (R * s**2) @ (R.T @ -down) / max(np.linalg.norm(s * (R.T @ down)), 1e-12)
            return np.vstack([pts, low])
        if t == G.mjGEOM_MESH:
            mid = m.geom_dataid[g]
            start, n = m.mesh_vertadr[mid], m.mesh_vertnum[mid]
            v = m.mesh_vert[start:start + n].astype(np.float64)
            return c + v @ R.T
        # heightfield, sdf, ...: the bounding box
        aabb = m.geom_aabb[g]
        corners = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float) * aabb[3:] + aabb[:3]
        return c + corners @ R.T

    def body_points(self, b: int, collision_only: bool = True) -> np.ndarray:
        gs = self.geoms(b, collision_only)
        if not gs:
            return np.zeros((0, 3))
        return np.vstack([self.geom_points(g) for g in gs])

    def joint_line(self, j: int) -> tuple[np.ndarray, np.ndarray]:
        u = self.d.xaxis[j].copy()
        return self.d.xanchor[j].copy(), u / np.linalg.norm(u)

    def to_local(self, b: int, p: np.ndarray) -> np.ndarray:
        R = self.d.xmat[b].reshape(3, 3)
        return R.T @ (np.asarray(p) - self.d.xpos[b])


@dataclass
class _Group:
    joints: list[int]
    centre: np.ndarray


def _groups(model: _Model, joints: list[int], tol: float) -> list[_Group]:
    """Consecutive hinges whose axes pass within ``tol`` of the group's centre form one group."""
    groups: list[_Group] = []
    for j in joints:
        a, u = model.joint_line(j)
        if groups:
            g = groups[-1]
            if len(g.joints) == 1:
                a0, u0 = model.joint_line(g.joints[0])
                near = _lines_distance(a0, u0, a, u) < tol and np.linalg.norm(a - a0) < 4 * tol
            else:
                near = _line_distance(g.centre, a, u) < tol
            if near:
                g.joints.append(j)
                lines = [model.joint_line(k) for k in g.joints]
                g.centre = _lines_centre(np.array([x[0] for x in lines]), np.array([x[1] for x in lines]))
                continue
        groups.append(_Group([j], a.copy()))
    return groups


# --------------------------------------------------------------------------------------------
# the draft


@dataclass
class _Site:
    name: str
    body: int
    pos: np.ndarray  # world, at the analysis pose
    kind: str = "kp"  # kp or corner
    note: str = ""  # a reason to check it (becomes an Unsure entry)


class _Drafter:
    def __init__(self, mjcf: Path, name: str, knee_bend: float = KNEE_BEND):
        self.src = mjcf
        self.name = name
        self.knee_bend = knee_bend
        self.M = _Model(mjcf)
        self.sites: dict[str, _Site] = {}
        self.keypoints: list[tuple[str, str, float]] = []  # human joint, site, weight
        self.summary: list[str] = []
        self.unsure_xml: list[tuple[str, str]] = []  # (what, a marker to find the line in the copy)
        self.unsure_toml: list[tuple[str, str]] = []  # (what, TOML key marker)
        self.added_ranges: dict[int, tuple[float, float]] = {}
        self.comments: dict[str, list[str]] = {}

    # ---------------------------------------------------------------------------- analysis
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
            groups = _groups(M, joints, self.tol)
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
                groups = _groups(M, joints, self.tol)
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
            said = [s for s in (_name_side(n) for n in chain_names) if s]
            if said and said[0] != side:
                self.unsure_toml.append((f"the {side} {what} (by y sign) ends in body {M.body_name(b)!r}, whose name "
                                         f"says {said[0]}: does the model face +x with +y to its left?",
                                         f"[soles.{side}]" if what == "leg" else "[keypoints]"))

    # ---------------------------------------------------------------------------- sites
    def add_site(self, name: str, body: int, pos, kind: str = "kp", note: str = "") -> str:
        self.sites[name] = _Site(name, body, np.asarray(pos, float).copy(), kind, note)
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
            knee = _point_on_line_nearest(ka, ku, hip) if len(knee_g.joints) == 1 else knee_g.centre
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
            elbow = _point_on_line_nearest(ea, eu, shoulder) if len(el_g.joints) == 1 else el_g.centre
            self.keypoint(f"{side}_shoulder", f"{s}_shoulder", M.m.jnt_bodyid[sh_g.joints[-1]], shoulder, 0.5)
            self.keypoint(f"{side}_elbow", f"{s}_elbow", M.m.jnt_bodyid[el_g.joints[-1]], elbow, 1.0)
            if len(groups) >= 3:
                wg = groups[2]
                wa, wu = M.joint_line(wg.joints[0])
                wrist = _point_on_line_nearest(wa, wu, elbow) if len(wg.joints) == 1 else wg.centre
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

    # ---------------------------------------------------------------------------- measures
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

    def joint_limits(self):
        """[(joint id, name, lo, hi, torque or None, how)] for the hinges in qpos order."""
        M, m = self.M, self.M.m
        act = {}
        for a in range(m.nu):
            if m.actuator_trntype[a] == M.mj.mjtTrn.mjTRN_JOINT:
                act.setdefault(int(m.actuator_trnid[a, 0]), []).append(a)
        rows = []
        for j in M.hinges:
            lims = []
            for a in act.get(j, []):
                if m.actuator_forcelimited[a]:
                    lims.append(float(np.max(np.abs(m.actuator_forcerange[a]))))
                if m.actuator_biastype[a] == 0 and m.actuator_ctrllimited[a]:
                    lims.append(float(np.max(np.abs(m.actuator_ctrlrange[a])) * m.actuator_gainprm[a, 0]
                                      * abs(m.actuator_gear[a, 0])))
            if m.jnt_actfrclimited[j]:
                lims.append(float(np.max(np.abs(m.jnt_actfrcrange[j]))))
            lo, hi = (float(v) for v in m.jnt_range[j]) if m.jnt_limited[j] else (None, None)
            rows.append((j, M.joint_name(j), lo, hi, min(lims) if lims else None, act.get(j, [])))
        return rows

    # ---------------------------------------------------------------------------- ranges
    def fill_missing_ranges(self, rows) -> None:
        """Hinges without a range get the range of their position actuator's ctrlrange (else +-pi)."""
        m = self.M.m
        for j, name, lo, hi, _, acts in rows:
            if lo is not None:
                continue
            rng = None
            for a in acts:
                if m.actuator_ctrllimited[a] and m.actuator_biastype[a] != 0:
                    rng = tuple(float(v) for v in m.actuator_ctrlrange[a])
            how = "its position actuator's ctrlrange" if rng else "+-pi"
            rng = rng or (-math.pi, math.pi)
            # inside one turn of a 4096-tick servo, so a draft servo map can cover it
            rng = (max(rng[0], -math.pi), min(rng[1], math.pi - 2 * math.pi / 4096))
            self.added_ranges[j] = rng
            self.unsure_xml.append((f"joint {name!r} has no range in {self.src.name}: the copy uses {how} "
                                    f"[{rng[0]:.4f}, {rng[1]:.4f}] rad; put the real mechanical range here",
                                    f'<joint name="{name}"'))

    def joint_range(self, j: int) -> tuple[float, float]:
        if j in self.added_ranges:
            return self.added_ranges[j]
        return tuple(float(v) for v in self.M.m.jnt_range[j])

    # ---------------------------------------------------------------------------- nominal pose
    def nominal_pose(self) -> dict[str, float]:
        M, m = self.M, self.M.m
        from scipy.optimize import least_squares

        pose: dict[int, float] = {}
        q0 = M.q0.copy()

        def qp(j):
            return m.jnt_qposadr[j]

        def set_q(assign):
            q = q0.copy()
            for j, v in assign.items():
                q[qp(j)] = v
            M.set_pose(q)

        notes = []
        bent = {}
        if self.knee_bend > 0:
            for side, roles in self.roles.items():
                hip_j, knee_j, ankle_j = roles["hip"], roles["knee"], roles["ankle"]
                foot = self.feet[side]
                hip_b = m.jnt_bodyid[hip_j]
                set_q({})
                R0 = M.d.xmat[foot].reshape(3, 3).copy()
                p_hip0 = M.d.xpos[hip_b].copy()
                ank0 = M.d.xpos[foot].copy() - p_hip0
                best = None
                for sign in (1.0, -1.0):
                    k = sign * self.knee_bend
                    lo, hi = self.joint_range(knee_j)
                    if not lo <= k <= hi:
                        continue

                    def resid(x):
                        set_q({hip_j: x[0], knee_j: k, ankle_j: x[1]})
                        R = M.d.xmat[foot].reshape(3, 3)
                        rel = R0.T @ R
                        ank = M.d.xpos[foot] - M.d.xpos[hip_b]
                        return [rel[0, 2] - rel[2, 0], (ank[0] - ank0[0])]

                    bounds = list(zip(self.joint_range(hip_j), self.joint_range(ankle_j)))
                    try:
                        sol = least_squares(resid, [0.0, 0.0], bounds=bounds)
                    except ValueError:
                        continue
                    set_q({hip_j: sol.x[0], knee_j: k, ankle_j: sol.x[1]})
                    knee_x = M.d.xpos[m.jnt_bodyid[knee_j], 0] - M.d.xpos[hip_b, 0]
                    ok = np.max(np.abs(sol.fun)) < 1e-4
                    if ok and knee_x > 0 and (best is None or knee_x > best[0]):
                        best = (knee_x, {hip_j: float(sol.x[0]), knee_j: k, ankle_j: float(sol.x[1])})
                if best is None:
                    notes.append(f"{side} leg: no flat-sole knee bend of {self.knee_bend} rad found")
                else:
                    bent.update(best[1])
            if len(bent) == 6:
                pose.update(bent)
            else:
                notes.append("the nominal pose keeps the legs straight")
        # arms: lower them to hang ARM_HANG from the body when the zero pose holds them out
        for side, (chain, groups) in self.arms.items():
            sign = 1.0 if side == "left" else -1.0
            sh, el = self.points[f"{side}_shoulder"], self.points[f"{side}_elbow"]
            v = (el - sh) / np.linalg.norm(el - sh)
            target = np.array([0.0, sign * math.sin(ARM_HANG), -math.cos(ARM_HANG)])
            if np.dot(v, target) > math.cos(0.3):
                continue
            best = (math.acos(np.clip(np.dot(v, target), -1, 1)), None, 0.0)
            elbow_body = m.jnt_bodyid[groups[1].joints[0]]
            for j in groups[0].joints:
                lo, hi = self.joint_range(j)
                for a in np.linspace(lo, hi, int((hi - lo) / 0.01) + 2):
                    set_q({j: a})
                    # the elbow point moves with the elbow body
                    p = M.d.xmat[elbow_body].reshape(3, 3) @ self._local(elbow_body, el) + M.d.xpos[elbow_body]
                    u = p - self._world_of("shoulder", side)
                    u = u / max(np.linalg.norm(u), 1e-9)
                    err = math.acos(np.clip(np.dot(u, target), -1, 1))
                    if err < best[0] - 1e-6:
                        best = (err, j, float(a))
            if best[1] is not None:
                pose[best[1]] = round(best[2], 3)
            else:
                notes.append(f"{side} arm: no single shoulder joint lowers it")
        set_q(pose)
        # soles flat?
        for side, (foot, half, z) in self.soles.items():
            zs = [self._world(f"{side[0]}_sole_{k}")[2] for k in ("fl", "fr", "rr", "rl")]
            if max(zs) - min(zs) > 1e-3:
                notes.append(f"{side} sole not flat at the nominal pose ({(max(zs) - min(zs)) * 1000:.1f} mm)")
        M.set_pose(q0)
        self.nominal_notes = notes
        return {M.joint_name(j): round(v, 4) for j, v in sorted(pose.items(), key=lambda kv: m.jnt_qposadr[kv[0]])}

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

    # ---------------------------------------------------------------------------- servos
    def servo_guess(self, rows):
        """A draft servo map when the actuators look like Dynamixel position servos, else None."""
        from motok_robot.robots import servo_models

        m = self.M.m
        if m.nu == 0 or self.M.m.body_subtreemass[0] > 15.0:
            return None
        torques = []
        for j, name, lo, hi, tq, acts in rows:
            if len(acts) != 1 or tq is None:
                return None
            a = acts[0]
            kp = m.actuator_gainprm[a, 0]
            position = (m.actuator_biastype[a] == 1 and kp > 0 and abs(m.actuator_biasprm[a, 1] + kp) < 1e-6 * kp)
            if not position:
                return None
            torques.append(tq)
        for j, *_ in rows:
            lo, hi = self.joint_range(j)
            if lo < -math.pi - 1e-9 or hi > math.pi - 2 * math.pi / 4096 + 1e-9:
                self.summary.append(f"no servo map: joint {self.M.joint_name(j)!r} turns beyond one servo turn")
                return None
        sheets = sorted(servo_models.DATASHEETS.values(), key=lambda s: s.stall_torque)
        top = max(torques)
        fits = [s for s in sheets if s.stall_torque >= top * 0.9999]
        if not fits:
            return None
        sheet = fits[0]
        return sheet, top

    # ---------------------------------------------------------------------------- writing
    def height(self) -> float:
        z = min(z for _, _, z in self.soles.values())
        return self.top - z


# --------------------------------------------------------------------------------------------
# the MJCF copy


def _parse_xml(path: Path) -> ET.ElementTree:
    try:
        return ET.parse(path, parser=ET.XMLParser(target=ET.TreeBuilder(insert_comments=True)))
    except ET.ParseError as exc:
        raise InputError(f"{path.name}: not valid XML: {exc}") from None


def _fix_asset_paths(root: ET.Element, src_dir: Path, out_dir: Path) -> None:
    """Point the copy's asset folders (and includes) back at the original's files."""
    comp = root.find("compiler")
    if comp is None:
        comp = ET.Element("compiler")
        comp.tail = "\n  "
        root.insert(0, comp)
    assetdir = comp.attrib.pop("assetdir", None)

    def rel(target: Path) -> str:
        return Path(os.path.relpath(target.resolve(), out_dir.resolve())).as_posix()

    for key in ("meshdir", "texturedir"):
        value = comp.get(key, assetdir)
        base = src_dir / value if value else src_dir
        comp.set(key, rel(base))
    for inc in root.iter("include"):
        f = inc.get("file")
        if f and not Path(f).is_absolute():
            inc.set("file", rel(src_dir / f))


def _fmt(v: float) -> str:
    s = f"{v:.6f}".rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


def _camera_attrs(height: float, target: np.ndarray) -> dict[str, str]:
    direction = np.array([0.78, -0.62, 0.06])
    direction /= np.linalg.norm(direction)
    pos = target + 2.0 * max(height, 0.2) * direction
    f = -direction
    x = np.cross(f, [0, 0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(-f, x)
    return {"name": "track", "mode": "trackcom", "pos": " ".join(_fmt(v) for v in pos),
            "xyaxes": " ".join(_fmt(v) for v in (*x, *y)), "fovy": "45"}


def _write_copy(dr: _Drafter, out_xml: Path, need_sites: list[_Site], add_floor: bool, add_camera: bool) -> list[str]:
    """Write the MJCF copy with the sites (and floor, camera, buffer, ranges) added. Returns what was added."""
    M = dr.M
    tree = _parse_xml(dr.src)
    root = tree.getroot()
    added = []
    _fix_asset_paths(root, dr.src.parent, out_xml.parent)
    world = root.find("worldbody")
    if world is None:
        raise InputError(f"{dr.src.name}: no <worldbody>")
    xml_bodies = list(world.iter("body"))
    by_name = {b.get("name"): b for b in xml_bodies if b.get("name")}
    same_order = len(xml_bodies) == M.m.nbody - 1

    def body_elem(b: int) -> ET.Element:
        name = M.body_name(b)
        if name in by_name:
            return by_name[name]
        if same_order:
            return xml_bodies[b - 1]
        raise InputError(f"{dr.src.name}: body #{b} has no name and the copy cannot place sites in it "
                         f"(bodies from <include>/<replicate>?); name it")

    def indent_of(elem: ET.Element) -> str:
        return elem.text if elem.text and elem.text.strip() == "" else "\n  "

    def insert(parent: ET.Element, child: ET.Element) -> None:
        kids = list(parent)
        idx = next((i for i, k in enumerate(kids) if k.tag == "body"), len(kids))
        child.tail = indent_of(parent)
        if idx == len(kids) and kids:
            child.tail = kids[-1].tail
            kids[-1].tail = indent_of(parent)
        parent.insert(idx, child)

    scale = max(dr.height(), 0.2)
    for s in need_sites:
        local = dr._local(s.body, s.pos)
        size = 0.012 * scale if s.kind == "kp" else 0.008 * scale
        rgba = "1 0.3 0.1 0.7" if s.kind == "kp" else "0.1 0.9 0.2 0.9"
        e = ET.Element("site", {"name": s.name, "pos": " ".join(_fmt(v) for v in local), "type": "sphere",
                                "size": _fmt(size), "group": "4", "rgba": rgba})
        insert(body_elem(s.body), e)
    if need_sites:
        added.append(f"{len(need_sites)} sites (render group 4)")
    for j, (lo, hi) in dr.added_ranges.items():
        name = M.joint_name(j)
        elems = [e for e in root.iter() if e.tag in ("joint",) and e.get("name") == name]
        if not elems:
            raise InputError(f"{dr.src.name}: cannot find <joint name={name!r}> to give it a range")
        elems[0].set("range", f"{_fmt(lo)} {_fmt(hi)}")
        elems[0].set("limited", "true")
    if dr.added_ranges:
        added.append(f"ranges on {len(dr.added_ranges)} joints")
    if add_floor:
        floor = ET.Element("geom", {"name": "floor", "type": "plane", "size": "0 0 0.05", "rgba": "0.8 0.8 0.8 1",
                                    "contype": "1", "conaffinity": "1", "condim": "3", "friction": "1 0.005 0.0001"})
        floor.tail = indent_of(world)
        world.insert(0, floor)
        added.append("a floor plane")
        if world.find("light") is None and not any(e.tag == "light" for e in world.iter()):
            light = ET.Element("light", {"name": "sun", "pos": "0 0 3", "dir": "0 0 -1", "directional": "true"})
            light.tail = indent_of(world)
            world.insert(0, light)
            added.append("a light")
    if add_camera:
        base = body_elem(M.base)
        target = np.array([0.0, 0.0, (dr.top + min(z for _, _, z in dr.soles.values())) / 2])
        cam = ET.Element("camera", _camera_attrs(dr.height(), dr._local(M.base, target)))
        insert(base, cam)
        added.append("a 'track' camera")
    vis = root.find("visual")
    if vis is None:
        vis = ET.Element("visual")
        vis.tail = "\n  "
        root.insert(1, vis)
    glob = vis.find("global")
    if glob is None:
        glob = ET.SubElement(vis, "global")
    if float(glob.get("offwidth", 640)) < 1280 or float(glob.get("offheight", 480)) < 960:
        glob.set("offwidth", "1280")
        glob.set("offheight", "960")
        added.append("a 1280x960 offscreen buffer")
    note = ET.Comment(f" motok-robot robots add: a copy of {dr.src.name} with {', '.join(added)} added; "
                      f"asset folders point back at the original's. Edit this copy, not the original. ")
    note.tail = "\n  "
    root.insert(0, note)
    out_xml.parent.mkdir(parents=True, exist_ok=True)
    tree.write(out_xml, encoding="unicode", xml_declaration=False)
    return added


# --------------------------------------------------------------------------------------------
# the TOML


class _Toml:
    def __init__(self):
        self.lines: list[str] = []

    def add(self, *lines: str) -> None:
        self.lines.extend(lines)

    def line_of(self, marker: str) -> int | None:
        for i, line in enumerate(self.lines, 1):
            if line.startswith(marker) or marker in line and not line.startswith("#"):
                return i
        return None

    def text(self) -> str:
        return "\n".join(self.lines) + "\n"


def _fnum(v: float, nd: int = 4) -> str:
    s = f"{v:.{nd}f}".rstrip("0")
    return s + "0" if s.endswith(".") else s


def _toml_text(dr: _Drafter, mjcf_ref: str, nominal: dict[str, float], rows, servo, scales) -> _Toml:
    M = dr.M
    t = _Toml()
    mass = float(M.m.body_subtreemass[0])
    height = dr.height()
    nj = len(M.hinges)
    t.add(f"# {dr.name} robot description, DRAFTED by `motok-robot robots add {dr.src.name}` (schema: docs/robots.md).",
          f"# Measured on {dr.src.name} at its zero pose; check the image and the list the command printed.",
          "# Angles in radians, lengths in metres, masses in kilograms.",
          "",
          f'name = "{dr.name}"',
          f'mjcf = "{mjcf_ref}"',
          f'summary = "{dr.name}: {nj} joints, {height:.2f} m, {mass:.1f} kg (drafted from {dr.src.name})"',
          f'torso_body = "{M.body_name(M.base)}"',
          f"# measured on the model: {mass:.3f} kg; zero-pose height (highest geom above the soles) {height:.3f} m",
          f"mass_range = [{_fnum(mass * 0.97, 3)}, {_fnum(mass * 1.03, 3)}]",
          f"height_range = [{_fnum(height * 0.97, 3)}, {_fnum(height * 1.03, 3)}]",
          "")
    t.add("# canonical human joint (motok_robot.motion.skeleton.JOINT_NAMES) -> robot site, cost weight.",
          "# Sites: hip / knee / ankle / shoulder / elbow / wrist at the centres of the leg's and arm's joint groups",
          "# (where their axes meet), pelvis between the hips, neck at the first head joint, head at the head's centre.",
          "[keypoints]")
    for human, site, w in dr.keypoints:
        t.add(f'{human} = {{ site = "{site}", weight = {w} }}')
    t.add("")
    t.add("# robot length / canonical human length (skeleton.rest_pose()) per limb, measured between the sites at")
    names = {"legs": "hip -> knee -> ankle", "arms": "shoulder -> elbow -> wrist", "torso": "pelvis -> neck",
             "head": "neck -> head"}
    t.add("# the zero pose: " + "; ".join(f"{k}: {names[k]} {r:.3f} / {h:.3f}" for k, (_, r, h) in scales.items()))
    t.add("[limb_scale]")
    for k, (s, _, _) in scales.items():
        t.add(f"{k} = {s:.3f}")
    t.add("")
    foot_desc = dr.sole_kind
    t.add(f"# soles: the lowest faces of each foot's collision geoms ({foot_desc}) at the zero pose; the centre and",
          "# corner sites lie on that plane, the corners bound the contact points (front-left, front-right,",
          "# rear-right, rear-left)")
    for side in ("left", "right"):
        foot, half, _ = dr.soles[side]
        s = side[0]
        t.add(f"[soles.{side}]",
              f'body = "{M.body_name(foot)}"',
              f'site = "{s}_sole"',
              f'corner_sites = ["{s}_sole_fl", "{s}_sole_fr", "{s}_sole_rr", "{s}_sole_rl"]',
              f"half_size = [{_fnum(half[0])}, {_fnum(half[1])}]",
              "")
    t.add(f"# nominal standing pose: knees bent {dr.knee_bend} rad, hip and ankle pitch solved for flat soles with the",
          "# ankles under the hips; arms lowered when the zero pose holds them out; joints not listed are 0")
    t.add("[nominal_pose]")
    for j, v in nominal.items():
        t.add(f"{j} = {v}")
    t.add("")
    t.add("# joint limits from the MJCF (range rad, torque N m):")
    for j, name, lo, hi, tq, _ in rows:
        lo, hi = dr.joint_range(j)
        t.add(f"#   {name}: [{lo:.3f}, {hi:.3f}], {'%.3g' % tq if tq is not None else 'NO TORQUE LIMIT'}"
              + ("  (range added in the copy)" if j in dr.added_ranges else ""))
    if servo is None:
        t.add("# rad/s. The MJCF gives no joint speeds: PLACEHOLDER, replace with the motors' figures",
              "[velocity_limits]",
              f"default = {VELOCITY_PLACEHOLDER}")
    else:
        sheet, top = servo
        t.add("", "# VERIFY: the actuators look like Dynamixel position servos, so this is a DRAFT servo map:",
              f"# model {sheet.model} = the smallest datasheet servo whose stall torque covers the MJCF's",
              f"# {top:.3g} N m; IDs in actuator order, sign +1, zero offset 2048: check every entry on the robot",
              "# (`motok-robot servo scan`, `motok-robot servo calibrate`) before playback.",
              "[bus]", "protocol = 2.0", "baud = 1000000   # VERIFY", "control_hz = 100   # VERIFY", "",
              "[servo_defaults]", f'model = "{sheet.model}"', "ticks_per_rev = 4096",
              f"velocity_limit = {math.floor(sheet.no_load_speed * 100) / 100}   # rad/s, datasheet no-load speed", "",
              "[servos]")
        rad = 2 * math.pi / 4096
        act_order = sorted(rows, key=lambda r: r[5][0])
        for i, (j, name, _, _, _, _) in enumerate(act_order, 1):
            lo, hi = dr.joint_range(j)
            tlo = max(0, math.floor(2048 + lo / rad + 1e-9))
            thi = min(4095, math.ceil(2048 + hi / rad - 1e-9))
            t.add(f"{name} = {{ id = {i}, sign = 1, zero_offset_ticks = 2048, min_ticks = {tlo}, max_ticks = {thi} }}")
    return t


# --------------------------------------------------------------------------------------------
# entry point


def _existing_site(M: _Model, name: str):
    sid = M.mj.mj_name2id(M.m, M.mj.mjtObj.mjOBJ_SITE, name)
    return sid if sid >= 0 else None


def draft(mjcf: str | os.PathLike, out: str | os.PathLike, name: str | None = None, knee_bend: float = KNEE_BEND,
          render: str | os.PathLike | None = "", force: bool = False) -> DraftResult:
    """Draft ``out`` (NAME.toml) for the robot in ``mjcf``; see the module docstring.

    ``render``: the check image (default ``NAME.png`` beside the TOML; None: no image).
    Raises :class:`InputError` (one line naming the file) for an unusable MJCF.
    """
    src = Path(mjcf).expanduser()
    if not src.is_file():
        raise InputError(f"{src}: MJCF file not found")
    out = Path(out).expanduser()
    if out.suffix != ".toml":
        raise InputError(f"--out must name a .toml file, got {out.name}")
    name = name or out.stem
    out_xml = out.with_suffix(".xml")
    image = None if render is None else Path(render) if render else out.with_suffix(".png")
    if out_xml.resolve() == src.resolve():
        raise InputError(f"{out.name}: the MJCF copy would overwrite the input {src} itself; choose another --out name")
    if not force:
        for p in (out, out_xml, image):
            if p is not None and p.exists():
                raise InputError(f"{p}: exists; pass --force to overwrite the draft")
    _parse_xml(src)  # XML errors first, as one line

    dr = _Drafter(src, name, knee_bend)
    dr.analyse()
    dr.place_sites()
    rows = dr.joint_limits()
    dr.fill_missing_ranges(rows)
    M = dr.M

    # which sites the MJCF already has (same name, same place) and which the copy must add
    need = []
    for s in list(dr.sites.values()):
        sid = _existing_site(M, s.name)
        if sid is not None:
            if np.linalg.norm(M.d.site_xpos[sid] - s.pos) < 0.005 and (
                    M.m.site_bodyid[sid] in M.ancestors(s.body) or s.body in M.ancestors(M.m.site_bodyid[sid])):
                continue  # the model's own site, at the same place on the same chain
            s.name = f"mk_{s.name}"
        need.append(s)
    dr.renamed = {s.name[3:]: s.name for s in need if s.name.startswith("mk_")}
    floor = M.mj.mj_name2id(M.m, M.mj.mjtObj.mjOBJ_GEOM, "floor")
    add_floor = floor < 0
    add_camera = M.mj.mj_name2id(M.m, M.mj.mjtObj.mjOBJ_CAMERA, "track") < 0
    small_buffer = M.m.vis.global_.offwidth < 1280 or M.m.vis.global_.offheight < 960
    copied = bool(need or dr.added_ranges or add_floor or add_camera or small_buffer)

    nominal = dr.nominal_pose()
    scales = dr.limb_scales()
    servo = dr.servo_guess(rows)
    out.parent.mkdir(parents=True, exist_ok=True)
    if copied:
        added = _write_copy(dr, out_xml, need, add_floor, add_camera)
        mjcf_ref = out_xml.name
    else:
        added = []
        mjcf_ref = Path(os.path.relpath(src.resolve(), out.parent.resolve())).as_posix()
    toml = _toml_text(dr, mjcf_ref, nominal, rows, servo, scales)
    if dr.renamed:
        toml.lines = [_rename_sites(line, dr.renamed) for line in toml.lines]
    out.write_text(toml.text())

    # what was inferred
    summary = [f"free base {M.body_name(M.base)!r} (torso_body); {len(M.hinges)} hinges; "
               f"{M.m.body_subtreemass[0]:.2f} kg; height {dr.height():.3f} m"]
    for side, (chain, groups) in dr.legs.items():
        summary.append(f"{side} leg: {' -> '.join(M.body_name(b) for b in chain)}; groups "
                       + " | ".join(",".join(M.joint_name(j) for j in g.joints) for g in groups))
    for side, (chain, groups) in dr.arms.items():
        summary.append(f"{side} arm: {' -> '.join(M.body_name(b) for b in chain)}; groups "
                       + " | ".join(",".join(M.joint_name(j) for j in g.joints) for g in groups))
    summary += dr.summary
    for side, (foot, half, z) in dr.soles.items():
        summary.append(f"{side} sole: {M.body_name(foot)}, {2 * half[0]:.3f} x {2 * half[1]:.3f} m ({dr.sole_kind})")
    summary.append("limb scale: " + ", ".join(f"{k} {v[0]:.3f}" for k, v in scales.items()))
    summary.append("nominal pose: " + (", ".join(f"{k} {v:g}" for k, v in nominal.items()) or "zero pose"))
    summary.append(f"servo map: {'draft, ' + servo[0].model + ' (VERIFY)' if servo else 'none (not Dynamixel-like)'}")
    if copied:
        summary.append(f"MJCF copy {out_xml.name}: added {', '.join(added)}")

    # what it could not infer
    unsure: list[Unsure] = []
    xml_lines = out_xml.read_text().splitlines() if copied else []

    def xml_line(marker: str):
        for i, line in enumerate(xml_lines, 1):
            if marker in line:
                return i, line
        return None, marker

    for s in dr.sites.values():
        if s.note:
            ln, text = xml_line(f'name="{s.name}"')
            unsure.append(Unsure(s.note, out_xml.name if copied else src.name, ln, text))
    for what, marker in dr.unsure_xml:
        ln, text = xml_line(marker)
        unsure.append(Unsure(what, out_xml.name, ln, text))
    for what, marker in dr.unsure_toml:
        ln = toml.line_of(marker)
        unsure.append(Unsure(what, out.name, ln, toml.lines[ln - 1] if ln else marker))
    for note in dr.nominal_notes:
        ln = toml.line_of("[nominal_pose]")
        unsure.append(Unsure(note + "; set the nominal angles by hand", out.name, ln, "[nominal_pose]"))
    for j, jname, lo, hi, tq, acts in rows:
        if tq is None:
            ln, text = xml_line(f'name="{jname}"') if copied else (None, f'<joint name="{jname}"')
            unsure.append(Unsure(f"joint {jname!r} has no torque limit: add actuatorfrcrange=\"-T T\" (N m) to it",
                                 out_xml.name if copied else src.name, ln, text))
        if not acts:
            unsure.append(Unsure(f"joint {jname!r} has no actuator: add one (<position joint=\"{jname}\" .../>)",
                                 out_xml.name if copied else src.name, None, f"<actuator> ... {jname}"))
    if servo is None:
        ln = toml.line_of("default = ")
        unsure.append(Unsure("joint speeds are not in the MJCF: a placeholder velocity limit (rad/s) for every joint; "
                             "put the motors' figures (per joint: JOINT = rad/s)", out.name, ln, toml.lines[ln - 1]))
    else:
        for key in ("baud = ", "[servos]"):
            ln = toml.line_of(key)
            what = ("the bus settings are guesses (protocol, baud, control rate)" if key.startswith("baud")
                    else "servo IDs, signs, zero offsets and the servo model are guesses: verify each on the robot")
            unsure.append(Unsure(what, out.name, ln, toml.lines[ln - 1]))

    result = DraftResult(out, out_xml if copied else src, copied, None, summary, unsure)
    # does it load?
    robot = None
    try:
        from motok_robot.robots import load

        robot = load(out)
    except InputError as exc:
        result.load_error = str(exc)
    if image is not None:
        try:
            result.image_path = render_check_image(dr, result, robot, image)
        except InputError as exc:  # no GL context: the draft is still written
            result.summary.append(f"no check image: {exc} (set MUJOCO_GL=egl before running motok-robot)")
    return result


def _rename_sites(line: str, renamed: dict[str, str]) -> str:
    for old, new in renamed.items():
        line = line.replace(f'"{old}"', f'"{new}"')
    return line


# --------------------------------------------------------------------------------------------
# the check image


def render_check_image(dr: _Drafter, result: DraftResult, robot, path: Path, width: int = 640, height: int = 800) -> Path:
    """Front and side views of the nominal pose, robot see-through, every keypoint and sole site labelled."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    import mujoco

    from motok_robot.robots.render import render_pose, save_png

    if robot is not None:
        model = robot.model
        qpos = robot.nominal_qpos()
        target = robot
    else:  # the draft does not load yet: draw the copy at the zero pose
        model = mujoco.MjModel.from_xml_path(str(result.mjcf_path))
        qpos = model.qpos0.copy()
        qpos[2] = -min(z for _, _, z in dr.soles.values())

        class _Shim:
            name = dr.name

        target = _Shim()
        target.model = model
    mine = {s.name for s in dr.sites.values()}
    for s in range(model.nsite):
        n = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_SITE, s)
        model.site_group[s] = 4 if n in mine else 5
    width = min(width, model.vis.global_.offwidth)
    height = min(height, model.vis.global_.offheight)
    opt = mujoco.MjvOption()
    opt.sitegroup[:] = 0
    opt.sitegroup[4] = 1
    opt.label = mujoco.mjtLabel.mjLABEL_SITE
    opt.flags[mujoco.mjtVisFlag.mjVIS_TRANSPARENT] = 1
    d = mujoco.MjData(model)
    d.qpos[:] = qpos
    mujoco.mj_kinematics(model, d)
    ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, n) for n in mine]
    pts = d.site_xpos[[i for i in ids if i >= 0]]
    centre = (pts.min(axis=0) + pts.max(axis=0)) / 2
    extent = float(np.max(pts.max(axis=0) - pts.min(axis=0)))
    views = []
    for azimuth in (180.0, 90.0):  # from the front (looking along -x), from the robot's right (along +y)
        cam = mujoco.MjvCamera()
        cam.type = mujoco.mjtCamera.mjCAMERA_FREE
        cam.lookat[:] = centre
        cam.distance = 1.25 * extent / math.tan(math.radians(model.vis.global_.fovy / 2)) / 2 + 0.1 * extent
        cam.azimuth = azimuth
        cam.elevation = -5.0
        views.append(render_pose(target, qpos, width=width, height=height, camera=cam, scene_option=opt))
    save_png(np.concatenate(views, axis=1), path)
    return path

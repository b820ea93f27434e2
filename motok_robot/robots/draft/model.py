"""The MJCF compiled by MuJoCo at its zero pose with the free base at the origin: the checks a
draftable humanoid must pass, tree walking (ancestors, chains, subtrees) and geom surface points."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from motok_robot.errors import InputError


class MjcfModel:
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


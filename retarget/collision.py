"""Self-collision avoidance: keep the robot's bodies apart while tracking the human.

Human arms swing close to the body and cross in front of it; a robot's torso is wider and its
limbs thicker relative to its size, so scaled human motion often drives an arm into the torso
or a hand into a thigh. Retargeting finds those overlaps and re-solves with constraints that
forbid them (an active set: a clip without overlaps costs nothing extra).

**Which pairs.** After a solve, the robot trajectory is checked with MuJoCo's own collision
detection on :func:`motok_robot.robots.collision.self_collision_model` (the model validation
uses), its geom margins widened by ``CollisionConfig.detect_margin`` (default 0: touching):
every geom pair that overlaps or comes closer than that in some frame becomes active.
Parent/child pairs and body pairs within 1 mm of each other at the nominal pose (close by
design) are never active; validation ignores parents, children and pairs overlapping at the
nominal pose. The rows of a pair depend on the joint angles only (bodies placed relative to
the base), which keeps the problem's derivatives small; a window problem is compiled once per
window length and active set (``Retargeter.problem``) and reused for later clips.

**Geometry, per active geom pair** (the geoms' own MJCF shapes):

* the larger geom (by volume) is a *solid*: a capsule, cylinder or sphere is a segment with a
  radius (a cylinder by the capsule that contains it); a box, ellipsoid or mesh is its box
  (MuJoCo's ``geom_aabb`` in the geom frame);
* the smaller geom is covered by *spheres* (:func:`geom_spheres`: a capsule by spheres of its
  radius on its segment; a box by a grid of spheres that each contain a cell of it).

**Constraint rows** (metres, ``>= 0`` means clear by at least ``CollisionConfig.margin``), per
sphere ``(c, r)``:

* against a segment ``[p0, p1]`` with radius ``R``: ``|c - closest point| - (r + R + margin)``,
  the closest point at ``t = clip((c - p0).(p1 - p0) / |p1 - p0|^2, 0, 1)``;
* against a box with half sizes ``h`` (centre ``o``, axes ``B``): with ``q = |B^T (c - o)| - h``,
  the signed box distance ``|max(q, 0)| + min(max_i q_i, 0)`` minus ``r + margin``. Outside
  the box (where the constraint boundary lies) it has a continuous gradient; the norm is
  smoothed by ``1e-12`` m^2.

These are exact for spheres, capsules and boxes and conservative for cylinders; covering a
capsule by spheres one radius apart leaves its surface up to ``0.134 r`` outside the spheres,
which ``CollisionConfig.margin`` absorbs. The MuJoCo check after the re-solve is the judge
(rows are added for pairs that still come close, up to ``CollisionConfig.max_rounds`` rounds).
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import mujoco
import numpy as np

from motok_robot.robots.collision import geom_pairs_in_collision, self_collision_model, touching_body_pairs
from retarget.kinematics import Frames, KinematicTree, quat_to_matrix_np

_EPS = 1e-12
_BOX_CELLS = 6  # a box's longest side is cut into at most this many cells (one sphere each)


@dataclass(frozen=True)
class Spheres:
    """Spheres fixed in a body: centres ``[n, 3]`` in the body frame (m), radii ``[n]`` (m)."""

    body: int
    centres: np.ndarray
    radii: np.ndarray


@dataclass(frozen=True)
class Solid:
    """A segment with a radius (``kind="segment"``: ``ends[2, 3]``, ``radius``) or a box
    (``kind="box"``: ``centre[3]``, ``axes[3, 3]`` columns = box axes, ``half[3]``), in the body frame."""

    body: int
    kind: str
    ends: np.ndarray | None = None
    radius: float = 0.0
    centre: np.ndarray | None = None
    axes: np.ndarray | None = None
    half: np.ndarray | None = None


def _geom_frame(model, g: int) -> tuple[np.ndarray, np.ndarray]:
    return np.array(model.geom_pos[g], dtype=np.float64), quat_to_matrix_np(model.geom_quat[g])


def _geom_volume(model, g: int) -> float:
    t, s = int(model.geom_type[g]), model.geom_size[g]
    if t == mujoco.mjtGeom.mjGEOM_SPHERE:
        return 4 / 3 * np.pi * s[0] ** 3
    if t in (mujoco.mjtGeom.mjGEOM_CAPSULE, mujoco.mjtGeom.mjGEOM_CYLINDER):
        return np.pi * s[0] ** 2 * 2 * s[1] + (4 / 3 * np.pi * s[0] ** 3 if t == mujoco.mjtGeom.mjGEOM_CAPSULE else 0.0)
    half = np.asarray(model.geom_aabb[g, 3:6])
    return float(np.prod(2 * half))


def geom_solid(model, g: int) -> Solid:
    """The geom ``g`` as a :class:`Solid` in its body's frame."""
    pos, rot = _geom_frame(model, g)
    t, s, body = int(model.geom_type[g]), model.geom_size[g], int(model.geom_bodyid[g])
    if t == mujoco.mjtGeom.mjGEOM_SPHERE:
        return Solid(body, "segment", ends=np.stack([pos, pos]), radius=float(s[0]))
    if t in (mujoco.mjtGeom.mjGEOM_CAPSULE, mujoco.mjtGeom.mjGEOM_CYLINDER):
        axis = rot[:, 2] * float(s[1])
        return Solid(body, "segment", ends=np.stack([pos - axis, pos + axis]), radius=float(s[0]))
    aabb = np.asarray(model.geom_aabb[g], dtype=np.float64)
    return Solid(body, "box", centre=pos + rot @ aabb[:3], axes=rot, half=aabb[3:6].copy())


def geom_spheres(model, g: int) -> Spheres:
    """Spheres that cover geom ``g`` (in its body's frame).

    A sphere is itself; a capsule is spheres of its radius along its segment, at most one
    radius apart; a cylinder, box, ellipsoid or mesh is its box (``geom_aabb``), whole along its
    thinnest axis and cut along the other two into cells about as long as its smallest half
    size (at most ``_BOX_CELLS`` along the longest side), one sphere per cell, containing the
    cell. The spheres stick out of a flat box by up to about half a cell: conservative."""
    pos, rot = _geom_frame(model, g)
    t, s, body = int(model.geom_type[g]), model.geom_size[g], int(model.geom_bodyid[g])
    if t == mujoco.mjtGeom.mjGEOM_SPHERE:
        return Spheres(body, pos[None, :], np.array([float(s[0])]))
    if t == mujoco.mjtGeom.mjGEOM_CAPSULE:
        r, half_len = float(s[0]), float(s[1])
        n = int(np.ceil(2 * half_len / r)) + 1
        u = np.linspace(-half_len, half_len, n)
        return Spheres(body, pos + u[:, None] * rot[:, 2], np.full(n, r))
    if t == mujoco.mjtGeom.mjGEOM_CYLINDER:
        centre, half = pos, np.array([s[0], s[0], s[1]], dtype=np.float64)
    else:
        aabb = np.asarray(model.geom_aabb[g], dtype=np.float64)
        centre, half = pos + rot @ aabb[:3], aabb[3:6]
    thin = int(np.argmin(half))
    # cells as thick as the box, but no shorter than a sixth of its longest side: a thin large
    # box (a sole) would otherwise need hundreds of spheres (hundreds of rows per frame)
    cell = max(float(half[thin]), 2 * float(half.max()) / _BOX_CELLS, 1e-6)
    grids, sizes = [], np.zeros(3)
    for i in range(3):
        n = 1 if i == thin else max(1, int(np.ceil(2 * half[i] / cell - 1e-9)))
        sizes[i] = 0.0 if i == thin else 2 * half[i] / n
        grids.append(np.array([0.0]) if i == thin else -half[i] + sizes[i] * (np.arange(n) + 0.5))
    local = np.stack(np.meshgrid(*grids, indexing="ij"), axis=-1).reshape(-1, 3)
    radius = float(np.sqrt(half[thin] ** 2 + np.sum((sizes / 2) ** 2)))
    return Spheres(body, centre + local @ rot.T, np.full(len(local), radius))


@dataclass(frozen=True)
class PairGeometry:
    """One geom pair of an active body pair: ``spheres`` kept clear of ``solid``."""

    name: str  # "body1|body2" (the geoms' bodies)
    spheres: Spheres
    solid: Solid


def pair_geometry(model, geom1: int, geom2: int) -> PairGeometry:
    """A geom pair as spheres (the smaller geom) against a solid (the larger one)."""
    small, big = (geom1, geom2) if _geom_volume(model, geom1) <= _geom_volume(model, geom2) else (geom2, geom1)
    name = "|".join(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, int(model.geom_bodyid[g])) for g in (geom1, geom2))
    return PairGeometry(name, geom_spheres(model, small), geom_solid(model, big))


def clearance_rows(tree: KinematicTree, frames: Frames, pairs: list[PairGeometry], margin: float) -> tuple[list, list[str]]:
    """Symbolic clearances (m, ``>= 0`` = apart by ``margin``) of every sphere of ``pairs``, with names."""
    rows, names = [], []
    for pair in pairs:
        sp, so = pair.spheres, pair.solid
        Rs, ps = frames.rot[sp.body], frames.pos[sp.body]
        Ro, po = frames.rot[so.body], frames.pos[so.body]
        if so.kind == "segment":
            e0 = po + ca.mtimes(Ro, ca.DM(so.ends[0].reshape(3, 1)))
            e1 = po + ca.mtimes(Ro, ca.DM(so.ends[1].reshape(3, 1)))
            axis = e1 - e0
            length2 = float(np.sum((so.ends[1] - so.ends[0]) ** 2))  # rigid: the same in every pose
        else:
            centre = po + ca.mtimes(Ro, ca.DM(so.centre.reshape(3, 1)))
            axes = ca.mtimes(Ro, ca.DM(so.axes))
        for c_local, r in zip(sp.centres, sp.radii):
            c = ps + ca.mtimes(Rs, ca.DM(c_local.reshape(3, 1)))
            if so.kind == "segment":
                if length2 > 0:
                    t = ca.fmin(ca.fmax(ca.dot(c - e0, axis) / length2, 0.0), 1.0)
                    d = c - (e0 + t * axis)
                else:
                    d = c - e0
                rows.append(ca.sqrt(ca.sumsqr(d) + _EPS) - (float(r) + so.radius + margin))
            else:
                q = ca.fabs(ca.mtimes(axes.T, c - centre)) - ca.DM(so.half.reshape(3, 1))
                outside = ca.sqrt(ca.sumsqr(ca.fmax(q, 0.0)) + _EPS) - np.sqrt(_EPS)
                inside = ca.fmin(ca.fmax(ca.fmax(q[0], q[1]), q[2]), 0.0)
                rows.append(outside + inside - (float(r) + margin))
            names.append(f"self-collision {pair.name}")
    return rows, names


class CollisionMonitor:
    """Finds the geom pairs of a robot trajectory that overlap or come closer than ``near`` (m).

    Body pairs closer than ``max(near, touching)`` at the nominal pose are close by design
    (feet side by side, a servo horn on the next link) and left out, as are parents and
    children (:mod:`motok_robot.robots.collision`)."""

    def __init__(self, model, nominal_qpos: np.ndarray, near: float, touching: float = 1e-3):
        self.model = self_collision_model(model, margin=near)
        self.near = float(near)
        tol = max(self.near, float(touching))
        self.ignored = touching_body_pairs(self_collision_model(model, margin=tol), nominal_qpos, tolerance=tol)
        self._data = mujoco.MjData(self.model)

    def close_pairs(self, qpos: np.ndarray) -> dict[tuple[int, int], float]:
        """``{(geom1, geom2): deepest overlap (m; negative = the closest gap)}`` over the frames of ``qpos[T, nq]``."""
        found: dict[tuple[int, int], float] = {}
        for q in np.atleast_2d(qpos):
            self._data.qpos[:] = q
            for a, b, depth in geom_pairs_in_collision(self.model, self._data, -self.near, self.ignored):
                found[(a, b)] = max(found.get((a, b), -np.inf), depth)
        return found

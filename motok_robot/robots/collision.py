"""Self-collision of a robot model: which body pairs overlap at a pose.

Shared by retargeting (which keeps the bodies apart, ``retarget.collision``) and validation
(which counts the frames where they overlap, ``motok_robot.sim``), so both judge the same
geometry the same way:

* :func:`self_collision_model` copies the model with every collision-capable robot geom
  (``contype`` or ``conaffinity`` non-zero; all robot geoms when fewer than two are) set to
  collide with every other one, and the world's geoms (the floor) left out. ``<exclude>``
  pairs of the MJCF still hold. ``margin`` (m) widens every geom's contact margin, so that
  pairs closer than ``margin`` are reported too (with a negative depth).
* :func:`body_pairs_in_collision` (:func:`geom_pairs_in_collision`) lists ``(body1, body2,
  depth)`` (``(geom1, geom2, depth)``) at the pose in ``data``,
  leaving out a body and its direct parent, and the ``ignored`` pairs (pairs that touch at the
  nominal pose are structural overlaps of the model, :func:`touching_body_pairs`).
"""

from __future__ import annotations

import copy

import mujoco
import numpy as np


def collision_capable_geoms(model: mujoco.MjModel) -> np.ndarray:
    """Bool ``[ngeom]``: the robot geoms (not attached to the world) that take part in self-collision."""
    robot_geom = np.asarray(model.geom_bodyid) != 0
    capable = robot_geom & ((np.asarray(model.geom_contype) | np.asarray(model.geom_conaffinity)) != 0)
    if capable.sum() < 2:  # a model with only visual geoms: use them all
        capable = robot_geom
    return capable


def self_collision_model(model: mujoco.MjModel, margin: float = 0.0) -> mujoco.MjModel:
    """A copy of ``model`` in which the collision-capable robot geoms all collide with each other."""
    out = copy.deepcopy(model)
    capable = collision_capable_geoms(model)
    out.geom_contype[:] = np.where(capable, 1, 0)
    out.geom_conaffinity[:] = np.where(capable, 1, 0)
    # the broad phase also filters on per-body flags compiled from the geoms: refresh them
    for b in range(out.nbody):
        flag = int(capable[out.geom_bodyid == b].any())
        out.body_contype[b] = flag
        out.body_conaffinity[b] = flag
    out.opt.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    out.opt.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
    if margin > 0:
        out.geom_margin[:] = np.where(capable, margin / 2.0, out.geom_margin)  # a pair's margin is the sum
    return out


def adjacent(model: mujoco.MjModel, b1: int, b2: int) -> bool:
    """The same body, or a body and its direct parent (MuJoCo never collides those)."""
    return b1 == b2 or model.body_parentid[b1] == b2 or model.body_parentid[b2] == b1


def geom_pairs_in_collision(model: mujoco.MjModel, data: mujoco.MjData, min_depth: float,
                            ignored: set = frozenset()) -> list[tuple[int, int, float]]:
    """``(geom1, geom2, depth m)`` with ``geom1 < geom2`` for the pose in ``data`` (a
    :func:`self_collision_model`'s data): the deepest contact of each geom pair at least
    ``min_depth`` deep (negative: closer than ``-min_depth``, with a widened margin), leaving
    out adjacent bodies and the ``ignored`` body pairs."""
    mujoco.mj_kinematics(model, data)
    mujoco.mj_collision(model, data)
    found: dict[tuple[int, int], float] = {}
    for i in range(data.ncon):
        con = data.contact[i]
        depth = -float(con.dist)
        if depth < min_depth:
            continue
        g1, g2 = sorted((int(con.geom1), int(con.geom2)))
        b1, b2 = int(model.geom_bodyid[g1]), int(model.geom_bodyid[g2])
        if adjacent(model, b1, b2) or (min(b1, b2), max(b1, b2)) in ignored:
            continue
        found[(g1, g2)] = max(found.get((g1, g2), -np.inf), depth)
    return [(a, b, d) for (a, b), d in found.items()]


def body_pairs_in_collision(model: mujoco.MjModel, data: mujoco.MjData, min_depth: float,
                            ignored: set = frozenset()) -> list[tuple[int, int, float]]:
    """``(body1, body2, depth m)`` with ``body1 < body2``: :func:`geom_pairs_in_collision` per body pair."""
    found: dict[tuple[int, int], float] = {}
    for g1, g2, depth in geom_pairs_in_collision(model, data, min_depth, ignored):
        b1, b2 = int(model.geom_bodyid[g1]), int(model.geom_bodyid[g2])
        pair = (min(b1, b2), max(b1, b2))
        found[pair] = max(found.get(pair, -np.inf), depth)
    return [(a, b, d) for (a, b), d in found.items()]


def touching_body_pairs(model: mujoco.MjModel, qpos: np.ndarray, tolerance: float = 1e-3) -> set:
    """Body pairs of a :func:`self_collision_model` within ``tolerance`` (m) of touching at ``qpos``.

    MuJoCo reports only pairs closer than the model's contact margin, so the tolerance reaches
    no further than the ``margin`` the model was made with: with ``margin=0`` (validation's
    model) these are the pairs that touch or overlap."""
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    return {(a, b) for a, b, _ in body_pairs_in_collision(model, data, min_depth=-tolerance)}

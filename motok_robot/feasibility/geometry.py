"""Planar geometry for support polygons, and the heading of a free base (numpy only).

Points are ``[N, 2]`` arrays of ground-plane (x, y) coordinates in metres.  Shared by the
feasibility stage (its CoM path) and validation (support polygons, CoP, fidelity).
"""

from __future__ import annotations

import numpy as np


def convex_hull(points: np.ndarray) -> np.ndarray:
    """Convex hull of ``points`` [N, 2] as vertices [H, 2] in counter-clockwise order.

    Andrew's monotone chain; collinear points are dropped.  Fewer than 3 distinct points give
    the distinct points themselves (a segment or a point).
    """
    pts = np.unique(np.asarray(points, dtype=np.float64).reshape(-1, 2), axis=0)
    if len(pts) < 3:
        return pts

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower: list = []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 1e-12:
            lower.pop()
        lower.append(p)
    upper: list = []
    for p in pts[::-1]:
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 1e-12:
            upper.pop()
        upper.append(p)
    hull = np.array(lower[:-1] + upper[:-1])
    return hull


def _segment_point(point: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The point of segment ``a``-``b`` nearest to ``point``."""
    ab = b - a
    denom = float(ab @ ab)
    t = 0.0 if denom == 0.0 else float(np.clip((point - a) @ ab / denom, 0.0, 1.0))
    return a + t * ab


def _segment_distance(point: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(point - _segment_point(point, a, b)))


def signed_distance(point: np.ndarray, hull: np.ndarray) -> float:
    """Signed distance (m) from ``point`` [2] to the convex polygon ``hull`` [H, 2] (CCW).

    Positive inside (distance to the nearest edge), negative outside (minus the distance to
    the polygon), 0 on the boundary.  A degenerate hull (segment or point) has no inside: the
    result is minus the distance to it.  An empty hull gives NaN.
    """
    point = np.asarray(point, dtype=np.float64)
    n = len(hull)
    if n == 0:
        return float("nan")
    if n == 1:
        return -float(np.linalg.norm(point - hull[0]))
    if n == 2:
        return -_segment_distance(point, hull[0], hull[1])
    edges = np.roll(hull, -1, axis=0) - hull
    rel = point - hull
    cross = edges[:, 0] * rel[:, 1] - edges[:, 1] * rel[:, 0]
    lengths = np.linalg.norm(edges, axis=1)
    inside_dist = cross / lengths  # signed distance to each edge line, positive on the inner side
    if np.all(inside_dist >= 0.0):
        return float(inside_dist.min())
    return -min(_segment_distance(point, hull[i], hull[(i + 1) % n]) for i in range(n))


def nearest_point(point: np.ndarray, hull: np.ndarray) -> np.ndarray:
    """``point`` [2] itself when it lies in the convex polygon ``hull`` [H, 2] (CCW), else the
    nearest point of the polygon's boundary (of the segment or point a degenerate hull is)."""
    point = np.asarray(point, dtype=np.float64)
    n = len(hull)
    if n == 1:
        return np.asarray(hull[0], dtype=np.float64)
    if n >= 3 and signed_distance(point, hull) >= 0.0:
        return point
    edges = [(hull[i], hull[(i + 1) % n]) for i in range(n if n >= 3 else 1)]
    candidates = [_segment_point(point, a, b) for a, b in edges]
    return min(candidates, key=lambda q: float(((point - q) ** 2).sum()))


def heading(qpos: np.ndarray) -> np.ndarray:
    """Base yaw [T] (rad) of ``qpos`` [T, nq] (free-joint quaternion wxyz at columns 3-6)."""
    w, x, y, z = np.asarray(qpos)[:, 3:7].T
    return np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))

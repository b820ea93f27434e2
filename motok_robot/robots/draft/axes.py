"""Joint axes as lines: distances between them, and the groups of consecutive hinges whose axes
(nearly) meet (a hip's pitch, roll and yaw; a shoulder; an ankle)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from motok_robot.robots.draft.model import MjcfModel


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


def point_on_line_nearest(a: np.ndarray, u: np.ndarray, p: np.ndarray) -> np.ndarray:
    return a + np.dot(p - a, u) * u



@dataclass
class JointGroup:
    joints: list[int]
    centre: np.ndarray


def joint_groups(model: MjcfModel, joints: list[int], tol: float) -> list[JointGroup]:
    """Consecutive hinges whose axes pass within ``tol`` of the group's centre form one group."""
    groups: list[JointGroup] = []
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
        groups.append(JointGroup([j], a.copy()))
    return groups

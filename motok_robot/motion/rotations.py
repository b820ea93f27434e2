"""Rotation helpers in numpy (no torch).

Conventions
-----------
* Quaternions are ``[..., 4]`` arrays in **w, x, y, z** order (scalar first, the MuJoCo
  order), Hamilton product, and rotate column vectors: ``quat_rotate(q, v) = q v q*``.
* Rotation matrices are ``[..., 3, 3]`` and act on column vectors: ``v' = R @ v``.
* Axis-angle vectors are ``[..., 3]``: the unit axis times the angle in radians.
* The continuous 6D representation (Zhou et al., CVPR 2019, "On the continuity of rotation
  representations in neural networks") is ``[..., 6]``: the **first two columns** of the
  rotation matrix, concatenated ``[R[:, 0], R[:, 1]]`` (the order HumanML3D uses).
  ``matrix_from_cont6d`` recovers the matrix by Gram-Schmidt, so any 6-vector whose two
  3-vectors are not parallel maps to a valid rotation.

All functions broadcast over leading dimensions and accept float32 or float64 arrays; they
compute in float64 unless stated otherwise.
"""

from __future__ import annotations

import numpy as np

_EPS = 1e-12


def _f64(x) -> np.ndarray:
    return np.asarray(x, dtype=np.float64)


# ----------------------------------------------------------------------------- quaternions


def quat_identity(shape: tuple[int, ...] = ()) -> np.ndarray:
    """Identity quaternions ``[*shape, 4]`` (w, x, y, z)."""
    q = np.zeros(tuple(shape) + (4,))
    q[..., 0] = 1.0
    return q


def quat_normalize(q) -> np.ndarray:
    """Unit quaternion(s) ``[..., 4]``; a zero quaternion becomes the identity."""
    q = _f64(q)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    out = q / np.maximum(n, _EPS)
    bad = (n[..., 0] < _EPS)
    if np.any(bad):
        out[bad] = np.array([1.0, 0.0, 0.0, 0.0])
    return out


def quat_conjugate(q) -> np.ndarray:
    """Conjugate ``[w, -x, -y, -z]``; the inverse of a unit quaternion."""
    q = _f64(q)
    return q * np.array([1.0, -1.0, -1.0, -1.0])


quat_inverse = quat_conjugate


def quat_mul(a, b) -> np.ndarray:
    """Hamilton product ``a * b`` of ``[..., 4]`` quaternions (apply ``b`` first, then ``a``)."""
    a = _f64(a)
    b = _f64(b)
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def quat_rotate(q, v) -> np.ndarray:
    """Rotate vectors ``v[..., 3]`` by unit quaternions ``q[..., 4]`` (broadcast)."""
    q = _f64(q)
    v = _f64(v)
    w = q[..., :1]
    u = q[..., 1:]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def quat_to_matrix(q) -> np.ndarray:
    """Unit quaternions ``[..., 4]`` -> rotation matrices ``[..., 3, 3]``."""
    q = quat_normalize(q)
    w, x, y, z = np.moveaxis(q, -1, 0)
    m = np.stack(
        [
            1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
            2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
            2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
        ],
        axis=-1,
    )
    return m.reshape(q.shape[:-1] + (3, 3))


def matrix_to_quat(m) -> np.ndarray:
    """Rotation matrices ``[..., 3, 3]`` -> unit quaternions ``[..., 4]`` with ``w >= 0``.

    Uses the numerically stable branch (largest of w, x, y, z) per element.
    """
    m = _f64(m)
    m00, m01, m02 = m[..., 0, 0], m[..., 0, 1], m[..., 0, 2]
    m10, m11, m12 = m[..., 1, 0], m[..., 1, 1], m[..., 1, 2]
    m20, m21, m22 = m[..., 2, 0], m[..., 2, 1], m[..., 2, 2]
    # four candidate solutions, each exact where its leading component is large
    cand = np.stack(
        [
            np.stack([1 + m00 + m11 + m22, m21 - m12, m02 - m20, m10 - m01], -1),
            np.stack([m21 - m12, 1 + m00 - m11 - m22, m01 + m10, m02 + m20], -1),
            np.stack([m02 - m20, m01 + m10, 1 - m00 + m11 - m22, m12 + m21], -1),
            np.stack([m10 - m01, m02 + m20, m12 + m21, 1 - m00 - m11 + m22], -1),
        ],
        axis=-2,
    )
    diag = np.stack([1 + m00 + m11 + m22, 1 + m00 - m11 - m22, 1 - m00 + m11 - m22, 1 - m00 - m11 + m22], -1)
    best = np.argmax(diag, axis=-1)
    q = np.take_along_axis(cand, best[..., None, None], axis=-2)[..., 0, :]
    q = quat_normalize(q)
    return np.where(q[..., :1] < 0, -q, q)


def quat_from_axis_angle(axis_angle) -> np.ndarray:
    """Axis-angle ``[..., 3]`` (rad) -> unit quaternions ``[..., 4]``."""
    aa = _f64(axis_angle)
    angle = np.linalg.norm(aa, axis=-1, keepdims=True)
    half = 0.5 * angle
    # sin(half)/angle, with its limit 1/2 at 0
    k = np.where(angle > 1e-8, np.sin(half) / np.maximum(angle, 1e-300), 0.5 - angle**2 / 48.0)
    return np.concatenate([np.cos(half), aa * k], axis=-1)


def quat_to_axis_angle(q) -> np.ndarray:
    """Unit quaternions ``[..., 4]`` -> axis-angle ``[..., 3]`` with angle in ``[0, pi]``."""
    q = quat_normalize(q)
    q = np.where(q[..., :1] < 0, -q, q)
    s = np.linalg.norm(q[..., 1:], axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(s, q[..., :1])
    k = np.where(s > 1e-8, angle / np.maximum(s, 1e-300), 2.0)
    return q[..., 1:] * k


def quat_between(v0, v1) -> np.ndarray:
    """Shortest-arc unit quaternion rotating direction ``v0[..., 3]`` onto ``v1[..., 3]``.

    Neither needs to be unit length. For opposite directions (the rotation is not unique)
    it returns a half turn about a fixed axis perpendicular to ``v0`` (the cross product of
    ``v0`` with the coordinate axis least aligned with it), so the result is always finite.
    Zero-length inputs give the identity.
    """
    v0 = _f64(v0)
    v1 = _f64(v1)
    v0, v1 = np.broadcast_arrays(v0, v1)
    n0 = np.linalg.norm(v0, axis=-1, keepdims=True)
    n1 = np.linalg.norm(v1, axis=-1, keepdims=True)
    xyz = np.cross(v0, v1)
    w = n0 * n1 + np.sum(v0 * v1, axis=-1, keepdims=True)
    q = np.concatenate([w, xyz], axis=-1)
    norm = np.linalg.norm(q, axis=-1)
    scale = (n0 * n1)[..., 0]
    opposite = (norm <= 1e-9 * np.maximum(scale, _EPS)) & (scale > _EPS)
    if np.any(opposite):
        a = v0[opposite]
        least = np.argmin(np.abs(a), axis=-1)
        e = np.zeros_like(a)
        e[np.arange(len(a)), least] = 1.0
        axis = np.cross(a, e)
        axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
        q[opposite] = np.concatenate([np.zeros((len(a), 1)), axis], axis=-1)
    return quat_normalize(q)


def quat_fix(q) -> np.ndarray:
    """Make a quaternion sequence ``[T, ..., 4]`` sign-continuous along axis 0.

    ``q`` and ``-q`` are the same rotation; this flips signs so consecutive quaternions have a
    non-negative dot product (useful before interpolating or differencing).
    """
    q = np.array(q, dtype=np.float64, copy=True)
    if q.shape[0] < 2:
        return q
    dots = np.sum(q[1:] * q[:-1], axis=-1)
    flips = np.cumsum(dots < 0, axis=0) % 2
    q[1:][flips.astype(bool)] *= -1.0
    return q


def quat_slerp(q0, q1, t) -> np.ndarray:
    """Spherical linear interpolation between unit quaternions (shortest path).

    ``t`` broadcasts against the leading dimensions (``t = 0`` gives ``q0``, ``1`` gives ``q1``).
    """
    q0 = quat_normalize(q0)
    q1 = quat_normalize(q1)
    t = _f64(t)[..., None]
    dot = np.sum(q0 * q1, axis=-1, keepdims=True)
    q1 = np.where(dot < 0, -q1, q1)
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    sin_theta = np.sin(theta)
    small = sin_theta < 1e-6
    w0 = np.where(small, 1.0 - t, np.sin((1.0 - t) * theta) / np.where(small, 1.0, sin_theta))
    w1 = np.where(small, t, np.sin(t * theta) / np.where(small, 1.0, sin_theta))
    return quat_normalize(w0 * q0 + w1 * q1)


# ----------------------------------------------------------------------------- matrices


def axis_angle_to_matrix(axis_angle) -> np.ndarray:
    """Axis-angle ``[..., 3]`` (rad) -> rotation matrices ``[..., 3, 3]`` (Rodrigues)."""
    return quat_to_matrix(quat_from_axis_angle(axis_angle))


def matrix_to_axis_angle(m) -> np.ndarray:
    """Rotation matrices ``[..., 3, 3]`` -> axis-angle ``[..., 3]`` (angle in ``[0, pi]``)."""
    return quat_to_axis_angle(matrix_to_quat(m))


def matrix_to_cont6d(m) -> np.ndarray:
    """Rotation matrices ``[..., 3, 3]`` -> 6D ``[..., 6]`` = ``[R[:, 0], R[:, 1]]``."""
    m = _f64(m)
    return np.concatenate([m[..., :, 0], m[..., :, 1]], axis=-1)


def matrix_from_cont6d(d6) -> np.ndarray:
    """6D ``[..., 6]`` -> rotation matrices ``[..., 3, 3]`` by Gram-Schmidt (Zhou et al.).

    The first column is the normalised first 3-vector; the second is the second 3-vector
    made orthogonal to it and normalised; the third is their cross product.
    """
    d6 = _f64(d6)
    a1, a2 = d6[..., :3], d6[..., 3:6]
    b1 = a1 / np.maximum(np.linalg.norm(a1, axis=-1, keepdims=True), _EPS)
    a2 = a2 - np.sum(b1 * a2, axis=-1, keepdims=True) * b1
    b2 = a2 / np.maximum(np.linalg.norm(a2, axis=-1, keepdims=True), _EPS)
    b3 = np.cross(b1, b2)
    return np.stack([b1, b2, b3], axis=-1)


def quat_to_cont6d(q) -> np.ndarray:
    """Unit quaternions ``[..., 4]`` -> 6D ``[..., 6]``."""
    return matrix_to_cont6d(quat_to_matrix(q))


def cont6d_to_quat(d6) -> np.ndarray:
    """6D ``[..., 6]`` -> unit quaternions ``[..., 4]`` (``w >= 0``)."""
    return matrix_to_quat(matrix_from_cont6d(d6))


def rotation_about_axis(angle, axis: int) -> np.ndarray:
    """Matrices ``[..., 3, 3]`` rotating by ``angle[...]`` rad about coordinate axis 0, 1 or 2.

    Right-handed: about z, +x turns towards +y; about y, +z turns towards +x; about x,
    +y turns towards +z.
    """
    angle = _f64(angle)
    c, s = np.cos(angle), np.sin(angle)
    m = np.zeros(angle.shape + (3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    m[..., axis, axis] = 1.0
    m[..., i, i] = c
    m[..., j, j] = c
    m[..., j, i] = s
    m[..., i, j] = -s
    return m


def wrap_angle(angle) -> np.ndarray:
    """Wrap angles (rad) to ``[-pi, pi)``."""
    angle = _f64(angle)
    return (angle + np.pi) % (2.0 * np.pi) - np.pi


def geodesic_angle(m0, m1) -> np.ndarray:
    """Angle (rad, ``[0, pi]``) of the rotation taking ``m0[..., 3, 3]`` to ``m1[..., 3, 3]``."""
    m0 = _f64(m0)
    m1 = _f64(m1)
    rel = np.swapaxes(m0, -1, -2) @ m1
    cos = (np.trace(rel, axis1=-2, axis2=-1) - 1.0) / 2.0
    return np.arccos(np.clip(cos, -1.0, 1.0))

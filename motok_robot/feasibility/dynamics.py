"""Velocities, accelerations, inverse dynamics with a contact model, and the ZMP.

Contact model of the inverse dynamics
-------------------------------------
A kinematic replay has no meaningful contact penetration, so the contacts MuJoCo would
measure after ``mj_forward`` (soft-constraint forces driven by penetration depth) say
nothing about the force the ground must supply.  Instead:

1. ``mj_inverse`` runs on a copy of the model with *all constraints disabled*; its
   ``qfrc_inverse`` [nv] is the generalised force that produces the trajectory's ``qacc``
   without any ground.  Its six free-base rows are the wrench the ground has to supply
   (the base is unactuated).
2. That base wrench is distributed over the **sole corners of the feet in contact** as
   point forces inside a linearised friction cone (4-sided pyramid, friction coefficient
   ``ValidationConfig.friction_coefficient``): non-negative least squares on the edge
   weights, with a tiny ridge so the split between feet is the smallest-norm one.  The
   ground can only push, so this is the physically admissible set of reactions.
3. Joint torques are ``qfrc_inverse[joint dofs] - (J_c^T f_c)[joint dofs]``.

What the feet cannot supply (a base wrench outside the cone, or any wrench during a
flight phase) is reported per frame as ``unsupported_force_n``: it means the motion is not
dynamically feasible with the planned contacts -- the same fact the ZMP check reports.

ZMP
---
``multibody`` (default): with the whole-body centre of mass c, its acceleration c'' and the
rate of change of the centroidal angular momentum L' (``subtree_angmom`` of the root body,
finite-differenced), the ground reaction is F = m (c'' - g) and the ZMP on the floor z = 0 is

    p_x = c_x - (c_z F_x + L'_y) / F_z,      p_y = c_y - (c_z F_y - L'_x) / F_z.

``cart_table``: the same with L' = 0 (the linear inverted pendulum / cart-table model).
Frames with F_z <= 0.1 m g (free fall) have no ZMP (NaN).
"""

from __future__ import annotations

import mujoco
import numpy as np
from scipy.optimize import nnls

GRAVITY = 9.81


def finite_difference_qvel(model: mujoco.MjModel, qpos: np.ndarray, fps: float) -> np.ndarray:
    """Generalised velocities [T, nv] of ``qpos`` [T, nq] (see :func:`qvel_qacc`)."""
    return qvel_qacc(model, qpos, fps)[0]


def qvel_qacc(model: mujoco.MjModel, qpos: np.ndarray, fps: float) -> tuple[np.ndarray, np.ndarray]:
    """Generalised velocities and accelerations [T, nv] of ``qpos`` [T, nq] sampled at ``fps``.

    Half-step velocities h_t = (q_{t+1} - q_t) / dt come from ``mj_differentiatePos`` (so the
    free joint's angular velocity is right, in the body frame); then the central estimates
    qvel_t = (h_{t-1} + h_t) / 2 and qacc_t = (h_t - h_{t-1}) / dt (the three-point second
    difference, which keeps a one-frame glitch at full height).  The first and last frames
    take their neighbour's acceleration and a one-sided velocity.
    """
    T = qpos.shape[0]
    dt = 1.0 / fps
    qvel = np.zeros((T, model.nv))
    qacc = np.zeros((T, model.nv))
    if T < 2:
        return qvel, qacc
    half = np.zeros((T - 1, model.nv))
    for t in range(T - 1):
        mujoco.mj_differentiatePos(model, half[t], dt, qpos[t], qpos[t + 1])
    qvel[0], qvel[-1] = half[0], half[-1]
    if T > 2:
        qvel[1:-1] = 0.5 * (half[:-1] + half[1:])
        qacc[1:-1] = (half[1:] - half[:-1]) / dt
        qacc[0], qacc[-1] = qacc[1], qacc[-2]
    return qvel, qacc


def finite_difference(values: np.ndarray, fps: float) -> np.ndarray:
    """Time derivative of ``values`` [T, ...] by central differences (one-sided at the ends)."""
    if values.shape[0] < 2:
        return np.zeros_like(values)
    return np.gradient(values, 1.0 / fps, axis=0)


def moving_average(values: np.ndarray, window: int) -> np.ndarray:
    """Centred moving average along axis 0; ``window`` <= 1 returns a copy.

    The ends are padded by odd reflection (``2 x[0] - x[k]``: the series continued on the line
    through its end), so a series that changes at a constant rate smooths to itself.  Padding
    with the end value instead made a CoM moving at constant speed look like it accelerated at
    the first and last frames of every clip (``v / 6 dt``: 0.7 m/s^2 at 0.2 m/s and 20 fps, a
    1.7 cm ZMP shift once differentiated twice).
    """
    if window <= 1 or values.shape[0] < window:
        return values.copy()
    pad = window // 2
    after = window - 1 - pad
    head = 2 * values[:1] - values[pad:0:-1]
    tail = 2 * values[-1:] - values[-2:-2 - after:-1]
    padded = np.concatenate([head, values, tail])
    kernel = np.ones(window) / window
    flat = padded.reshape(padded.shape[0], -1)
    out = np.stack([np.convolve(flat[:, k], kernel, mode="valid") for k in range(flat.shape[1])], axis=1)
    return out.reshape(values.shape)


class ContactDistributor:
    """Distributes a base wrench over sole-corner point forces (see module docstring).

    One instance per robot; :meth:`solve` is called once per frame.
    """

    def __init__(self, model: mujoco.MjModel, base_dof: np.ndarray, friction: float, edges: int = 4):
        self.model = model
        self.base_dof = np.asarray(base_dof)
        angles = np.arange(edges) * 2 * np.pi / edges
        cone = np.stack([friction * np.cos(angles), friction * np.sin(angles), np.ones(edges)], axis=1)
        self.cone = cone / np.linalg.norm(cone, axis=1, keepdims=True)  # [E, 3] unit edge directions
        self._jacp = np.zeros((3, model.nv))

    def solve(self, data: mujoco.MjData, qfrc_inverse: np.ndarray, points: np.ndarray, bodies: np.ndarray):
        """Contact forces for one frame.

        data:          MjData after ``mj_inverse`` (positions valid).
        qfrc_inverse:  float [nv] from ``mj_inverse`` with constraints disabled.
        points:        float [C, 3] world contact points (sole corners in contact), may be empty.
        bodies:        int [C] body of each point.
        Returns (qfrc_contact [nv] = sum J_c^T f_c, forces [C, 3] N, unsupported [6] residual
        base wrench the contacts cannot supply).
        """
        nv = self.model.nv
        target = qfrc_inverse[self.base_dof]
        if len(points) == 0:
            return np.zeros(nv), np.zeros((0, 3)), target.copy()
        jacobians = np.empty((len(points), 3, nv))
        for c, (point, body) in enumerate(zip(points, bodies)):
            mujoco.mj_jac(self.model, data, self._jacp, None, point, int(body))
            jacobians[c] = self._jacp
        # generalised force of a unit force along each edge of each contact: [C, E, nv]
        columns = np.einsum("ek,ckv->cev", self.cone, jacobians).reshape(-1, nv)
        a_base = columns[:, self.base_dof].T  # [6, C*E]
        scale = max(float(np.abs(target).max()), 1.0)
        ridge = 1e-4
        a_stack = np.vstack([a_base, ridge * np.eye(a_base.shape[1])])
        b_stack = np.concatenate([target / scale, np.zeros(a_base.shape[1])])
        weights, _ = nnls(a_stack, b_stack, maxiter=50 * a_base.shape[1])
        weights *= scale
        qfrc_contact = columns.T @ weights
        forces = (weights.reshape(len(points), -1)[:, :, None] * self.cone[None]).sum(1)
        unsupported = target - qfrc_contact[self.base_dof]
        return qfrc_contact, forces, unsupported


def zmp_from_centroidal(com: np.ndarray, com_acc: np.ndarray, angmom_rate: np.ndarray | None,
                        mass: float) -> np.ndarray:
    """ZMP [T, 2] (m, floor z = 0) from CoM [T, 3], its acceleration [T, 3] (m/s^2) and the
    centroidal angular momentum rate [T, 3] (N m; None for the cart-table model)."""
    force = mass * (com_acc + np.array([0.0, 0.0, GRAVITY]))
    rate = np.zeros_like(com) if angmom_rate is None else angmom_rate
    zmp = np.full((com.shape[0], 2), np.nan)
    ok = force[:, 2] > 0.1 * mass * GRAVITY
    fz = force[ok, 2]
    zmp[ok, 0] = com[ok, 0] - (com[ok, 2] * force[ok, 0] + rate[ok, 1]) / fz
    zmp[ok, 1] = com[ok, 1] - (com[ok, 2] * force[ok, 1] - rate[ok, 0]) / fz
    return zmp


def required_torque(index, qpos: np.ndarray, fps: float, contact_height_m: float = 0.005,
                    friction: float = 0.8, loaded: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Joint angles, velocities and required torques [T, nj] of ``qpos`` [T, nq] at ``fps``:
    ``mj_inverse`` without constraints, the ground reaction distributed over the sole corners
    lower than ``contact_height_m`` (:class:`ContactDistributor`).  Validation's kinematic replay
    measures the same torques with everything else it checks.  ``loaded`` [T, 2] (bool), when
    given, also keeps a foot's corners out where it is False: a foot on the floor planned to
    carry no weight (the feasibility stage's trailing foot after the other has landed)."""
    model = index.kin_model
    data = mujoco.MjData(model)
    qvel, qacc = qvel_qacc(model, qpos, fps)
    distributor = ContactDistributor(model, index.base_dof, friction)
    corner_bodies = index.sole_body[:, None].repeat(4, axis=1)
    torque = np.zeros((qpos.shape[0], index.nj))
    if loaded is not None and np.shape(loaded) != (qpos.shape[0], 2):
        raise ValueError(f"loaded has shape {np.shape(loaded)}, expected ({qpos.shape[0]}, 2)")
    for t in range(qpos.shape[0]):
        data.qpos[:] = qpos[t]
        data.qvel[:] = qvel[t]
        data.qacc[:] = qacc[t]
        mujoco.mj_inverse(model, data)
        corners = data.site_xpos[index.corner_sites]
        down = corners[:, :, 2].min(axis=1) < contact_height_m
        if loaded is not None:
            down &= loaded[t]
        qfrc_contact, _, _ = distributor.solve(data, data.qfrc_inverse, corners[down].reshape(-1, 3),
                                               corner_bodies[down].reshape(-1))
        torque[t] = (data.qfrc_inverse - qfrc_contact)[index.dof_adr]
    return qpos[:, index.qpos_adr], qvel[:, index.dof_adr], torque

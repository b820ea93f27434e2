"""The per-window trajectory optimisation, built once per robot and window length.

Decision variables, for each of the ``W`` frames of a window (``nx = 6 + nj`` per frame)::

    x[t] = (base x, y, z [m], yaw, pitch, roll [rad], joint angles [nj] in robot.joint_names order)

**Base orientation.** ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)`` (intrinsic z-y-x Euler angles).
Yaw is an *unwrapped* angle (never wrapped to +-pi) warm-started from the unwrapped human
heading and bounded to that heading +- ``SolverConfig.max_yaw_offset``, so turning through
+-pi never flips. Pitch and roll are bounded to ``+-SolverConfig.max_tilt``
(1 rad < pi/2, away from the only singularity of this parametrisation) and the base height
to ``SolverConfig.base_height_range`` x its nominal height: these box bounds keep the
optimiser out of flipped or lying-down local minima. No unit-norm constraint is needed
(unlike a quaternion) and the variables stay well scaled.

**Parameters** (a numeric vector ``p``, so one compiled solver serves every window):
scaled human keypoint targets ``[W, K, 3]``, human heading ``[W]``, human foot directions
``[W, 2, 2]``, contact masks ``[W, 2]`` (used by the soft balance terms), the two committed
frames before the window ``[2, nx]``, a flag that says whether they exist, and
(frames per second, ground height).

**Objective** (sum over frames; positions divided by the robot leg length ``L``):
keypoint error ``w_k |site - target|^2 / L^2``; heading ``(yaw - heading)^2``; per foot
``|sole forward (xy) - human foot direction|^2``; velocity ``|x[t]-x[t-1]|^2`` and
acceleration ``|x[t+1]-2x[t]+x[t-1]|^2`` (base position in leg lengths), including the
committed frames before the window; ``|joints - nominal|^2``; base tilt; optional soft balance
terms in contact frames: CoM over the support centre (``CostWeights.com``) and the cart-table
ZMP ``c_xy - (c_z - ground) c''_xy / (g + c''_z)`` (CoM second difference times fps^2) over the
support centre (``CostWeights.zmp``); the support centre is the sole site of the foot in
contact, the midpoint of both in double support.

**Constraints** ``g`` per frame (bounds chosen per call, so contact phases need no rebuild):

* joint velocity: ``x_j[t] - x_j[t-1]`` within ``+-velocity_limit * dt`` (also across the seam);
* per sole, 3 corner heights: ``= ground`` in contact (three corners fix the sole plane: on
  the ground and flat), ``>= ground`` otherwise, plus the 4th corner ``>= ground`` out of
  contact (in contact it lies on the plane of the other three);
* per sole, no slip between consecutive contact frames: sole-site ``xy`` unchanged and the
  sole edge direction unchanged (``cross_z = 0``); chained across the seam to the committed
  frame before the window;
* swing foot (bounds on the same rows, from :mod:`retarget.swing`): out of contact all four
  corners at least a clearance above the ground that rises from lift-off and falls to
  touch-down; in the swing frame next to a contact frame the corners lie in a thin band
  (flat, low sole) and the sole site moves at most a small step horizontally;
* the lateral distance of the left sole site from the right one across the human heading is
  at least a minimum (the feet do not cross into each other).
* optional self-collision rows (``collision_pairs``, :mod:`retarget.collision`): clearances
  ``>= 0`` between the spheres and solids of the given body pairs (a problem per pair set; the
  retargeter adds the pairs that come close, so clips without contact pay nothing).

Joint ranges and the base tilt, yaw and height bounds are variable bounds (no rows in ``g``).
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from retarget.config import CostWeights, SolverConfig
from retarget.kinematics import KinematicTree, center_of_mass, forward_kinematics, quat_to_matrix_np, site_position, site_rotation
from retarget.robot_model import RetargetRobot

SIDES = ("left", "right")
GRAVITY = 9.81  # m/s^2, for the cart-table ZMP of the soft balance term
BASE_NAMES = ("base_x", "base_y", "base_z", "base_yaw", "base_pitch", "base_roll")


def euler_zyx_matrix(yaw, pitch, roll):
    """``Rz(yaw) @ Ry(pitch) @ Rx(roll)`` as a CasADi expression (3x3)."""
    cy, sy, cp, sp, cr, sr = ca.cos(yaw), ca.sin(yaw), ca.cos(pitch), ca.sin(pitch), ca.cos(roll), ca.sin(roll)
    return ca.vertcat(
        ca.horzcat(cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr),
        ca.horzcat(sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr),
        ca.horzcat(-sp, cp * sr, cp * cr),
    )


def euler_zyx_from_quat(q: np.ndarray) -> np.ndarray:
    """(yaw, pitch, roll) of a w, x, y, z quaternion."""
    R = quat_to_matrix_np(q)
    return np.array([np.arctan2(R[1, 0], R[0, 0]), np.arcsin(np.clip(-R[2, 0], -1, 1)), np.arctan2(R[2, 1], R[2, 2])])


def quat_from_euler_zyx(ypr: np.ndarray) -> np.ndarray:
    """w, x, y, z quaternions ``[..., 4]`` of ``ypr[..., 3]`` (yaw, pitch, roll), sign-continuous."""
    ypr = np.asarray(ypr, dtype=np.float64)
    hy, hp, hr = ypr[..., 0] / 2, ypr[..., 1] / 2, ypr[..., 2] / 2
    cy, sy, cp, sp, cr, sr = np.cos(hy), np.sin(hy), np.cos(hp), np.sin(hp), np.cos(hr), np.sin(hr)
    q = np.stack(
        [
            cy * cp * cr + sy * sp * sr,
            cy * cp * sr - sy * sp * cr,
            cy * sp * cr + sy * cp * sr,
            sy * cp * cr - cy * sp * sr,
        ],
        axis=-1,
    )
    if q.ndim == 2:  # make consecutive quaternions continuous (q and -q are the same rotation)
        for t in range(1, len(q)):
            if np.dot(q[t], q[t - 1]) < 0:
                q[t] = -q[t]
    return q


@dataclass
class RobotKinematics:
    """CasADi functions of one frame's variables ``x[nx]`` used by the window problem and metrics.

    ``frame(x) -> (keypoints [3, K], sole_site [3, 2], sole_forward [3, 2], corners [3, 8], com [3])``
    with corners ordered left 0..3, right 0..3.
    """

    robot: RetargetRobot
    nx: int
    nj: int
    frame: ca.Function
    leg_length: float
    nominal_x: np.ndarray  # [nx]
    nominal_sites: dict  # human joint -> nominal world position (3,)
    tree: KinematicTree | None = None

    @classmethod
    def build(cls, robot: RetargetRobot) -> "RobotKinematics":
        tree = KinematicTree.from_model(robot.model)
        nj = len(robot.joint_names)
        nx = 6 + nj
        x = ca.SX.sym("x", nx)
        frames = _body_frames(robot, tree, x)
        kp = [site_position(tree, frames, tree.site_id(k.site)) for k in robot.keypoints]
        # sole forward axis: the site-local direction that is world +x in the nominal pose
        nominal_fk = _numeric_site_rotations(robot, [robot.soles[s].site for s in SIDES])
        sole_pos, sole_fwd, corners = [], [], []
        for side, Rn in zip(SIDES, nominal_fk):
            sid = tree.site_id(robot.soles[side].site)
            sole_pos.append(site_position(tree, frames, sid))
            base_yaw = euler_zyx_from_quat(robot.nominal_qpos[3:7])[0]
            fwd_world = np.array([np.cos(base_yaw), np.sin(base_yaw), 0.0])
            f_local = Rn.T @ fwd_world
            sole_fwd.append(ca.mtimes(site_rotation(tree, frames, sid), ca.DM(f_local)))
            if len(robot.soles[side].corner_sites) != 4:
                raise ValueError(f"robot {robot.name!r}: the {side} sole needs 4 corner sites")
            corners += [site_position(tree, frames, tree.site_id(c)) for c in robot.soles[side].corner_sites]
        com = center_of_mass(tree, frames)
        frame = ca.Function(
            "frame",
            [x],
            [ca.horzcat(*kp) if kp else ca.SX.zeros(3, 0), ca.horzcat(*sole_pos), ca.horzcat(*sole_fwd), ca.horzcat(*corners), com],
            ["x"],
            ["keypoints", "sole_site", "sole_forward", "corners", "com"],
        )
        nominal_x = np.concatenate([robot.nominal_qpos[:3], euler_zyx_from_quat(robot.nominal_qpos[3:7]), robot.nominal_qpos[robot.qpos_adr]])
        kp_nom = np.array(frame(nominal_x)[0]).T if kp else np.zeros((0, 3))
        nominal_sites = {k.human_joint: kp_nom[i] for i, k in enumerate(robot.keypoints)}
        from retarget.targets import robot_leg_length

        try:
            leg = robot_leg_length(nominal_sites)
        except Exception:
            leg = float(max(robot.nominal_qpos[2], 0.1))
        return cls(robot=robot, nx=nx, nj=nj, frame=frame, leg_length=leg, nominal_x=nominal_x, nominal_sites=nominal_sites, tree=tree)

    def clearance_function(self, pairs: tuple, margin: float) -> tuple[ca.Function, list[str]]:
        """``x[nx] -> clearances[n]`` (m, ``>= 0`` = apart by ``margin``) of the self-collision
        ``pairs`` (:class:`retarget.collision.PairGeometry`), and the name of each row."""
        from retarget.collision import clearance_rows

        x = ca.SX.sym("x", self.nx)
        # distances between bodies do not depend on where the robot stands: the rows see the
        # joints only (base at the origin, unrotated), which keeps their derivatives small
        local = ca.vertcat(ca.SX.zeros(6, 1), x[6:])
        rows, names = clearance_rows(self.tree, _body_frames(self.robot, self.tree, local), list(pairs), margin)
        return ca.Function("clearance", [x], [ca.vertcat(*rows) if rows else ca.SX.zeros(0, 1)]), names

    def qpos_from_x(self, x: np.ndarray) -> np.ndarray:
        """``x[T, nx]`` -> MuJoCo ``qpos[T, nq]`` (quaternion w, x, y, z, sign-continuous)."""
        x = np.atleast_2d(x)
        q = np.tile(self.robot.nominal_qpos, (len(x), 1))
        q[:, :3] = x[:, :3]
        q[:, 3:7] = quat_from_euler_zyx(x[:, 3:6])
        q[:, self.robot.qpos_adr] = x[:, 6:]
        return q

    def x_from_qpos(self, qpos: np.ndarray) -> np.ndarray:
        """MuJoCo ``qpos[T, nq]`` -> ``x[T, nx]`` (yaw unwrapped over time)."""
        qpos = np.atleast_2d(qpos)
        x = np.zeros((len(qpos), self.nx))
        x[:, :3] = qpos[:, :3]
        x[:, 3:6] = np.array([euler_zyx_from_quat(q) for q in qpos[:, 3:7]])
        x[:, 3] = np.unwrap(x[:, 3])
        x[:, 6:] = qpos[:, self.robot.qpos_adr]
        return x


def _body_frames(robot: RetargetRobot, tree: KinematicTree, x):
    """World frames of every body for the solver variables ``x[nx]`` (symbolic)."""
    qpos = [ca.SX(float(v)) for v in robot.nominal_qpos]
    for i, a in enumerate(robot.qpos_adr):
        qpos[int(a)] = x[6 + i]
    qpos[0], qpos[1], qpos[2] = x[0], x[1], x[2]
    return forward_kinematics(tree, ca.vertcat(*qpos), root_rotation=euler_zyx_matrix(x[3], x[4], x[5]))


def _numeric_site_rotations(robot: RetargetRobot, sites: list[str]) -> list[np.ndarray]:
    import mujoco

    data = mujoco.MjData(robot.model)
    data.qpos[:] = robot.nominal_qpos
    mujoco.mj_kinematics(robot.model, data)
    out = []
    for s in sites:
        sid = mujoco.mj_name2id(robot.model, mujoco.mjtObj.mjOBJ_SITE, s)
        out.append(np.array(data.site_xmat[sid]).reshape(3, 3))
    return out


@dataclass
class WindowSolution:
    x: np.ndarray  # [W, nx]
    success: bool
    status: str
    iterations: int
    violated: str | None  # name of the worst violated constraint (None when all hold)
    violated_frame: int | None  # window-local frame of that constraint
    violation: float  # its violation (m or rad)
    solve_seconds: float


class WindowProblem:
    """IPOPT problem for ``window`` frames of one robot; call :meth:`solve` once per window."""

    def __init__(
        self,
        kin: RobotKinematics,
        window: int,
        weights: CostWeights = CostWeights(),
        solver: SolverConfig = SolverConfig(),
        velocity_constraints: bool = True,
        collision_pairs: tuple = (),
        collision_margin: float = 0.0,
    ):
        self.kin, self.W, self.weights, self.solver_config = kin, int(window), weights, solver
        self.collision_pairs = tuple(collision_pairs)
        self.velocity_constraints = velocity_constraints
        nv = kin.nj if velocity_constraints else 0
        robot = kin.robot
        W, nx, nj, K = self.W, kin.nx, kin.nj, len(robot.keypoints)
        self.K = K
        L = kin.leg_length
        X = ca.SX.sym("X", nx, W)
        P_target = ca.SX.sym("target", 3 * K, W)
        P_heading = ca.SX.sym("heading", 1, W)
        P_foot = ca.SX.sym("foot", 4, W)
        P_contact = ca.SX.sym("contact", 2, W)
        P_hist = ca.SX.sym("hist", nx, 2)
        P_has_hist = ca.SX.sym("has_hist")
        P_clock = ca.SX.sym("clock", 2)  # frames per second, ground height (m)
        params = [P_target, P_heading, P_foot, P_contact, P_hist, P_has_hist, P_clock]
        self._param_shapes = [p.shape for p in params]

        kp_w = np.array([k.weight for k in robot.keypoints], dtype=np.float64)
        pos_scale = np.concatenate([np.full(3, 1.0 / L), np.ones(3 + nj)])  # velocity/accel in leg lengths
        nominal_j = kin.nominal_x[6:]
        yaw_offset = kin.nominal_x[3]

        res = []  # residuals r: the objective is |r|^2 (Gauss-Newton Hessian 2 J_r^T J_r)
        sq = np.sqrt
        g, names = [], []
        frames = [kin.frame(X[:, t]) for t in range(W)]
        hist_frame = kin.frame(P_hist[:, 1])
        clearance, clearance_names = kin.clearance_function(self.collision_pairs, collision_margin) if self.collision_pairs else (None, [])
        for t in range(W):
            xt = X[:, t]
            kp, sole, fwd, corners, com = frames[t]
            # keypoints
            if K:
                err = (ca.reshape(P_target[:, t], 3, K) - kp) / L
                res.append(ca.vec(ca.mtimes(err, ca.diag(ca.DM(np.sqrt(weights.keypoint * kp_w))))))
            res.append(sq(weights.heading) * (xt[3] - P_heading[t] - yaw_offset))
            for s in range(2):
                d = fwd[:2, s] - P_foot[2 * s : 2 * s + 2, t]
                res.append(sq(weights.foot_yaw) * d)
            dj = xt[6:] - nominal_j
            res.append(sq(weights.nominal) * dj)
            res.append(sq(weights.base_tilt) * xt[4:6])
            if weights.com > 0 or weights.zmp > 0:
                m = P_contact[:, t]
                centre = (m[0] * sole[:2, 0] + m[1] * sole[:2, 1]) / (m[0] + m[1] + 1e-9)
                support = ca.fmin(m[0] + m[1], 1.0)
            if weights.com > 0:
                res.append(sq(weights.com) * support * (com[:2] - centre) / L)
            if weights.zmp > 0 and W >= 3:
                # cart-table ZMP from the CoM's second difference (central; one-sided at the
                # window's last frame; the committed frame before the window at its first)
                if t == 0:
                    c3, zw = (hist_frame[4], com, frames[1][4]), P_has_hist
                elif t == W - 1:
                    c3, zw = (frames[t - 2][4], frames[t - 1][4], com), 1.0
                else:
                    c3, zw = (frames[t - 1][4], com, frames[t + 1][4]), 1.0
                acc_c = (c3[0] - 2 * c3[1] + c3[2]) * P_clock[0] ** 2
                zmp = com[:2] - (com[2] - P_clock[1]) * acc_c[:2] / (GRAVITY + acc_c[2])
                res.append(sq(weights.zmp) * zw * support * (zmp - centre) / L)
            # smoothness, including the committed frames before the window
            prev = X[:, t - 1] if t >= 1 else P_hist[:, 1]
            hw = 1.0 if t >= 1 else P_has_hist
            res.append(hw * sq(weights.velocity) * (xt - prev) * pos_scale)
            if t >= 2:
                acc, aw = xt - 2 * X[:, t - 1] + X[:, t - 2], 1.0
            elif t == 1:
                acc, aw = xt - 2 * X[:, 0] + P_hist[:, 1], P_has_hist
            else:
                acc, aw = xt - 2 * P_hist[:, 1] + P_hist[:, 0], P_has_hist
            res.append(aw * sq(weights.acceleration) * acc * pos_scale)
            # constraints
            if velocity_constraints:
                g.append(xt[6:] - prev[6:])
                names += [f"joint {n} velocity" for n in robot.joint_names]
            prev_sole, prev_corners = (frames[t - 1][1], frames[t - 1][3]) if t >= 1 else (hist_frame[1], hist_frame[3])
            for s, side in enumerate(SIDES):
                c = corners[:, 4 * s : 4 * s + 4]
                g.append(c[2, :].T)
                names += [f"{side} sole corner {i} height" for i in range(4)]
                g.append(sole[:2, s] - prev_sole[:2, s])
                names += [f"{side} sole slip x", f"{side} sole slip y"]
                e_now = c[:2, 1] - c[:2, 0]
                pc = prev_corners[:, 4 * s : 4 * s + 4]
                e_prev = pc[:2, 1] - pc[:2, 0]
                g.append(e_now[0] * e_prev[1] - e_now[1] * e_prev[0])
                names += [f"{side} sole yaw slip"]
            # lateral distance of the left sole site from the right one, across the human heading
            h = P_heading[t]
            d = sole[:2, 0] - sole[:2, 1]
            g.append(-ca.sin(h) * d[0] + ca.cos(h) * d[1])
            names += ["feet lateral separation"]
            if clearance is not None:
                g.append(clearance(xt))
                names += clearance_names
        self._n_clearance = len(clearance_names)
        self._ng_frame = nv + 2 * (4 + 2 + 1) + 1 + self._n_clearance
        self._names = names
        self.nlp_x = ca.vec(X)
        p = ca.vertcat(*[ca.vec(q) for q in params])
        r = ca.vertcat(*res)
        nlp = {"x": self.nlp_x, "p": p, "f": ca.sumsqr(r), "g": ca.vertcat(*g)}
        opts = {
            "print_time": False,
            "ipopt.print_level": 0,
            "ipopt.sb": "yes",
            "ipopt.tol": solver.tol,
            "ipopt.acceptable_tol": solver.acceptable_tol,
            "ipopt.constr_viol_tol": solver.constr_viol_tol,
            "ipopt.max_iter": solver.max_iter,
            "ipopt.hessian_approximation": "limited-memory" if solver.hessian == "limited-memory" else "exact",
            "ipopt.linear_solver": solver.linear_solver,
            "ipopt.mu_strategy": solver.mu_strategy,
        }
        if solver.hessian == "gauss-newton":
            Jr = ca.jacobian(r, self.nlp_x)
            lam_f, lam_g = ca.SX.sym("lam_f"), ca.SX.sym("lam_g", nlp["g"].shape[0])
            # Gauss-Newton for the least-squares objective, exact curvature of the constraints
            Hg, _ = ca.hessian(ca.dot(lam_g, nlp["g"]), self.nlp_x)
            H = ca.triu(lam_f * 2 * ca.mtimes(Jr.T, Jr) + Hg)
            opts["hess_lag"] = ca.Function("nlp_hess_l", [self.nlp_x, p, lam_f, lam_g], [H])
        opts["ipopt.mu_init"] = solver.mu_init
        opts.update({f"ipopt.{k}": v for k, v in solver.extra})
        self.solver = ca.nlpsol("retarget_window", "ipopt", nlp, opts)
        self.ng = int(nlp["g"].shape[0])

        zn = float(kin.nominal_x[2])
        zlo, zhi = (solver.base_height_range[0] * zn, solver.base_height_range[1] * zn) if zn > 0 else (-np.inf, np.inf)
        lo = np.concatenate([[-np.inf, -np.inf, zlo], [-np.inf, -solver.max_tilt, -solver.max_tilt], robot.joint_range[:, 0]])
        hi = np.concatenate([[np.inf, np.inf, zhi], [np.inf, solver.max_tilt, solver.max_tilt], robot.joint_range[:, 1]])
        self.lbx = np.tile(lo, W)
        self.ubx = np.tile(hi, W)

    def constraint_bounds(
        self,
        contacts: np.ndarray,
        prev_contact: np.ndarray | None,
        vel_step: np.ndarray,
        ground: float,
        clearance: np.ndarray | None = None,
        flat: np.ndarray | None = None,
        flat_tolerance: float = 0.0,
        transition_step: float = np.inf,
        min_separation: float = -np.inf,
    ):
        """Bounds ``(lbg, ubg)`` for a window's contact mask ``[W, 2]`` and the contact state of the
        frame before it (``None`` = no committed frame before the window).

        ``clearance[W, 2]`` (m, optional): minimum height above ``ground`` of all sole corners in
        swing frames; ``flat[W, 2]`` bool (optional): swing frames whose corners must also stay
        below ``ground + clearance + flat_tolerance`` (flat, low sole at lift-off / touch-down);
        ``transition_step`` (m): largest horizontal sole-site move between a contact frame and
        the swing frame next to it (lift-off and touch-down; ``inf`` = free); ``min_separation``
        (m): smallest lateral distance of the left sole site from the right one, measured across
        the human heading (``-inf`` = free; keeps the feet from crossing into each other).
        """
        nj = self.kin.nj
        lb, ub = [], []
        inf = np.inf
        for t in range(self.W):
            has_prev = t > 0 or prev_contact is not None
            if self.velocity_constraints:
                lb.append(-vel_step if has_prev else np.full(nj, -inf))
                ub.append(vel_step if has_prev else np.full(nj, inf))
            for s in range(2):
                on = bool(contacts[t, s])
                if on:
                    lb.append(np.array([ground, ground, ground, -inf]))
                    ub.append(np.array([ground] * 3 + [inf]))
                else:
                    low = ground + (float(clearance[t, s]) if clearance is not None else 0.0)
                    high = low + flat_tolerance if (flat is not None and flat[t, s]) else inf
                    lb.append(np.full(4, low))
                    ub.append(np.full(4, high))
                before = bool(contacts[t - 1, s]) if t > 0 else (prev_contact is not None and bool(prev_contact[s]))
                if on and before:
                    slip = 0.0
                elif has_prev and on != before:
                    slip = transition_step
                else:
                    slip = inf
                lb.append(np.array([-slip, -slip, -inf if slip > 0 else 0.0]))
                ub.append(np.array([slip, slip, inf if slip > 0 else 0.0]))
            lb.append([min_separation])
            ub.append([inf])
            if self._n_clearance:
                lb.append(np.zeros(self._n_clearance))
                ub.append(np.full(self._n_clearance, inf))
        return np.concatenate(lb), np.concatenate(ub)

    def solve(
        self,
        x0: np.ndarray,
        targets: np.ndarray,
        heading: np.ndarray,
        foot_dir: np.ndarray,
        contacts: np.ndarray,
        history: np.ndarray | None,
        prev_contact: np.ndarray | None,
        vel_step: np.ndarray,
        ground: float = 0.0,
        clearance: np.ndarray | None = None,
        flat: np.ndarray | None = None,
        flat_tolerance: float = 0.0,
        transition_step: float = np.inf,
        fps: float = 20.0,
        min_separation: float = -np.inf,
    ) -> WindowSolution:
        """Solve one window.

        ``x0[W, nx]`` warm start; ``targets[W, K, 3]`` (m); ``heading[W]`` (rad); ``foot_dir[W, 2, 2]``;
        ``contacts[W, 2]`` bool; ``history[2, nx]`` the two committed frames before the window (or None);
        ``prev_contact[2]`` contact state of the frame before; ``vel_step[nj]`` max joint change per frame (rad);
        ``clearance[W, 2]``, ``flat[W, 2]``, ``flat_tolerance``, ``transition_step``: swing-foot
        bounds, see :meth:`constraint_bounds`; ``fps`` frames per second (for the ZMP term).
        """
        import time

        W, nx = self.W, self.kin.nx
        hist = np.zeros((nx, 2)) if history is None else np.asarray(history).T
        p = np.concatenate(
            [
                np.asarray(targets, dtype=np.float64).reshape(W, -1).T.ravel(order="F"),
                np.asarray(heading, dtype=np.float64).ravel(),
                np.asarray(foot_dir, dtype=np.float64).reshape(W, 4).T.ravel(order="F"),
                np.asarray(contacts, dtype=np.float64).reshape(W, 2).T.ravel(order="F"),
                hist.ravel(order="F"),
                [0.0 if history is None else 1.0],
                [float(fps), float(ground)],
            ]
        )
        lbg, ubg = self.constraint_bounds(contacts, None if history is None else prev_contact, vel_step, ground,
                                          clearance, flat, flat_tolerance, transition_step, min_separation)
        lbx, ubx = self.lbx.copy(), self.ubx.copy()
        yaw_ref = np.asarray(heading, dtype=np.float64).ravel() + self.kin.nominal_x[3]
        lbx[3::nx] = yaw_ref - self.solver_config.max_yaw_offset
        ubx[3::nx] = yaw_ref + self.solver_config.max_yaw_offset
        x0v = np.clip(np.asarray(x0, dtype=np.float64).reshape(W, nx).ravel(), lbx, ubx)
        start = time.perf_counter()
        res = self.solver(x0=x0v, p=p, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
        seconds = time.perf_counter() - start
        stats = self.solver.stats()
        x = np.array(res["x"]).reshape(W, nx)
        gval = np.array(res["g"]).ravel()
        viol_g = np.maximum(lbg - gval, gval - ubg)
        viol_x = np.maximum(lbx - x.ravel(), x.ravel() - ubx)
        worst_g = int(np.argmax(viol_g)) if len(viol_g) else 0
        worst_x = int(np.argmax(viol_x))
        tol = 10 * self.solver_config.constr_viol_tol
        violated, violation, vframe = None, 0.0, None
        if len(viol_g) and viol_g[worst_g] > tol and viol_g[worst_g] >= viol_x[worst_x]:
            t = worst_g // self._ng_frame
            violated, violation, vframe = self._names[worst_g], float(viol_g[worst_g]), t
        elif viol_x[worst_x] > tol:
            t, i = divmod(worst_x, nx)
            name = (BASE_NAMES + tuple(self.kin.robot.joint_names))[i]
            violated, violation, vframe = f"{name} bound", float(viol_x[worst_x]), t
        status = str(stats.get("return_status", "unknown"))
        success = bool(stats.get("success", False)) or (status == "Solved_To_Acceptable_Level" and violated is None)
        return WindowSolution(
            x=x, success=success and violated is None, status=status, iterations=int(stats.get("iter_count", -1)),
            violated=violated, violated_frame=vframe, violation=violation, solve_seconds=seconds,
        )

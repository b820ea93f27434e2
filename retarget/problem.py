# Size (656 lines): one optimisation problem; its costs and constraints share the per-frame symbols.
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
* in the problems built with ``turn_rows`` (the retargeter's choice for a window where the human
  heading turns faster than half the bound in some frame: a spin), the base's turn
  ``yaw[t] - yaw[t-1]`` within ``+-SolverConfig.max_base_turn_speed_deg * dt`` (a base that
  lagged a spinning human caught up by 53 degrees in one frame; a row in every problem, even
  where it never binds, moved a real walk's torque from 0.996 to 1.005 of the OP3's limit);
* per sole, 3 corner heights: ``= ground`` in contact (three corners fix the sole plane: on
  the ground and flat), ``>= ground`` otherwise, plus the 4th corner ``>= ground`` out of
  contact (in contact it lies on the plane of the other three);
* per sole, no slip between consecutive contact frames: sole-site ``xy`` unchanged and the
  sole edge direction unchanged (``cross_z = 0`` with a positive dot product: a sole flipped
  half a turn also has ``cross_z = 0``); a planted foot that pivots (the human's turns fast,
  ``ContactConfig.pivot_speed_deg``) may turn about its sole site by up to ``pivot`` per frame
  (``|cross_z| <= |e|^2 sin(pivot)``); chained across the seam to the committed frame before
  the window;
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
    objective: float = float("nan")  # the window's objective at x


class StageFunctions:
    """The window problem split into one stage per frame (the problem's structure).

    Stage ``t`` sees ``z = (x[t-2], x[t-1], x[t])`` (and ``x[t+1]`` when the ZMP term is on)
    plus its own parameters ``s`` (targets, heading, foot directions, contacts of frame ``t``,
    then the weights of the history terms, the ZMP stencil, frames per second and the ground
    height). It returns the frame's objective ``f_t = |r_t|^2`` and constraint rows ``g_t``;
    the window's objective is ``sum_t f_t`` and its rows are ``g_t`` stacked. Because every
    stage touches three or four consecutive frames only, the gradient, constraint Jacobian and
    Lagrangian Hessian of the window are sums of small per-stage blocks: they are built
    symbolically for one stage (SX, exact) and assembled for the window with MX, so building
    the problem and generating its C code cost the same for a 60-frame window as for a few
    frames, instead of growing with the window (the whole-window SX graph of the exact
    Hessian had 1.15 M instructions).
    """

    #: per-stage constants after the frame parameters: velocity weight, acceleration weight,
    #: ZMP weight, ZMP stencil (1 central, 0 one-sided at the window end), fps, ground height
    N_CONST = 6

    def __init__(self, kin: "RobotKinematics", weights: CostWeights, hessian: str, velocity_constraints: bool,
                 collision_pairs: tuple, collision_margin: float, zmp: bool, turn_rows: bool = False):
        robot = kin.robot
        nx, nj, K = kin.nx, kin.nj, len(robot.keypoints)
        L = kin.leg_length
        self.offsets = (-2, -1, 0, 1) if zmp else (-2, -1, 0)
        span = len(self.offsets)
        z = ca.SX.sym("z", nx * span)
        xs = {o: z[i * nx : (i + 1) * nx] for i, o in enumerate(self.offsets)}
        ns = 3 * K + 1 + 4 + 2
        self.ns = ns + self.N_CONST
        s = ca.SX.sym("s", self.ns)
        target, heading, foot, contact = s[: 3 * K], s[3 * K], s[3 * K + 1 : 3 * K + 5], s[3 * K + 5 : 3 * K + 7]
        w_vel, w_acc, w_zmp, central, fps, ground = (s[ns + i] for i in range(self.N_CONST))

        kp_w = np.array([k.weight for k in robot.keypoints], dtype=np.float64)
        pos_scale = np.concatenate([np.full(3, 1.0 / L), np.ones(3 + nj)])  # velocity/accel in leg lengths
        nominal_j = kin.nominal_x[6:]
        yaw_offset = kin.nominal_x[3]
        sq = np.sqrt
        xt, prev, prev2 = xs[0], xs[-1], xs[-2]
        kp, sole, fwd, corners, com = kin.frame(xt)
        prev_frame = kin.frame(prev)
        res = []
        if K:
            err = (ca.reshape(target, 3, K) - kp) / L
            res.append(ca.vec(ca.mtimes(err, ca.diag(ca.DM(np.sqrt(weights.keypoint * kp_w))))))
        res.append(sq(weights.heading) * (xt[3] - heading - yaw_offset))
        for side in range(2):
            res.append(sq(weights.foot_yaw) * (fwd[:2, side] - foot[2 * side : 2 * side + 2]))
        res.append(sq(weights.nominal) * (xt[6:] - nominal_j))
        res.append(sq(weights.base_tilt) * xt[4:6])
        if weights.com > 0 or weights.zmp > 0:
            centre = (contact[0] * sole[:2, 0] + contact[1] * sole[:2, 1]) / (contact[0] + contact[1] + 1e-9)
            support = ca.fmin(contact[0] + contact[1], 1.0)
        if weights.com > 0:
            res.append(sq(weights.com) * support * (com[:2] - centre) / L)
        if zmp:
            # cart-table ZMP from the CoM's second difference: central (t-1, t, t+1), or
            # one-sided (t-2, t-1, t) at the window's last frame
            c_m2, c_m1, c_p1 = kin.frame(prev2)[4], prev_frame[4], kin.frame(xs[1])[4]
            acc_c = (central * (c_m1 - 2 * com + c_p1) + (1 - central) * (c_m2 - 2 * c_m1 + com)) * fps**2
            zmp_xy = com[:2] - (com[2] - ground) * acc_c[:2] / (GRAVITY + acc_c[2])
            res.append(sq(weights.zmp) * w_zmp * support * (zmp_xy - centre) / L)
        res.append(w_vel * sq(weights.velocity) * (xt - prev) * pos_scale)
        res.append(w_acc * sq(weights.acceleration) * (xt - 2 * prev + prev2) * pos_scale)
        r = ca.vertcat(*res)
        f = ca.sumsqr(r)

        g, names = [], []
        if velocity_constraints:
            g.append(xt[6:] - prev[6:])
            names += [f"joint {n} velocity" for n in robot.joint_names]
        if turn_rows:
            g.append(xt[3] - prev[3])
            names += ["base yaw turn"]
        prev_sole, prev_corners = prev_frame[1], prev_frame[3]
        for side_i, side in enumerate(SIDES):
            c = corners[:, 4 * side_i : 4 * side_i + 4]
            g.append(c[2, :].T)
            names += [f"{side} sole corner {i} height" for i in range(4)]
            g.append(sole[:2, side_i] - prev_sole[:2, side_i])
            names += [f"{side} sole slip x", f"{side} sole slip y"]
            e_now = c[:2, 1] - c[:2, 0]
            pc = prev_corners[:, 4 * side_i : 4 * side_i + 4]
            e_prev = pc[:2, 1] - pc[:2, 0]
            g.append(e_now[0] * e_prev[1] - e_now[1] * e_prev[0])
            g.append(e_now[0] * e_prev[0] + e_now[1] * e_prev[1])
            names += [f"{side} sole yaw slip", f"{side} sole yaw flip"]
        # lateral distance of the left sole site from the right one, across the human heading
        d = sole[:2, 0] - sole[:2, 1]
        g.append(-ca.sin(heading) * d[0] + ca.cos(heading) * d[1])
        names += ["feet lateral separation"]
        self.n_clearance = 0
        if collision_pairs:
            clearance, clearance_names = kin.clearance_function(tuple(collision_pairs), collision_margin)
            g.append(clearance(xt))
            names += clearance_names
            self.n_clearance = len(clearance_names)
        g = ca.vertcat(*g)
        self.names = names
        self.ng = int(g.shape[0])
        self.nz = int(z.shape[0])
        lam_f, lam_g = ca.SX.sym("lam_f"), ca.SX.sym("lam_g", self.ng)
        self.fg = ca.Function("stage_fg", [z, s], [f, g])
        self.grad = ca.Function("stage_grad", [z, s], [f, ca.gradient(f, z)])
        self.jac = ca.Function("stage_jac", [z, s], [g, ca.jacobian(g, z)])
        if hessian == "gauss-newton":
            # Gauss-Newton for the least-squares objective, exact curvature of the constraints
            Jr = ca.jacobian(r, z)
            H = lam_f * 2 * ca.mtimes(Jr.T, Jr) + ca.hessian(ca.dot(lam_g, g), z)[0]
        else:
            H = ca.hessian(lam_f * f + ca.dot(lam_g, g), z)[0]
        self.hess = ca.Function("stage_hess", [z, s, lam_f, lam_g], [H])


def _scatter(entries_src: np.ndarray, rows: np.ndarray, cols: np.ndarray, shape: tuple, n_src: int):
    """The sparsity of the ``shape`` matrix with entries at ``(rows, cols)`` and the constant
    matrix ``A`` (``nnz x n_src``) with ``nonzeros = A @ source`` (entries at the same place add)."""
    order = np.lexsort((rows, cols))  # column-major, as CasADi stores nonzeros
    rows, cols, src = rows[order], cols[order], entries_src[order]
    flat = cols.astype(np.int64) * shape[0] + rows
    uniq, dest = np.unique(flat, return_inverse=True)
    urows, ucols = (uniq % shape[0]).astype(np.int64), (uniq // shape[0]).astype(np.int64)
    colind = np.searchsorted(ucols, np.arange(shape[1] + 1)).astype(np.int64)
    sp = ca.Sparsity(int(shape[0]), int(shape[1]), colind.tolist(), urows.tolist())
    A = ca.DM(ca.Sparsity.triplet(len(uniq), int(n_src), dest.tolist(), src.tolist()), 1.0)
    return sp, A


def window_functions(kin: "RobotKinematics", window: int, stage: StageFunctions, prefix: str) -> dict:
    """The window's NLP functions for IPOPT, assembled from ``stage`` with MX: ``nlp``
    ``(x, p) -> (f, g)``, ``nlp_grad_f`` ``-> (f, grad_f)``, ``nlp_jac_g`` ``-> (g, jac_g)`` and
    ``nlp_hess_l`` ``(x, p, lam_f, lam_g) -> triu(H)``; names start with ``prefix``.

    Every stage function is evaluated once for all frames (``Function.map``); the window's
    Jacobian and Hessian nonzeros are one constant sparse matrix times the stages' nonzeros
    (the blocks of consecutive stages that overlap add up), so the graph and its C code stay
    small whatever the window length."""
    W, nx, K = int(window), kin.nx, len(kin.robot.keypoints)
    offsets = stage.offsets
    sizes = [3 * K * W, W, 4 * W, 2 * W, 2 * nx, 1, 2]
    x = ca.MX.sym("x", nx * W)
    p = ca.MX.sym("p", int(sum(sizes)))
    parts, i = [], 0
    for n in sizes:
        parts.append(p[i : i + n])
        i += n
    target = ca.reshape(parts[0], 3 * K, W)
    heading, foot, contact = ca.reshape(parts[1], 1, W), ca.reshape(parts[2], 4, W), ca.reshape(parts[3], 2, W)
    hist, has_hist, clock = ca.reshape(parts[4], nx, 2), parts[5], parts[6]
    X = ca.reshape(x, nx, W)

    def shifted(o):  # columns x[t + o] for t = 0..W-1 (history before the window; x[W-1] past its end)
        if o < 0:
            return ca.horzcat(hist[:, 2 + o :], X[:, : W + o]) if W + o > 0 else hist[:, 2 + o : 2 + o + W]
        if o > 0:
            return ca.horzcat(X[:, o:], ca.repmat(X[:, W - 1], 1, o))
        return X

    Z = ca.vertcat(*[shifted(o) for o in offsets])
    ones = ca.DM.ones(1, W)

    def first(n, value):  # a row that is ``value`` in the first n frames and 1 after
        return ca.horzcat(ca.repmat(value, 1, min(n, W)), ones[:, min(n, W) :]) if W > n else ca.repmat(value, 1, W)

    central = ca.DM.ones(1, W)
    central[W - 1] = 0
    if len(offsets) < 4:
        central = ca.DM.zeros(1, W)
    S = ca.vertcat(target, heading, foot, contact, first(1, has_hist), first(2, has_hist), first(1, has_hist), central,
                   ca.repmat(clock[0], 1, W), ca.repmat(clock[1], 1, W))
    ng = stage.ng
    f_all, g_all = stage.fg.map(W)(Z, S)
    f = ca.sum2(f_all)
    g = ca.vec(g_all)
    _, gz = stage.grad.map(W)(Z, S)
    grad = 0
    for a, o in enumerate(offsets):
        block = gz[a * nx : (a + 1) * nx, :]
        if o < 0:
            block = ca.horzcat(block[:, -o:], ca.MX(nx, min(-o, W)))[:, :W]
        elif o > 0:
            block = ca.horzcat(ca.MX(nx, o), block[:, : W - o])[:, :W]
        grad = grad + block
    grad_f = ca.vec(grad)

    def place(sp_stage, keep_upper: bool):
        """Rows, columns and source nonzero of every stage nonzero inside the window."""
        r, c = (np.array(v, dtype=np.int64) for v in sp_stage.get_triplet())
        n = len(r)
        rows, cols, src = [], [], []
        off = np.array(offsets)
        for t in range(W):
            if keep_upper:  # Hessian: rows and columns are both frame variables
                fi, fj = t + off[r // nx], t + off[c // nx]
                ok = (fi >= 0) & (fi < W) & (fj >= 0) & (fj < W)
                R, C = fi * nx + r % nx, fj * nx + c % nx
                ok &= R <= C
            else:  # Jacobian: rows of stage t, columns of frames t + offset
                fj = t + off[c // nx]
                ok = (fj >= 0) & (fj < W)
                R, C = t * ng + r, fj * nx + c % nx
            rows.append(R[ok])
            cols.append(C[ok])
            src.append(t * n + np.flatnonzero(ok))
        return np.concatenate(rows), np.concatenate(cols), np.concatenate(src), n

    _, jz = stage.jac.map(W)(Z, S)
    rows, cols, src, n = place(stage.jac.sparsity_out(1), False)
    sp, A = _scatter(src, rows, cols, (ng * W, nx * W), n * W)
    jac_g = ca.sparsity_cast(ca.mtimes(A, ca.sparsity_cast(jz, ca.Sparsity.dense(n * W, 1))), sp)

    lam_f = ca.MX.sym("lam_f")
    lam_g = ca.MX.sym("lam_g", ng * W)
    hz = stage.hess.map(W)(Z, S, lam_f, ca.reshape(lam_g, ng, W))
    rows, cols, src, n = place(stage.hess.sparsity_out(0), True)
    sp, A = _scatter(src, rows, cols, (nx * W, nx * W), n * W)
    H = ca.sparsity_cast(ca.mtimes(A, ca.sparsity_cast(hz, ca.Sparsity.dense(n * W, 1))), sp)
    return {
        "nlp": ca.Function(f"{prefix}nlp", [x, p], [f, g], ["x", "p"], ["f", "g"]),
        "grad_f": ca.Function(f"{prefix}nlp_grad_f", [x, p], [f, grad_f], ["x", "p"], ["f", "grad_f_x"]),
        "jac_g": ca.Function(f"{prefix}nlp_jac_g", [x, p], [g, jac_g], ["x", "p"], ["g", "jac_g_x"]),
        "hess_lag": ca.Function(f"{prefix}nlp_hess_l", [x, p, lam_f, lam_g], [H], ["x", "p", "lam_f", "lam_g"], ["hess_gamma_x_x"]),
    }


class WindowProblem:
    """IPOPT problem for ``window`` frames of one robot; call :meth:`solve` once per window.

    ``cache`` (a :class:`retarget.cache.ProblemCache`, or None): where the compiled NLP
    functions of this problem are looked up (a hit skips the symbolic build) and stored."""

    def __init__(
        self,
        kin: RobotKinematics,
        window: int,
        weights: CostWeights = CostWeights(),
        solver: SolverConfig = SolverConfig(),
        velocity_constraints: bool = True,
        collision_pairs: tuple = (),
        collision_margin: float = 0.0,
        cache=None,
        turn_rows: bool = False,
    ):
        self.kin, self.W, self.weights, self.solver_config = kin, int(window), weights, solver
        self.collision_pairs = tuple(collision_pairs)
        self.velocity_constraints = velocity_constraints
        self.turn_rows = bool(turn_rows)
        robot = kin.robot
        W, nx = self.W, kin.nx
        self.K = len(robot.keypoints)
        zmp = weights.zmp > 0 and W >= 3
        self.cache_status = "off"
        functions = names = None
        key = None
        if cache is not None:
            key = cache.key(kin, W, weights, solver, velocity_constraints, self.collision_pairs, collision_margin,
                            self.turn_rows)
            loaded = cache.load(key)
            if loaded is not None:
                functions, names, self._n_clearance = loaded
                self.cache_status = "hit"
        if functions is None:
            stage = StageFunctions(kin, weights, solver.hessian, velocity_constraints, self.collision_pairs,
                                   collision_margin, zmp, self.turn_rows)
            prefix = f"rt{key[:12]}_" if key else "rt_"
            functions, names, self._n_clearance = window_functions(kin, W, stage, prefix), stage.names, stage.n_clearance
            if cache is not None:
                self.cache_status = cache.store(key, functions, names, self._n_clearance, kin.nominal_x)
        self._ng_frame = len(names)
        self._names = list(names) * W
        corners = np.array(kin.frame(kin.nominal_x)[3]).T.reshape(2, 4, 3)
        edge = corners[:, 1, :2] - corners[:, 0, :2]
        self._edge2 = (edge ** 2).sum(axis=1)  # per sole, the squared corner 0 -> 1 edge (yaw rows' scale)
        opts = {
            "print_time": False,
            "calc_lam_p": False,
            "no_nlp_grad": True,
            "ipopt.print_level": 0,
            "ipopt.sb": "yes",
            "ipopt.tol": solver.tol,
            "ipopt.acceptable_tol": solver.acceptable_tol,
            "ipopt.constr_viol_tol": solver.constr_viol_tol,
            "ipopt.max_iter": solver.max_iter,
            "ipopt.max_cpu_time": float(solver.max_cpu_time),
            "ipopt.hessian_approximation": "limited-memory" if solver.hessian == "limited-memory" else "exact",
            "ipopt.linear_solver": solver.linear_solver,
            "ipopt.mu_strategy": solver.mu_strategy,
            "grad_f": functions["grad_f"],
            "jac_g": functions["jac_g"],
        }
        if solver.hessian != "limited-memory":
            opts["hess_lag"] = functions["hess_lag"]
        opts["ipopt.mu_init"] = solver.mu_init
        opts.update({f"ipopt.{k}": v for k, v in solver.extra})
        self.functions = functions
        self.solver = ca.nlpsol("retarget_window", "ipopt", functions["nlp"], opts)
        self.ng = self._ng_frame * W

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
        pivot: np.ndarray | None = None,
        yaw_step: float = np.inf,
    ):
        """Bounds ``(lbg, ubg)`` for a window's contact mask ``[W, 2]`` and the contact state of the
        frame before it (``None`` = no committed frame before the window).

        ``clearance[W, 2]`` (m, optional): minimum height above ``ground`` of all sole corners in
        swing frames; ``flat[W, 2]`` bool (optional): swing frames whose corners must also stay
        below ``ground + clearance + flat_tolerance`` (flat, low sole at lift-off / touch-down);
        ``transition_step`` (m): largest horizontal sole-site move between a contact frame and
        the swing frame next to it (lift-off and touch-down; ``inf`` = free); ``min_separation``
        (m): smallest lateral distance of the left sole site from the right one, measured across
        the human heading (``-inf`` = free; keeps the feet from crossing into each other);
        ``pivot[W, 2]`` (rad, optional): how far a planted sole may turn from the frame before
        (0 = not at all); ``yaw_step`` (rad): how far the base may turn from the frame before (a
        problem built with ``turn_rows``).
        """
        nj = self.kin.nj
        lb, ub = [], []
        inf = np.inf
        for t in range(self.W):
            has_prev = t > 0 or prev_contact is not None
            if self.velocity_constraints:
                lb.append(-vel_step if has_prev else np.full(nj, -inf))
                ub.append(vel_step if has_prev else np.full(nj, inf))
            if self.turn_rows:
                lb.append([-yaw_step if has_prev else -inf])
                ub.append([yaw_step if has_prev else inf])
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
                    turn = min(float(pivot[t, s]), 1.5) if pivot is not None else 0.0
                    twist = self._edge2[s] * np.sin(turn)
                    lb.append(np.array([0.0, 0.0, -twist, 0.0]))
                    ub.append(np.array([0.0, 0.0, twist, inf]))
                    continue
                slip = transition_step if has_prev and on != before else inf
                lb.append(np.array([-slip, -slip, -inf, -inf]))
                ub.append(np.array([slip, slip, inf, inf]))
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
        pivot: np.ndarray | None = None,
    ) -> WindowSolution:
        """Solve one window.

        ``x0[W, nx]`` warm start; ``targets[W, K, 3]`` (m); ``heading[W]`` (rad); ``foot_dir[W, 2, 2]``;
        ``contacts[W, 2]`` bool; ``history[2, nx]`` the two committed frames before the window (or None);
        ``prev_contact[2]`` contact state of the frame before; ``vel_step[nj]`` max joint change per frame (rad);
        ``clearance[W, 2]``, ``flat[W, 2]``, ``flat_tolerance``, ``transition_step``, ``pivot``:
        foot bounds, see :meth:`constraint_bounds`; ``fps`` frames per second (for the ZMP term).
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
                                          clearance, flat, flat_tolerance, transition_step, min_separation, pivot,
                                          np.radians(self.solver_config.max_base_turn_speed_deg) / fps)
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
            objective=float(np.array(res["f"]).ravel()[0]),
        )

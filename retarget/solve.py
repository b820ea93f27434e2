# Size (419 lines): one clip solve: contacts, scaling and the window loop share its state.
"""Retarget a whole clip: contact detection, scaling, then window after window of IPOPT.

Windows: window ``k`` optimises frames ``[s_k, s_k + W)``; its first ``W - overlap`` frames are
committed, the last ``overlap`` frames only warm-start the next window (which starts at
``s_k + W - overlap`` and re-solves them knowing more of the future). The last window is
moved back to end at the clip's last frame (it may re-solve committed frames). Every window
sees the two committed frames before it as fixed history: they enter the velocity and
acceleration costs, the joint velocity bounds and the no-slip constraints, so position,
velocity and planted feet are continuous across the seams.

``mode="per-frame"`` is the same problem with ``W = 1`` and no overlap: one frame at a time,
warm-started from the previous frame (the IK baseline).
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from motok_robot.errors import InputError
from motok_robot.motion.skeleton import JOINT_NAMES, leg_length, rest_pose
from retarget.config import ContactConfig, RetargetConfig
from retarget.contacts import contact_phases, detect_contacts, ensure_double_support, fill_support
from retarget.problem import RobotKinematics, WindowProblem
from retarget.robot_model import RetargetRobot
from retarget.swing import swing_clearance, transition_frames
from retarget.targets import HumanTargets, make_targets

#: off a terminal, clips of more windows than this report progress (a line every 30 s)
LOG_PROGRESS_WINDOWS = 20


@dataclass
class WindowReport:
    start: int
    stop: int
    status: str
    success: bool
    iterations: int
    violated: str | None  # "frame F: constraint" of the worst violated constraint, None when all hold
    violation: float
    seconds: float


@dataclass
class RetargetResult:
    """Output of :func:`Retargeter.run`.

    ``qpos[T, nq]`` MuJoCo order (free base pos, quat w x y z, joints); ``x[T, nx]`` the solver
    variables (base pos, yaw/pitch/roll, joints); ``contacts[T, 2]`` bool (left, right);
    ``keypoint_error[T, K]`` metres between robot site and scaled human target;
    ``targets`` the scaled human targets; ``source[T, 22, 3]`` the input joints;
    ``collision_pairs`` the geom pairs that came close and were kept apart (``retarget.collision``).
    """

    robot: str
    fps: float
    qpos: np.ndarray
    x: np.ndarray
    joint_names: list[str]
    contacts: np.ndarray
    keypoint_error: np.ndarray
    keypoint_names: list[str]
    targets: HumanTargets
    source: np.ndarray
    windows: list[WindowReport] = field(default_factory=list)
    solve_seconds: float = 0.0
    mode: str = "trajectory"
    collision_pairs: list[str] = field(default_factory=list)  # geom pairs kept apart ("geom1|geom2")
    collision_rounds: int = 0  # re-solves with self-collision rows (0: nothing came close)
    first_window_seconds: float = float("nan")  # from the start of run() until the first window was solved

    @property
    def success(self) -> bool:
        return all(w.success for w in self.windows)

    def failed_windows(self) -> list[WindowReport]:
        return [w for w in self.windows if not w.success]

    def solver_status(self) -> list[dict]:
        return [asdict(w) for w in self.windows]


def validate_joints(joints, source: str = "input") -> np.ndarray:
    """Check a ``[T, 22, 3]`` joint array; raise :class:`InputError` naming the problem."""
    j = np.asarray(joints)
    if j.ndim != 3 or j.shape[-1] != 3:
        raise InputError(f"{source}: joints must have shape [T, 22, 3], got {list(j.shape)}")
    if j.shape[1] != len(JOINT_NAMES):
        raise InputError(f"{source}: joints have {j.shape[1]} joints per frame, expected {len(JOINT_NAMES)} (canonical body)")
    if j.shape[0] < 1:
        raise InputError(f"{source}: the motion has no frames")
    j = j.astype(np.float64)
    bad = ~np.isfinite(j)
    if bad.any():
        t, k, _ = np.argwhere(bad)[0]
        raise InputError(f"{source}: non-finite value (NaN/inf) at frame {t}, joint {JOINT_NAMES[k]!r} ({bad.any(axis=2).sum()} joint values bad)")
    return j


def scaled_contact_config(joints: np.ndarray, config: ContactConfig) -> ContactConfig:
    """Thresholds scaled by the body's leg length relative to the canonical adult's."""
    r = float(np.median(leg_length(joints)) / leg_length(rest_pose()))
    if not np.isfinite(r) or r <= 0:
        return config
    return replace(
        config,
        toe_height=config.toe_height * r,
        ankle_height=config.ankle_height * r,
        enter_speed=config.enter_speed * r,
        exit_speed=config.exit_speed * r,
    )


class Retargeter:
    """Holds a robot's kinematics and the compiled window problems (built once, reused)."""

    def __init__(self, robot: RetargetRobot, config: RetargetConfig = RetargetConfig(), cache=None):
        if config.mode not in ("trajectory", "per-frame"):
            raise InputError(f"unknown retargeting mode {config.mode!r} (trajectory or per-frame)")
        if config.mode == "trajectory" and not (config.window >= 2 and 0 <= config.overlap < config.window - 1):
            raise InputError(f"window {config.window} / overlap {config.overlap}: need window >= 2 and 0 <= overlap < window - 1")
        self.robot, self.config = robot, config
        self.kin = RobotKinematics.build(robot)
        # compiled problems on disk (retarget.cache): None = from the environment, False = off
        from retarget.cache import ProblemCache

        if cache is None:
            cache = ProblemCache.from_env()
        self.cache = cache if isinstance(cache, ProblemCache) else (ProblemCache(cache) if cache else None)
        self._problems: dict[tuple, WindowProblem] = {}
        self._monitor = None

    @property
    def window(self) -> int:
        return 1 if self.config.mode == "per-frame" else self.config.window

    @property
    def overlap(self) -> int:
        return 0 if self.config.mode == "per-frame" else self.config.overlap

    def problem(self, size: int, geom_pairs: tuple = (), turn_rows: bool = False) -> WindowProblem:
        """The compiled problem for ``size`` frames, with self-collision rows for ``geom_pairs``
        (sorted ``(geom1, geom2)`` MuJoCo geom ids) and, with ``turn_rows``, the bound on the
        base's turn between frames (built on first use)."""
        from retarget.collision import pair_geometry

        key = (size, tuple(geom_pairs), bool(turn_rows))
        if key not in self._problems:
            geometry = tuple(pair_geometry(self.robot.model, *pair) for pair in geom_pairs)
            self._problems[key] = WindowProblem(self.kin, size, self.config.weights, self.config.solver,
                                                collision_pairs=geometry, collision_margin=self.config.collision.margin,
                                                cache=self.cache, turn_rows=turn_rows)
        return self._problems[key]

    def spins(self, heading: np.ndarray, fps: float) -> bool:
        """Whether a window whose human heading is ``heading`` [W] (rad) gets the bound on the
        base's turn: the human turns faster than half of ``SolverConfig.max_base_turn_speed_deg``
        in some frame of it (the Bandai spinning kick: 25-33 degrees a frame at 20 fps)."""
        h = np.unwrap(np.asarray(heading, dtype=np.float64).ravel())
        limit = np.radians(self.config.solver.max_base_turn_speed_deg)
        return h.size > 1 and float(np.abs(np.diff(h)).max()) * fps > 0.5 * limit

    def collision_monitor(self):
        """The :class:`retarget.collision.CollisionMonitor` of this robot (built on first use)."""
        from retarget.collision import CollisionMonitor

        if self._monitor is None:
            self._monitor = CollisionMonitor(self.robot.model, self.robot.nominal_qpos, self.config.collision.detect_margin)
        return self._monitor

    def prepare(self, frames: int) -> None:
        """Build every problem a clip of ``frames`` frames needs (so timing can exclude it)."""
        self.problem(min(self.window, frames))
        if self._presolve_size(min(self.window, frames)) > 0:
            self.problem(self._presolve_size(min(self.window, frames)))

    def _presolve_size(self, first_window: int) -> int:
        n = self.config.presolve_frames
        return n if self.config.mode == "trajectory" and 2 <= n < first_window else 0

    def _swing_bounds(self, contacts: np.ndarray, fps: float, foot_dir: np.ndarray) -> dict:
        """Foot keyword arguments of :meth:`WindowProblem.solve` for the whole clip (swing bounds,
        feet apart, pivots of planted feet from the human foot directions ``foot_dir`` [T, 2, 2])."""
        sw = self.config.swing
        gap = self.config.min_foot_gap
        sep = -np.inf if gap is None else self._sole_width() + gap * self.kin.leg_length
        cc = self.config.contacts
        pivot = pivot_allowance(foot_dir, fps, contacts, cc.pivot_speed_deg, cc.pivot_min_turn_deg, cc.pivot_margin)
        if sw.height <= 0:
            return {"clearance": None, "flat": None, "flat_tolerance": 0.0, "transition_step": np.inf, "min_separation": sep,
                    "pivot": pivot}
        return {
            "min_separation": sep,
            "pivot": pivot,
            "clearance": swing_clearance(contacts, fps, sw),
            "flat": transition_frames(contacts),
            "flat_tolerance": sw.flat_tolerance,
            "transition_step": sw.transition_speed / fps,
        }

    def _sole_width(self) -> float:
        """Smallest lateral distance (m) between the two sole sites at which the soles just touch:
        half the lateral extent of each sole (corners relative to its site) in the nominal pose, summed."""
        out = self.kin.frame(self.kin.nominal_x)
        site, corners = np.array(out[1]).T, np.array(out[3]).T.reshape(2, 4, 3)
        yaw = self.kin.nominal_x[3]
        across = np.array([-np.sin(yaw), np.cos(yaw)])
        left = float(-((corners[0, :, :2] - site[0, :2]) @ across).min())  # extent towards the right foot
        right = float(((corners[1, :, :2] - site[1, :2]) @ across).max())  # extent towards the left foot
        return left + right

    @staticmethod
    def _slice(bounds: dict, s: int, e: int) -> dict:
        return {k: (v[s:e] if isinstance(v, np.ndarray) else v) for k, v in bounds.items()}

    def _presolve(self, x, known, n, first_window: int, targets: HumanTargets, kp_targets, contacts, vel_step, swing: dict, fps: float) -> None:
        """Sweep the first window in chunks of ``n`` frames (each chunk chained to the previous one
        and warm-started from it by nearest pose): a cheap, rough first pass that warm-starts the
        first full window much better than the nominal pose does."""
        prob = self.problem(n)
        for s in range(0, first_window - n + 1, n):
            x0 = self._warm_start(x, known, s, s + n, targets, kp_targets)
            history = x[s - 2 : s] if s >= 2 else None
            sol = prob.solve(x0, kp_targets[s : s + n], targets.heading[s : s + n], targets.foot_dir[s : s + n],
                             contacts[s : s + n], history, contacts[s - 1] if s else None, vel_step, self.config.ground_height,
                             **self._slice(swing, s, s + n), fps=fps)
            x[s : s + n] = sol.x
            known[s : s + n] = True

    def _keypoint_errors(self, x: np.ndarray, kp_targets: np.ndarray) -> np.ndarray:
        """[W, K] distance (m) of each keypoint of the solved frames ``x`` [W, nx] from its target."""
        W, K = len(x), kp_targets.shape[1]
        if not K:
            return np.zeros((W, 0))
        kp = np.array(self.kin.frame.map(W)(x.T)[0]).reshape(3, K, W, order="F")
        return np.linalg.norm(kp.transpose(2, 1, 0) - kp_targets, axis=-1)

    def windows(self, T: int) -> list[tuple[int, int, int]]:
        """``[(start, stop, commit_stop)]`` for a clip of ``T`` frames."""
        W, O = self.window, self.overlap
        if T <= W:
            return [(0, T, T)]
        out, s = [], 0
        while s + W < T:
            out.append((s, s + W, s + W - O))
            s += W - O
        out.append((T - W, T, T))
        return out

    def run(self, joints: np.ndarray, fps: float, progress: bool | None = None, source: str = "input") -> RetargetResult:
        """Retarget ``joints[T, 22, 3]`` (metres, z up) sampled at ``fps``."""
        cfg = self.config
        joints = validate_joints(joints, source)
        if not np.isfinite(fps) or fps <= 0:
            raise InputError(f"{source}: fps must be positive, got {fps}")
        T = len(joints)
        contact_cfg = scaled_contact_config(joints, cfg.contacts)
        contacts = fill_support(detect_contacts(joints, fps, contact_cfg), joints, contact_cfg)
        contacts = ensure_double_support(contacts, contact_cfg.min_double_support, contact_cfg.min_swing_frames)
        targets = make_targets(joints, self.kin.nominal_sites, self.robot.limb_scale, contacts, scale=cfg.scale, mode=cfg.scaling)
        K = len(self.robot.keypoints)
        kp_idx = [JOINT_NAMES.index(k.human_joint) for k in self.robot.keypoints]
        kp_targets = targets.joints[:, kp_idx, :]  # [T, K, 3]
        vel_step = self.robot.velocity_limit * cfg.velocity_margin / fps
        swing = self._swing_bounds(contacts, fps, targets.foot_dir)

        x = np.zeros((T, self.kin.nx))
        known = np.zeros(T, dtype=bool)  # frames with a solved value (committed or look-ahead)
        start_time = time.perf_counter()
        clip = (targets, kp_targets, contacts, vel_step, swing, fps)
        reports = self._solve_windows(x, known, clip, (), progress, f"retarget {self.robot.name} ({cfg.mode})")
        active, rounds, reports = self._avoid_self_collision(x, known, clip, reports, progress)
        solve_seconds = time.perf_counter() - start_time
        if self.cache is not None:
            self.cache.flush()  # C code of the problems built for this clip, compiled in the background

        qpos = self.kin.qpos_from_x(x)
        kp_err = self._keypoint_errors(x, kp_targets)
        return RetargetResult(
            robot=self.robot.name, fps=float(fps), qpos=qpos, x=x, joint_names=list(self.robot.joint_names),
            contacts=contacts, keypoint_error=kp_err, keypoint_names=[k.human_joint for k in self.robot.keypoints],
            targets=targets, source=np.asarray(joints, dtype=np.float32), windows=reports,
            solve_seconds=solve_seconds, mode=cfg.mode, collision_rounds=rounds,
            first_window_seconds=self._first_window_at - start_time,
            collision_pairs=[self._pair_name(p) for p in active],
        )

    def _solve_windows(self, x, known, clip, geom_pairs: tuple, progress, desc: str) -> list[WindowReport]:
        """Solve every window of the clip in order, writing ``x`` and ``known``; the window reports."""
        from tqdm import tqdm

        targets, kp_targets, contacts, vel_step, swing, fps = clip
        T = len(x)
        reports: list[WindowReport] = []
        windows = list(self.windows(T))
        if progress is None:  # a terminal gets the bar; a log gets a line every 30 s on long clips
            import sys

            quiet = not sys.stderr.isatty() and len(windows) <= LOG_PROGRESS_WINDOWS
            bar = tqdm(windows, desc=desc, unit="window", disable=quiet,
                       mininterval=0.1 if sys.stderr.isatty() else 30.0)
        else:
            bar = tqdm(windows, desc=desc, unit="window", disable=not progress)
        for s, e, commit in bar:
            prob = self.problem(e - s, geom_pairs, self.spins(targets.heading[s:e], fps))
            presolved = s == 0 and known.sum() == 0 and self._presolve_size(e) > 0
            if presolved:
                self._presolve(x, known, self._presolve_size(e), e, targets, kp_targets, contacts, vel_step, swing, fps)
            history = x[s - 2 : s] if s >= 2 else (np.stack([x[0], x[0]]) if s == 1 else None)
            prev_contact = contacts[s - 1] if s >= 1 else None

            def solve_window():
                return prob.solve(
                    self._warm_start(x, known, s, e, targets, kp_targets), kp_targets[s:e], targets.heading[s:e],
                    targets.foot_dir[s:e], contacts[s:e], history, prev_contact, vel_step, self.config.ground_height,
                    **self._slice(swing, s, e), fps=fps,
                )

            sol = solve_window()
            if presolved and (not sol.success or self._keypoint_errors(sol.x, kp_targets[s:e]).max(initial=0.0)
                              > self.config.presolve_retry_per_leg * self.kin.leg_length):
                # the presolve's chain can start the first window where IPOPT finds no way back to
                # feasibility (seen on a Bandai walk with the OP3's one-way elbows), or in a bad local
                # minimum (a generated kick: the base pinned at its lowest bound, keypoints 27 cm off,
                # "Solve_Succeeded"): solve it again from the plain warm start, the nominal pose on the
                # human root, and keep the better solution
                known[s:e] = False
                again = solve_window()
                if again.success and (not sol.success or again.objective < sol.objective):
                    sol = again
            x[s:e] = sol.x
            known[s:e] = True
            if not reports and not geom_pairs:
                self._first_window_at = time.perf_counter()
            violated = None if sol.violated is None else f"frame {s + sol.violated_frame}: {sol.violated}"
            reports.append(WindowReport(s, e, sol.status, sol.success, sol.iterations, violated, sol.violation, sol.solve_seconds))
        bar.close()
        return reports

    def _avoid_self_collision(self, x, known, clip, reports: list, progress) -> tuple[list, int, list]:
        """Re-solve the clip with self-collision rows for the geom pairs that come close; the
        active set grows while new pairs come close (``CollisionConfig.max_rounds`` at most).

        A re-solve that leaves more windows failed than the solution it started from is undone.
        Returns the geom pairs kept apart in the solution left in ``x`` (none if every re-solve
        was undone), the number of re-solves tried and the window reports of that solution."""
        cfg = self.config.collision
        active: set = set()
        kept: set = set()
        rounds = 0
        if not cfg.enabled:
            return [], 0, reports
        monitor = self.collision_monitor()
        for _ in range(cfg.max_rounds):
            close = set(monitor.close_pairs(self.kin.qpos_from_x(x)))
            if close <= active:
                break
            active |= close
            before = x.copy()
            rounds += 1
            rows = self._compiled_superset(active, {e - s for s, e, _ in self.windows(len(x))})
            names = ", ".join(self._pair_name(p) for p in sorted(active))
            again = self._solve_windows(x, known, clip, rows, progress, f"self-collision pass {rounds} ({names})")
            if sum(not w.success for w in again) > sum(not w.success for w in reports):
                x[:] = before
                break
            reports, kept = again, set(active)
        return sorted(kept), rounds, reports

    def _compiled_superset(self, pairs: set, sizes: set) -> tuple:
        """The smallest pair set that holds ``pairs`` and is compiled for every window size in
        ``sizes`` (building a problem takes seconds; rows for pairs that stay apart cost little
        to solve), else ``pairs`` sorted."""
        found = [key for _, key, _ in self._problems
                 if pairs <= set(key) and all((n, key, False) in self._problems for n in sizes)]
        return min(found, key=len) if found else tuple(sorted(pairs))

    def _pair_name(self, pair: tuple[int, int]) -> str:
        import mujoco

        m = self.robot.model
        return "|".join(geom_label(m, g) for g in pair)

    def _warm_start(self, x, known, s, e, targets: HumanTargets, kp_targets) -> np.ndarray:
        """Initial guess for frames ``[s, e)``: earlier solutions where they exist; otherwise the
        solved frame whose human pose (keypoint targets relative to the root, in the heading
        frame) is nearest, moved to this frame's root and heading (walking repeats itself, so
        this is usually a close guess); the nominal pose on the human root for the first window."""
        x0 = np.zeros((e - s, self.kin.nx))
        root = self._root_track(kp_targets)
        solved = np.flatnonzero(known[:s]) if s > 0 else np.flatnonzero(known)
        if len(solved):
            local = _heading_local(kp_targets - root[:, None, :], targets.heading)
            lib = local[solved].reshape(len(solved), -1)
        for i, t in enumerate(range(s, e)):
            if known[t]:
                x0[i] = x[t]
                continue
            if len(solved):
                u = int(solved[np.argmin(((lib - local[t].reshape(1, -1)) ** 2).sum(axis=1))])
                d = targets.heading[t] - targets.heading[u]
                c, si = np.cos(d), np.sin(d)
                rot = np.array([[c, -si, 0], [si, c, 0], [0, 0, 1]])
                x0[i] = x[u]
                x0[i, :3] = root[t] + rot @ (x[u, :3] - root[u])
                x0[i, 3] = x[u, 3] + d
                continue
            ref = t - 1 if t >= 1 and (known[t - 1] or i > 0) else None
            if ref is not None:
                prev = x0[i - 1] if i > 0 else x[ref]
                x0[i] = prev
                x0[i, :3] += root[t] - root[ref]
                x0[i, 3] += targets.heading[t] - targets.heading[ref]
            else:
                n = self.kin.nominal_x.copy()
                offset = n[:3] - self._nominal_root()
                c, si = np.cos(targets.heading[t]), np.sin(targets.heading[t])
                rot = np.array([[c, -si, 0], [si, c, 0], [0, 0, 1]])
                n[:3] = root[t] + rot @ offset
                n[2] = self.kin.nominal_x[2] + (root[t, 2] - self._nominal_root()[2])
                n[3] = self.kin.nominal_x[3] + targets.heading[t]
                x0[i] = n
        return x0

    def _root_index(self) -> list[int]:
        names = [k.human_joint for k in self.robot.keypoints]
        if "pelvis" in names:
            return [names.index("pelvis")]
        hips = [names.index(n) for n in ("left_hip", "right_hip") if n in names]
        return hips or list(range(len(names)))

    def _root_track(self, kp_targets) -> np.ndarray:
        idx = self._root_index()
        return kp_targets[:, idx].mean(axis=1) if idx else np.zeros((len(kp_targets), 3))

    def _nominal_root(self) -> np.ndarray:
        idx = self._root_index()
        pts = [self.kin.nominal_sites[self.robot.keypoints[i].human_joint] for i in idx]
        return np.mean(pts, axis=0) if pts else self.kin.nominal_x[:3]


def geom_label(model, g: int) -> str:
    """A geom's name, or for an unnamed one (every geom of Menagerie's OP3) its body's name and
    its number, ``"l_el_link/18"``."""
    import mujoco

    name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g)
    if name:
        return name
    body = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, int(model.geom_bodyid[g])) or f"body {model.geom_bodyid[g]}"
    return f"{body}/{g}"


def pivot_allowance(foot_dir: np.ndarray, fps: float, contacts: np.ndarray, speed_deg: float, min_turn_deg: float,
                    margin: float) -> np.ndarray:
    """[T, 2] rad: how far each planted robot sole may turn from the frame before: ``margin``
    times the human foot's turn (``foot_dir`` [T, 2, 2], unit horizontal directions) in frames
    where that foot turns faster than ``speed_deg`` degrees a second within a contact phase
    (``contacts`` [T, 2]) over which it turns more than ``min_turn_deg`` in all (a pivot on the
    stance foot, as in a spinning kick), else 0 (the sole holds its yaw; a walking foot's
    direction also swings at heel strike and toe-off, by up to 25 degrees on the Bandai walks)."""
    foot_dir = np.asarray(foot_dir, dtype=np.float64)
    contacts = np.asarray(contacts, dtype=bool)
    T = foot_dir.shape[0]
    out = np.zeros((T, 2))
    if T < 2:
        return out
    angle = np.unwrap(np.arctan2(foot_dir[..., 1], foot_dir[..., 0]), axis=0)
    turn = np.r_[np.zeros((1, 2)), np.abs(np.diff(angle, axis=0))]
    fast = turn * fps > np.radians(speed_deg)
    for k in range(2):
        for start, stop in contact_phases(contacts[:, k]):
            if stop - start >= 2 and np.ptp(angle[start:stop, k]) > np.radians(min_turn_deg):
                phase = slice(start + 1, stop)  # frames planted after a planted frame
                out[phase, k] = np.where(fast[phase, k], margin * turn[phase, k], 0.0)
    return out


def _heading_local(v: np.ndarray, heading: np.ndarray) -> np.ndarray:
    """Rotate vectors ``v[T, K, 3]`` by ``-heading[T]`` about z."""
    c, s = np.cos(-heading)[:, None], np.sin(-heading)[:, None]
    out = v.copy()
    out[..., 0] = c * v[..., 0] - s * v[..., 1]
    out[..., 1] = s * v[..., 0] + c * v[..., 1]
    return out


def retarget(joints: np.ndarray, fps: float, robot: RetargetRobot, config: RetargetConfig = RetargetConfig(), progress: bool | None = None) -> RetargetResult:
    """One-shot convenience wrapper around :class:`Retargeter`."""
    return Retargeter(robot, config).run(joints, fps, progress=progress)

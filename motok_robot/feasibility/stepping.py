"""Foothold tracking from leg odometry: each step lands where the plan put it in the world.

A walk played on position servos does not land its feet exactly where the plan put them: a
millimetre or a few per step (a lagging or overshooting swing leg, a stance foot rolling on its
edge) adds up over tens of steps into a robot that walks ahead of or behind its path
(validation's ``base_drift``).  A rig cannot see its world position, but it can measure its own
steps: while both feet are on the floor, forward kinematics of the servo present positions gives
the vector from one foot to the other.  Summed over the steps (leg odometry, assuming planted
feet do not slip) it tells where each foot stands relative to its planned foothold.

Per foot ``k`` the tracker keeps ``E_k``, the estimated horizontal offset (m, world axes of the
plan) of the foot from its planned foothold:

* at the end of each double support (the last frame before foot ``a`` lifts, with ``c`` landed
  from a step), the foot-to-foot vector is measured, linearised about the plan:
  ``delta = M (present - q_plan)``, and ``E_c = E_a + gain x delta`` (clamped);
* foot ``a`` then swings to its planned foothold: ``E_a`` eases from its value at lift-off to 0
  along the swing's own horizontal profile (``ramp``), so it lands where the plan put it;
* the base follows its feet: ``E_base`` is the support-weighted mean of the feet's ``E``, and
  each leg gets the joint offsets that move its foot by ``E_k - E_base`` relative to the base,
  the foot's height and orientation unchanged (``C_k``, the damped inverse of the leg's
  Jacobian at the plan).  A stance foot therefore stays where it is, and the swing foot is
  carried toward its planned foothold.

Everything that depends on the plan is precomputed (:class:`SteppingPlan`); at run time the
tracker is a few small matrix products per tick, vectorised over a batch of robots, and needs
neither MuJoCo nor the reference.  Heading errors are not tracked (the IMU cannot observe yaw).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from motok_robot.errors import InputError

#: file fields of a stepping plan in servo_goals.npz (docs/CONTRACTS.md)
FIELDS = ("step_ramp", "step_support", "step_correct", "step_events", "step_measure", "step_joints", "step_limits")
#: at most this many measurement events per plan frame (one per lift-off: far fewer)
MAX_EVENTS_PER_FRAME = 1


@dataclass
class SteppingPlan:
    """Per-frame and per-event quantities of the tracker (frames at the balance plan's fps)."""

    ramp: np.ndarray      # [T, 2] 1 while a foot stands, 0 -> 1 from its last frame down over its swing
    support: np.ndarray   # [T, 2] share of each foot in the base's offset (rows sum to 1)
    correct: np.ndarray   # [T, 2, nj, 2] joint offsets (rad) per metre of foot k's horizontal move
    events: np.ndarray    # [E, 3] int: frame, lifting foot a, landed foot c (-1: nothing to measure)
    measure: np.ndarray   # [E, 2, nj] change of the horizontal vector foot a -> foot c per joint rad
    joints: np.ndarray    # [E, nj] planned joint angles at the event frame (rad)
    gain: float           # share of each measured error acted on (1: deadbeat)
    max_offset_m: float   # each foot's estimate is clamped to this horizontal distance (m)

    def fields(self) -> dict:
        return {"step_ramp": self.ramp, "step_support": self.support, "step_correct": self.correct,
                "step_events": self.events.astype(np.int64), "step_measure": self.measure, "step_joints": self.joints,
                "step_limits": np.array([self.gain, self.max_offset_m])}

    @classmethod
    def from_fields(cls, fields: dict, T: int, nj: int, where: str) -> "SteppingPlan | None":
        """The stepping plan stored in a servo_goals file (None when it has none)."""
        if "step_ramp" not in fields:
            return None
        missing = [k for k in FIELDS if k not in fields]
        if missing:
            raise InputError(f"{where}: field(s) {', '.join(missing)} missing (a stepping plan needs all of {', '.join(FIELDS)})")
        events = np.asarray(fields["step_events"])
        E = events.shape[0] if events.ndim == 2 else -1
        if events.dtype.kind not in "iu" or events.shape != (E, 3) or not 0 <= E <= MAX_EVENTS_PER_FRAME * T:
            raise InputError(f"{where}: field 'step_events' must be an integer array of shape (E, 3), E <= {T}, "
                             f"got {events.dtype} {events.shape}")
        if E and (events[:, 0].min() < 0 or events[:, 0].max() >= T or events[:, 1].min() < 0 or events[:, 1].max() > 1
                  or events[:, 2].min() < -1 or events[:, 2].max() > 1 or np.any(np.diff(events[:, 0]) < 0)):
            raise InputError(f"{where}: field 'step_events' holds a frame outside 0..{T - 1}, a foot other than "
                             "0/1 (-1 for none), or frames out of order")
        shapes = {"step_ramp": (T, 2), "step_support": (T, 2), "step_correct": (T, 2, nj, 2),
                  "step_measure": (E, 2, nj), "step_joints": (E, nj), "step_limits": (2,)}
        arrays = {}
        for key, shape in shapes.items():
            value = np.asarray(fields[key])
            if value.dtype.kind not in "fi" or value.shape != shape:
                raise InputError(f"{where}: field '{key}' must be a float array of shape {shape}, got {value.dtype} {value.shape}")
            value = value.astype(np.float64)
            if not np.isfinite(value).all():
                raise InputError(f"{where}: field '{key}' is not finite")
            arrays[key] = value
        gain, max_offset = arrays["step_limits"]
        if not (0.0 <= gain <= 1.0 and 0.0 <= max_offset <= 1.0):
            raise InputError(f"{where}: field 'step_limits' = ({gain}, {max_offset}): gain must lie in [0, 1] and the "
                             "largest offset in [0, 1] m")
        return cls(ramp=arrays["step_ramp"], support=arrays["step_support"], correct=arrays["step_correct"],
                   events=events.astype(np.int64), measure=arrays["step_measure"], joints=arrays["step_joints"],
                   gain=float(gain), max_offset_m=float(max_offset))


def swing_ramp(contacts: np.ndarray, lift_share: float) -> np.ndarray:
    """[T, 2]: 1 where a foot is in contact; over each swing the horizontal progress of the swing
    foot as :func:`~motok_robot.feasibility.footsteps.plan_steps` moves it
    (:func:`~motok_robot.feasibility.footsteps.swing_progress`)."""
    from motok_robot.feasibility.footsteps import swing_progress

    contacts = np.asarray(contacts, dtype=bool)
    T = contacts.shape[0]
    ramp = np.ones((T, 2))
    for k in range(2):
        t = 0
        while t < T:
            if contacts[t, k]:
                t += 1
                continue
            s = t
            while t < T and not contacts[t, k]:
                t += 1
            ramp[s:t, k] = swing_progress(t - s, lift_share)
    return ramp


def support_shares(contacts: np.ndarray, fps: float) -> np.ndarray:
    """[T, 2] share of each foot in the base's offset: 1 for the only foot down, blended over
    0.1 s around each change of support (both feet down or both up: half each)."""
    from motok_robot.feasibility.balance import support_weights

    w = support_weights(contacts, fps, 0.0)
    total = w.sum(axis=1, keepdims=True)
    return np.where(total > 1e-9, w / np.maximum(total, 1e-9), 0.5)


def lift_off_events(contacts: np.ndarray) -> list[tuple[int, int, int]]:
    """(frame, lifting foot a, landed foot c or -1) per lift-off in ``contacts`` [T, 2]: ``frame``
    is the last frame with both feet down before ``a`` lifts; ``c`` is given when the other foot
    came down from a step before it (a step to measure), -1 at the first lift-off from standing."""
    contacts = np.asarray(contacts, dtype=bool)
    events = []
    stepped = [False, False]
    for t in range(1, contacts.shape[0]):
        for k in range(2):
            if not contacts[t - 1, k] and contacts[t, k]:
                stepped[k] = True
        for a in range(2):
            c = 1 - a
            if contacts[t - 1, a] and not contacts[t, a] and contacts[t - 1, c]:
                events.append((t - 1, a, c if stepped[c] else -1))
    return events


def _leg_dofs(index, side: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    joints = np.flatnonzero(side == k)
    return joints, np.asarray(index.dof_adr, dtype=int)[joints]


def build_stepping(index, qpos: np.ndarray, fps: float, contacts: np.ndarray, *, lift_share: float,
                   gain: float, max_offset_m: float, damping: float = 1e-4) -> SteppingPlan:
    """The tracker's plan for the walk ``qpos`` [T, nq] at ``fps`` with planned foot contacts
    ``contacts`` [T, 2] on robot ``index`` (see the module docstring)."""
    from motok_robot.feasibility.balance import leg_roles

    qpos = np.asarray(qpos, dtype=np.float64)
    contacts = np.asarray(contacts, dtype=bool)
    T, nj = qpos.shape[0], index.nj
    model = index.kin_model
    data = mujoco.MjData(model)
    _, side = leg_roles(index)
    legs = [_leg_dofs(index, side, k) for k in range(2)]
    events = lift_off_events(contacts)
    event_at = {}
    for e, (frame, _, _) in enumerate(events):
        event_at.setdefault(frame, []).append(e)
    correct = np.zeros((T, 2, nj, 2))
    measure = np.zeros((len(events), 2, nj))
    joints = np.zeros((len(events), nj))
    jp = np.zeros((2, 3, model.nv))
    jr = np.zeros((2, 3, model.nv))
    target = np.zeros((6, 2))
    target[0, 0] = target[1, 1] = 1.0  # a horizontal move, height and orientation kept
    all_dofs = np.asarray(index.dof_adr, dtype=int)
    for t in range(T):
        data.qpos[:] = qpos[t]
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        for k in range(2):
            mujoco.mj_jacSite(model, data, jp[k], jr[k], int(index.sole_site[k]))
            cols, dofs = legs[k]
            if not cols.size:
                continue
            J = np.vstack([jp[k][:, dofs], jr[k][:, dofs]])  # [6, m]: the foot relative to the base
            correct[t, k][cols] = J.T @ np.linalg.solve(J @ J.T + damping * np.eye(6), target)
        for e in event_at.get(t, []):
            a = events[e][1]
            measure[e] = jp[1 - a][:2, all_dofs] - jp[a][:2, all_dofs]  # d(foot c - foot a)/dq, c = 1 - a
            joints[e] = qpos[t, index.qpos_adr]
    ramp = swing_ramp(contacts, lift_share)
    for frame, a, _ in events:  # the lifting foot's offset starts easing at its last frame down
        ramp[frame, a] = 0.0
    return SteppingPlan(ramp=ramp, support=support_shares(contacts, fps),
                        correct=correct, events=np.array(events, dtype=np.int64).reshape(-1, 3), measure=measure,
                        joints=joints, gain=float(gain), max_offset_m=float(max_offset_m))


class FootholdTracker:
    """The run-time part for a batch of ``batch`` robots: :meth:`offsets` once per tick."""

    def __init__(self, plan: SteppingPlan, fps: float, batch: int = 1):
        self.plan = plan
        self.fps = float(fps)
        self.batch = int(batch)
        self.reset()

    def reset(self) -> None:
        self.estimate = np.zeros((self.batch, 2, 2))  # E_k per robot (m, world xy)
        self.at_lift = np.zeros((self.batch, 2, 2))   # E_k when foot k last lifted
        self.next_event = 0
        self.measured = 0                             # events with a measurement acted on

    def copy_state(self, other: "FootholdTracker") -> None:
        """Take ``other``'s state (its robot 0) for every robot of this batch."""
        self.estimate[:] = other.estimate[0]
        self.at_lift[:] = other.at_lift[0]
        self.next_event = other.next_event
        self.measured = other.measured

    def _event(self, e: int, present: np.ndarray | None) -> None:
        p = self.plan
        _, a, c = (int(v) for v in p.events[e])
        if c >= 0 and present is not None:
            ok = np.isfinite(present).all(axis=1)
            delta = (present - p.joints[e]) @ p.measure[e].T  # [B, 2] measured - planned vector a -> c
            new = self.estimate[:, a] + p.gain * delta
            norm = np.sqrt((new * new).sum(axis=1, keepdims=True))
            new = new * np.minimum(1.0, p.max_offset_m / np.maximum(norm, 1e-12))
            self.estimate[:, c] = np.where(ok[:, None], new, self.estimate[:, c])
            self.measured += 1
        if c >= 0:
            self.at_lift[:, c] = self.estimate[:, c]
        # a standing foot has at_lift == estimate; the lifting one eases from it to its foothold
        self.estimate[:, a] = 0.0

    def offsets(self, t: float, present: np.ndarray | None) -> np.ndarray:
        """Joint offsets [B, nj] (rad) at tick time ``t`` (s); ``present`` [B, nj] rad or None
        (then a measurement due now is skipped: the estimate keeps its value)."""
        p = self.plan
        x = min(max(float(t) * self.fps, 0.0), float(p.ramp.shape[0] - 1))
        while self.next_event < p.events.shape[0] and p.events[self.next_event, 0] <= x + 1e-9:
            self._event(self.next_event, present)
            self.next_event += 1
        i = int(math.floor(x))
        k = min(i + 1, p.ramp.shape[0] - 1)
        f = x - i
        ramp = (1 - f) * p.ramp[i] + f * p.ramp[k]            # [2]
        support = (1 - f) * p.support[i] + f * p.support[k]   # [2]
        correct = (1 - f) * p.correct[i] + f * p.correct[k]   # [2, nj, 2]
        feet = (1 - ramp)[None, :, None] * self.at_lift + ramp[None, :, None] * self.estimate  # [B, 2, 2]
        base = np.einsum("k,bkx->bx", support, feet)
        move = feet - base[:, None, :]                                                     # [B, 2, 2]
        return np.einsum("kjx,bkx->bj", correct, move)

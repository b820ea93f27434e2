"""One sentence -> human motion -> robot trajectory -> MuJoCo validation -> servo playback.

The Python API behind ``motok-robot run``::

    from motok_robot import Pipeline

    pipe = Pipeline()                                   # models are loaded once, on first use
    result = pipe.run("a person waves the right hand", robot="op3_like", seconds=6, out_dir="wave/")
    result.passed, result.failed_checks                 # the validation verdict
    result.files["video"], result.timings["retarget"]   # paths and per-stage seconds

Stages and the files they write into ``out_dir`` (file formats: docs/CONTRACTS.md):

=============  ===============================================================================
generate       ``motion.npz`` (human joints [T, 22, 3] m z-up, features, tokens)
retarget       ``robot.npz`` (qpos [T, nq] in MuJoCo order, contacts, keypoint errors)
validate       ``report.json`` (pass/fail checks), ``plots``: ``balance_topview.png``,
               ``feet.png``, ``joints.png``, ``torques.png``; ``render``: ``video.mp4``
playback       ``playback.csv`` (one row per control tick) and ``playback.stats.json``;
               with ``playback="sim"`` and ``config.sim_video``: ``playback_sim.mp4``
(always)       ``summary.md`` linking every file with the verdict and per-stage times,
               ``pipeline.json`` (the same, machine-readable)
=============  ===============================================================================

Playback modes: ``"dry-run"`` (default) streams to an emulated Dynamixel chain (the same
streamer, pre-flight, limiter and log as hardware) in simulated time; ``"sim"`` streams to the
MuJoCo model (:class:`~motok_robot.servo.sim_rig.SimRig`) in simulated time; ``"port"`` streams
to real servos on ``port`` in real time and only when the validation report passed (or with
``force=True``).  A failed validation is not an error: every file is still written, the
verdict says FAIL, and hardware playback is refused.

Two repairs follow a failed validation, each kept only when it trades no passing check for a
failing one (thresholds are never changed): when the robot loses its footing or balance, the
motion is retargeted again with the ZMP term and a foot planted in every frame
(``PipelineConfig.balance_zmp_weight``; stage ``balance``),
and when it asks more than the servos have, the robot plays it slower
(``PipelineConfig.max_retime``; stage ``retime``).  ``summary.md`` notes what was done.

Output is atomic: the stages write into a hidden folder ``.OUT.partial-*`` next to ``out_dir``,
renamed to ``out_dir`` only when every stage finished.  If a stage raises (or Ctrl-C), the
partial folder is renamed ``OUT.failed/`` with ``FAILED.txt`` naming the stage and the error,
and ``out_dir`` is not created.  Invalid input (empty or too long text, unknown robot,
non-positive seconds, a negative seed, an output folder that cannot be written, a missing
serial port) raises :class:`~motok_robot.errors.InputError` before any work and leaves nothing.

This module does not import torch, MuJoCo or matplotlib at import time.
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import os
import re
import shutil
import tempfile
import time
import uuid
import warnings
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from motok_robot.errors import HardwareError, InputError, MotokError
from motok_robot.text.prompts import MAX_SEED, PromptSpec, check_seconds, check_seed, read_prompts  # noqa: F401 (public here too)
from motok_robot.text.validate import MAX_TEXT_CHARS, check_text  # noqa: F401  (MAX_TEXT_CHARS: public here too)

PLAYBACK_MODES = ("dry-run", "sim", "port")
#: Clip length used with constraints when no ``seconds`` is given (the planner's no-text default).
DEFAULT_CONSTRAINED_SECONDS = 6.0
#: Stages timed in :attr:`PipelineResult.timings`, in order.
STAGES = ("generate", "retarget", "feasibility", "validate", "balance", "retime", "plots", "render", "playback")
#: validation checks that a slower playback of the same motion can fix
SPEED_CHECKS = frozenset({"torque", "joint_velocity", "joint_acceleration"})
#: validation checks of the robot's footing and balance, which retargeting with the ZMP term and a
#: foot planted in every frame can fix (``PipelineConfig.balance_zmp_weight``)
BALANCE_CHECKS = frozenset({"floating", "zmp", "static_balance", "center_of_pressure", "fall", "base_drift"})
#: slow-down factors the pipeline tries, in order, up to ``PipelineConfig.max_retime``
RETIME_STEPS = (1.25, 1.5, 2.0, 3.0)
PLOT_FILES = ("balance_topview.png", "feet.png", "joints.png", "torques.png")


# ----------------------------------------------------------------------------- motion from a file
@dataclass
class SourceMotion:
    """A motion read from a file instead of generated (``run --motion``): a ``motion.npz``, or a
    mocap file (BVH / ASF+AMC / DeepMimic JSON) put on the canonical skeleton with its features."""

    joints: np.ndarray  #: float32 [T, 22, 3] metres, z up
    features: np.ndarray  #: float32 [T, 263]
    text: str
    model: str
    fps: int = 20
    seed: int = 0

    @property
    def seconds(self) -> float:
        return self.joints.shape[0] / self.fps

    def save(self, path) -> Path:
        from motok_robot.planner.motion_file import save_motion

        return save_motion(path, self.joints, self.features, np.zeros(0, np.int64), self.text, self.seed,
                           self.model, self.fps)


def load_source_motion(path, skeleton: str = "bandai", asf=None) -> SourceMotion:
    """Read ``--motion``: ``motion.npz`` as it is; a mocap file through the data importers
    (20 fps) and :func:`~motok_robot.motion.features.normalise_joints` (canonical bones, floor at
    z = 0, facing +x), with joints recovered from its features so the two agree frame by frame."""
    from motok_robot.motion.features import features_from_joints, joints_from_features
    from retarget.io import read_input

    p = Path(path)
    text, model = f"motion:{p.name}", f"file:{p.name}"
    if p.suffix.lower() == ".npz":
        from motok_robot.npz_files import read_npz_fields
        from retarget.io import read_motion_npz

        data = read_npz_fields(p, "motion file")
        human = read_motion_npz(p)  # joints [T, 22, 3], fps and the size bounds checked, as retarget does
        text = str(data["text"]) if "text" in data and data["text"].size == 1 and str(data["text"]) else text
        model = str(data["model"]) if "model" in data and data["model"].size == 1 and str(data["model"]) else model
        features = np.asarray(data["features"]) if "features" in data else None
        if features is not None and abs(human.fps - 20.0) <= 1e-6:  # as generated: used as it is
            if features.ndim != 2 or features.shape[1] != 263 or features.dtype.kind != "f":
                raise InputError(f"{p}: field 'features' must be a float array [T, 263], got shape {features.shape} "
                                 f"({features.dtype})")
            if not np.isfinite(features).all():
                frame = int(np.argwhere(~np.isfinite(features))[0][0])
                raise InputError(f"{p}: field 'features' is not finite (NaN or inf) at frame {frame}: fix the file")
            return SourceMotion(np.asarray(human.joints, np.float32), features.astype(np.float32), text, model)
        # at another frame rate the saved features (defined at 20 fps) do not apply: resample the
        # joints (the file's fps is honoured, as retarget honours it) and recompute them
    else:
        human = read_input(p, skeleton=skeleton, asf=asf)
    if abs(human.fps - 20.0) > 1e-6:
        from motok_robot.motion.features import resample

        human.joints = resample(human.joints, human.fps, 20.0)
    features = features_from_joints(human.joints)
    joints = joints_from_features(features).astype(np.float32)
    return SourceMotion(joints, features.astype(np.float32), text, model)


# ----------------------------------------------------------------------------- configuration
@dataclass
class PipelineConfig:
    """Settings of a :class:`Pipeline` (every default in one place).

    Attributes:
        planner: ``"masked"`` (default) or ``"ar"``.
        tokenizer_run, planner_run: run directories (None: ``models/tokenizer``,
            ``models/planner_<planner>``, see :mod:`motok_robot.planner.generate`).
        device: torch device of generation.
        generation: extra keyword arguments of ``MotionGenerator.generate`` (``cfg_scale``,
            ``steps``, ``decoder_steps``, ``decoder_seed``, ``temperature``, ``top_k``, ``top_p``).
        retarget: a :class:`retarget.config.RetargetConfig` (None: its defaults).
        validation: a :class:`motok_robot.sim.config.ValidationConfig` (None: its defaults).
        playback: a :class:`motok_robot.servo.config.PlaybackConfig` (None: the robot's bus
            rate and the defaults).
        plots: write the validation PNG plots.
        realtime: play dry-run and sim playback at the wall-clock rate (default: simulated time,
            which takes a fraction of a second; hardware always runs in real time).
        sim_video: with ``playback="sim"`` and ``render``, also record ``playback_sim.mp4`` (the
            simulated servo playback, ramp included; slow: about 10x the clip with software EGL).
        max_retime: when a speed check fails (:data:`SPEED_CHECKS`: the motion asks more
            torque, speed or acceleration than the servos have), play the robot trajectory up
            to this many times slower (:func:`retarget.retime.retime`, tried at
            :data:`RETIME_STEPS`) and keep the first timing whose speed checks all pass and that
            fails no check the original timing passed; the original timing is kept when none
            does.  Thresholds are never changed.  1.0 = never slow down.
        balance_zmp_weight: when a footing or balance check fails (:data:`BALANCE_CHECKS`:
            both feet in the air, ZMP or CoM outside the support, a fall, base drift) and
            retargeting ran without the ZMP term (``retarget.weights.zmp == 0``), retarget the
            motion again with this ZMP weight and a robot foot planted in every frame where no
            human foot is (contact support ``"always"``: a servo humanoid has no flight phase),
            and keep the new trajectory when the checks it fails, speed checks aside (retiming
            comes next), are a strict subset of those the first one failed; otherwise the first
            is kept.  Clips that pass (most gestures) never pay for the slower ZMP solve.  0 =
            never re-solve.
        feasibility: a :class:`motok_robot.feasibility.config.FeasibilityConfig` to run the
            feasibility stage after retargeting (docs/feasibility.md): the robot trajectory
            becomes the one the robot executes closed loop, judged against the retargeted one,
            and the balance repair and the slow-down are not tried (the stage owns timing and
            balance).  None (default): retargeting's trajectory is validated as it is, with the
            two repairs below.
        balance_acceleration_weight: the joint-acceleration weight (``CostWeights.acceleration``)
            of that re-solve.  The ZMP term rewards CoM accelerations that move the ZMP under the
            foot, and with the plain weight (5) the optimiser gets them from frame-to-frame
            zig-zags of the stance knee, which the servos cannot deliver (the torque check then
            fails); a stiffer weight makes it shift the CoM smoothly instead (docs/retarget.md,
            balance repair).
    """

    planner: str = "masked"
    tokenizer_run: str | Path | None = None
    planner_run: str | Path | None = None
    device: str = "cpu"
    generation: dict = field(default_factory=dict)
    retarget: object | None = None
    validation: object | None = None
    playback: object | None = None
    plots: bool = True
    realtime: bool = False
    sim_video: bool = False
    max_retime: float = 2.0
    balance_zmp_weight: float = 1000.0
    balance_acceleration_weight: float = 50.0
    feasibility: object | None = None


@dataclass
class PlaybackSummary:
    """What the playback stage did.

    ``mode``: dry-run / sim / port; ``status``: ``completed``, ``refused`` (hardware without a
    passing report), ``skipped`` (robot without servos), ``stopped`` (a servo fault or a fall)
    or ``error``; ``gate``: None when the validation report allows hardware playback, else why
    not; ``line``: the streamer's one-line result; ``fell``: sim only.
    """

    mode: str
    status: str
    gate: str | None = None
    line: str = ""
    error: str | None = None
    fell: bool | None = None
    forced: bool = False

    @property
    def ok(self) -> bool:
        """Played to the end (or nothing to play on a robot without servos) and did not fall."""
        return self.status in ("completed", "skipped") and not self.fell


@dataclass
class PipelineResult:
    """One finished run.

    Attributes:
        out_dir: the output folder.
        text, robot, seconds (of the generated clip), seed: what was run.
        files: ``{name: Path}`` of every file written (``motion``, ``robot``, ``report``,
            ``plot_<name>``, ``video``, ``playback_log``, ``playback_stats``, ``playback_video``,
            ``summary``, ``result``).
        passed: the validation verdict (``report.json`` ``passed``).
        failed_checks: names of the failing validation checks.
        timings: seconds per stage (:data:`STAGES`, plus ``load`` when models were loaded
            during this run, and ``total``).
        playback: :class:`PlaybackSummary`.
        report: the validation report (dict).
        model: identifiers of the generation models.
        notes: warnings worth reading (failed solver windows, forced playback ...).
        retime_factor: how many times slower than the human motion the robot plays it (1.0:
            not slowed down; see ``PipelineConfig.max_retime``).
        zmp_weight: the ZMP weight of the retargeting that made the kept trajectory (0: without
            the ZMP term; see ``PipelineConfig.balance_zmp_weight``).
        acceleration_weight: the joint-acceleration weight of that retargeting (see
            ``PipelineConfig.balance_acceleration_weight``).
    """

    out_dir: Path
    text: str
    robot: str
    seconds: float
    seed: int
    files: dict[str, Path]
    passed: bool
    failed_checks: list[str]
    timings: dict[str, float]
    playback: PlaybackSummary
    report: dict
    model: str = ""
    notes: list[str] = field(default_factory=list)
    retime_factor: float = 1.0
    zmp_weight: float = 0.0
    acceleration_weight: float = 0.0

    @property
    def ok(self) -> bool:
        """Validation passed and playback completed."""
        return self.passed and self.playback.ok

    def line(self) -> str:
        """A one-line verdict."""
        verdict = "PASS" if self.passed else "FAIL"
        return f'{verdict} "{self.text}" on {self.robot} ({self.seconds:.1f} s, seed {self.seed}) -> {self.out_dir}'

    def to_dict(self) -> dict:
        return {
            "out_dir": str(self.out_dir), "text": self.text, "robot": self.robot, "seconds": self.seconds,
            "seed": self.seed, "passed": self.passed, "failed_checks": list(self.failed_checks),
            "files": {k: _rel(v, self.out_dir) for k, v in self.files.items()},
            "timings_s": {k: round(v, 4) for k, v in self.timings.items()},
            "playback": asdict(self.playback), "model": self.model, "notes": list(self.notes),
            "retime_factor": self.retime_factor, "zmp_weight": self.zmp_weight,
            "acceleration_weight": self.acceleration_weight,
        }


# ----------------------------------------------------------------------------- input checks
def check_robot(robot) -> str:
    """The robot name or path, when :func:`motok_robot.robots.load` can find it (no MuJoCo)."""
    from motok_robot.robots import list_robots, models_dir

    if not isinstance(robot, (str, os.PathLike)) or not str(robot).strip():
        raise InputError(f"robot must be a robot name, got {robot!r}")
    text = str(robot)
    p = Path(text).expanduser()
    if p.suffix in (".toml", ".xml") or os.sep in text:
        if not p.with_suffix(".toml").is_file():
            raise InputError(f"robot description not found: {p.with_suffix('.toml')} (a robot is NAME.xml + NAME.toml)")
        return text
    known = list_robots()
    if text not in known:
        raise InputError(f"unknown robot {text!r}; known robots: {', '.join(known) or 'none'} (in {models_dir()})")
    return text


def check_out_dir(out_dir, overwrite: bool = False) -> Path:
    """``out_dir`` as a Path when it can be written (probed by creating a folder next to it).

    Raises InputError when it is a file, a non-empty folder (unless ``overwrite``), or when its
    nearest existing parent is not a writable folder.  Creates nothing that stays.
    """
    if out_dir is None or not str(out_dir).strip():
        raise InputError("an output folder is required (--out DIR)")
    out = Path(out_dir).expanduser().absolute()
    if out.exists():
        if not out.is_dir():
            raise InputError(f"output folder {out} is an existing file")
        if any(out.iterdir()) and not overwrite:
            raise InputError(f"output folder {out} exists and is not empty; choose a new folder or pass --overwrite")
    ancestor = out.parent
    while not ancestor.exists():
        if ancestor == ancestor.parent:
            break
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise InputError(f"output folder {out} cannot be created: {ancestor} is not a folder")
    try:
        probe = tempfile.mkdtemp(prefix=".motok-probe-", dir=ancestor)
        os.rmdir(probe)
    except OSError as exc:
        raise InputError(f"output folder {out} cannot be written: {ancestor}: {exc.strerror or exc}") from None
    return out


def check_playback(playback: str, port: str | None) -> None:
    if playback not in PLAYBACK_MODES:
        raise InputError(f"playback must be one of {', '.join(PLAYBACK_MODES)}, got {playback!r}")
    if playback == "port":
        if not port:
            raise InputError("hardware playback needs a serial port (--port DEV)")
        if not os.path.exists(port) and not str(port).upper().startswith("COM"):
            raise InputError(f"serial port {port} does not exist (is the USB adapter plugged in?)")
    elif port:
        raise InputError(f"a serial port ({port}) was given with playback {playback!r}; use playback='port'")


def slug(text: str, limit: int = 40) -> str:
    """A folder-name-safe short form of ``text``."""
    return re.sub(r"[^a-z0-9]+", "_", text.lower()).strip("_")[:limit].rstrip("_") or "prompt"


def _rel(path: Path | str, root: Path) -> str:
    try:
        return Path(path).relative_to(root).as_posix()
    except ValueError:
        return str(path)


# ----------------------------------------------------------------------------- the pipeline
_ROBOT_STAGES: dict[tuple[str, str], dict] = {}


def load_robot_stages(name: str, retarget_config=None) -> dict:
    """``{"robot", "retargeter", "index"}`` for robot ``name``: the :class:`~motok_robot.robots.Robot`,
    its :class:`~retarget.solve.Retargeter` (compiled window problems are kept in it) and its
    validation :class:`~motok_robot.robots.index.RobotIndex`; reused per process for the same
    robot file and retargeting settings."""
    from motok_robot.robots import load
    from motok_robot.robots.index import index_robot
    from retarget.config import RetargetConfig
    from retarget.robot_model import RetargetRobot
    from retarget.solve import Retargeter

    retarget_config = retarget_config or RetargetConfig()
    robot = load(name)
    key = (str(robot.mjcf_path), repr(retarget_config))
    if key not in _ROBOT_STAGES:
        _ROBOT_STAGES[key] = {"robot": robot, "retargeter": Retargeter(RetargetRobot.from_robot(robot), retarget_config),
                              "index": index_robot(robot)}
    return _ROBOT_STAGES[key]


def balance_retargeter(entry: dict, weight: float,
                       acceleration: float = PipelineConfig.balance_acceleration_weight):
    """The retargeter of the balance repair for a :func:`load_robot_stages` ``entry``: its plain
    retargeter's settings with the ZMP term at ``weight``, the joint-acceleration weight at
    ``acceleration`` and a foot planted in every frame (contact support ``"always"``).  Built
    once per robot entry and weights; its compiled window problems are kept like the plain
    retargeter's."""
    from dataclasses import replace

    from retarget.solve import Retargeter

    key = (float(weight), float(acceleration))
    cache = entry.setdefault("balance_retargeters", {})
    if key not in cache:
        base = entry["retargeter"]
        weights = replace(base.config.weights, zmp=key[0], acceleration=key[1])
        cache[key] = Retargeter(base.robot, replace(base.config, weights=weights,
                                                    contacts=replace(base.config.contacts, support="always")))
    return cache[key]


class Pipeline:
    """Loaded models and robots; :meth:`run` turns sentences into validated robot trajectories.

    Args:
        config: :class:`PipelineConfig`; keyword arguments override its fields
            (``Pipeline(planner_run="runs/masked", tokenizer_run="runs/tok", plots=False)``).

    The generation models are loaded on the first :meth:`run` (and reused, also by
    :func:`motok_robot.generate` in the same process); robots, their compiled retargeting
    problems and validation indices are cached per robot.
    """

    def __init__(self, config: PipelineConfig | None = None, **overrides) -> None:
        config = config or PipelineConfig()
        unknown = set(overrides) - set(PipelineConfig.__dataclass_fields__)
        if unknown:
            raise TypeError(f"unknown Pipeline option(s): {', '.join(sorted(unknown))}")
        for key, value in overrides.items():
            setattr(config, key, value)
        if config.planner not in ("masked", "ar"):
            raise InputError(f"planner must be 'masked' or 'ar', got {config.planner!r}")
        if not config.max_retime >= 1:  # also rejects NaN
            raise InputError(f"max_retime (--max-retime) must be >= 1 (1 = never slow down), got {config.max_retime}")
        if not config.balance_zmp_weight >= 0:  # also rejects NaN
            raise InputError(f"balance_zmp_weight (--balance-zmp-weight) must be >= 0, got {config.balance_zmp_weight}")
        if not config.balance_acceleration_weight >= 0:
            raise InputError("balance_acceleration_weight (--balance-acceleration-weight) must be >= 0, "
                             f"got {config.balance_acceleration_weight}")
        self.config = config
        self._generator = None
        self._robots: dict[str, dict] = {}

    # ------------------------------------------------------------------ loading
    @property
    def generator(self):
        """The loaded :class:`~motok_robot.planner.generate.MotionGenerator` (loads on first use)."""
        if self._generator is None:
            from motok_robot.planner.generate import load_generator

            cfg = self.config
            self._generator = load_generator(cfg.planner, cfg.tokenizer_run, cfg.planner_run, cfg.device)
        return self._generator

    def load_models(self) -> float:
        """Load the generation models now; returns the seconds it took (0 when already loaded)."""
        if self._generator is not None:
            return 0.0
        start = time.perf_counter()
        _ = self.generator
        return time.perf_counter() - start

    def robot(self, name: str) -> dict:
        """Cached ``{"robot", "retargeter", "index"}`` for ``name`` (loaded and compiled once per process)."""
        if name not in self._robots:
            self._robots[name] = load_robot_stages(name, self.config.retarget)
        return self._robots[name]

    # ------------------------------------------------------------------ one run
    def check(self, text, robot="op3_like", seconds=None, seed=0, constraints=None, out_dir=None,
              playback="dry-run", port=None, overwrite=False, motion=None) -> dict:
        """Check a request without doing any work (no models loaded, nothing written).

        Returns the cleaned arguments; raises :class:`InputError` with a one-line message.
        """
        if motion is not None:
            if constraints is not None:
                raise InputError("constraints apply to generation; they cannot be combined with a --motion file")
            if not Path(motion).is_file():
                raise InputError(f"motion file {motion} does not exist")
        clean_text = check_text(text) if (text is not None or motion is None) else None
        seconds = check_seconds(seconds)
        seed = check_seed(seed)
        robot = check_robot(robot)
        check_playback(playback, port)
        if constraints is not None:
            frames = getattr(constraints, "frames", None)
            if not isinstance(frames, int) or frames < 1:
                raise InputError("constraints must be a motok_robot.control.constraints.Constraints")
            if seconds is None:
                seconds = frames / 20.0
            elif round(seconds * 20) != frames:
                raise InputError(f"constraints are laid on {frames} frames, but seconds={seconds:g} gives "
                                 f"{round(seconds * 20)} frames at 20 fps")
        out = check_out_dir(out_dir, overwrite)
        return dict(text=clean_text, robot=robot, seconds=seconds, seed=seed, out_dir=out, motion=motion)

    def run(self, text: str, robot: str = "op3_like", seconds: float | None = None, seed: int = 0,
            constraints=None, out_dir: str | Path = "motok_out", playback: str = "dry-run",
            port: str | None = None, force: bool = False, render: bool = True, *, control=None,
            control_path: str = "both", overwrite: bool = False, plots: bool | None = None,
            progress: bool | None = False, motion: str | Path | None = None,
            skeleton: str = "bandai") -> PipelineResult:
        """Generate, retarget, validate and play one sentence; write every file to ``out_dir``.

        Args:
            text: the prompt (at most 500 characters).
            robot: robot name (``motok-robot robots list``) or ``NAME.toml`` path.
            seconds: clip length (None: estimated from the text; 6 s with constraints).
            seed: seeds generation (same seed, same motion).
            constraints: a :class:`motok_robot.control.constraints.Constraints` (None: free).
            out_dir: output folder (must not exist, or be empty, unless ``overwrite``).
            playback: ``"dry-run"`` (emulated servo chain), ``"sim"`` (MuJoCo) or ``"port"``.
            port: serial device for ``playback="port"``.
            force: play on hardware even when validation failed.
            render: write ``video.mp4`` (and ``playback_sim.mp4`` with ``playback="sim"`` and
                ``config.sim_video``).
            control: :class:`motok_robot.control.config.ControlConfig` for constrained generation.
            control_path: ``"both"``, ``"planner"`` or ``"decoder"`` (constrained generation).
            overwrite: replace a non-empty ``out_dir`` (only once the new run has finished).
            plots: write the validation plots (None: ``config.plots``).
            progress: show a stage progress bar (None: when stderr is a terminal).
            motion: start from this file instead of generating (``motion.npz``, ``.bvh``, ``.amc``
                with its ``.asf`` next to it, DeepMimic ``.json``); ``text`` may then be None.
            skeleton: BVH skeleton map for ``motion`` (``bandai``, ``acrnn`` or a map JSON).
        Returns:
            :class:`PipelineResult`.  Raises :class:`InputError` for invalid input (nothing written)
            and :class:`MotokError` naming the stage when a stage fails (see the module docstring).
        """
        req = self.check(text, robot, seconds, seed, constraints, out_dir, playback, port, overwrite, motion)
        req["skeleton"] = skeleton
        timings: dict[str, float] = {}
        start_all = time.perf_counter()
        if motion is None:
            if self._generator is None:
                timings["load"] = self.load_models()
            if req["seconds"] is not None:
                self.generator.frames_for(req["seconds"])  # InputError above the planner's maximum
        t = time.perf_counter()
        entry = self.robot(req["robot"])
        if time.perf_counter() - t > 1e-3:
            timings["setup"] = time.perf_counter() - t
        if playback == "port" and not entry["robot"].servos:
            raise InputError(f"robot {entry['robot'].name} has no servo map ([servos] in its description); "
                             "it cannot play on hardware")
        out: Path = req["out_dir"]
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.parent / f".{out.name}.partial-{os.getpid()}-{uuid.uuid4().hex[:8]}"
        tmp.mkdir()
        state = {"stage": "generate"}
        bar = None
        try:
            from tqdm import tqdm

            bar = tqdm(total=4, desc="generate", unit="stage", disable=None if progress is None else not progress,
                       leave=False)
            result = self._run_stages(req, entry, tmp, timings, bar, state, constraints, control, control_path,
                                      playback, port, force, render, self.config.plots if plots is None else plots)
        except BaseException as exc:  # noqa: BLE001 - every failure leaves OUT.failed, never a complete-looking OUT
            self._fail(tmp, out, state["stage"], exc)
            where = f"{state['stage']} stage failed"
            if isinstance(exc, MotokError):
                raise type(exc)(f"{where}: {exc} (partial files in {out}.failed)") from exc
            if isinstance(exc, Exception):  # a library error: one line for the user, the cause stays chained
                raise MotokError(f"{where}: {type(exc).__name__}: {exc} (partial files in {out}.failed)") from exc
            raise  # KeyboardInterrupt / SystemExit
        finally:
            if bar is not None:
                bar.close()
        timings["total"] = time.perf_counter() - start_all
        result.timings = timings
        self._write_summary(result, tmp)
        self._finish(tmp, out)
        result.out_dir = out
        result.files = {k: out / _rel(v, tmp) for k, v in result.files.items()}
        return result

    def _run_stages(self, req, entry, tmp: Path, timings, bar, state, constraints, control, control_path,
                    playback, port, force, render, plots) -> PipelineResult:
        files: dict[str, Path] = {}
        notes: list[str] = []

        def stage(name: str) -> str:
            state["stage"] = name
            bar.set_description(name)
            return name

        # 1. generation -> motion.npz
        stage("generate")
        t = time.perf_counter()
        motion = self._generate(req, constraints, control, control_path)
        files["motion"] = motion.save(tmp / "motion.npz")
        timings["generate"] = time.perf_counter() - t
        bar.update()

        # 2. retargeting -> robot.npz
        stage("retarget")
        from retarget.io import write_robot_npz

        t = time.perf_counter()
        entry["retargeter"].prepare(len(motion.joints))  # compiles the window problem once per length
        setup = time.perf_counter() - t
        if setup > 1e-3:
            timings["setup"] = timings.get("setup", 0.0) + setup
        t = time.perf_counter()

        rt = entry["retargeter"].run(motion.joints, float(motion.fps), progress=False, source="motion.npz")
        files["robot"] = write_robot_npz(tmp / "robot.npz", rt)
        timings["retarget"] = time.perf_counter() - t
        zmp_weight = float(entry["retargeter"].config.weights.zmp)
        acceleration_weight = float(entry["retargeter"].config.weights.acceleration)
        bar.update()

        cfg = self.config
        servo_goals = None
        if cfg.feasibility is not None:  # 3a. feasibility -> the executed robot.npz, servo_goals.npz
            stage("feasibility")
            t = time.perf_counter()
            servo_goals = self._feasible(entry, files, tmp, notes)
            timings["feasibility"] = time.perf_counter() - t

        # 3. validation -> report.json, plots, video.mp4
        stage("validate")
        t = time.perf_counter()
        from motok_robot.sim.report import write_report
        from motok_robot.sim.trajectory import load_robot_npz
        from motok_robot.sim.validate import validate_trajectory, write_servo_goals

        def validate_robot_file():
            trajectory = load_robot_npz(files["robot"], entry["robot"])
            trajectory.source = "robot.npz"
            digest = hashlib.sha256(files["robot"].read_bytes()).hexdigest()  # the playback gate checks it
            return trajectory, validate_trajectory(trajectory, entry["index"], cfg.validation, out_dir=None,
                                                   input_sha256=digest, servo_goals=servo_goals)

        trajectory, validation = validate_robot_file()
        timings["validate"] = time.perf_counter() - t
        unbalanced = BALANCE_CHECKS.intersection(validation.report["failed_checks"])
        if servo_goals is not None:
            unbalanced = set()  # the feasibility stage owns balance and timing
        if unbalanced and cfg.balance_zmp_weight > 0 and zmp_weight == 0:
            stage("balance")
            t = time.perf_counter()
            rebalanced = self._rebalance(entry, motion, files["robot"], rt, unbalanced, validation,
                                         validate_robot_file, notes)
            if rebalanced is not None:
                rt, trajectory, validation = rebalanced
                zmp_weight = cfg.balance_zmp_weight
                acceleration_weight = cfg.balance_acceleration_weight
            timings["balance"] = time.perf_counter() - t
        notes[:0] = _retargeting_notes(rt)
        retime_factor = 1.0
        too_fast = SPEED_CHECKS.intersection(validation.report["failed_checks"])
        if too_fast and cfg.max_retime > 1.0 and servo_goals is None:
            stage("retime")
            t = time.perf_counter()
            trajectory, validation, retime_factor = self._slow_down(files["robot"], too_fast, validation, trajectory,
                                                                    validate_robot_file, notes)
            timings["retime"] = time.perf_counter() - t
        report = validation.report
        report["outputs"] = {"report": "report.json", "plots": [], "video": None}
        if plots:
            from motok_robot.sim.plots import save_plots

            t = time.perf_counter()
            for p in save_plots(validation, tmp):
                files[f"plot_{Path(p).stem}"] = Path(p)
                report["outputs"]["plots"].append(Path(p).name)
            timings["plots"] = time.perf_counter() - t
        if render:
            from motok_robot.sim.render import render_video

            t = time.perf_counter()
            files["video"] = Path(render_video(validation, trajectory, tmp / "video.mp4", cfg.validation))
            report["outputs"]["video"] = "video.mp4"
            timings["render"] = time.perf_counter() - t
        report.setdefault("timing_s", {}).update(
            {k: timings[k] for k in ("plots", "render") if k in timings})
        goals_path = write_servo_goals(validation, tmp)
        if goals_path is not None:
            files["servo_goals"] = goals_path
        files["report"] = write_report(report, tmp / "report.json")
        bar.update()

        # 4. playback
        stage("playback")
        t = time.perf_counter()
        pb = self._playback(entry["robot"], tmp, playback, port, force, render, files, notes)
        timings["playback"] = time.perf_counter() - t
        bar.update()

        return PipelineResult(
            out_dir=tmp, text=req["text"] or motion.text, robot=entry["robot"].name, seconds=float(motion.seconds),
            seed=req["seed"], files=files, passed=bool(report["passed"]),
            failed_checks=list(report["failed_checks"]), timings=timings, playback=pb, report=report,
            model=motion.model, notes=notes, retime_factor=retime_factor, zmp_weight=zmp_weight,
            acceleration_weight=acceleration_weight)

    def _feasible(self, entry: dict, files: dict, tmp: Path, notes: list) -> dict:
        """Run the feasibility stage on ``files["robot"]`` (rewritten as the executed trajectory,
        with ``servo_goals.npz`` and ``feasibility.json`` beside it); returns the servo goals."""
        from retarget.io import read_robot_npz

        from motok_robot.feasibility.feedforward import load_servo_goals
        from motok_robot.feasibility.stage import RECORD_FILE, make_feasible, write_feasible

        result = make_feasible(read_robot_npz(files["robot"]), entry["index"], self.config.feasibility)
        write_feasible(result, tmp, entry["robot"].name)
        files["feasibility"] = tmp / RECORD_FILE
        rec = result.record
        shift = rec.get("zmp_shift")
        notes.append(f"feasibility: executed closed loop from rest{', time warp %.2fx' % rec['time_warp'] if rec['time_warp'] != 1 else ''}"
                     + (f", CoM moved up to {shift['com_shift_m_max'] * 100:.1f} cm" if shift else "")
                     + (f", goals refined ({rec['refine']['rollouts']} rollouts)" if "refine" in rec else "")
                     + ("; the robot FELL" if result.fell else ""))
        return load_servo_goals(tmp / "servo_goals.npz")

    def _balance_retargeter(self, entry: dict):
        """:func:`balance_retargeter` of ``entry`` at ``balance_zmp_weight`` and
        ``balance_acceleration_weight``."""
        return balance_retargeter(entry, self.config.balance_zmp_weight, self.config.balance_acceleration_weight)

    def _rebalance(self, entry: dict, motion, robot_path: Path, first, unbalanced: set, validation,
                   validate_robot_file, notes: list[str]):
        """Retarget ``motion`` again with the ZMP term (``balance_zmp_weight``) and a foot planted in
        every frame, and validate it.  Keeps the new trajectory in ``robot_path`` and returns
        ``(retarget result, trajectory, validation)`` when the checks it fails, speed checks
        aside, are a strict subset of those that failed before and no more of its solver windows
        end with a hard constraint violated than in ``first`` (the first retargeting result; a
        window that stopped short of optimality with every constraint holding counts as
        feasible: validation judges it); otherwise restores the first trajectory and returns None."""
        from retarget.io import write_robot_npz

        weights = (f"weight {self.config.balance_zmp_weight:g}, "
                   f"acceleration weight {self.config.balance_acceleration_weight:g}")
        original_bytes = robot_path.read_bytes()
        before = set(validation.report["failed_checks"])
        rt = self._balance_retargeter(entry).run(motion.joints, float(motion.fps), progress=False, source="motion.npz")
        write_robot_npz(robot_path, rt)
        trajectory, balanced = validate_robot_file()
        after = set(balanced.report["failed_checks"])
        listed = ", ".join(sorted(unbalanced))
        infeasible = sum(w.violated is not None for w in rt.windows) - sum(w.violated is not None for w in first.windows)
        if infeasible > 0:
            robot_path.write_bytes(original_bytes)
            notes.append(f"balance: {listed} failed; retargeting again with the ZMP term ({weights}) left "
                         f"{infeasible} more solver window(s) with a constraint violated, so the first trajectory is kept")
            return None
        if after - SPEED_CHECKS < before - SPEED_CHECKS:
            now = "every check passes" if not after else f"fails {', '.join(sorted(after))}"
            notes.append(f"balance: {listed} failed; retargeted again with the ZMP term ({weights}) and a "
                         f"foot planted in every frame, the trajectory kept: {now}")
            return rt, trajectory, balanced
        robot_path.write_bytes(original_bytes)
        notes.append(f"balance: {listed} failed; retargeting again with the ZMP term ({weights}) and a foot "
                     f"planted in every frame failed "
                     f"{', '.join(sorted(after)) or 'nothing'} instead, not fewer checks, so the first trajectory is kept")
        return None

    def _slow_down(self, robot_path: Path, too_fast: set, validation, trajectory, validate_robot_file, notes):
        """Play ``robot_path`` slower (:data:`RETIME_STEPS` up to ``max_retime``) until no speed
        check fails and no check fails that passed before; keep the original file and verdict
        when no factor does.  Returns
        ``(trajectory, validation, factor)`` of the timing kept (``robot_path`` holds it)."""
        from retarget.io import read_robot_npz, write_robot_npz
        from retarget.retime import retime

        limit = self.config.max_retime
        original_bytes = robot_path.read_bytes()
        original = read_robot_npz(robot_path)
        before = ", ".join(f"{name} {validation.report['checks'][name]['value']:.2f}" for name in sorted(too_fast))
        factors = [f for f in RETIME_STEPS if f < limit - 1e-9] + [limit]
        failed_before = set(validation.report["failed_checks"])
        for factor in factors:
            write_robot_npz(robot_path, retime(original, factor))
            slowed_trajectory, slowed = validate_robot_file()
            failed_now = set(slowed.report["failed_checks"])
            if not SPEED_CHECKS.intersection(failed_now) and failed_now <= failed_before:
                after = ", ".join(f"{name} {slowed.report['checks'][name]['value']:.2f}" for name in sorted(too_fast))
                notes.append(f"retime: the motion asked more than the servos have ({before}); the robot plays it "
                             f"{factor:g}x slower ({after}; {slowed_trajectory.duration_s:.1f} s instead of "
                             f"{trajectory.duration_s:.1f} s)")
                return slowed_trajectory, slowed, factor
        robot_path.write_bytes(original_bytes)
        notes.append(f"retime: {before} fail; playing up to {limit:g}x slower did not bring "
                     f"{', '.join(sorted(too_fast))} within the servo limits without failing another check, "
                     "so the original timing is kept")
        return trajectory, validation, 1.0

    def _generate(self, req, constraints, control, control_path):
        """Generation, unconstrained (the planner) or constrained (the control stage), or a motion file."""
        if req.get("motion") is not None:
            source = load_source_motion(req["motion"], req.get("skeleton", "bandai"))
            if req["seconds"] is not None:  # keep the first `seconds` of the file
                frames = max(2, round(req["seconds"] * source.fps))
                source.joints, source.features = source.joints[:frames], source.features[:frames]
            if req["text"] is not None:
                source.text = req["text"]
            return source
        opts = dict(self.config.generation)
        if constraints is None:
            return self.generator.generate(text=req["text"], seconds=req["seconds"], seed=req["seed"], **opts)
        # Constrained generation: motok_robot.control.generate.generate_motion (issue 4).  It shares the
        # per-process model cache with load_generator (same planner / run / device arguments).
        try:
            from motok_robot.control.generate import generate_motion
        except ModuleNotFoundError as exc:
            if exc.name in ("motok_robot.control.generate",):
                raise InputError("constraints were given but constrained generation "
                                 "(motok_robot.control.generate) is not available in this build") from None
            raise
        cfg = self.config
        return generate_motion(req["text"], constraints=constraints, control=control, control_path=control_path,
                               seconds=req["seconds"] or DEFAULT_CONSTRAINED_SECONDS, seed=req["seed"],
                               planner=cfg.planner, tokenizer_run=cfg.tokenizer_run, planner_run=cfg.planner_run,
                               device=cfg.device, **opts)

    def _playback(self, robot, tmp: Path, mode: str, port, force: bool, render: bool, files, notes) -> PlaybackSummary:
        from motok_robot.servo.bus import DynamixelBus
        from motok_robot.servo.config import PlaybackConfig
        from motok_robot.servo.convert import ServoMap
        from motok_robot.servo.imu import ImuMount
        from motok_robot.servo.streamer import PlaybackWarning, Streamer, check_validation_report, load_trajectory
        from motok_robot.servo.timing import FakeClock

        gate = None
        try:
            check_validation_report(files["robot"], files["report"], force=False, robot_name=robot.name)
        except InputError as exc:
            gate = str(exc).split("refusing to play: ", 1)[-1].split(". Validate it first", 1)[0]
            gate = gate.replace(str(tmp) + os.sep, "")  # name files relative to the output folder
        summary = PlaybackSummary(mode=mode, status="completed", gate=gate)
        if not robot.servos:
            summary.status = "skipped"
            summary.line = f"robot {robot.name} has no servo map; nothing to play"
            return summary
        if mode == "port" and gate is not None:
            if not force:
                summary.status = "refused"
                summary.line = f"hardware playback refused: {gate} (pass --force to play anyway)"
                return summary
            summary.forced = True
            notes.append(f"hardware playback FORCED without a passing validation report ({gate})")
            warnings.warn(f"playing on {port} WITHOUT a passing validation report ({gate}) because of --force",
                          PlaybackWarning, stacklevel=3)
        servo_map = ServoMap.from_specs(robot.servos)
        trajectory = load_trajectory(files["robot"], servo_map, robot.name, files["report"])
        defaults = self.config.playback or PlaybackConfig()
        rate = defaults.rate_hz
        if self.config.playback is None and robot.bus is not None:
            rate = robot.bus.control_hz
        config = PlaybackConfig(**{**asdict(defaults), "rate_hz": rate})
        baud = robot.bus.baud if robot.bus is not None else 2_000_000
        imu = ImuMount.from_spec(robot.bus.imu) if robot.bus is not None and robot.bus.imu is not None else None
        simulated = mode != "port" and not self.config.realtime
        clock = FakeClock() if simulated else None
        log_path = tmp / "playback.csv"
        rig = None
        try:
            if mode == "dry-run":
                from motok_robot.servo.emulator import emulated_chain

                chain = emulated_chain(servo_map, baud=baud, imu_id=imu.id if imu is not None else None,
                                       **({"clock": clock} if clock else {}))
                bus = DynamixelBus(f"emulated:{robot.name}", baud, port_handler=chain, imu=imu)
            elif mode == "sim":
                from motok_robot.servo.sim_rig import SimRig

                video = tmp / "playback_sim.mp4" if render and self.config.sim_video else None
                bus = rig = SimRig(robot, clock=clock, render_path=video)
            else:
                bus = DynamixelBus(port, baud, imu=imu)
        except HardwareError as exc:
            summary.status, summary.error = "error", str(exc)
            return summary
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", PlaybackWarning)
                streamer = Streamer(bus, servo_map, config, clock=clock, log_path=log_path)
                streamer.preflight()
                played = streamer.play(trajectory)
            summary.line = played.line().replace(str(log_path), log_path.name)
            notes.extend(f"playback: {w.message}" for w in caught if issubclass(w.category, PlaybackWarning))
        except HardwareError as exc:  # the streamer already stopped safely and names the servo
            summary.status, summary.error = "stopped", str(exc).replace(str(tmp) + os.sep, "")
        finally:
            bus.close()
        for key, path in (("playback_log", log_path), ("playback_stats", log_path.with_name("playback.stats.json"))):
            if path.is_file():
                files[key] = path
        if "playback_stats" in files:  # the streamer records the log's (temporary) absolute path
            stats = json.loads(files["playback_stats"].read_text(encoding="utf-8"))
            stats["log_path"] = log_path.name
            files["playback_stats"].write_text(json.dumps(stats, indent=2) + "\n", encoding="utf-8")
        if rig is not None:
            summary.fell = bool(rig.fell)
            summary.line += (f"; simulated robot {'FELL' if rig.fell else 'stayed upright'} "
                             f"(lowest base height {rig.min_base_height:.3f} m)")
            if (tmp / "playback_sim.mp4").is_file():
                files["playback_video"] = tmp / "playback_sim.mp4"
        if simulated:
            summary.line += " [simulated time]"
        return summary

    # ------------------------------------------------------------------ output folder
    @staticmethod
    def _fail(tmp: Path, out: Path, stage: str, error: BaseException) -> None:
        """Rename the partial folder ``OUT.failed`` and write ``FAILED.txt`` into it."""
        failed = out.with_name(out.name + ".failed")
        try:
            (tmp / "FAILED.txt").write_text(
                f"FAILED at stage {stage}: {type(error).__name__}: {error}\n"
                "The files here are partial; the run did not finish.\n", encoding="utf-8")
            if failed.exists():
                shutil.rmtree(failed)
            os.replace(tmp, failed)
        except OSError:
            shutil.rmtree(tmp, ignore_errors=True)

    @staticmethod
    def _finish(tmp: Path, out: Path) -> None:
        """Move the finished folder to ``out`` (replacing an old one only now)."""
        old = None
        if out.exists():
            if any(out.iterdir()):
                old = out.with_name(f".{out.name}.old-{uuid.uuid4().hex[:8]}")
                os.replace(out, old)
            else:
                out.rmdir()
        os.replace(tmp, out)
        stale = out.with_name(out.name + ".failed")
        if stale.is_dir():
            shutil.rmtree(stale, ignore_errors=True)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)

    def _write_summary(self, result: PipelineResult, tmp: Path) -> None:
        result.files["summary"] = tmp / "summary.md"
        result.files["result"] = tmp / "pipeline.json"
        result.out_dir = tmp
        (tmp / "summary.md").write_text(summary_markdown(result), encoding="utf-8")
        data = result.to_dict()
        data["out_dir"] = "."
        (tmp / "pipeline.json").write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")

    # ------------------------------------------------------------------ many prompts
    def run_batch(self, prompts: list[PromptSpec], out_dir, robot: str = "op3_like", playback: str = "dry-run",
                  render: bool = False, overwrite: bool = False, progress: bool | None = None) -> Path:
        """Run every prompt into ``out_dir/NNN_slug/`` and write ``out_dir/summary.csv``.

        A prompt whose run fails is recorded (``error`` column, ``NNN_slug.failed/``) and the
        batch goes on.  Returns the path of ``summary.csv``.
        """
        from tqdm import tqdm

        if not prompts:
            raise InputError("no prompts to run")
        if playback == "port":
            raise InputError("a prompt list cannot play on hardware; run one prompt with --port")
        check_robot(robot)
        check_playback(playback, None)
        out = check_out_dir(out_dir, overwrite)
        for spec in prompts:
            check_text(spec.text), check_seconds(spec.seconds), check_seed(spec.seed)
        self.load_models()
        for spec in prompts:
            if spec.seconds is not None:
                try:
                    self.generator.frames_for(spec.seconds)
                except InputError as exc:
                    raise InputError(f"prompt on line {spec.line}: {exc}") from None
        out.mkdir(parents=True, exist_ok=True)
        rows = []
        try:
            for i, spec in enumerate(tqdm(prompts, desc="prompts", unit="prompt", disable=None if progress is None
                                          else not progress)):
                folder = f"{i:03d}_{slug(spec.text)}"
                row = {"index": i, "text": spec.text, "seed": spec.seed, "folder": folder}
                try:
                    res = self.run(spec.text, robot=robot, seconds=spec.seconds, seed=spec.seed,
                                   out_dir=out / folder, playback=playback, render=render, overwrite=True)
                except Exception as exc:  # noqa: BLE001 - record it and go on with the list
                    failed = out / f"{folder}.failed"
                    row.update(passed=False, error=str(exc), seconds=spec.seconds,
                               folder=failed.name if failed.is_dir() else "")
                else:
                    row.update(seconds=round(res.seconds, 3), passed=res.passed,
                               failed_checks=";".join(res.failed_checks), playback=res.playback.status,
                               **{f"{k}_s": round(v, 3) for k, v in res.timings.items() if k in (*STAGES, "total")})
                rows.append(row)
        finally:  # also after Ctrl-C: the rows of the prompts that ran
            self._write_summary_csv(out, rows)
        return out / "summary.csv"

    @staticmethod
    def _write_summary_csv(out: Path, rows: list[dict]) -> None:
        columns = ["index", "text", "seconds", "seed", "folder", "passed", "failed_checks", "playback",
                   *(f"{s}_s" for s in (*STAGES, "total")), "error"]
        buffer = io.StringIO()
        writer = csv.DictWriter(buffer, fieldnames=columns, extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            writer.writerow({k: "" if row.get(k) is None else row.get(k, "") for k in columns})
        path = out / "summary.csv"
        part = out / ".summary.csv.partial"
        part.write_text(buffer.getvalue(), encoding="utf-8")
        os.replace(part, path)


def _retargeting_notes(rt) -> list[str]:
    """Notes worth reading about a retargeting result: body parts kept apart, failed windows."""
    notes = []
    if rt.collision_pairs:
        notes.append(f"retargeting: kept {len(rt.collision_pairs)} body part pairs apart that the human motion "
                     f"drove into each other ({', '.join(rt.collision_pairs)})")
    failed_windows = rt.failed_windows()
    if failed_windows:
        violated = [w.violated for w in failed_windows if w.violated is not None]
        holding = (f"{len(violated)} with a constraint violated (first: {violated[0]})" if violated
                   else "every constraint holds")
        notes.append(f"retargeting: {len(failed_windows)}/{len(rt.windows)} solver windows did not converge "
                     f"(first: frames {failed_windows[0].start}-{failed_windows[0].stop}, "
                     f"{failed_windows[0].status}; {holding})")
    return notes


# ----------------------------------------------------------------------------- summary.md
_FILE_LABELS = {
    "motion": "human motion (joints, features, tokens)",
    "robot": "robot trajectory (qpos, contacts, keypoint errors)",
    "servo_goals": "servo goals the physics rollout tracked and playback streams (feedforward)",
    "report": "validation report",
    "video": "validation video (reference | physics rollout)",
    "playback_log": "playback log (one row per control tick)",
    "playback_stats": "playback loop statistics",
    "playback_video": "simulated playback video",
    "result": "this summary, machine-readable",
}


def summary_markdown(result: PipelineResult) -> str:
    """``summary.md``: verdict, failing checks, per-stage times and links to every file."""
    root = result.out_dir
    verdict = "PASS" if result.passed else "FAIL"
    lines = [f"# {verdict}: \"{result.text}\"", "",
             f"* robot: `{result.robot}`; clip: {result.seconds:.2f} s; seed: {result.seed}"
             + (f"; the robot plays it {result.retime_factor:g}x slower (servo limits)" if result.retime_factor != 1.0 else "")
             + (f"; retargeted with the ZMP term (weight {result.zmp_weight:g}, acceleration weight "
                f"{result.acceleration_weight:g})" if result.zmp_weight > 0 else ""),
             f"* models: `{result.model}`" if result.model else "* models: -",
             f"* validation: **{verdict}**"
             + (f" - failing checks: {', '.join(f'`{c}`' for c in result.failed_checks)}" if result.failed_checks else
                " - every check passed"),
             f"* playback ({result.playback.mode}): **{result.playback.status}**"
             + (f" - {result.playback.line}" if result.playback.line else "")
             + (f" - {result.playback.error}" if result.playback.error else ""), ""]
    if result.playback.gate:
        lines += [f"Hardware playback would be refused: {result.playback.gate}.", ""]
    if result.report:
        from motok_robot.sim.report import summary_text

        lines += ["## Validation", "", "```", summary_text(result.report), "```", ""]
    lines += ["## Stage times", "", "| stage | seconds |", "|---|---:|"]
    for key in ("load", "setup", *STAGES, "total"):
        if key in result.timings:
            lines.append(f"| {key} | {result.timings[key]:.3f} |")
    lines += ["", "## Files", ""]
    for key, path in result.files.items():
        if key == "summary":
            continue
        name = _rel(path, root)
        label = _FILE_LABELS.get(key) or ("plot: " + key[5:].replace("_", " ") if key.startswith("plot_") else key)
        lines.append(f"* [{name}]({name}) - {label}")
    for key in [k for k in result.files if k.startswith("plot_")]:
        name = _rel(result.files[key], root)
        lines += ["", f"![{key[5:]}]({name})"]
    if result.notes:
        lines += ["", "## Notes", ""] + [f"* {n}" for n in result.notes]
    return "\n".join(lines) + "\n"

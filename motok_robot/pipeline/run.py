"""The :class:`Pipeline`: loaded models and robots, the request check, and one run from the
request to the finished output folder (the stages themselves: :mod:`motok_robot.pipeline.stages`)."""

from __future__ import annotations

import time
from pathlib import Path

from motok_robot.errors import InputError, MotokError
from motok_robot.pipeline.batch import run_batch
from motok_robot.pipeline.config import PipelineConfig
from motok_robot.pipeline.output import fail, finish, partial_folder
from motok_robot.pipeline.repairs import balance_retargeter
from motok_robot.pipeline.request import check_request
from motok_robot.pipeline.result import PipelineResult, relative
from motok_robot.pipeline.stages import run_stages
from motok_robot.pipeline.summary import write_summary
from motok_robot.robots.robot import DEFAULT_ROBOT
from motok_robot.text.prompts import PromptSpec

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
    def check(self, text, robot=DEFAULT_ROBOT, seconds=None, seed=0, constraints=None, out_dir=None,
              playback="dry-run", port=None, overwrite=False, motion=None) -> dict:
        """Check a request without doing any work (no models loaded, nothing written).

        Returns the cleaned arguments; raises :class:`InputError` with a one-line message.
        """
        return check_request(text, robot, seconds, seed, constraints, out_dir, playback, port, overwrite, motion)

    def run(self, text: str, robot: str = DEFAULT_ROBOT, seconds: float | None = None, seed: int = 0,
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
            playback: ``"dry-run"`` (emulated servo chain), ``"sim"`` (MuJoCo), ``"port"`` or
                ``"none"`` (no playback stage: a validation sweep).
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
            and :class:`MotokError` naming the stage when a stage fails (see :mod:`motok_robot.pipeline`).
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
        tmp = partial_folder(out)
        state = {"stage": "generate"}
        bar = None
        try:
            from tqdm import tqdm

            bar = tqdm(total=4, desc="generate", unit="stage", disable=None if progress is None else not progress,
                       leave=False)
            result = run_stages(self, req, entry, tmp, timings, bar, state, constraints, control, control_path,
                                playback, port, force, render, self.config.plots if plots is None else plots)
        except BaseException as exc:  # noqa: BLE001 - every failure leaves OUT.failed, never a complete-looking OUT
            fail(tmp, out, state["stage"], exc)
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
        write_summary(result, tmp)
        finish(tmp, out)
        result.out_dir = out
        result.files = {k: out / relative(v, tmp) for k, v in result.files.items()}
        return result

    def _balance_retargeter(self, entry: dict):
        """:func:`balance_retargeter` of ``entry`` at ``balance_zmp_weight`` and
        ``balance_acceleration_weight`` (a method, so that a subclass or a test can swap it)."""
        return balance_retargeter(entry, self.config.balance_zmp_weight, self.config.balance_acceleration_weight)

    # ------------------------------------------------------------------ many prompts
    def run_batch(self, prompts: list[PromptSpec], out_dir, robot: str = DEFAULT_ROBOT, playback: str = "dry-run",
                  render: bool = False, overwrite: bool = False, progress: bool | None = None) -> Path:
        """Run every prompt into ``out_dir/NNN_slug/`` and write ``out_dir/summary.csv``
        (:func:`~motok_robot.pipeline.batch.run_batch`).

        A prompt whose run fails is recorded (``error`` column, ``NNN_slug.failed/``) and the
        batch goes on.  Returns the path of ``summary.csv``.
        """
        return run_batch(self, prompts, out_dir, robot=robot, playback=playback, render=render, overwrite=overwrite,
                         progress=progress)

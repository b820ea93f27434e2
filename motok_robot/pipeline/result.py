"""What a run returns: :class:`PipelineResult` and its :class:`PlaybackSummary`."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path

#: Stages timed in :attr:`PipelineResult.timings`, in order.
STAGES = ("generate", "retarget", "feasibility", "validate", "balance", "retime", "plots", "render", "playback")


@dataclass
class PlaybackSummary:
    """What the playback stage did.

    ``mode``: dry-run / sim / port / none; ``status``: ``completed``, ``refused`` (hardware without a
    passing report), ``skipped`` (robot without servos, or playback ``none``), ``stopped`` (a servo fault or a fall)
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
            "files": {k: relative(v, self.out_dir) for k, v in self.files.items()},
            "timings_s": {k: round(v, 4) for k, v in self.timings.items()},
            "playback": asdict(self.playback), "model": self.model, "notes": list(self.notes),
            "retime_factor": self.retime_factor, "zmp_weight": self.zmp_weight,
            "acceleration_weight": self.acceleration_weight,
        }


def relative(path: Path | str, root: Path) -> str:
    """``path`` relative to ``root`` (posix form), or as it is when it lies outside ``root``."""
    try:
        return Path(path).relative_to(root).as_posix()
    except ValueError:
        return str(path)

"""Bounds on the sizes that user input decides, checked before anything is allocated.

One bound per kind of input, each with a default and an environment variable to raise it (the
``--limit NAME=VALUE`` option of ``motok-robot`` sets the same variable for one run):

=================  ==========================  ==========  =========================================
name               environment variable        default     what it bounds
=================  ==========================  ==========  =========================================
``frames``         ``MOTOK_MAX_FRAMES``        100000      frames of a motion, trajectory or mocap file
``seconds``        ``MOTOK_MAX_SECONDS``       600         duration (s): clips, ``--seconds``, ``--ramp``
``rate``           ``MOTOK_MAX_RATE``          1000        frame / control rate (Hz), upper bound
``min_rate``       ``MOTOK_MIN_RATE``          1           frame rate (Hz), lower bound
``joints``         ``MOTOK_MAX_JOINTS``        512         joints of a skeleton or trajectory
``file_bytes``     ``MOTOK_MAX_FILE_BYTES``    268435456   size of an input file on disk (256 MiB)
``inflated_bytes`` ``MOTOK_MAX_INFLATED_BYTES`` 1073741824  arrays of one .npz once decompressed (1 GiB)
=================  ==========================  ==========  =========================================

Every check raises :class:`~motok_robot.errors.InputError` naming the file (or option), the
field, the number and the limit, and how to raise it.  Light: standard library only.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

from motok_robot.errors import InputError


@dataclass(frozen=True)
class Limit:
    name: str
    env: str
    default: float
    unit: str


LIMITS: dict[str, Limit] = {lim.name: lim for lim in (
    Limit("frames", "MOTOK_MAX_FRAMES", 100_000, "frames"),
    Limit("seconds", "MOTOK_MAX_SECONDS", 600.0, "s"),
    Limit("rate", "MOTOK_MAX_RATE", 1000.0, "Hz"),
    Limit("min_rate", "MOTOK_MIN_RATE", 1.0, "Hz"),
    Limit("joints", "MOTOK_MAX_JOINTS", 512, "joints"),
    Limit("file_bytes", "MOTOK_MAX_FILE_BYTES", 256 * 2**20, "bytes"),
    Limit("inflated_bytes", "MOTOK_MAX_INFLATED_BYTES", 2**30, "bytes"),
)}


def limit(name: str) -> float:
    """The bound ``name`` (:data:`LIMITS`): its environment variable when set, else the default."""
    spec = LIMITS[name]
    raw = os.environ.get(spec.env)
    if raw is None or not raw.strip():
        return spec.default
    try:
        value = float(raw)
    except ValueError:
        raise InputError(f"environment variable {spec.env}={raw!r} is not a number") from None
    if not (math.isfinite(value) and value > 0):
        raise InputError(f"environment variable {spec.env}={raw!r} must be a positive finite number")
    return value


def set_limit(assignment: str) -> None:
    """Apply ``NAME=VALUE`` (the ``--limit`` option) to this process's environment."""
    name, sep, value = assignment.partition("=")
    name = name.strip().replace("-", "_")
    if not sep or name not in LIMITS:
        raise InputError(f"--limit {assignment!r}: expected NAME=VALUE with NAME one of {', '.join(LIMITS)}")
    os.environ[LIMITS[name].env] = value.strip()
    limit(name)  # validates the number


def _how(name: str) -> str:
    spec = LIMITS[name]
    return f"raise it with {spec.env}=N or --limit {name}=N"


def _fmt(value: float) -> str:
    return f"{value:,.0f}" if float(value).is_integer() and abs(value) < 1e15 else f"{value:g}"


def check_count(name: str, value: float, where: str, what: str) -> None:
    """``value`` (frames, joints, ...) must not exceed :func:`limit` ``(name)``."""
    bound = limit(name)
    if not value <= bound:
        raise InputError(f"{where}: {what} is {_fmt(value)} {LIMITS[name].unit}, above the limit of "
                         f"{_fmt(bound)} ({_how(name)})")


def check_frames(frames: float, where: str, what: str = "the number of frames") -> None:
    check_count("frames", frames, where, what)


def check_joints(joints: float, where: str, what: str = "the number of joints") -> None:
    check_count("joints", joints, where, what)


def check_seconds(seconds: float, where: str, what: str = "the duration") -> None:
    """A duration (s): finite, >= 0 and at most the ``seconds`` limit."""
    if not (isinstance(seconds, (int, float)) and math.isfinite(seconds) and seconds >= 0):
        raise InputError(f"{where}: {what} must be a finite number of seconds >= 0, got {seconds!r}")
    check_count("seconds", seconds, where, what)


def check_rate(rate: float, where: str, what: str = "the frame rate") -> None:
    """A rate (Hz, fps): finite and inside ``min_rate``..``rate``."""
    lo, hi = limit("min_rate"), limit("rate")
    if not (isinstance(rate, (int, float)) and math.isfinite(rate) and lo <= rate <= hi):
        raise InputError(f"{where}: {what} is {rate!r} Hz, outside the allowed {lo:g}..{hi:g} Hz "
                         f"(raise the bounds with {LIMITS['min_rate'].env} / {LIMITS['rate'].env} "
                         "or --limit min_rate=N / --limit rate=N)")


def check_file_size(path: str | Path, what: str = "file") -> int:
    """The size of ``path`` in bytes; InputError when it is above the ``file_bytes`` limit."""
    path = Path(path)
    size = path.stat().st_size
    check_count("file_bytes", size, str(path), f"the {what} size")
    return size

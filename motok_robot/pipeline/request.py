"""Request and option checks: every argument of a run is checked before any work, and a bad one
raises :class:`~motok_robot.errors.InputError` with one line (nothing loaded, nothing written)."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from motok_robot.errors import InputError
from motok_robot.robots.robot import DEFAULT_ROBOT
from motok_robot.text.prompts import check_seconds, check_seed
from motok_robot.text.validate import check_text

#: where the playback stage streams: an emulated servo chain, the MuJoCo model, real servos
PLAYBACK_MODES = ("dry-run", "sim", "port", "none")
#: Clip length used with constraints when no ``seconds`` is given (the planner's no-text default).
DEFAULT_CONSTRAINED_SECONDS = 6.0


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
    """``playback`` is one of :data:`PLAYBACK_MODES`, and ``port`` exists exactly when it is ``"port"``."""
    if playback not in PLAYBACK_MODES:
        raise InputError(f"playback must be one of {', '.join(PLAYBACK_MODES)}, got {playback!r}")
    if playback == "port":
        if not port:
            raise InputError("hardware playback needs a serial port (--port DEV)")
        if not os.path.exists(port) and not str(port).upper().startswith("COM"):
            raise InputError(f"serial port {port} does not exist (is the USB adapter plugged in?)")
    elif port:
        raise InputError(f"a serial port ({port}) was given with playback {playback!r}; use playback='port'")


def check_request(text, robot=DEFAULT_ROBOT, seconds=None, seed=0, constraints=None, out_dir=None,
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

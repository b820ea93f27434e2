"""Config dataclasses to and from plain dicts (JSON sections), with clear errors (light: no torch).

Used by the tokenizer, planner and evaluator configs so that a config file or a run
directory's ``config.json`` with a misspelt or misplaced setting is rejected with the file
section, the unknown names and the known ones, never a ``TypeError`` from a constructor.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any, TypeVar

from motok_robot.errors import InputError

T = TypeVar("T")


def dataclass_from_dict(cls: type[T], data: Any, where: str, noun: str = "field") -> T:
    """``cls(**data)`` after checking that ``data`` is a dict of ``cls``'s field names.

    ``where`` names the place in messages (e.g. ``"run/config.json 'planner'"``); ``noun`` is
    what the unknown names are called there (``"field"`` or ``"key"``). Errors raised by the
    dataclass itself (``__post_init__`` validation) pass through unchanged.
    """
    if not isinstance(data, dict):
        raise InputError(f"{where}: expected a JSON object, got {type(data).__name__}")
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - names)
    if unknown:
        raise InputError(f"{where}: unknown {noun}(s) {unknown}; known: {sorted(names)}")
    try:
        return cls(**data)
    except TypeError as exc:  # pragma: no cover - defensive (every field has a default)
        raise InputError(f"{where}: {exc}") from None


def dataclass_to_dict(config: Any) -> dict[str, Any]:
    """``dataclasses.asdict(config)`` with top-level tuples as lists (what JSON gives back)."""
    out = dataclasses.asdict(config)
    for key, value in out.items():
        if isinstance(value, tuple):
            out[key] = list(value)
    return out


def changed_fields(section: str, saved: dict[str, Any], asked: dict[str, Any], keys) -> list[str]:
    """``"section.key is SAVED (asked ASKED)"`` for each of ``keys`` whose asked value differs from
    the saved one: what a ``--resume`` command would otherwise drop without a word."""
    return [f"{section}.{key} is {saved.get(key)!r} (asked {asked.get(key)!r})"
            for key in keys if asked.get(key) != saved.get(key)]


def read_json_object(path: str | Path, what: str) -> dict:
    """The JSON object in ``path``; ``what`` names the file's role in messages ("--config", "joint map").

    Raises :class:`InputError` naming the file when it is missing, unreadable, not valid JSON
    (with the line) or not a JSON object at the top level.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{what} {path}: file not found")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise InputError(f"{what} {path}: not valid JSON (line {exc.lineno}: {exc.msg})") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{what} {path}: cannot be read ({exc})") from None
    if not isinstance(data, dict):
        raise InputError(f"{what} {path}: expected a JSON object at the top level, got {type(data).__name__}")
    return data

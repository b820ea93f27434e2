"""Prompt files (``--prompts FILE`` of ``run`` and ``generate``) and the checks of their cells.

A prompt file is either one prompt per line (blank lines and lines starting with ``#`` are
skipped), or a CSV file whose header row names the columns ``text`` and optionally ``seconds``
and ``seed``.  Both commands read it with :func:`read_prompts`, so a file means the same to
both.  Every row is checked; errors name the file and the line.
"""

from __future__ import annotations

import csv
import math
import re
from dataclasses import dataclass
from pathlib import Path

from motok_robot.errors import InputError
from motok_robot.text.validate import check_text


@dataclass
class PromptSpec:
    """One row of a ``--prompts`` file: the text, its seconds (None: estimated) and seed."""

    text: str
    seconds: float | None = None
    seed: int = 0
    line: int = 0


def check_seconds(seconds, where: str = "seconds") -> float | None:
    if seconds is None:
        return None
    if isinstance(seconds, bool) or not isinstance(seconds, (int, float)) or not math.isfinite(seconds):
        raise InputError(f"{where} must be a number, got {seconds!r}")
    if seconds <= 0:
        raise InputError(f"{where} must be positive, got {seconds:g}")
    from motok_robot.limits import check_seconds as check_duration

    check_duration(float(seconds), where.split(":")[0], where)
    return float(seconds)


def check_seed(seed, where: str = "seed") -> int:
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        try:
            import numpy as np

            if isinstance(seed, np.integer) and seed >= 0:
                return int(seed)
        except ImportError:  # pragma: no cover
            pass
        raise InputError(f"{where} must be a non-negative integer, got {seed!r}")
    if seed > MAX_SEED:
        raise InputError(f"{where} {seed} is too large: seeds are 0..{MAX_SEED} (2**63 - 1)")
    return int(seed)


#: the largest seed (torch and numpy take signed 64-bit seeds)
MAX_SEED = 2**63 - 1


#: a plain-list line that ends in CSV cells of numbers ("a person bows,,3", "a person bows,4"):
#: without the header it would be read as the prompt text, numbers included
_HEADERLESS_CSV_ROW = re.compile(r"^.+?,\s*[0-9.]*\s*(,\s*-?[0-9]*\s*)?$")


def read_prompts(path, seconds: float | None = None, seed: int = 0) -> list[PromptSpec]:
    """Prompts of a ``--prompts`` file.

    Either one prompt per line (blank lines and lines starting with ``#`` are skipped), or a CSV
    file whose header row names the columns ``text`` and optionally ``seconds`` and ``seed``.
    A row without seconds or seed (every plain line, an empty or missing CSV cell) takes
    ``seconds`` (None: the length estimated from the text) and ``seed``: the command line's
    ``--seconds`` and ``--seed``.  Every row is checked; errors name the line.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"--prompts {path}: file not found")
    try:
        content = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"--prompts {path}: cannot read ({exc})") from None
    lines = content.splitlines()
    numbered = [(i + 1, ln) for i, ln in enumerate(lines) if ln.strip() and not ln.lstrip().startswith("#")]
    if not numbered:
        raise InputError(f"--prompts {path}: no prompts (one per line, or CSV with a text,seconds,seed header)")
    first = next(csv.reader([numbered[0][1]]))
    header = [c.strip().lower() for c in first]
    specs: list[PromptSpec] = []
    if "text" in header and set(header) <= {"text", "seconds", "seed"}:
        for number, ln in numbered[1:]:
            if ln.count('"') % 2:
                raise InputError(f"--prompts {path}: line {number}: unbalanced double quote; quote a text that holds "
                                 'commas as "like, this" and double a quote inside it ("")')
            cells = next(csv.reader([ln]))
            if len(cells) > len(header):
                raise InputError(f"--prompts {path}: line {number}: {len(cells)} columns, the header has {len(header)}")
            row = dict(zip(header, (c.strip() for c in cells)))
            where = f"--prompts {path}: line {number}"
            try:
                text = check_text(row.get("text", ""))
            except InputError as exc:
                raise InputError(f"{where}: {exc}") from None
            row_seconds = _parse_number(row.get("seconds", ""), float, f"{where}: seconds")
            row_seed = _parse_number(row.get("seed", ""), int, f"{where}: seed")
            if row_seconds is not None:
                row_seconds = check_seconds(row_seconds, f"{where}: seconds")
            if row_seed is not None:
                row_seed = check_seed(row_seed, f"{where}: seed")
            specs.append(PromptSpec(text, seconds if row_seconds is None else row_seconds,
                                    seed if row_seed is None else row_seed, number))
        if not specs:
            raise InputError(f"--prompts {path}: the CSV has a header but no rows")
    else:
        for number, ln in numbered:
            if _HEADERLESS_CSV_ROW.match(ln):
                raise InputError(f"--prompts {path}: line {number}: {ln.strip()!r} looks like a CSV row "
                                 "(text,seconds,seed) but the file has no header; start the file with the line "
                                 "'text,seconds,seed', or drop the numbers to use --seconds / --seed")
            try:
                specs.append(PromptSpec(check_text(ln), seconds, seed, number))
            except InputError as exc:
                raise InputError(f"--prompts {path}: line {number}: {exc}") from None
    return specs


def _parse_number(cell: str, kind, where: str):
    if cell is None or cell == "":
        return None
    try:
        return kind(cell)
    except ValueError:
        raise InputError(f"{where}: {cell!r} is not {'an integer' if kind is int else 'a number'}") from None

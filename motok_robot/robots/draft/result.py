"""What a draft returns: :class:`DraftResult`, with :class:`Unsure` entries for what it could not infer."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path


@dataclass
class Unsure:
    """Something the draft could not infer: what, and the file + line to edit."""

    what: str
    file: str
    line: int | None
    text: str  # the line as written

    def format(self) -> str:
        where = f"{self.file}:{self.line}" if self.line else self.file
        return f"{where}: {self.what}\n      {self.text.strip()}"


@dataclass
class DraftResult:
    toml_path: Path
    mjcf_path: Path  # the MJCF the TOML names (the copy, or the user's file when nothing was added)
    copied: bool
    image_path: Path | None
    summary: list[str]  # what was inferred, one line each
    unsure: list[Unsure] = field(default_factory=list)
    load_error: str | None = None  # the draft does not load (after the listed edits it should)

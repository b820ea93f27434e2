"""The atomic output folder: a run writes into a hidden partial folder next to ``OUT``, renamed
``OUT`` when every stage finished, or ``OUT.failed/`` (with ``FAILED.txt``) when one raised."""

from __future__ import annotations

import os
import shutil
import uuid
from pathlib import Path


def partial_folder(out: Path) -> Path:
    """Create and return the hidden folder ``.OUT.partial-PID-XXXXXXXX`` next to ``out``."""
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.parent / f".{out.name}.partial-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    tmp.mkdir()
    return tmp


def fail(tmp: Path, out: Path, stage: str, error: BaseException) -> None:
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


def finish(tmp: Path, out: Path) -> None:
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

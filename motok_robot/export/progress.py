"""Progress of an export that also shows when the output is not a terminal, and the row writer
that reports it.

On a terminal: one line rewritten in place.  Elsewhere (a log, a pipe, CI): a line every
``interval_s`` seconds and one at the end, so a long export never looks stalled.
"""

from __future__ import annotations

import sys
import time


class Progress:
    """``progress(done, total)`` callable writing ``"<what>: done/total <unit>"`` to ``stream``."""

    def __init__(self, what: str, unit: str, stream=None, interval_s: float = 5.0, clock=time.monotonic):
        self.what, self.unit = what, unit
        self.stream = stream if stream is not None else sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.interval_s = interval_s
        self.clock = clock
        self._last = None
        self._open = False

    def __call__(self, done: int, total: int) -> None:
        now = self.clock()
        final = done >= total
        if not final and self._last is not None and now - self._last < (0.1 if self.tty else self.interval_s):
            return
        self._last = now
        text = f"{self.what}: {done}/{total} {self.unit}"
        if self.tty:
            self.stream.write("\r" + text + ("\n" if final else ""))
            self._open = not final
        else:
            self.stream.write(text + "\n")
        self.stream.flush()

    def close(self) -> None:
        """End a line left open on a terminal (an export that stopped early)."""
        if self._open:
            self.stream.write("\n")
            self.stream.flush()
            self._open = False


def write_rows(handle, rows, separator: str, number_format: str, progress=None, step: int = 2000) -> None:
    """Write the number array ``rows[T, C]`` as ``T`` text lines (``separator`` between values,
    each formatted with ``number_format``) in blocks of ``step`` rows, calling
    ``progress(done, T)`` after each block."""
    total = len(rows)
    line = separator.join([f"%{number_format}"] * (rows.shape[1] if total else 0))  # one % per row: fast
    for start in range(0, total, step):
        block = rows[start : start + step].tolist()
        handle.write("\n".join(line % tuple(row) for row in block) + "\n")
        if progress is not None:
            progress(min(start + step, total), total)

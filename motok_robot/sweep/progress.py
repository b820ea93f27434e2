"""The progress line of a sweep: cells done, failed and running, the rate and an ETA.

On a terminal the line is redrawn in place twice a second; elsewhere (a log file, CI) a full line
is printed every ``interval_s`` seconds (default 10) and when the sweep ends.
"""

from __future__ import annotations

import sys
import time


def duration(seconds: float) -> str:
    """``3h05m``, ``4m10s`` or ``12s``."""
    seconds = max(0, int(round(seconds)))
    hours, rest = divmod(seconds, 3600)
    minutes, secs = divmod(rest, 60)
    return f"{hours}h{minutes:02d}m" if hours else f"{minutes}m{secs:02d}s" if minutes else f"{secs}s"


class SweepProgress:
    """Counts of one sweep run; :meth:`show` prints them when it is time."""

    def __init__(self, total: int, skipped: int = 0, stream=None, enabled: bool | None = True,
                 interval_s: float | None = None) -> None:
        self.stream = stream if stream is not None else sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.enabled = enabled if enabled is not None else True
        self.interval_s = interval_s if interval_s is not None else (0.5 if self.tty else 10.0)
        self.total, self.skipped = total, skipped
        self.done = self.failed = self.errors = self.running = 0
        self.started = time.monotonic()
        self._shown = 0.0

    def finished(self, status: str) -> None:
        self.done += 1
        self.failed += status == "failed"
        self.errors += status in ("error", "timeout")
        self.show()

    def line(self) -> str:
        finished = self.skipped + self.done
        elapsed = time.monotonic() - self.started
        text = (f"sweep: {finished}/{self.total} cells" + (f" ({self.skipped} from before)" if self.skipped else "")
                + f" | {self.failed} failed validation, {self.errors} errors | {self.running} running")
        if self.done:
            rate = self.done / elapsed
            left = self.total - finished
            text += f" | {rate * 60:.1f} cells/min | ETA {duration(left / rate) if left else '0s'}"
        return text + f" | {duration(elapsed)} elapsed"

    def show(self, force: bool = False) -> None:
        if not self.enabled:
            return
        now = time.monotonic()
        if not force and now - self._shown < self.interval_s:
            return
        self._shown = now
        if self.tty:
            self.stream.write("\r\x1b[K" + self.line())
        else:
            self.stream.write(self.line() + "\n")
        self.stream.flush()

    def close(self) -> None:
        self.running = 0
        self.show(force=True)
        if self.enabled and self.tty:
            self.stream.write("\n")
            self.stream.flush()

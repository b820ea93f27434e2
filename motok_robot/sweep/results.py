"""The result rows of a sweep and its cell folders, kept consistent through crashes and Ctrl-C.

``DIR/rows.jsonl`` is the journal: one JSON row per finished cell, appended and flushed as the
cell ends, after its folder ``DIR/cells/<cell_id>/`` was moved into place (so a row always has
its folder; a torn last line, left by a killed driver, is ignored).  ``results.parquet`` and
``results.csv`` are rewritten from the journal every few seconds and when the sweep stops, each
through a temporary file and a rename: a reader never sees half a table, and after a crash the
tables hold every row but the last few seconds' (``--resume`` reads the journal).  One driver at
a time: ``DIR/.sweep.lock`` is held (``flock``) while a sweep writes.
"""

from __future__ import annotations

import csv
import io
import json
import os
import shutil
import time
import uuid
from pathlib import Path

from motok_robot.errors import InputError

JOURNAL = "rows.jsonl"
PARQUET = "results.parquet"
CSV = "results.csv"
CELLS = "cells"
LOCK = ".sweep.lock"
#: the first columns of the table, in this order; the rest follow grouped by prefix
KEY_COLUMNS = ("cell_id", "input", "prompt", "motion", "seed", "robot", "variant", "status", "passed",
               "failed_checks", "n_failed_checks", "error")
_GROUPS = ("metric_", "fidelity_", "feasibility_", "time_")
_LAST_COLUMNS = ("cell_s", "roundtrip_s", "worker", "attempts", "inputs_hash", "report_sha", "qpos_sha",
                 "run_id", "finished_at", "folder")


def order_columns(names) -> list[str]:
    """Table columns: :data:`KEY_COLUMNS`, the other result fields, metrics, fidelity, feasibility,
    stage times, then the bookkeeping columns."""
    names = list(dict.fromkeys(names))
    first = [c for c in KEY_COLUMNS if c in names]
    last = [c for c in _LAST_COLUMNS if c in names]
    grouped = {g: sorted(c for c in names if c.startswith(g) and c not in first) for g in _GROUPS}
    grouped["time_"] = sorted(grouped["time_"], key=_stage_order)
    taken = set(first) | set(last) | {c for cols in grouped.values() for c in cols}
    rest = [c for c in names if c not in taken]
    return first + rest + [c for g in _GROUPS for c in grouped[g]] + last


def _stage_order(column: str) -> tuple:
    order = ("load", "setup", "generate", "retarget", "feasibility", "validate", "balance", "retime", "plots",
             "render", "playback", "total")
    stage = column[len("time_"):-len("_s")]
    return (order.index(stage) if stage in order else len(order) - 1, stage)


class ResultStore:
    """The journal, the two tables and the cell folders of one sweep folder ``out``."""

    def __init__(self, out: Path, table_interval_s: float = 5.0) -> None:
        self.out = Path(out)
        self.table_interval_s = table_interval_s
        self.rows: dict[str, dict] = {}
        self._lock = None
        self._journal = None
        self._tables_at = 0.0

    # ------------------------------------------------------------------ opening
    def lock(self) -> None:
        """Take ``DIR/.sweep.lock``; InputError when another sweep holds it."""
        import fcntl

        self.out.mkdir(parents=True, exist_ok=True)
        handle = open(self.out / LOCK, "a+", encoding="utf-8")
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.close()
            raise InputError(f"another sweep is writing {self.out} (it holds {self.out / LOCK})") from None
        handle.truncate(0)
        handle.write(f"{os.getpid()}\n")
        handle.flush()
        self._lock = handle

    def read_journal(self) -> dict[str, dict]:
        """The rows of ``rows.jsonl`` by cell id (the last row of a cell wins; a torn line is skipped)."""
        rows: dict[str, dict] = {}
        path = self.out / JOURNAL
        if not path.is_file():
            return rows
        with open(path, encoding="utf-8") as handle:
            for line in handle:
                try:
                    row = json.loads(line)
                except json.JSONDecodeError:  # a line cut short when the driver was killed
                    continue
                if isinstance(row, dict) and "cell_id" in row:
                    rows[row["cell_id"]] = row
        return rows

    def start(self, kept: dict[str, dict]) -> None:
        """Begin writing with the rows ``kept`` from before: the journal is rewritten with only them,
        and every folder under ``cells/`` without a kept row is removed."""
        self.rows = dict(kept)
        self._rewrite(self.out / JOURNAL, "".join(json.dumps(r) + "\n" for r in self.rows.values()))
        cells = self.out / CELLS
        cells.mkdir(exist_ok=True)
        for entry in cells.iterdir():  # cells to rerun, cells the spec no longer has, interrupted writes
            if entry.name not in self.rows:
                if entry.is_dir():
                    shutil.rmtree(entry, ignore_errors=True)
                else:
                    entry.unlink(missing_ok=True)
        self._journal = open(self.out / JOURNAL, "a", encoding="utf-8")

    # ------------------------------------------------------------------ writing
    def add(self, row: dict, files: dict[str, bytes]) -> None:
        """Record one finished cell: its folder, then its journal line; the tables now and then."""
        cell_id = row["cell_id"]
        cells = self.out / CELLS
        tmp = cells / f".{cell_id}.tmp-{uuid.uuid4().hex[:8]}"
        tmp.mkdir()
        for name, blob in files.items():
            target = tmp / name
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_bytes(blob)
        final = cells / cell_id
        if final.exists():
            old = cells / f".{cell_id}.old-{uuid.uuid4().hex[:8]}"
            os.replace(final, old)
            shutil.rmtree(old, ignore_errors=True)
        os.replace(tmp, final)
        self._journal.write(json.dumps(row) + "\n")
        self._journal.flush()
        os.fsync(self._journal.fileno())
        self.rows[cell_id] = row
        if time.monotonic() - self._tables_at >= self.table_interval_s:
            self.write_tables()

    def write_tables(self) -> None:
        """Rewrite ``results.parquet`` and ``results.csv`` from the rows (each atomically)."""
        rows = list(self.rows.values())
        columns = order_columns(c for r in rows for c in r) or list(KEY_COLUMNS)
        write_parquet(self.out / PARQUET, rows, columns)
        buffer = io.StringIO()
        writer = csv.DictWriter(buffer, fieldnames=columns, extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            writer.writerow({k: "" if row.get(k) is None else row.get(k) for k in columns})
        self._rewrite(self.out / CSV, buffer.getvalue())
        self._tables_at = time.monotonic()

    def close(self) -> None:
        if self._journal is not None:
            self._journal.close()
            self._journal = None
        if self._lock is not None:
            self._lock.close()  # releases the flock
            self._lock = None

    @staticmethod
    def _rewrite(path: Path, text: str) -> None:
        part = path.with_name(f".{path.name}.partial")
        with open(part, "w", encoding="utf-8") as handle:
            handle.write(text)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(part, path)


def write_parquet(path: Path, rows: list[dict], columns: list[str]) -> None:
    """``rows`` as a Parquet table at ``path`` (through a temporary file); a column whose values do not
    share a type is stored as text."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    arrays = []
    for name in columns:
        values = [r.get(name) for r in rows]
        try:
            arrays.append(pa.array(values))
        except (pa.ArrowInvalid, pa.ArrowTypeError):
            arrays.append(pa.array([None if v is None else str(v) for v in values], pa.string()))
    table = pa.Table.from_arrays(arrays, names=columns)
    part = path.with_name(f".{path.name}.partial")
    pq.write_table(table, part)
    os.replace(part, path)


def read_table(out: Path) -> list[dict]:
    """The rows of ``DIR/results.parquet`` (for tests and scripts)."""
    import pyarrow.parquet as pq

    return pq.read_table(Path(out) / PARQUET).to_pylist()

"""Run a sweep: spec -> cells to run (after ``--resume``) -> engine -> rows, tables and summary.

The Python API behind ``motok-robot sweep``::

    from motok_robot.sweep.driver import run_sweep

    outcome = run_sweep("examples/sweep_small.toml", "sweep_out/", workers=2)
    outcome.counts, outcome.paths["parquet"]

Everything goes into ``out``: ``cells/<cell_id>/`` (the files of each cell: ``robot.npz``,
``report.json``, ...; ``FAILED.txt`` for a cell that raised), ``rows.jsonl``,
``results.parquet``, ``results.csv``, ``summary.md`` with its heatmaps, and ``spec.toml`` (a
copy of the spec).  See docs/sweep.md.
"""

from __future__ import annotations

import hashlib
import time
import uuid
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

from motok_robot.errors import InputError
from motok_robot.sweep import results as R

#: a hint printed when Ray or pyarrow is missing
INSTALL_HINT = 'pip install -e ".[sweep]"  (Ray and pyarrow)'


@dataclass
class SweepOutcome:
    """What one call of :func:`run_sweep` did.

    ``counts``: cells by status over the whole table (``passed``, ``failed``, ``error``,
    ``timeout``); ``ran`` / ``skipped``: cells run now / kept from before (``--resume``);
    ``wall_s``: seconds of this call; ``cell_s``: the cells' own seconds summed (as the workers
    measured them); ``roundtrip_s``: hand-over to result back in the driver, summed;
    ``write_s``: the driver's seconds writing rows, folders and tables; ``startup_s``: starting
    the engine (Ray and its workers); ``paths``: the files written.
    """

    total: int
    ran: int = 0
    skipped: int = 0
    counts: dict[str, int] = field(default_factory=dict)
    wall_s: float = 0.0
    startup_s: float = 0.0
    cell_s: float = 0.0
    roundtrip_s: float = 0.0
    write_s: float = 0.0
    workers: int = 1
    paths: dict[str, Path] = field(default_factory=dict)

    @property
    def all_passed(self) -> bool:
        return self.counts.get("passed", 0) == self.total

    def line(self) -> str:
        c = self.counts
        return (f"{c.get('passed', 0)}/{self.total} cells passed validation, {c.get('failed', 0)} failed, "
                f"{c.get('error', 0)} errors, {c.get('timeout', 0)} over the time budget "
                f"({self.ran} run now on {self.workers} worker{'s' * (self.workers != 1)}, {self.skipped} from before; "
                f"{self.wall_s:.1f} s)")


def require(module: str) -> None:
    """InputError with the install hint when ``module`` (ray, pyarrow) cannot be imported."""
    try:
        __import__(module)
    except ImportError:
        raise InputError(f"motok-robot sweep needs {module}, which is not installed: {INSTALL_HINT}") from None


def task_of(cell, spec, motion_digest: str | None) -> dict:
    """The plain-data task a worker runs for ``cell`` (see :meth:`CellRunner.run_cell`)."""
    from motok_robot.sweep.inputs import motion_files

    return {"cell_id": cell.cell_id, "prompt": cell.prompt, "seed": cell.seed, "robot": cell.robot,
            "argv": list(spec.variants[cell.variant].argv), "plots": spec.plots, "budget_s": spec.time_budget_s,
            "motion_names": [p.name for p in motion_files(cell.motion)] if cell.motion is not None else None,
            "motion_sha": motion_digest}


def prepare_out(out: Path, resume: bool) -> Path:
    """``out`` as an absolute path when a sweep may write there (new, empty, or a sweep with ``--resume``)."""
    out = Path(out).expanduser().absolute()
    if out.exists() and not out.is_dir():
        raise InputError(f"output folder {out} is an existing file")
    if out.is_dir() and any(p.name != R.LOCK for p in out.iterdir()):
        if not (out / R.JOURNAL).is_file():
            raise InputError(f"output folder {out} is not empty and holds no sweep; choose a new folder")
        if not resume:
            raise InputError(f"output folder {out} holds a sweep already; pass --resume to finish it, or choose a "
                             "new folder")
    return out


def run_sweep(spec_path, out, workers: int | None = None, address: str | None = None, resume: bool = False,
              rerun_errors: bool = False, progress: bool | None = True, engine=None) -> SweepOutcome:
    """Run every cell of the spec at ``spec_path`` into ``out``; see the module docstring.

    ``workers``: 1 runs in this process without Ray; more (or None: every CPU of the Ray cluster)
    runs on that many Ray actors, on a local Ray instance or, with ``address`` (``auto`` or
    ``HOST:PORT``), on a running cluster.  ``resume``: keep the rows of cells whose inputs hash
    the same (``rerun_errors``: except errors and time-outs).  ``engine``: an engine object to
    use instead (tests).  Ctrl-C stops the sweep with the tables holding every finished cell.
    """
    from motok_robot.sweep.engine import Job, RayEngine, SerialEngine
    from motok_robot.sweep.inputs import InputHasher, input_hashes, motion_files
    from motok_robot.sweep.progress import SweepProgress
    from motok_robot.sweep.spec import load_spec

    if workers is not None and workers < 1:
        raise InputError(f"--workers must be at least 1, got {workers}")
    require("pyarrow")
    in_process = engine is None and workers == 1 and not address
    if engine is None and not in_process:
        require("ray")
    spec = load_spec(spec_path)
    out = prepare_out(out, resume)
    started = time.monotonic()
    store = R.ResultStore(out)
    store.lock()
    outcome = SweepOutcome(total=len(spec.cells))
    try:
        hashes = input_hashes(spec)
        previous = store.read_journal() if resume else {}
        kept = {cid: row for cid, row in previous.items()
                if cid in hashes and row.get("inputs_hash") == hashes[cid]
                and not (rerun_errors and row.get("status") in ("error", "timeout"))}
        store.start(kept)
        (out / "spec.toml").write_bytes(spec.path.read_bytes())
        hasher = InputHasher()
        digests = {}
        for cell in spec.cells:
            if cell.motion is not None and cell.motion not in digests:
                parts = "".join(hasher.file(p) for p in motion_files(cell.motion))
                digests[cell.motion] = hashlib.sha256(parts.encode("ascii")).hexdigest()
        jobs = [Job(cell, task_of(cell, spec, digests.get(cell.motion))) for cell in spec.cells if cell.cell_id not in kept]
        outcome.skipped = len(spec.cells) - len(jobs)
        bar = SweepProgress(len(spec.cells), outcome.skipped, enabled=progress)
        run_id = uuid.uuid4().hex[:12]
        t = time.monotonic()
        if engine is None:
            engine = SerialEngine() if in_process else RayEngine(workers, address)
        outcome.startup_s = time.monotonic() - t
        outcome.workers = engine.workers

        def blobs(job) -> tuple:
            if job.cell.motion is None:
                return ()
            files = motion_files(job.cell.motion)
            if hasattr(engine, "put"):
                return tuple(engine.put(f"{digests[job.cell.motion]}:{p.name}", p.read_bytes) for p in files)
            return tuple(p.read_bytes() for p in files)

        def done(job, result) -> None:
            received = time.monotonic()
            row = {"cell_id": job.cell.cell_id, "input": job.cell.input_label, "prompt": job.cell.prompt,
                   "motion": job.cell.motion_label, "seed": job.cell.seed, "robot": job.cell.robot,
                   "variant": job.cell.variant, "passed": False, "failed_checks": "", "n_failed_checks": None,
                   **result["row"], "roundtrip_s": received - job.submitted, "attempts": job.attempts,
                   "engine_notes": "; ".join(job.notes), "inputs_hash": hashes[job.cell.cell_id], "run_id": run_id,
                   "finished_at": datetime.now(timezone.utc).isoformat(timespec="milliseconds"),
                   "folder": f"{R.CELLS}/{job.cell.cell_id}"}
            store.add(row, result["files"])
            outcome.ran += 1
            outcome.cell_s += float(row.get("cell_s") or 0.0)
            outcome.roundtrip_s += row["roundtrip_s"]
            outcome.write_s += time.monotonic() - received
            bar.finished(row["status"])

        def running(count: int) -> None:
            bar.running = count
            bar.show()

        try:
            engine.run(jobs, blobs, done, running)
        finally:
            t = time.monotonic()
            store.write_tables()
            outcome.write_s += time.monotonic() - t
            bar.close()
            engine.close()
        rows = list(store.rows.values())
        outcome.paths = {"parquet": out / R.PARQUET, "csv": out / R.CSV, "journal": out / R.JOURNAL}
        from motok_robot.sweep.summary import write_summary

        outcome.paths.update(write_summary(out, rows, spec))
    finally:
        store.close()
    for row in store.rows.values():
        outcome.counts[row["status"]] = outcome.counts.get(row["status"], 0) + 1
    outcome.wall_s = time.monotonic() - started
    return outcome

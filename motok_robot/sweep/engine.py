"""Where the cells run: in this process (``--workers 1``), or on Ray actors (local or a cluster).

Both engines take :class:`Job` s and call ``done(job, result)`` with the result of
:meth:`motok_robot.sweep.worker.CellRunner.run_cell` for each; the Ray engine also makes up the
result of a cell whose worker it had to stop (time budget) or that lost its worker twice.

Ray: one actor per worker (``num_cpus=1``), each holding a :class:`CellRunner` and given one cell
at a time, so a cell's deadline counts from when it was handed over and a killed worker loses one
cell.  That cell is given to a fresh actor once more; when that worker dies too, the cell is
recorded as an error.  A cell over its budget is stopped inside the worker (SIGALRM, the worker
goes on); a worker that does not answer ``grace`` seconds later is killed and replaced.
"""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass, field

#: how often a dead worker's cell is tried again
WORKER_RETRIES = 1


@dataclass
class Job:
    """A cell to run: the :class:`~motok_robot.sweep.spec.Cell`, the task its worker gets, the attempts so far."""

    cell: object
    task: dict
    attempts: int = 0
    submitted: float = 0.0
    notes: list[str] = field(default_factory=list)


def failure(job: Job, status: str, error: str, worker: str = "") -> dict:
    """A result for a cell the engine gave up on (``status`` timeout or error)."""
    return {"row": {"status": status, "error": error, "worker": worker, "cell_s": time.monotonic() - job.submitted},
            "files": {}}


class SerialEngine:
    """Every cell in this process, one after the other (no Ray): for debugging and ``--workers 1``."""

    workers = 1

    def __init__(self) -> None:
        from motok_robot.sweep.worker import CellRunner, worker_env

        self.runner = CellRunner(worker_env())

    def run(self, jobs, blobs, done, running) -> None:
        """Run ``jobs``; ``blobs(job)`` gives the motion bytes, ``running(n)`` reports cells in flight."""
        for job in jobs:
            job.attempts += 1
            job.submitted = time.monotonic()
            running(1)
            done(job, self.runner.run_cell(job.task, *blobs(job)))
        running(0)

    def close(self) -> None:
        self.runner.close()


class _Slot:
    """One Ray actor and the cell it is running."""

    def __init__(self, actor, index: int) -> None:
        self.actor = actor
        self.index = index
        self.name_ref = actor.name.remote()
        self.job: Job | None = None
        self.ref = None

    def worker_name(self, ray) -> str:
        try:
            return ray.get(self.name_ref, timeout=0.1)
        except Exception:  # noqa: BLE001 - not started, or dead: no name to give
            return f"actor-{self.index}"


class RayEngine:
    """Cells on ``workers`` Ray actors: a local Ray instance, or the cluster at ``address``."""

    def __init__(self, workers: int | None, address: str | None = None, grace_s: float = 60.0) -> None:
        import ray

        from motok_robot.sweep.worker import CellRunner, worker_env

        self.ray = ray
        self._started_ray = False
        if not ray.is_initialized():
            if address:
                try:
                    ray.init(address=address, log_to_driver=False)
                except (ConnectionError, RuntimeError, ValueError) as exc:
                    from motok_robot.errors import InputError

                    raise InputError(f"cannot attach to the Ray cluster at --address {address}: {_first_line(exc)} "
                                     "(is `ray start --head` running there? with an explicit HOST:PORT and token "
                                     "authentication, set RAY_AUTH_MODE=token and the cluster's token: docs/sweep.md)"
                                     ) from None
            else:
                ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False)
            self._started_ray = True
        if not workers:
            workers = max(1, int(ray.cluster_resources().get("CPU", 1)))
        self.workers = workers
        self.grace_s = grace_s
        self._env = worker_env()
        self._remote = ray.remote(num_cpus=1, max_restarts=0, max_task_retries=0)(CellRunner)
        self._spawned = 0
        self.slots = [self._new_slot() for _ in range(workers)]
        self._refs: dict[str, object] = {}

    def _new_slot(self) -> _Slot:
        self._spawned += 1
        return _Slot(self._remote.remote(self._env), self._spawned)

    def put(self, key: str, read):
        """The bytes ``read()`` gives, put in the object store once per ``key`` (a motion file the
        cells of it share)."""
        if key not in self._refs:
            self._refs[key] = self.ray.put(read())
        return self._refs[key]

    def run(self, jobs, blobs, done, running) -> None:
        ray = self.ray
        queue = deque(jobs)
        busy: dict = {}

        def hand_out() -> None:
            for i, slot in enumerate(self.slots):
                if slot.job is None and queue:
                    job = queue.popleft()
                    job.attempts += 1
                    job.submitted = time.monotonic()
                    slot.job, slot.ref = job, slot.actor.run_cell.remote(job.task, *blobs(job))
                    busy[slot.ref] = i

        while queue or busy:
            hand_out()
            running(len(busy))
            ready, _ = ray.wait(list(busy), num_returns=1, timeout=0.5)
            for ref in ready:
                i = busy.pop(ref)
                slot = self.slots[i]
                job, slot.job, slot.ref = slot.job, None, None
                try:
                    result = ray.get(ref)
                except ray.exceptions.RayActorError as exc:  # the worker died with this cell
                    self.slots[i] = self._new_slot()
                    if job.attempts <= WORKER_RETRIES:
                        job.notes.append(f"worker {slot.worker_name(ray)} died; retried")
                        queue.appendleft(job)
                        continue
                    result = failure(job, "error", f"the worker died running this cell {job.attempts} times "
                                                   f"(last: {_first_line(exc)})", slot.worker_name(ray))
                except ray.exceptions.RayError as exc:
                    result = failure(job, "error", f"Ray: {_first_line(exc)}", slot.worker_name(ray))
                hand_out()  # the worker's next cell first: writing this one's row overlaps with it
                done(job, result)
            now = time.monotonic()
            for i, slot in enumerate(self.slots):
                job = slot.job
                if job is not None and now - job.submitted > job.task["budget_s"] + self.grace_s:
                    name = slot.worker_name(ray)
                    ray.kill(slot.actor, no_restart=True)
                    busy.pop(slot.ref, None)
                    self.slots[i] = self._new_slot()
                    done(job, failure(job, "timeout", f"cancelled: over its time budget of {job.task['budget_s']:g} s "
                                                      f"(the worker did not stop it; killed after {self.grace_s:g} s more)",
                                      name))
        running(0)

    def close(self) -> None:
        """Let the workers remove their scratch folders (a few seconds at most), then stop them."""
        ray = self.ray
        try:
            ray.wait([slot.actor.close.remote() for slot in self.slots], num_returns=len(self.slots), timeout=5)
        except Exception:  # noqa: BLE001 - a dead worker has nothing to clean
            pass
        for slot in self.slots:
            try:
                self.ray.kill(slot.actor, no_restart=True)
            except Exception:  # noqa: BLE001 - already gone
                pass
        if self._started_ray:
            self.ray.shutdown()


def _first_line(exc: BaseException) -> str:
    lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
    return lines[0][:300] if lines else type(exc).__name__

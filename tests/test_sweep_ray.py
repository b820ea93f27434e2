"""`motok-robot sweep` on a local Ray with 2 CPUs: the same reports as in process, a killed worker.

Starting Ray takes 5-20 s on the 2-core machine, so these tests are marked slow.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

pytest.importorskip("pyarrow")
ray = pytest.importorskip("ray")

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

from bench_sweep import start_worker_killer  # noqa: E402
from test_sweep import spec_file, write_stand  # noqa: E402

from motok_robot.sweep import results as R  # noqa: E402
from motok_robot.sweep.driver import run_sweep  # noqa: E402

pytestmark = pytest.mark.slow

SPEC = """
motions = ["stand.npz"]
seeds = [0, 1]
robots = ["humanoid25"]
[variants.plain]
[variants.feasible]
feasible = true
"""


@pytest.fixture(scope="module")
def local_ray():
    os.environ.setdefault("RAY_AUTH_MODE", "disabled")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield
    ray.shutdown()


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    root = tmp_path_factory.mktemp("sweep_ray")
    write_stand(root / "stand.npz")
    return root


def test_serial_and_ray_give_the_same_report_for_a_cell(folder, tmp_path, local_ray):
    spec = spec_file(folder, SPEC)
    serial = run_sweep(spec, tmp_path / "serial", workers=1, progress=False)
    on_ray = run_sweep(spec, tmp_path / "ray", workers=2, progress=False)
    assert serial.ran == on_ray.ran == 4 and on_ray.workers == 2
    a = {r["cell_id"]: r for r in R.read_table(tmp_path / "serial")}
    b = {r["cell_id"]: r for r in R.read_table(tmp_path / "ray")}
    assert a.keys() == b.keys()
    for cell_id in a:
        assert a[cell_id]["report_sha"] == b[cell_id]["report_sha"], cell_id
        assert a[cell_id]["qpos_sha"] == b[cell_id]["qpos_sha"], cell_id
    workers = {r["worker"] for r in b.values()}
    assert len(workers) == 2 and not any(w.endswith(f":{os.getpid()}") for w in workers)


def test_a_killed_worker_cell_is_retried_once_and_every_cell_gets_a_row(folder, tmp_path, local_ray):
    spec = spec_file(folder, SPEC.replace("seeds = [0, 1]", "seeds = [0, 1, 2, 3]"), "kill.toml")
    out = tmp_path / "kill"
    killer, killed = start_worker_killer(out / R.JOURNAL, after_rows=1, timeout_s=120)
    outcome = run_sweep(spec, out, workers=2, progress=False)
    killer.join(timeout=1)
    assert killed, "no busy worker was found to kill"
    rows = R.read_table(out)
    assert len(rows) == outcome.total == 8
    retried = [r for r in rows if r["attempts"] == 2]
    assert len(retried) == 1 and "died; retried" in retried[0]["engine_notes"]
    assert retried[0]["status"] in ("passed", "failed") and not retried[0]["worker"].endswith(f":{killed[0]}")
    assert all(r["status"] in ("passed", "failed") for r in rows)

"""Long retargeting runs show progress off a terminal; a window's solve is bounded in CPU time."""

from __future__ import annotations

import pytest

pytest.importorskip("casadi")

from retarget import solve as solve_mod  # noqa: E402
from retarget.config import RetargetConfig, SolverConfig  # noqa: E402
from retarget.solve import Retargeter  # noqa: E402
from tests.test_retarget import synthetic_walk, toy_robot  # noqa: E402


def test_progress_reaches_a_log_when_the_clip_is_long(capsys, monkeypatch):
    monkeypatch.setattr(solve_mod, "LOG_PROGRESS_WINDOWS", 0)  # every clip counts as long here
    cfg = RetargetConfig(window=4, overlap=0, presolve_frames=0)
    Retargeter(toy_robot(), cfg).run(synthetic_walk(T=8), 20.0)  # progress=None: decide by the output
    err = capsys.readouterr().err  # pytest's capture is not a terminal
    assert "window" in err and "retarget" in err


def test_short_clips_stay_quiet_off_a_terminal(capsys):
    cfg = RetargetConfig(window=4, overlap=0, presolve_frames=0)
    Retargeter(toy_robot(), cfg).run(synthetic_walk(T=8), 20.0)
    assert "window" not in capsys.readouterr().err


def test_a_window_solve_stops_at_its_cpu_time_bound():
    assert SolverConfig().max_cpu_time == 60.0  # windows take well under a second
    cfg = RetargetConfig(window=4, overlap=0, presolve_frames=0, solver=SolverConfig(max_cpu_time=1e-9))
    result = Retargeter(toy_robot(), cfg).run(synthetic_walk(T=8), 20.0, progress=False)
    assert not result.success
    assert {w.status for w in result.windows} == {"Maximum_CpuTime_Exceeded"}

"""The on-disk cache of compiled window problems (retarget/cache.py) and the stage-wise problem.

The toy robot of tests/test_retarget.py with 3-frame windows keeps the C code small; the one
test that runs the compiler is marked slow when it needs more than a few seconds."""

from __future__ import annotations

import json
import warnings
from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip("mujoco")
ca = pytest.importorskip("casadi")

from retarget import cache as cache_mod  # noqa: E402
from retarget.cache import ProblemCache, default_dir  # noqa: E402
from retarget.config import CostWeights, RetargetConfig  # noqa: E402
from retarget.problem import RobotKinematics, WindowProblem  # noqa: E402
from retarget.solve import Retargeter  # noqa: E402
from tests.test_retarget import synthetic_walk, toy_robot  # noqa: E402

W = 3


@pytest.fixture(scope="module")
def kin():
    return RobotKinematics.build(toy_robot())


@pytest.fixture(autouse=True)
def _fresh_warnings():
    cache_mod._warned.clear()
    yield
    cache_mod._warned.clear()


def _point(prob: WindowProblem, seed: int = 0):
    rng = np.random.default_rng(seed)
    x = np.tile(prob.kin.nominal_x, prob.W) + 0.1 * rng.standard_normal(prob.W * prob.kin.nx)
    p = 0.3 * rng.standard_normal(prob.functions["nlp"].size1_in(1))
    p[-3:] = (1.0, 20.0, 0.0)
    return x, p


def _whole_window_reference(kin, W, weights):
    """The objective and constraints of the window written without stages (one SX graph, as the
    problem was built before the stage split), for the same x and p layout."""
    from retarget.problem import StageFunctions

    st = StageFunctions(kin, weights, "exact", True, (), 0.0, weights.zmp > 0 and W >= 3)
    x = ca.SX.sym("x", kin.nx * W)
    K = len(kin.robot.keypoints)
    p = ca.SX.sym("p", 3 * K * W + W + 4 * W + 2 * W + 2 * kin.nx + 3)
    X = ca.reshape(x, kin.nx, W)
    o = 0
    tgt = ca.reshape(p[o : o + 3 * K * W], 3 * K, W); o += 3 * K * W
    hd = p[o : o + W]; o += W
    ft = ca.reshape(p[o : o + 4 * W], 4, W); o += 4 * W
    ct = ca.reshape(p[o : o + 2 * W], 2, W); o += 2 * W
    hist = ca.reshape(p[o : o + 2 * kin.nx], kin.nx, 2); o += 2 * kin.nx
    has, fps, ground = p[o], p[o + 1], p[o + 2]
    cols = [hist[:, 0], hist[:, 1]] + [X[:, t] for t in range(W)]
    f, g = 0, []
    for t in range(W):
        z = ca.vertcat(*[cols[t + 2 + o] if t + o < W else X[:, W - 1] for o in st.offsets])
        const = ca.vertcat(has if t == 0 else 1, has if t <= 1 else 1, has if t == 0 else 1,
                           0 if t == W - 1 or len(st.offsets) < 4 else 1, fps, ground)
        ft_, gt = st.fg(z, ca.vertcat(tgt[:, t], hd[t], ft[:, t], ct[:, t], const))
        f, g = f + ft_, g + [gt]
    g = ca.vertcat(*g)
    lf, lg = ca.SX.sym("lf"), ca.SX.sym("lg", g.shape[0])
    H = ca.triu(ca.hessian(lf * f + ca.dot(lg, g), x)[0])
    return ca.Function("ref", [x, p, lf, lg], [f, g, ca.gradient(f, x), ca.jacobian(g, x), H])


@pytest.mark.parametrize("zmp", [0.0, 50.0])
def test_stage_assembly_equals_the_whole_window_derivatives(kin, zmp):
    weights = replace(CostWeights(), zmp=zmp, com=zmp)
    prob = WindowProblem(kin, 3, weights)
    ref = _whole_window_reference(kin, 3, weights)
    x, p = _point(prob)
    lg = np.random.default_rng(1).standard_normal(prob.ng)
    f, g, grad, jac, hess = ref(x, p, 0.7, lg)
    fn = prob.functions
    assert float(fn["nlp"](x, p)[0]) == pytest.approx(float(f), rel=1e-12)
    np.testing.assert_allclose(np.array(fn["nlp"](x, p)[1]), np.array(g), atol=1e-12)
    np.testing.assert_allclose(np.array(fn["grad_f"](x, p)[1]), np.array(grad), rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(ca.DM(fn["jac_g"](x, p)[1]).full(), ca.DM(jac).full(), atol=1e-10)
    np.testing.assert_allclose(ca.DM(fn["hess_lag"](x, p, 0.7, lg)).full(), ca.DM(hess).full(), rtol=1e-9, atol=1e-7)


def test_cache_folder_from_environment(monkeypatch, tmp_path):
    monkeypatch.setenv("MOTOK_ROBOT_CACHE", str(tmp_path / "c"))
    assert default_dir() == tmp_path / "c"
    for off in ("off", "0", "none", ""):
        monkeypatch.setenv("MOTOK_ROBOT_CACHE", off)
        assert default_dir() is None
    assert Retargeter(toy_robot(), RetargetConfig(window=W, overlap=0, presolve_frames=0)).cache is None
    monkeypatch.delenv("MOTOK_ROBOT_CACHE")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert default_dir() == tmp_path / "xdg" / "motok-robot"


def test_key_depends_on_robot_settings_and_window(kin, tmp_path):
    c = ProblemCache(tmp_path)
    base = c.key(kin, W, CostWeights(), RetargetConfig().solver, True, (), 0.0)
    assert base == c.key(kin, W, CostWeights(), RetargetConfig().solver, True, (), 0.0)
    assert base != c.key(kin, W + 1, CostWeights(), RetargetConfig().solver, True, (), 0.0)
    assert base != c.key(kin, W, replace(CostWeights(), heading=2.0), RetargetConfig().solver, True, (), 0.0)
    assert base != c.key(kin, W, CostWeights(), replace(RetargetConfig().solver, tol=1e-5), True, (), 0.0)
    other = toy_robot()
    other.joint_range[0, 1] -= 0.01
    assert base != ProblemCache(tmp_path).key(RobotKinematics.build(other), W, CostWeights(), RetargetConfig().solver, True, (), 0.0)


def test_no_compiler_falls_back_to_memory_with_one_warning(kin, tmp_path, monkeypatch):
    monkeypatch.setenv("CC", str(tmp_path / "no-such-cc"))
    c = ProblemCache(tmp_path / "cache")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        a = WindowProblem(kin, W, cache=c)
        b = WindowProblem(kin, W + 1, cache=c)
    msgs = [str(w.message) for w in caught if "motok-robot cache" in str(w.message)]
    assert len(msgs) == 1 and "no C compiler" in msgs[0]
    assert a.cache_status == b.cache_status == "no compiler"
    assert c.flush() == [] and not list((tmp_path / "cache").glob("*.so"))


def _fake_entry(c: ProblemCache, entry: str, so_bytes: bytes, **meta_changes):
    c.folder.mkdir(parents=True, exist_ok=True)
    so, meta = c.paths(entry)
    so.write_bytes(so_bytes)
    m = {"format": cache_mod.FORMAT, "key": entry, "casadi": ca.__version__, "so_sha256": cache_mod._sha256(so_bytes),
         "prefix": "x_", "nx": 1, "nx_w": 1, "np": 1, "ng": 1, "window": 1, "nominal_x": [0.0], "names": [],
         "n_clearance": 0, "reference": {}}
    m.update(meta_changes)
    meta.write_text(json.dumps(m))


@pytest.mark.parametrize("case", ["garbage library", "checksum", "foreign key", "other casadi", "bad json"])
def test_corrupted_or_foreign_entries_are_rebuilt_never_trusted(kin, tmp_path, case):
    c = ProblemCache(tmp_path, background=False)
    key = c.key(kin, W, CostWeights(), RetargetConfig().solver, True, (), 0.0)
    if case == "garbage library":
        _fake_entry(c, key, b"\x7fELF not really a library")
    elif case == "checksum":
        _fake_entry(c, key, b"abc", so_sha256="0" * 64)
    elif case == "foreign key":
        _fake_entry(c, key, b"abc", key="f" * 64)
    elif case == "other casadi":
        _fake_entry(c, key, b"abc", casadi="0.0.1")
    else:
        c.folder.mkdir(parents=True, exist_ok=True)
        c.paths(key)[0].write_bytes(b"abc")
        c.paths(key)[1].write_text("{ truncated")
    with pytest.warns(RuntimeWarning, match="unusable"):
        prob = WindowProblem(kin, W, cache=c)
    assert prob.cache_status in ("queued", "no compiler")
    assert not c.paths(key)[1].exists()  # the bad entry is gone
    assert any(e.startswith("rebuilt") for e in c.events)
    c._pending.clear()


@pytest.mark.slow
def test_compiled_entry_round_trip_and_tampered_reference(tmp_path):
    """Compile once, load in a fresh retargeter (same result, no symbolic build), then a tampered
    entry (its functions no longer match the reference values) is rebuilt."""
    if cache_mod.compiler() is None:
        pytest.skip("no C compiler")
    cfg = RetargetConfig(window=W, overlap=0, presolve_frames=0)
    joints = synthetic_walk(T=5)
    first = Retargeter(toy_robot(), cfg, cache=ProblemCache(tmp_path, background=False))
    r1 = first.run(joints, 20.0, progress=False)
    assert all(p.cache_status == "queued" for p in first._problems.values())
    assert sum(e.startswith("compiled") for e in first.cache.events) == len(first._problems)
    second = Retargeter(toy_robot(), cfg, cache=ProblemCache(tmp_path, background=False))
    r2 = second.run(joints, 20.0, progress=False)
    assert all(p.cache_status == "hit" for p in second._problems.values())
    assert r2.success
    np.testing.assert_allclose(r2.x, r1.x, atol=1e-5)
    for meta_path in tmp_path.glob("*.json"):  # every entry: which ones prepare() loads depends on the clip
        meta = json.loads(meta_path.read_text())
        meta["reference"]["f"] *= 1.5
        meta_path.write_text(json.dumps(meta))
    third = Retargeter(toy_robot(), cfg, cache=ProblemCache(tmp_path, background=False))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        third.prepare(5)
    assert any("reproduce" in e for e in third.cache.events), third.cache.events
    assert any("reproduce" in str(w.message) for w in caught)
    assert any(p.cache_status == "queued" for p in third._problems.values())
    third.cache._pending.clear()


def test_eviction_keeps_the_most_recently_used(tmp_path):
    c = ProblemCache(tmp_path)
    import os

    for i, key in enumerate(("a" * 64, "b" * 64, "c" * 64)):
        _fake_entry(c, key, b"x" * 1000)
        os.utime(c.paths(key)[1], (1000 + i, 1000 + i))
    gone = c.evict(max_bytes=3000)  # three entries of about 1.3 kB
    assert gone == ["a" * 64] and c.paths("c" * 64)[1].exists()

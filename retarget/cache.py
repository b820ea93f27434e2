# Size (456 lines): one cache life cycle (key, build, verify, load, fall back) kept in one place.
"""On-disk cache of compiled window problems (C code from CasADi, built with the system compiler).

A window problem (:class:`retarget.problem.WindowProblem`) is four NLP functions (objective and
constraints, gradient, constraint Jacobian, Lagrangian Hessian). The first process that needs
one builds it symbolically (about half a second) and solves with CasADi's virtual machine; it
also writes the functions as C (``casadi.CodeGenerator``) and starts the system C compiler in
the background (a detached, low-priority process), so the clip is not held up. Every later
process loads the shared library (``casadi.external``) and starts solving at once, with
compiled derivatives (faster than the virtual machine).

**Where.** ``$MOTOK_ROBOT_CACHE`` or ``$XDG_CACHE_HOME/motok-robot`` (default
``~/.cache/motok-robot``); ``MOTOK_ROBOT_CACHE=off`` (or ``0``, ``none``) turns the cache off,
as does ``Retargeter(..., cache=False)`` / ``motok-robot retarget --no-cache``. ``$CC`` names
the compiler (default ``gcc``).

**Key.** The sha256 of: the robot (its compiled MuJoCo model as MJB bytes, which hold the
MJCF's geometry, and the description: joints, ranges, velocity limits, nominal pose,
keypoints, soles), the problem settings (weights, solver settings, window length, velocity
rows, self-collision geometry and margin), the CasADi and MuJoCo versions and the source of
the modules that write the expressions (``problem.py``, ``kinematics.py``, ``collision.py``,
``cache.py``): a code change invalidates every entry.

**Entries** are ``<key>.so`` and ``<key>.json`` (the key's inputs, the row names, the
library's sha256 and reference values of every function at a fixed test point). Both are
written to temporary names and renamed into place (atomic), the JSON last. An entry is used
only if the JSON parses, names this key and CasADi version, the library's sha256 matches, the
library loads with the expected function shapes, and its four functions reproduce the
reference values at the test point; otherwise it is deleted with one warning line and the
problem is built again (and recompiled). Without a compiler the problem is built in memory
every time, with one warning line per process.
"""

from __future__ import annotations

import atexit
import hashlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

FORMAT = 1
CFLAGS = ("-O1", "-fPIC", "-shared")  # -O1: 3-4x faster than the VM; -O2/-O3 take much longer to build
LOCK_STALE_SECONDS = 1800.0
COMPILE_LOCK = "compile.lock"
MAX_SOURCE_BYTES = 4_000_000  # larger C files (many self-collision rows) are not compiled: gcc needs GBs
MAX_BYTES = 1 << 30  # the cache keeps at most this much; the least recently used entries go first
_SOURCES = ("problem.py", "kinematics.py", "collision.py", "cache.py")
_warned: set = set()


def _warn_once(tag: str, message: str) -> None:
    if tag not in _warned:
        _warned.add(tag)
        warnings.warn(message, RuntimeWarning, stacklevel=3)


def default_dir() -> Path | None:
    """The cache folder from the environment (None: turned off)."""
    env = os.environ.get("MOTOK_ROBOT_CACHE")
    if env is not None:
        if env.strip().lower() in ("", "0", "off", "none", "false", "no"):
            return None
        return Path(env).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "motok-robot"


def compiler() -> str | None:
    """Path of the C compiler (``$CC`` or gcc), None when there is none."""
    cc = os.environ.get("CC", "gcc")
    return shutil.which(cc)


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def file_sha256(path: Path) -> str:
    """Hex sha256 of the file's bytes, read 1 MB at a time."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def robot_bytes(robot) -> bytes:
    """Bytes that identify a :class:`retarget.robot_model.RetargetRobot` for the cache key."""
    import mujoco

    buf = np.empty(mujoco.mj_sizeModel(robot.model), dtype=np.uint8)
    mujoco.mj_saveModel(robot.model, None, buf)
    desc = {
        "joints": list(robot.joint_names),
        "qpos_adr": np.asarray(robot.qpos_adr).tolist(),
        "range": np.asarray(robot.joint_range).tolist(),
        "velocity": np.asarray(robot.velocity_limit).tolist(),
        "nominal": np.asarray(robot.nominal_qpos).tolist(),
        "keypoints": [repr(k) for k in robot.keypoints],
        "soles": {k: repr(v) for k, v in sorted(robot.soles.items())},
    }
    return buf.tobytes() + json.dumps(desc, sort_keys=True).encode()


def _pair_repr(pair) -> str:
    sp, so = pair.spheres, pair.solid
    arrays = [sp.centres, sp.radii] + [a for a in (so.ends, so.centre, so.axes, so.half) if a is not None]
    return repr((pair.name, sp.body, so.body, so.kind, so.radius, [np.asarray(a).tolist() for a in arrays]))


def check_point(nx: int, np_: int, ng: int, window: int, nominal_x: np.ndarray) -> tuple:
    """The fixed test point ``(x, p, lam_f, lam_g)`` at which entries are verified."""
    rng = np.random.default_rng(12345)
    x = np.tile(nominal_x, window) + 0.05 * rng.standard_normal(nx * window)
    p = 0.2 * rng.standard_normal(np_)
    p[-3:] = (1.0, 20.0, 0.0)  # has history, fps, ground
    return x, p, 0.7, rng.standard_normal(ng)


def _reference(functions: dict, point: tuple) -> dict:
    """Reference values of the four functions at ``point``: full vectors for f, g and the
    gradient, and three checksums of the Jacobian and Hessian nonzeros."""
    import casadi as ca

    x, p, lf, lg = point
    f, g = functions["nlp"](x, p)
    _, grad = functions["grad_f"](x, p)
    _, jac = functions["jac_g"](x, p)
    hess = functions["hess_lag"](x, p, lf, lg)

    def sums(m):
        v = np.array(ca.DM(m).nonzeros(), dtype=np.float64)
        w = np.cos(np.arange(len(v)))
        return [len(v), float(v.sum()), float(np.abs(v).sum()), float((w * v).sum())]

    return {"f": float(f), "g": np.array(g).ravel().tolist(), "grad": np.array(grad).ravel().tolist(),
            "jac": sums(jac), "hess": sums(hess)}


def _same(ref: dict, new: dict) -> bool:
    def close(a, b):
        a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
        return a.shape == b.shape and bool(np.allclose(a, b, rtol=1e-7, atol=1e-9 * max(1.0, float(np.abs(a).max(initial=0)))))

    return (close(ref["f"], new["f"]) and close(ref["g"], new["g"]) and close(ref["grad"], new["grad"])
            and ref["jac"][0] == new["jac"][0] and ref["hess"][0] == new["hess"][0]
            and close(ref["jac"][1:], new["jac"][1:]) and close(ref["hess"][1:], new["hess"][1:]))


class ProblemCache:
    """Compiled window problems in ``folder`` (see the module docstring).

    ``background=True`` (default) compiles in a detached low-priority process and returns at
    once; ``False`` compiles before :meth:`store` returns (tests, benchmarks)."""

    def __init__(self, folder: str | Path, background: bool = True):
        self.folder = Path(folder).expanduser()
        self.background = background
        self._robot_hash: dict[int, str] = {}
        self.events: list[str] = []  # "hit KEY", "miss KEY", "rebuilt KEY: why", "compiled KEY", ...
        self._pending: dict = {}
        self._atexit = False

    @classmethod
    def from_env(cls, background: bool = True) -> "ProblemCache | None":
        folder = default_dir()
        return None if folder is None else cls(folder, background=background)

    # -- keys ---------------------------------------------------------------------------
    def key(self, kin, window, weights, solver, velocity_constraints, collision_pairs, margin,
            turn_rows: bool = False) -> str:
        import casadi
        import mujoco

        robot = kin.robot
        rid = id(robot)
        if rid not in self._robot_hash:
            self._robot_hash[rid] = _sha256(robot_bytes(robot))
        here = Path(__file__).resolve().parent
        code = _sha256(b"".join((here / name).read_bytes() for name in _SOURCES))
        parts = {
            "format": FORMAT,
            "robot": self._robot_hash[rid],
            "window": int(window),
            "weights": repr(weights),
            "solver": repr(solver),
            "velocity_constraints": bool(velocity_constraints),
            "turn_rows": bool(turn_rows),
            "collision": [_pair_repr(p) for p in collision_pairs],
            "margin": repr(float(margin)),
            "casadi": casadi.__version__,
            "mujoco": mujoco.__version__,
            "code": code,
            "cflags": list(CFLAGS),
        }
        self._last_parts = parts
        return _sha256(json.dumps(parts, sort_keys=True).encode())

    def paths(self, key: str) -> tuple[Path, Path]:
        return self.folder / f"{key}.so", self.folder / f"{key}.json"

    # -- loading --------------------------------------------------------------------------
    def load(self, key: str):
        """``(functions, row names per frame, clearance rows per frame)`` of a valid entry, else None
        (a present but invalid entry is deleted with one warning line)."""
        so, meta_path = self.paths(key)
        if not meta_path.exists():
            self.events.append(f"miss {key[:12]}")
            return None
        try:
            out = self._load_checked(key, so, meta_path)
        except Exception as exc:  # corrupted, truncated, foreign: never trusted
            self._discard(key)
            _warn_once(f"bad {key}", f"motok-robot cache: entry {key[:12]} in {self.folder} is unusable ({exc}); rebuilding it")
            self.events.append(f"rebuilt {key[:12]}: {exc}")
            return None
        self.events.append(f"hit {key[:12]}")
        try:
            os.utime(meta_path)  # least recently used entries are evicted first (MAX_BYTES)
        except OSError:
            pass
        return out

    def _load_checked(self, key: str, so: Path, meta_path: Path):
        import casadi as ca

        meta = json.loads(meta_path.read_text())
        if meta.get("format") != FORMAT or meta.get("key") != key:
            raise ValueError("the entry belongs to another key")
        if meta.get("casadi") != ca.__version__:
            raise ValueError(f"built with CasADi {meta.get('casadi')}, this is {ca.__version__}")
        if not so.exists():
            raise ValueError("the shared library is missing")
        if file_sha256(so) != meta["so_sha256"]:
            raise ValueError("the shared library does not match its checksum")
        prefix = meta["prefix"]
        names = {"nlp": "nlp", "grad_f": "nlp_grad_f", "jac_g": "nlp_jac_g", "hess_lag": "nlp_hess_l"}
        functions = {k: ca.external(prefix + v, str(so)) for k, v in names.items()}
        nx_w, np_ = int(meta["nx_w"]), int(meta["np"])
        nlp = functions["nlp"]
        if nlp.n_in() != 2 or nlp.size1_in(0) != nx_w or nlp.size1_in(1) != np_:
            raise ValueError("the library's functions have other shapes")
        ng = int(meta["ng"])
        point = check_point(int(meta["nx"]), np_, ng, int(meta["window"]), np.asarray(meta["nominal_x"]))
        if not _same(meta["reference"], _reference(functions, point)):
            raise ValueError("the library's functions do not reproduce the reference values")
        return functions, list(meta["names"]), int(meta["n_clearance"])

    def _discard(self, key: str) -> None:
        for p in self.paths(key):
            try:
                p.unlink()
            except OSError:
                pass

    # -- storing --------------------------------------------------------------------------
    def store(self, key: str, functions: dict, names: list[str], n_clearance: int, nominal_x: np.ndarray) -> str:
        """Queue ``functions`` for the entry ``key``: their C code is written and compiled at
        :meth:`flush` (after the clip is solved, so a cold start is not held up; also at exit).
        Returns ``"queued"``, or ``"no compiler"`` (one warning line per process)."""
        if compiler() is None:
            _warn_once("no compiler", f"motok-robot cache: no C compiler ({os.environ.get('CC', 'gcc')}) found; "
                                      "window problems are built in memory in every process (set CC, or MOTOK_ROBOT_CACHE=off)")
            self.events.append(f"no compiler {key[:12]}")
            return "no compiler"
        if not self._atexit:
            atexit.register(self.flush)
            self._atexit = True
        self._pending[key] = (functions, list(names), int(n_clearance), np.asarray(nominal_x, dtype=np.float64),
                              dict(getattr(self, "_last_parts", {})))
        return "queued"

    def flush(self) -> list[str]:
        """Write and compile every queued entry (in a detached low-priority process unless
        ``background=False``); the status of each: compiling, compiled, busy or failed."""
        if not self._pending:
            return []
        lock = self.folder / COMPILE_LOCK
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            self._pending.clear()
            _warn_once("folder", f"motok-robot cache: cannot create {self.folder} ({exc}); continuing in memory")
            return ["failed"]
        # one compile at a time per cache folder (a compile takes a core and up to a few GB for
        # the largest problems): a process that finds one running leaves its problems to a later one
        if not _take_lock(lock):
            out = []
            for key in list(self._pending):
                self.events.append(f"busy {key[:12]}")
                out.append("busy")
            self._pending.clear()
            return out
        out, jobs = [], []
        while self._pending:
            key, item = self._pending.popitem()
            status, work = self._write(key, *item)
            out.append(status)
            if work is not None:
                jobs.append((work, key))
        cc = compiler()
        if not jobs:
            lock.unlink(missing_ok=True)
        elif self.background:
            args = [sys.executable, "-m", "retarget.cache", "compile", cc] + [str(a) for job in jobs for a in job]
            env = dict(os.environ)
            env["PYTHONPATH"] = str(Path(__file__).resolve().parents[1]) + os.pathsep + env.get("PYTHONPATH", "")
            subprocess.Popen(args, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                             start_new_session=True, env=env, close_fds=True)
            self.events += [f"compiling {key[:12]}" for _, key in jobs]
            out = ["compiling" if s == "written" else s for s in out]
        else:
            ok = compile_entries(jobs, cc, nice=False)
            self.events += [f"{'compiled' if o else 'failed'} {key[:12]}" for o, (_, key) in zip(ok, jobs)]
            it = iter(ok)
            out = [("compiled" if next(it) else "failed") if s == "written" else s for s in out]
        self.evict()
        return out

    def evict(self, max_bytes: int = MAX_BYTES) -> list[str]:
        """Delete the least recently used entries until the cache holds at most ``max_bytes``."""
        try:
            entries = [(m.stat().st_mtime, m.stem) for m in self.folder.glob("*.json")]
        except OSError:
            return []
        sizes = {k: sum(p.stat().st_size for p in self.paths(k) if p.exists()) for _, k in entries}
        total, gone = sum(sizes.values()), []
        for _, k in sorted(entries):
            if total <= max_bytes:
                break
            self._discard(k)
            total -= sizes[k]
            gone.append(k)
        return gone

    def _write(self, key: str, functions: dict, names: list[str], n_clearance: int, nominal_x: np.ndarray, parts: dict):
        """Write the C code and metadata of one entry into a fresh work folder: ``(status, folder)``."""
        import casadi as ca

        try:
            if self.paths(key)[1].exists():
                return "present", None
            nlp = functions["nlp"]
            nx_w, np_, ng = nlp.size1_in(0), nlp.size1_in(1), nlp.size1_out(1)
            prefix = nlp.name()[: -len("nlp")]
            nx = len(nominal_x)
            point = check_point(nx, np_, ng, nx_w // nx, nominal_x)
            meta = {
                "format": FORMAT, "key": key, "casadi": ca.__version__, "prefix": prefix,
                "nx": nx, "nx_w": nx_w, "np": np_, "ng": ng, "window": nx_w // nx,
                "nominal_x": nominal_x.tolist(), "names": names, "n_clearance": n_clearance, "inputs": parts,
                "reference": _reference(functions, point), "created": time.strftime("%Y-%m-%dT%H:%M:%S"),
            }
            work = Path(tempfile.mkdtemp(prefix=f".{key[:12]}-", dir=self.folder))
            cg = ca.CodeGenerator(f"{prefix}nlp.c", {"with_header": False})
            for name in ("nlp", "grad_f", "jac_g", "hess_lag"):
                cg.add(functions[name])
            cg.generate(str(work) + os.sep)
            size = sum(p.stat().st_size for p in work.glob("*.c"))
            if size > MAX_SOURCE_BYTES:
                shutil.rmtree(work, ignore_errors=True)
                self.events.append(f"too large {key[:12]}: {size / 1e6:.1f} MB of C")
                return "too large", None
            (work / "meta.json").write_text(json.dumps(meta))
            return "written", work
        except Exception as exc:
            self.events.append(f"failed {key[:12]}: {exc}")
            _warn_once(f"store {key}", f"motok-robot cache: could not write entry {key[:12]} in {self.folder} ({exc}); "
                                       "continuing in memory")
            return "failed", None


def _take_lock(lock: Path) -> bool:
    try:
        fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        os.write(fd, str(os.getpid()).encode())
        os.close(fd)
        return True
    except FileExistsError:
        try:
            if time.time() - lock.stat().st_mtime < LOCK_STALE_SECONDS:
                return False
            lock.write_text(str(os.getpid()))
            return True
        except OSError:
            return False


def _lower_priority() -> None:
    """Run this (background compile) process at the lowest CPU priority, where the OS allows it."""
    try:
        os.nice(19)
    except OSError:
        pass


def compile_entry(work: Path, key: str, cc: str, nice: bool = True) -> bool:
    """Compile the C file in ``work`` into ``<key>.so`` next to it, then publish ``<key>.json``
    (both renamed into place); remove ``work``. True on success."""
    work = Path(work)
    folder = work.parent
    ok = False
    try:
        if nice:
            _lower_priority()
        sources = sorted(work.glob("*.c"))
        lib = work / "lib.so"
        subprocess.run([cc, *CFLAGS, *map(str, sources), "-o", str(lib), "-lm"], check=True,
                       stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        meta = json.loads((work / "meta.json").read_text())
        meta["so_sha256"] = file_sha256(lib)
        meta["compiler"] = cc
        os.replace(lib, folder / f"{key}.so")
        tmp = work / "entry.json"
        tmp.write_text(json.dumps(meta))
        os.replace(tmp, folder / f"{key}.json")
        ok = True
    except Exception as exc:  # noqa: BLE001 - reported in the log next to the entry
        try:
            (folder / f"{key}.log").write_text(f"{type(exc).__name__}: {exc}\n{getattr(exc, 'stderr', b'') or b''!r}\n")
        except OSError:
            pass
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return ok


def compile_entries(jobs: list, cc: str, nice: bool = True) -> list[bool]:
    """Compile ``[(work folder, key)]`` one after the other, then release the folder's compile lock."""
    try:
        if nice:
            _lower_priority()
        return [compile_entry(Path(work), key, cc, nice=False) for work, key in jobs]
    finally:
        for work, _ in jobs[:1]:
            try:
                (Path(work).parent / COMPILE_LOCK).unlink()
            except OSError:
                pass


def main(argv: list[str]) -> int:
    if len(argv) >= 4 and argv[0] == "compile" and len(argv) % 2 == 0:
        jobs = [(Path(argv[i]), argv[i + 1]) for i in range(2, len(argv), 2)]
        return 0 if all(compile_entries(jobs, argv[1])) else 1
    print("usage: python -m retarget.cache compile CC WORKDIR KEY [WORKDIR KEY ...]", file=sys.stderr)
    return 2


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))

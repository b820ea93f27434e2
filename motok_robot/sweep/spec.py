"""The sweep spec: a TOML file naming the inputs, seeds, robots and setting variants of a campaign.

::

    prompts = ["a person waves the right hand", "a person bows"]   # and / or
    motions = ["stand.npz"]                 # motion files (paths relative to this file)
    seeds = [0, 1, 2]                       # or { start = 0, count = 10 }
    robots = ["op3", "op3_like"]
    time_budget_s = 600                     # per cell; a cell over it is cancelled and recorded
    plots = false                           # the validation PNGs of every cell (slow)

    [run]                                   # `run` options every cell gets
    seconds = 4

    [variants.plain]                        # named setting variants: `run` options over [run]
    [variants.feasible]
    feasible = true
    feasible-retime = 1.5

The cells are the cartesian product inputs x seeds x robots x variants, or an explicit list::

    [[cells]]
    prompt = "a person bows"                # or motion = "stand.npz"
    seed = 3                                # default 0
    robot = "op3_like"                      # default op3
    variant = "feasible"                    # default: the only variant

An option is a ``run`` option spelled without the dashes (``max-retime`` or ``max_retime``):
``true`` gives a flag, ``false`` leaves it out, a number or a string gives its value.  Every
error names the file and the field.  Light: standard library only at import time.
"""

from __future__ import annotations

import hashlib
import math
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path

from motok_robot.errors import InputError

#: most cells one spec may ask for (checked before the product is built)
MAX_CELLS = 100_000
#: most entries of one list (prompts, motions, seeds, robots, variants, cells)
MAX_ENTRIES = 10_000
#: per-cell time budget when the spec gives none (seconds)
DEFAULT_TIME_BUDGET_S = 900.0
TOP_LEVEL_KEYS = ("prompts", "motions", "seeds", "robots", "time_budget_s", "plots", "run", "variants", "cells")
CELL_KEYS = ("prompt", "motion", "seed", "robot", "variant")
DEFAULT_VARIANT = "default"


@dataclass(frozen=True)
class Variant:
    """A named setting variant: its ``run`` options as command-line arguments (``[run]`` first)."""

    name: str
    argv: tuple[str, ...]


@dataclass(frozen=True)
class Cell:
    """One pipeline run of the sweep: an input (a prompt or a motion file), a seed, a robot, a variant."""

    prompt: str | None
    motion: Path | None  #: absolute path of the motion file
    motion_label: str | None  #: the motion as the spec wrote it
    seed: int
    robot: str
    variant: str

    @property
    def input_label(self) -> str:
        """The prompt, or ``motion:NAME`` (the row label of the heatmaps)."""
        return self.prompt if self.prompt is not None else f"motion:{self.motion_label}"

    @property
    def key(self) -> tuple:
        """What identifies the cell across runs of the same spec (``--resume`` matches on it)."""
        return (self.prompt or "", self.motion_label or "", self.seed, self.robot, self.variant)

    @property
    def cell_id(self) -> str:
        """A folder-safe, readable and unique name: ``<input>_<robot>_s<seed>_<variant>_<hash>``."""
        digest = hashlib.sha256(repr(self.key).encode("utf-8")).hexdigest()[:8]
        label = self.prompt if self.prompt is not None else Path(self.motion_label).stem
        return f"{folder_name(label, 32)}_{folder_name(Path(self.robot).stem, 20)}_s{self.seed}_{folder_name(self.variant, 20)}_{digest}"


@dataclass
class SweepSpec:
    """A parsed spec: the cells to run and the settings shared by all of them."""

    path: Path
    cells: list[Cell]
    variants: dict[str, Variant]
    time_budget_s: float = DEFAULT_TIME_BUDGET_S
    plots: bool = False


def folder_name(text: str, limit: int) -> str:
    """``text`` as lower-case letters, digits and ``_``, at most ``limit`` characters."""
    return re.sub(r"[^a-z0-9]+", "_", str(text).lower()).strip("_")[:limit].rstrip("_") or "x"


def load_spec(path: str | Path) -> SweepSpec:
    """Read and check a spec file; :class:`InputError` naming the file and the field otherwise."""
    from motok_robot.limits import check_file_size

    path = Path(path).expanduser()
    if not path.is_file():
        raise InputError(f"sweep spec {path} does not exist" if not path.exists() else f"sweep spec {path} is not a file")
    check_file_size(path, "sweep spec")
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except UnicodeDecodeError as exc:
        raise InputError(f"{path}: not a UTF-8 text file ({exc.reason} at byte {exc.start})") from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{path}: not valid TOML: {exc}") from None
    return parse_spec(data, path)


def parse_spec(data: dict, path: Path) -> SweepSpec:
    """The :class:`SweepSpec` of the TOML table ``data`` read from ``path``."""
    path = Path(path).absolute()
    where = _Where(path)
    unknown = [k for k in data if k not in TOP_LEVEL_KEYS]
    if unknown:
        raise where.error(unknown[0], f"unknown field; a spec has {', '.join(TOP_LEVEL_KEYS)}")
    budget = data.get("time_budget_s", DEFAULT_TIME_BUDGET_S)
    if isinstance(budget, bool) or not isinstance(budget, (int, float)) or not (math.isfinite(budget) and budget > 0):
        raise where.error("time_budget_s", f"must be a positive number of seconds, got {budget!r}")
    plots = data.get("plots", False)
    if not isinstance(plots, bool):
        raise where.error("plots", f"must be true or false, got {plots!r}")
    variants = _variants(data, where)
    if "cells" in data:
        listed = [k for k in ("prompts", "motions", "seeds", "robots") if k in data]
        if listed:
            raise where.error(listed[0], "give either the lists (prompts, motions, seeds, robots) or [[cells]], not both")
        cells = _listed_cells(data["cells"], variants, where)
    else:
        cells = _product_cells(data, variants, where)
    spec = SweepSpec(path=path, cells=cells, variants=variants, time_budget_s=float(budget), plots=plots)
    from motok_robot.sweep.run_options import check_variants

    check_variants(spec)
    return spec


class _Where:
    """Error messages that name the spec file and the field."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.known_robots: list[str] | None = None  # the installed robots, listed once

    def error(self, field: str, message: str) -> InputError:
        return InputError(f"{self.path}: field '{field}': {message}")


def _list(data: dict, key: str, where: _Where, default=None) -> list:
    if key not in data:
        return list(default or [])
    value = data[key]
    if not isinstance(value, list):
        raise where.error(key, f"must be a list, got {type(value).__name__}")
    if len(value) > MAX_ENTRIES:
        raise where.error(key, f"has {len(value)} entries; at most {MAX_ENTRIES}")
    return value


def _prompt(value, field: str, where: _Where) -> str:
    from motok_robot.text.validate import check_text

    try:
        return check_text(value, name="the prompt")
    except InputError as exc:
        raise where.error(field, str(exc)) from None


def _motion(value, field: str, where: _Where) -> tuple[Path, str]:
    if not isinstance(value, str) or not value.strip():
        raise where.error(field, f"must be a motion file path, got {value!r}")
    p = Path(value).expanduser()
    full = p if p.is_absolute() else where.path.parent / p
    if not full.is_file():
        raise where.error(field, f"motion file {full} does not exist")
    from motok_robot.limits import check_file_size

    try:
        check_file_size(full, "motion file")  # the driver reads it to send it to the workers
    except InputError as exc:
        raise where.error(field, str(exc)) from None
    return full.resolve(), value


def _seed(value, field: str, where: _Where) -> int:
    from motok_robot.text.prompts import check_seed

    try:
        return check_seed(value, "the seed")
    except InputError as exc:
        raise where.error(field, str(exc)) from None


def _seeds(data: dict, where: _Where) -> list[int]:
    if "seeds" not in data:
        return [0]
    value = data["seeds"]
    if isinstance(value, dict):
        extra = set(value) - {"start", "count"}
        if extra or "count" not in value:
            raise where.error("seeds", "a range is { start = S, count = N }")
        start, count = value.get("start", 0), value["count"]
        if isinstance(count, bool) or not isinstance(count, int) or not 1 <= count <= MAX_ENTRIES:
            raise where.error("seeds.count", f"must be an integer 1..{MAX_ENTRIES}, got {count!r}")
        first = _seed(start, "seeds.start", where)
        _seed(first + count - 1, "seeds.count", where)
        return list(range(first, first + count))
    seeds = [_seed(s, f"seeds[{i}]", where) for i, s in enumerate(_list(data, "seeds", where))]
    if not seeds:
        raise where.error("seeds", "is empty")
    return seeds


def _robot(value, field: str, where: _Where) -> str:
    """An installed robot name, or a ``NAME.toml`` path (relative to the spec) made absolute."""
    from motok_robot.robots.robot import list_robots, models_dir

    if not isinstance(value, str) or not value.strip():
        raise where.error(field, f"must be a robot name, got {value!r}")
    name = value.strip()
    if name.endswith((".toml", ".xml")) or "/" in name:
        p = Path(name).expanduser()
        full = (p if p.is_absolute() else where.path.parent / p).with_suffix(".toml")
        if not full.is_file():
            raise where.error(field, f"robot description not found: {full} (a robot is NAME.xml + NAME.toml)")
        return str(full.resolve())
    if where.known_robots is None:
        where.known_robots = list_robots()
    known = where.known_robots
    if name not in known:
        raise where.error(field, f"unknown robot {name!r}; known robots: {', '.join(known) or 'none'} (in {models_dir()})")
    return name


def _variants(data: dict, where: _Where) -> dict[str, Variant]:
    from motok_robot.sweep.run_options import variant_argv

    shared = data.get("run", {})
    if not isinstance(shared, dict):
        raise where.error("run", f"must be a table of `run` options, got {type(shared).__name__}")
    base = variant_argv(shared, "run", where.path)
    tables = data.get("variants", {DEFAULT_VARIANT: {}})
    if not isinstance(tables, dict) or not tables:
        raise where.error("variants", "must hold at least one table [variants.NAME]")
    if len(tables) > MAX_ENTRIES:
        raise where.error("variants", f"has {len(tables)} entries; at most {MAX_ENTRIES}")
    variants = {}
    for name, options in tables.items():
        if not isinstance(options, dict):
            raise where.error(f"variants.{name}", f"must be a table of `run` options, got {type(options).__name__}")
        variants[name] = Variant(name, base + variant_argv(options, f"variants.{name}", where.path))
    return variants


def _product_cells(data: dict, variants: dict[str, Variant], where: _Where) -> list[Cell]:
    from motok_robot.robots.robot import DEFAULT_ROBOT

    prompts = [_prompt(p, f"prompts[{i}]", where) for i, p in enumerate(_list(data, "prompts", where))]
    motions = [_motion(m, f"motions[{i}]", where) for i, m in enumerate(_list(data, "motions", where))]
    if not prompts and not motions:
        raise where.error("prompts", "give prompts, motions (files), or a [[cells]] list")
    seeds = _seeds(data, where)
    robots = [_robot(r, f"robots[{i}]", where) for i, r in enumerate(_list(data, "robots", where, [DEFAULT_ROBOT]))]
    if not robots:
        raise where.error("robots", "is empty")
    for key, values in (("prompts", prompts), ("motions", [m for m, _ in motions]), ("seeds", seeds),
                        ("robots", robots)):
        _unique(values, key, where)
    count = (len(prompts) + len(motions)) * len(seeds) * len(robots) * len(variants)
    if count > MAX_CELLS:
        raise where.error("prompts", f"the product gives {count} cells; at most {MAX_CELLS} per spec (split it)")
    inputs = [(p, None, None) for p in prompts] + [(None, full, label) for full, label in motions]
    return [Cell(prompt, motion, label, seed, robot, variant)
            for prompt, motion, label in inputs for robot in robots for seed in seeds for variant in variants]


def _listed_cells(entries, variants: dict[str, Variant], where: _Where) -> list[Cell]:
    from motok_robot.robots.robot import DEFAULT_ROBOT

    if not isinstance(entries, list) or not entries:
        raise where.error("cells", "must be a non-empty list of tables [[cells]]")
    if len(entries) > min(MAX_ENTRIES, MAX_CELLS):
        raise where.error("cells", f"has {len(entries)} entries; at most {min(MAX_ENTRIES, MAX_CELLS)}")
    cells = []
    for i, entry in enumerate(entries):
        field = f"cells[{i}]"
        if not isinstance(entry, dict):
            raise where.error(field, f"must be a table, got {type(entry).__name__}")
        unknown = [k for k in entry if k not in CELL_KEYS]
        if unknown:
            raise where.error(f"{field}.{unknown[0]}", f"unknown field; a cell has {', '.join(CELL_KEYS)}")
        if ("prompt" in entry) == ("motion" in entry):
            raise where.error(field, "give either prompt or motion")
        prompt = _prompt(entry["prompt"], f"{field}.prompt", where) if "prompt" in entry else None
        motion, label = _motion(entry["motion"], f"{field}.motion", where) if "motion" in entry else (None, None)
        seed = _seed(entry.get("seed", 0), f"{field}.seed", where)
        robot = _robot(entry.get("robot", DEFAULT_ROBOT), f"{field}.robot", where)
        if "variant" in entry:
            variant = entry["variant"]
            if variant not in variants:
                raise where.error(f"{field}.variant", f"unknown variant {variant!r}; the spec has "
                                                      f"{', '.join(variants)}")
        elif len(variants) == 1:
            variant = next(iter(variants))
        else:
            raise where.error(f"{field}.variant", f"name one of the variants ({', '.join(variants)})")
        cells.append(Cell(prompt, motion, label, seed, robot, variant))
    _unique([c.key for c in cells], "cells", where)
    return cells


def _unique(values: list, key: str, where: _Where) -> None:
    """InputError naming ``key[i]`` when entry ``i`` repeats an earlier one."""
    first: dict = {}
    for i, value in enumerate(values):
        if value in first:
            raise where.error(f"{key}[{i}]", f"the same as {key}[{first[value]}]")
        first[value] = i

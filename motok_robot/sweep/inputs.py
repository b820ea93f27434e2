"""What a cell reads, and its hash: ``--resume`` reruns a cell whose inputs hash differently.

The hash covers the cell's keys, its variant's ``run`` options, the spec's ``plots``, the bytes
of its motion file (and the ``.asf`` skeletons beside an ``.amc``), of its robot description
(``NAME.toml`` + ``NAME.xml``), of the generation models a prompt cell loads, of every file a
``run`` option names, and the motok-robot version.  Code changes inside one version are not
seen: start a new ``--out`` after changing the code.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

#: most companion files of one motion file (the ``.asf`` skeletons next to an ``.amc``)
MAX_COMPANIONS = 16


def motion_files(path: Path) -> list[Path]:
    """The files a motion needs: itself, and for an ``.amc`` the ``.asf`` skeletons next to it."""
    files = [Path(path)]
    if Path(path).suffix.lower() == ".amc":
        files += sorted(Path(path).parent.glob("*.asf"))[:MAX_COMPANIONS]  # the importer picks one by name
    return files


class InputHasher:
    """Hashes cells' inputs, each file read once."""

    def __init__(self) -> None:
        self._files: dict[Path, str] = {}

    def file(self, path: Path) -> str:
        """sha256 of a file's bytes (of the names and hashes of a folder's files)."""
        from motok_robot.limits import limit

        path = Path(path)
        if path not in self._files:
            if path.is_dir():
                parts = [f"{p.name}:{self.file(p)}" for p in sorted(path.iterdir()) if p.is_file()]
                self._files[path] = hashlib.sha256("\n".join(parts).encode("utf-8")).hexdigest()
            elif not path.is_file():
                self._files[path] = "missing"
            elif path.stat().st_size > limit("file_bytes"):  # too big to read: its size and time stand for it
                st = path.stat()
                self._files[path] = f"size {st.st_size} mtime {st.st_mtime_ns}"
            else:
                digest = hashlib.sha256()
                with open(path, "rb") as handle:
                    for block in iter(lambda: handle.read(1 << 20), b""):
                        digest.update(block)
                self._files[path] = digest.hexdigest()
        return self._files[path]

    def robot(self, robot: str) -> dict:
        from motok_robot.paths import robots_dir

        toml = Path(robot) if robot.endswith(".toml") else robots_dir() / f"{robot}.toml"
        return {"toml": self.file(toml), "xml": self.file(toml.with_suffix(".xml"))}

    def models(self, args) -> dict:
        """The generation model folders a prompt cell loads (the defaults of ``run`` when not given)."""
        from motok_robot.paths import models_dir

        tokenizer = Path(args.tokenizer) if args.tokenizer else models_dir() / "tokenizer"
        planner = Path(args.planner_run) if args.planner_run else models_dir() / f"planner_{args.planner}"
        return {"tokenizer": self.file(tokenizer), "planner": self.file(planner)}

    def cell(self, cell, variant, plots: bool, args) -> str:
        """The inputs hash of ``cell`` run with ``variant`` (``args``: its parsed options)."""
        from motok_robot import __version__

        named = {tok: self.file(Path(tok)) for tok in variant.argv if Path(tok).is_absolute() and Path(tok).exists()}
        payload = {
            "version": __version__, "key": list(cell.key), "options": list(variant.argv), "plots": plots,
            "motion": [self.file(p) for p in motion_files(cell.motion)] if cell.motion is not None else None,
            "robot": self.robot(cell.robot),
            "models": self.models(args) if cell.motion is None else None,
            "files": named,
        }
        return hashlib.sha256(json.dumps(payload, sort_keys=True).encode("utf-8")).hexdigest()


def input_hashes(spec) -> dict[str, str]:
    """``{cell_id: inputs hash}`` for every cell of ``spec``."""
    from motok_robot.sweep.run_options import parse

    hasher = InputHasher()
    parsed = {name: parse(v.argv) for name, v in spec.variants.items()}
    return {c.cell_id: hasher.cell(c, spec.variants[c.variant], spec.plots, parsed[c.variant]) for c in spec.cells}

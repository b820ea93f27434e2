"""``motok-robot sweep``: run a campaign of cells (inputs x seeds x robots x variants) on Ray.

Light module: Ray, pyarrow and the pipeline are imported inside the handler.

    motok-robot sweep examples/sweep_small.toml --out sweep/                # local Ray, one worker per CPU
    motok-robot sweep spec.toml --out sweep/ --workers 1                    # in this process, no Ray
    motok-robot sweep spec.toml --out sweep/ --address auto                 # on a running Ray cluster
    motok-robot sweep spec.toml --out sweep/ --resume                       # finish an interrupted sweep

Exit status: 0 when every cell passed validation; 1 when a cell failed validation, raised or ran
over its time budget (each is a row of the table); 2 for invalid input (one line on stderr).
"""

from __future__ import annotations

import argparse
from pathlib import Path


def register(commands, groups) -> None:
    parser = commands.add_parser(
        "sweep", help="validation campaign: prompts/motions x seeds x robots x settings, on Ray",
        description="Run every cell of SPEC.toml (an input, a seed, a robot and a setting variant) through the "
                    "pipeline without rendering: generate (or read the motion file), retarget, the feasibility stage "
                    "when the variant asks for it, validate. Writes one row per cell to OUT/results.parquet and "
                    "OUT/results.csv, the files of each cell to OUT/cells/<cell_id>/, and OUT/summary.md with pass-rate "
                    "heatmaps.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="Spec format, fault tolerance and multi-node clusters: docs/sweep.md. Needs the sweep extra: "
               'pip install -e ".[sweep]".')
    parser.add_argument("spec", type=Path, metavar="SPEC.toml", help="the sweep spec (see examples/sweep_small.toml)")
    parser.add_argument("--out", required=True, type=Path, metavar="DIR", help="output folder (new, or a sweep to --resume)")
    parser.add_argument("--workers", type=int, default=None, metavar="N",
                        help="Ray workers, one CPU each (default: every CPU of this machine, or of the cluster with "
                             "--address); 1 runs the cells in this process without Ray")
    parser.add_argument("--address", default=None, metavar="auto|HOST:PORT",
                        help="attach to a running Ray cluster (`ray start --head` on its head node) instead of "
                             "starting a local Ray")
    parser.add_argument("--resume", action="store_true",
                        help="continue the sweep in DIR: keep every cell whose result row exists and whose inputs "
                             "hash the same, run the rest")
    parser.add_argument("--rerun-errors", action="store_true",
                        help="with --resume: run again the cells that raised or ran over their time budget")
    parser.set_defaults(func=sweep_command)


def sweep_command(args: argparse.Namespace) -> int:
    import os

    from motok_robot.errors import InputError
    from motok_robot.sweep.driver import run_sweep

    if args.rerun_errors and not args.resume:
        raise InputError("--rerun-errors needs --resume")
    workers = args.workers
    if workers is None and not args.address:
        workers = os.cpu_count() or 1
    outcome = run_sweep(args.spec, args.out, workers=workers, address=args.address, resume=args.resume,
                        rerun_errors=args.rerun_errors)
    print(outcome.line())
    print(f"  table: {outcome.paths['parquet']} (and {outcome.paths['csv'].name}); summary: {outcome.paths['summary']}")
    return 0 if outcome.all_passed else 1

"""``summary.md`` of a sweep: pass rates, heatmaps, the most common failing checks, the slowest cells.

Heatmaps (PNG, matplotlib without a display): pass rate per input (prompt or motion file) x robot,
and per input x seed, each over the cells of that pair (a cell that raised or ran out of time
counts as not passed).
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path

HEATMAPS = {"robot": "heatmap_input_robot.png", "seed": "heatmap_input_seed.png"}
#: most rows / columns a heatmap draws (the table in summary.md has them all)
MAX_HEATMAP_AXIS = 80
SLOWEST = 10
MAX_ERRORS_LISTED = 20


def pass_rates(rows: list[dict], row_key: str, col_key: str) -> dict[tuple, tuple[int, int]]:
    """``{(row value, column value): (passed, cells)}``."""
    rates: dict[tuple, list[int]] = {}
    for r in rows:
        cell = rates.setdefault((r[row_key], r[col_key]), [0, 0])
        cell[0] += r.get("status") == "passed"
        cell[1] += 1
    return {k: (v[0], v[1]) for k, v in rates.items()}


def _order(values, spec_order) -> list:
    present = set(values)
    ordered = [v for v in dict.fromkeys(spec_order) if v in present]
    return ordered + sorted(present - set(ordered), key=str)


def _rate(pair) -> str:
    passed, cells = pair
    return f"{100 * passed / cells:.0f}% ({passed}/{cells})" if cells else "-"


def rate_table(rows, row_key: str, col_key: str, row_order, col_order) -> list[str]:
    """A markdown table of pass rates, ``row_key`` down, ``col_key`` across, with totals."""
    rates = pass_rates(rows, row_key, col_key)
    row_values = _order([r[row_key] for r in rows], row_order)
    col_values = _order([r[col_key] for r in rows], col_order)
    lines = [f"| {row_key} \\ {col_key} | " + " | ".join(str(c) for c in col_values) + " | all |",
             "|---|" + "---:|" * (len(col_values) + 1)]
    for rv in row_values:
        cells = [rates.get((rv, cv), (0, 0)) for cv in col_values]
        total = (sum(p for p, _ in cells), sum(n for _, n in cells))
        lines.append(f"| {_md(rv)} | " + " | ".join(_rate(c) for c in cells) + f" | {_rate(total)} |")
    totals = [(sum(rates.get((rv, cv), (0, 0))[0] for rv in row_values),
               sum(rates.get((rv, cv), (0, 0))[1] for rv in row_values)) for cv in col_values]
    everything = (sum(p for p, _ in totals), sum(n for _, n in totals))
    lines.append("| **all** | " + " | ".join(_rate(t) for t in totals) + f" | {_rate(everything)} |")
    return lines


def _md(value) -> str:
    return str(value).replace("|", "\\|")


def heatmap(path: Path, rows, row_key: str, col_key: str, row_order, col_order, title: str) -> Path:
    """A PNG heatmap of pass rates (``row_key`` down, ``col_key`` across)."""
    import numpy as np
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    rates = pass_rates(rows, row_key, col_key)
    row_values = _order([r[row_key] for r in rows], row_order)[:MAX_HEATMAP_AXIS]
    col_values = _order([r[col_key] for r in rows], col_order)[:MAX_HEATMAP_AXIS]
    grid = np.full((len(row_values), len(col_values)), np.nan)
    for i, rv in enumerate(row_values):
        for j, cv in enumerate(col_values):
            passed, cells = rates.get((rv, cv), (0, 0))
            if cells:
                grid[i, j] = passed / cells
    label_width = 0.07 * max((min(len(str(r)), 50) for r in row_values), default=0)
    fig = Figure(figsize=(min(2.5 + label_width + 0.6 * len(col_values), 30), min(1.5 + 0.35 * len(row_values), 30)))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    image = ax.imshow(grid, vmin=0, vmax=1, cmap="RdYlGn", aspect="auto")
    ax.set_xticks(range(len(col_values)), [str(c) for c in col_values], rotation=45, ha="right", fontsize=8)
    ax.set_yticks(range(len(row_values)), [str(r)[:50] for r in row_values], fontsize=8)
    if grid.size <= 400:
        for (i, j), value in np.ndenumerate(grid):
            if not np.isnan(value):
                ax.text(j, i, f"{100 * value:.0f}", ha="center", va="center", fontsize=7)
    ax.set_xlabel(col_key)
    ax.set_title(title, fontsize=10)
    fig.colorbar(image, ax=ax, label="pass rate")
    part = path.with_name(f".{path.name}.partial")
    fig.savefig(part, format="png", dpi=100, bbox_inches="tight")
    part.replace(path)
    return path


def summary_markdown(rows: list[dict], spec) -> str:
    """The text of ``summary.md``."""
    statuses = Counter(r.get("status") for r in rows)
    inputs = [c.input_label for c in spec.cells]
    robots = [c.robot for c in spec.cells]
    seeds = [c.seed for c in spec.cells]
    variants = list(spec.variants)
    lines = [f"# Sweep: {spec.path.name}", "",
             f"* cells: {len(spec.cells)} in the spec, {len(rows)} with a result",
             f"* passed validation: {statuses['passed']}; failed validation: {statuses['failed']}; "
             f"errors: {statuses['error']}; over the time budget ({spec.time_budget_s:g} s): {statuses['timeout']}",
             f"* cell time: {sum(float(r.get('cell_s') or 0) for r in rows):.1f} s summed over the cells", "",
             "Results: [results.parquet](results.parquet), [results.csv](results.csv) (one row per cell), "
             "the files of each cell in `cells/<cell_id>/`.", ""]
    if not rows:
        return "\n".join(lines + ["No cell has finished yet."]) + "\n"
    lines += ["## Pass rate by variant and robot", ""] + rate_table(rows, "variant", "robot", variants, robots)
    lines += ["", "## Pass rate by input and robot", "", f"![input x robot]({HEATMAPS['robot']})", ""]
    lines += rate_table(rows, "input", "robot", inputs, robots)
    lines += ["", "## Pass rate by input and seed", "", f"![input x seed]({HEATMAPS['seed']})", ""]
    lines += rate_table(rows, "input", "seed", inputs, seeds)
    checks = Counter(c for r in rows if r.get("failed_checks") for c in str(r["failed_checks"]).split(";"))
    validated = sum(r.get("status") in ("passed", "failed") for r in rows)
    lines += ["", "## Most common failing checks", ""]
    if checks:
        lines += ["| check | cells failing | share of validated cells |", "|---|---:|---:|"]
        lines += [f"| `{name}` | {count} | {100 * count / validated:.0f}% |" for name, count in checks.most_common(15)]
    else:
        lines.append("No validated cell failed a check.")
    timed = sorted((r for r in rows if r.get("cell_s") is not None), key=lambda r: -float(r["cell_s"]))[:SLOWEST]
    lines += ["", "## Slowest cells", "", "| cell | status | seconds | slowest stage |", "|---|---|---:|---|"]
    for r in timed:
        stages = {k[5:-2]: v for k, v in r.items() if k.startswith("time_") and k != "time_total_s" and v is not None}
        slowest = max(stages, key=stages.get) if stages else "-"
        lines.append(f"| [{r['cell_id']}]({r.get('folder', '')}) | {r.get('status')} | {float(r['cell_s']):.2f} | "
                     + (f"{slowest} {stages[slowest]:.2f} s" if stages else "-") + " |")
    broken = [r for r in rows if r.get("status") in ("error", "timeout")]
    if broken:
        lines += ["", f"## Errors and time-outs ({len(broken)})", ""]
        lines += [f"* `{r['cell_id']}` ({r['status']}): {r.get('error', '')}" for r in broken[:MAX_ERRORS_LISTED]]
        if len(broken) > MAX_ERRORS_LISTED:
            lines.append(f"* ... {len(broken) - MAX_ERRORS_LISTED} more: see the `error` column of the table")
    return "\n".join(lines) + "\n"


def write_summary(out: Path, rows: list[dict], spec) -> dict[str, Path]:
    """Write ``summary.md`` and the heatmaps into ``out``; returns their paths."""
    out = Path(out)
    paths = {}
    if rows:
        inputs = [c.input_label for c in spec.cells]
        paths["heatmap_robot"] = heatmap(out / HEATMAPS["robot"], rows, "input", "robot", inputs,
                                         [c.robot for c in spec.cells], "pass rate: input x robot")
        paths["heatmap_seed"] = heatmap(out / HEATMAPS["seed"], rows, "input", "seed", inputs,
                                        [c.seed for c in spec.cells], "pass rate: input x seed")
    part = out / ".summary.md.partial"
    part.write_text(summary_markdown(rows, spec), encoding="utf-8")
    part.replace(out / "summary.md")
    paths["summary"] = out / "summary.md"
    return paths

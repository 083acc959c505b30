"""Configurations across data sets: the benchmark table, average ranks, Friedman's test.

Each cell is a configuration's mean metric on a data set with its object-bootstrap interval. The
ranks and Friedman's test (with Iman-Davenport's F and Nemenyi's critical difference, Demsar
2006) treat each data set as one block, so they are over the configurations that ran on every
data set of the report; a configuration missing from one is listed with where it is missing,
never ranked on what it has.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats as sps

from tactile_exp import stats
from tactile_exp.metrics import METRICS
from tactile_exp.report.leaderboard import Board


@dataclass(frozen=True)
class Benchmark:
    datasets: tuple[str, ...]
    configurations: tuple[str, ...]  # ranked ones first (best mean rank first), then the rest
    cells: dict[tuple[str, str], stats.Interval]  # (configuration, data set) -> mean [CI]
    mean_ranks: dict[str, float]  # over the data sets, for the configurations on all of them
    missing: dict[str, tuple[str, ...]]  # configuration -> the data sets it did not run on
    friedman: stats.Friedman | None
    why_not: str  # why there is no Friedman test ("" when there is)


def benchmark(boards: list[Board]) -> Benchmark:
    """The table of ``boards`` (one per data set, two or more)."""
    datasets = tuple(b.dataset for b in boards)
    cells = {(e.name, b.dataset): e.value for b in boards for e in b.entries}
    every = sorted({name for name, _ in cells})
    missing = {
        name: tuple(d for d in datasets if (name, d) not in cells)
        for name in every
        if any((name, d) not in cells for d in datasets)
    }
    complete = [name for name in every if name not in missing]
    values = np.array([[cells[name, d].estimate for d in datasets] for name in complete])
    friedman, why = None, ""
    ranks: dict[str, float] = {}
    if len(complete) >= 2:
        per_dataset = sps.rankdata(-values, axis=0)
        ranks = dict(zip(complete, per_dataset.mean(axis=1).tolist(), strict=True))
    if len(complete) >= 3:
        friedman = stats.friedman(complete, values)
    else:
        why = f"{len(complete)} configuration(s) ran on every data set; Friedman's test needs 3"
    ranked = sorted(complete, key=lambda n: (ranks.get(n, 0.0), n))
    order = tuple(ranked + [n for n in every if n in missing])
    return Benchmark(datasets, order, cells, ranks, missing, friedman, why)


def rows(bench: Benchmark, metric: str) -> list[dict[str, str]]:
    """Configurations x data sets, machine-readable (``<data set>`` and its interval's ends)."""
    out = []
    for name in bench.configurations:
        row = {
            "configuration": name,
            "mean_rank": f"{bench.mean_ranks[name]:.4f}" if name in bench.mean_ranks else "",
        }
        for d in bench.datasets:
            iv = bench.cells.get((name, d))
            row[d] = "" if iv is None else f"{iv.estimate:.6f}"
            row[f"{d} ci_low"] = "" if iv is None or iv.missing else f"{iv.low:.6f}"
            row[f"{d} ci_high"] = "" if iv is None or iv.missing else f"{iv.high:.6f}"
        row["missing_on"] = " ".join(bench.missing.get(name, ()))
        out.append(row)
    return out


def markdown(bench: Benchmark, metric: str) -> str:
    label = METRICS.build(metric).label
    head = ["configuration", *bench.datasets, "mean rank"]
    lines = [
        f"Mean {label} % [95% CI] per data set; the mean rank is over the "
        f"{len(bench.datasets)} data sets (1 = best), for the configurations that ran on all.",
        "",
        "| " + " | ".join(head) + " |",
        "|" + "---|" * len(head),
    ]
    for name in bench.configurations:
        cells = []
        for d in bench.datasets:
            iv = bench.cells.get((name, d))
            if iv is None:
                cells.append("not run")
            elif iv.missing:
                cells.append(f"{iv.estimate * 100:.1f} (no interval)")
            else:
                cells.append(f"{iv.estimate * 100:.1f} [{iv.low * 100:.1f}, {iv.high * 100:.1f}]")
        rank = f"{bench.mean_ranks[name]:.2f}" if name in bench.mean_ranks else "not ranked"
        lines.append(f"| `{name}` | " + " | ".join(cells) + f" | {rank} |")
    lines.append("")
    if bench.missing:
        lines += [
            "Not ranked (missing on a data set): "
            + "; ".join(f"`{n}` (not on {', '.join(ds)})" for n, ds in bench.missing.items()),
            "",
        ]
    f = bench.friedman
    if f is None:
        lines += [f"No Friedman test: {bench.why_not}.", ""]
    else:
        lines += [
            f"Friedman over {f.n_adjectives} data sets and {len(f.names)} configurations: "
            f"chi2 = {f.statistic:.2f}, p = {f.p:.3g}; Iman-Davenport F = {f.f_statistic:.2f}, "
            f"p = {f.f_p:.3g}. Nemenyi's critical difference at 0.05 is "
            f"{f.critical_difference:.2f} ranks: configurations joined by a bar in the diagram "
            "are not distinguishable.",
            "",
            "![critical-difference diagram over data sets](benchmark_cd.png)",
            "",
        ]
    return "\n".join(lines) + "\n"

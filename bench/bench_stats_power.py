"""Bench: what the report's statistics can tell apart, on simulated PHAC-2-sized data, with the
object bootstrap drawing each adjective's objects on its own (``independent``, the old way) or
jointly across the adjectives that share them (``joint``, ``tactile_exp.stats.RESAMPLING``).

Protocols (``tests/stats_fixture.py``): the published split (PHAC-2's table: 21 test objects
shared by 24 adjectives, 1 to 3 positive each) and 5 folds pooled over PHAC-2's 60 objects
(every adjective tests every object). ``rho``: the share of an object effect's variance that is
the object's own difficulty, alike in every adjective (0: independent adjectives). For each
cell, over ``--sets`` simulated data sets: how often the 95% interval of the mean AUC covers the
population value and its mean width; how often three identically distributed configurations are
called different (any verdict other than "not distinguishable", Holm over their three
comparisons: the family-wise false-positive rate); the power to call a configuration better when
its AUC is higher by 0.05 or 0.10 on every adjective (the report's verdict rule). Prints a
Markdown table (docs/statistics.md quotes it).

    PYTHONPATH=. python bench/bench_stats_power.py [--sets 400] [--boot 1000]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from stats_fixture import population_mean, simulate  # noqa: E402

from tactile_exp import stats  # noqa: E402

DIFFERENCES = (0.05, 0.10)
PROTOCOLS = ("published", "folds")
RHOS = (0.0, 0.5)
RESAMPLINGS = ("independent", "joint")


def run(protocol: str, rho: float, resampling: str, n_sets: int, n_boot: int) -> dict:
    """One cell: the same simulated data sets (seeded by protocol and rho) for either bootstrap."""
    stats.RESAMPLING = resampling
    rng = np.random.default_rng([2027, PROTOCOLS.index(protocol), int(rho * 100)])
    covered = false_family = 0
    widths = []
    detected = dict.fromkeys(DIFFERENCES, 0)
    for _ in range(n_sets):
        a, b, c, *better = simulate(rng, protocol, (0.0, 0.0, 0.0, *DIFFERENCES), rho)
        iv = stats.mean_interval([a], n_boot)
        covered += iv.low <= population_mean() <= iv.high
        widths.append(iv.high - iv.low)
        pairs = (("a", a, "b", b), ("a", a, "c", c), ("b", b, "c", c))
        family = stats.with_holm([stats.compare(x, [e], y, [f], n_boot) for x, e, y, f in pairs])
        false_family += any(cmp.verdict != "not distinguishable" for cmp in family)
        for delta, ev in zip(DIFFERENCES, better, strict=True):
            cmp = stats.with_holm([stats.compare("better", [ev], "a", [a], n_boot)])[0]
            detected[delta] += cmp.verdict == "better beats a"
    out = {"coverage": covered / n_sets, "width": float(np.mean(widths))}
    out["false positives"] = false_family / n_sets
    return out | {f"power {d:.2f}": detected[d] / n_sets for d in DIFFERENCES}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sets", type=int, default=400)
    parser.add_argument("--boot", type=int, default=1000)
    args = parser.parse_args()
    print(f"{args.sets} data sets per cell, {args.boot} resamples, 24 adjectives", flush=True)
    print(
        "| protocol | rho | bootstrap | coverage (95%) | width | false positives (3 alike, "
        "Holm) | power 0.05 | power 0.10 | seconds |"
    )
    print("|---|---|---|---|---|---|---|---|---|", flush=True)
    for protocol in PROTOCOLS:
        for rho in RHOS:
            for resampling in RESAMPLINGS:
                start = time.perf_counter()
                found = run(protocol, rho, resampling, args.sets, args.boot)
                cells = " | ".join(
                    f"{v:.3f}" if k == "width" else f"{v:.1%}" for k, v in found.items()
                )
                seconds = time.perf_counter() - start
                print(
                    f"| {protocol} | {rho} | {resampling} | {cells} | {seconds:.0f} |", flush=True
                )


if __name__ == "__main__":
    main()

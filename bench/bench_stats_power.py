"""Bench: what the report's statistics can tell apart, on simulated PHAC-2-sized data.

For each protocol (the published split: ~3 positive and ~4 negative test objects per adjective;
5 folds pooled over PHAC-2's 60 objects) and 400 simulated data sets of 24 adjectives
(``tests/stats_fixture.py``): how often the 95% interval of the mean AUC covers the population
value, how often three identically distributed configurations are called different (Holm over
their three comparisons: the family-wise false-positive rate), and the power to call a
configuration better when its mean AUC is higher by 0.05 or 0.10 (paired bootstrap + Wilcoxon,
as the report decides). Prints one line per protocol; ``--sets N`` for a quicker look.

    PYTHONPATH=. python bench/bench_stats_power.py
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


def run(protocol: str, n_sets: int, n_boot: int) -> dict[str, float]:
    rng = np.random.default_rng(2027)
    covered = false_family = 0
    detected = dict.fromkeys(DIFFERENCES, 0)
    for i in range(n_sets):
        a, b, c, *better = simulate(rng, protocol, (0.0, 0.0, 0.0, *DIFFERENCES))
        iv = stats.mean_interval([a], n_boot, seed=i)
        covered += iv.low <= population_mean() <= iv.high
        pairs = (("a", a, "b", b), ("a", a, "c", c), ("b", b, "c", c))
        family = stats.with_holm([stats.compare(x, [e], y, [f], n_boot, i) for x, e, y, f in pairs])
        false_family += any(cmp.verdict != "not distinguishable" for cmp in family)
        for delta, ev in zip(DIFFERENCES, better, strict=True):
            cmp = stats.with_holm([stats.compare("better", [ev], "a", [a], n_boot, i)])[0]
            detected[delta] += cmp.verdict == "better beats a"
    out = {"coverage": covered / n_sets, "fwer": false_family / n_sets}
    return out | {f"power {d:.2f}": detected[d] / n_sets for d in DIFFERENCES}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sets", type=int, default=400)
    parser.add_argument("--boot", type=int, default=1000)
    args = parser.parse_args()
    for protocol in ("published", "folds"):
        start = time.perf_counter()
        found = run(protocol, args.sets, args.boot)
        cells = ", ".join(f"{k} {v:.3f}" for k, v in found.items())
        print(
            f"{protocol}: {args.sets} data sets, {args.boot} resamples: {cells} "
            f"({time.perf_counter() - start:.0f} s)"
        )


if __name__ == "__main__":
    main()

"""Bench: static features of every trial and dynamic HMM chains per adjective, first run vs cache.

``--rows`` instead times Table I rows A-F as one sweep per adjective, before and after the
fitted-chain cache, side by side: each row fits its features on the adjective's split,
transforms every trial and fits the object-CV linear SVM on the training trials (trial-level
features for every row, B and D included). "Before" refits the 16 chains in rows C, D, E and F
(no chain cache, as every job did); "after" shares a fresh chain cache across the six rows, so
row C fits the chains and D, E, F load them. The trial tables are built once beforehand, cached
in both cases. Prints the seconds of each row, both sweep totals and their ratio.

Targets (full default synthetic file, 600 trials): static features < 2 min (first run, reading
the file included); dynamic chains for 24 adjectives < 10 min. ``--adjectives N`` times N
adjectives and extrapolates to 24 (printed as such); ``--static-only`` stops after the static
figures. ``--cache-dir`` holds the synthetic data file (made there if missing); the feature
caches go to a fresh temporary folder, so the first run is a true one.

    .venv/bin/python bench/bench_baselines.py --cache-dir ~/.cache/tactile_exp --adjectives 3
    .venv/bin/python bench/bench_baselines.py --cache-dir ~/.cache/tactile_exp --rows --adjectives 1
"""

from __future__ import annotations

import argparse
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

from tactile_exp.baselines import features as feat
from tactile_exp.baselines.dynamic import DynamicFeatures
from tactile_exp.baselines.features import FEATURE_KINDS, BaselineFeatures
from tactile_exp.baselines.svm import ObjectCVLinearSVM
from tactile_exp.data.layout import ADJECTIVES, TrialName
from tactile_exp.data.phac2 import PHAC2
from tactile_exp.data.splits import make_split
from tactile_exp.data.synthetic import default_file


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--cache-dir", type=Path, default=Path(tempfile.gettempdir()) / "tactile_bench"
    )
    parser.add_argument("--adjectives", type=int, default=24, help="adjectives to fit (<= 24)")
    parser.add_argument("--grid", default="small")
    parser.add_argument("--static-only", action="store_true", help="skip the dynamic features")
    parser.add_argument("--rows", action="store_true", help="rows A-F before/after chain cache")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench_baselines_") as feature_cache:
        (rows if args.rows else run)(args, Path(feature_cache))


ROWS = {  # Table I row -> BaselineFeatures settings (conf/experiment/table1_[a-f]_*.yaml)
    "A": dict(features=("static",)),
    "B": dict(features=("static",)),
    "C": dict(features=("dynamic",)),
    "D": dict(features=("dynamic",)),
    "E": dict(features=("static", "dynamic")),
    "F": dict(features=("static", "dynamic"), dynamic_pool="object"),
}


def rows(args: argparse.Namespace, feature_cache: Path) -> None:
    data = PHAC2(default_file(args.cache_dir))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tables = args.cache_dir / "preprocessed"  # where the engine keeps them
        BaselineFeatures(
            data, features=FEATURE_KINDS, hmm_grid=args.grid, cache_dir=tables
        ).prepare()
    names = feat._trials(data)
    totals = {"before": 0.0, "after": 0.0}
    for adj in ADJECTIVES[: args.adjectives]:
        split = data.split(adj)
        train = list(split.train)
        y = np.array([split.labels[t] for t in train])
        groups = np.array([TrialName.parse(t).object_id for t in train])
        for when, chain_cache in (("before", None), ("after", feature_cache / adj)):
            seconds = {}
            for row, settings in ROWS.items():
                t0 = time.perf_counter()
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    bf = BaselineFeatures(
                        data, hmm_grid=args.grid, cache_dir=chain_cache, **settings
                    ).fit(split)
                    ObjectCVLinearSVM().fit(bf.transform(train), y, groups)
                    bf.transform(names)
                seconds[row] = time.perf_counter() - t0
            totals[when] += sum(seconds.values())
            per_row = ", ".join(f"{r} {s:.1f}" for r, s in seconds.items())
            print(f"  {adj} {when:>6}: rows {per_row} s; sweep {sum(seconds.values()):.1f} s")
    print(
        f"rows A-F, {args.adjectives} adjective(s): before {totals['before']:.1f} s, after "
        f"{totals['after']:.1f} s: x{totals['before'] / totals['after']:.1f} faster"
    )


def run(args: argparse.Namespace, feature_cache: Path) -> None:
    start = time.perf_counter()
    data = PHAC2(default_file(args.cache_dir))
    print(f"data: {data} ready in {time.perf_counter() - start:.1f} s")

    def tables(**kw) -> float:
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            feat.build_tables(data, cache_dir=feature_cache, **kw)
        return time.perf_counter() - t0

    n = len(data.trials)
    static_first = tables(static_f_max=100.0)
    feat._MEMO.clear()
    static_cached = tables(static_f_max=100.0)
    print(
        f"static features, {n} trials: first {static_first:.1f} s "
        f"({1e3 * static_first / n:.0f} ms/trial; target < 120 s), "
        f"cached {static_cached:.2f} s (x{static_first / static_cached:.0f} faster)"
    )
    if args.static_only:
        return
    lengths = DynamicFeatures.lengths(args.grid)
    seq_first = tables(lengths=lengths)
    feat._MEMO.clear()
    seq_cached = tables(lengths=lengths)
    print(
        f"HMM input table, {n} trials: first {seq_first:.1f} s, cached {seq_cached:.2f} s "
        f"(x{seq_first / seq_cached:.0f} faster)"
    )
    _, table = feat.build_tables(data, lengths=lengths, cache_dir=feature_cache)
    k = min(args.adjectives, len(ADJECTIVES))
    t0 = time.perf_counter()
    for adj in ADJECTIVES[:k]:
        t1 = time.perf_counter()
        model = DynamicFeatures(args.grid).fit(table, make_split(data, adj))
        model.transform(table, table.trials)
        print(
            f"  {adj}: 16 chains {time.perf_counter() - t1:.1f} s, first (N,T,K) {model.params_[0]}"
        )
    per_adj = (time.perf_counter() - t0) / k
    label = "measured" if k == len(ADJECTIVES) else f"extrapolated from {k}"
    print(
        f"dynamic chains ({args.grid} grid): {per_adj:.1f} s/adjective; 24 adjectives "
        f"{24 * per_adj / 60:.1f} min ({label}; target < 10 min)"
    )


if __name__ == "__main__":
    main()

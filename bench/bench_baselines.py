"""Bench: static features of every trial and dynamic HMM chains per adjective, first run vs cache.

``--rows`` instead times Table I rows A-F as one sweep per adjective, the plain code and the
fast one side by side (interleaved per adjective, in one process): each row fits its features on
the adjective's split, transforms the training and test trials and fits the object-CV linear SVM
on the training side; rows B and D pool each object's trial features (mean, as the engine's
``combine_instances=mean`` with all of an object's trials). "Before": no chain cache (rows C, D,
E, F each fit the 16 chains), the plain code the tests keep as oracles (``plain_paths`` of
``tests/baselines_oracles.py``: per-trial static PCA one trial-EP at a time, one pipeline per
(C, draw), per-call HMM scoring, chains fitted one after the other) and liblinear's SVM. "After"
shares a fresh chain cache across the six rows (row C fits, D, E, F reuse) with the package's
shortcuts and the Newton SVM (``SquaredHingeSVM``, the optimum of liblinear's objective). Prints
the seconds of each row, both sweep totals and their ratio, the rows where the chosen C differs
(liblinear stops short of the optimum at large C) and the largest test-AUC difference. Target
the sweep at least 3x faster after the change than before.

Targets (full default synthetic file, 600 trials): static features < 2 min (first run, reading
the file included); dynamic chains for 24 adjectives < 10 min. ``--adjectives N`` times N
adjectives and extrapolates to 24 (printed as such); ``--static-only`` stops after the static
figures. Last, the HMM EM of the last adjective's 16 chains: hmmlearn vs ours, same symbols.
``--cache-dir`` holds the synthetic data file (made there if missing); the feature
caches go to a fresh temporary folder, so the first run is a true one.

    .venv/bin/python bench/bench_baselines.py --cache-dir ~/.cache/tactile_exp --adjectives 3
    .venv/bin/python bench/bench_baselines.py --cache-dir ~/.cache/tactile_exp --rows --adjectives 1
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
from sklearn.metrics import roc_auc_score

from tactile_exp.baselines import dynamic as dyn
from tactile_exp.baselines import features as feat
from tactile_exp.baselines.dynamic import DynamicFeatures
from tactile_exp.baselines.features import FEATURE_KINDS, BaselineFeatures
from tactile_exp.data.layout import ADJECTIVES, Split, TrialName
from tactile_exp.data.phac2 import PHAC2
from tactile_exp.data.splits import make_split
from tactile_exp.data.synthetic import default_file
from tactile_exp.models.linear_svm import ObjectCVLinearSVM

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from baselines_oracles import plain_paths  # noqa: E402 (the oracles live beside the tests)


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


# Table I row -> (BaselineFeatures settings, whether the SVM sees one mean vector per object)
# as in conf/experiment/table1_[a-f]_*.yaml
ROWS: dict[str, tuple[dict, bool]] = {
    "A": (dict(features=("static",)), False),
    "B": (dict(features=("static",)), True),
    "C": (dict(features=("dynamic",)), False),
    "D": (dict(features=("dynamic",)), True),
    "E": (dict(features=("static", "dynamic")), False),
    "F": (dict(features=("static", "dynamic"), dynamic_pool="object"), False),
}


def rows(args: argparse.Namespace, feature_cache: Path) -> None:
    data = PHAC2(default_file(args.cache_dir))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tables = args.cache_dir / "preprocessed"  # where the engine keeps them
        BaselineFeatures(
            data, features=FEATURE_KINDS, hmm_grid=args.grid, cache_dir=tables
        ).prepare()
    totals = {"before": 0.0, "after": 0.0}
    per_row = {when: dict.fromkeys(ROWS, 0.0) for when in totals}
    other_c, auc_gap = [], 0.0
    for adj in ADJECTIVES[: args.adjectives]:
        split = make_split(data, adj)
        results = {}
        for when, chain_cache, solver in (
            ("before", None, "liblinear"),
            ("after", feature_cache / adj, "newton"),
        ):
            switch = plain_paths() if when == "before" else contextlib.nullcontext()
            with switch:
                seconds, results[when] = {}, {}
                for row, (settings, pool) in ROWS.items():
                    t0 = time.perf_counter()
                    results[when][row] = _row(
                        data, split, args.grid, chain_cache, settings, pool, solver
                    )
                    seconds[row] = time.perf_counter() - t0
            totals[when] += sum(seconds.values())
            for row in ROWS:
                per_row[when][row] += seconds[row]
            line = ", ".join(f"{r} {s:.1f}" for r, s in seconds.items())
            print(f"  {adj} {when:>6}: rows {line} s; sweep {sum(seconds.values()):.1f} s")
        for row in ROWS:
            (c0, auc0), (c1, auc1) = results["before"][row], results["after"][row]
            if c0 != c1:
                other_c.append(f"{adj} {row}: C {c0:g} -> {c1:g}, AUC {auc0:.3f} -> {auc1:.3f}")
            auc_gap = max(auc_gap, abs(auc0 - auc1))
    for row in ROWS:
        b, a = per_row["before"][row], per_row["after"][row]
        print(f"row {row}: before {b:.1f} s, after {a:.1f} s (x{b / a:.1f})")
    print(
        f"rows A-F, {args.adjectives} adjective(s): before {totals['before']:.1f} s, after "
        f"{totals['after']:.1f} s: x{totals['before'] / totals['after']:.1f} faster; chosen C "
        f"differs in {len(other_c)} of {len(ROWS) * args.adjectives} rows; largest test-AUC "
        f"difference {auc_gap:.2g}"
    )
    for line in other_c:
        print("  " + line)


def _row(
    data: PHAC2,
    split: Split,
    grid: str,
    chain_cache: Path | None,
    settings: dict,
    pool: bool,
    solver: str,
) -> tuple[float, float]:
    """One row on one adjective: (chosen C, test AUC)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        bf = BaselineFeatures(data, hmm_grid=grid, cache_dir=chain_cache, **settings).fit(split)
        sides = []
        for trials in (split.train, split.test):
            X = bf.transform(trials)
            y = np.array([split.labels[t] for t in trials])
            groups = np.array([TrialName.parse(t).object_id for t in trials])
            sides.append(_pool(X, y, groups) if pool else (X, y, groups))
        svm = ObjectCVLinearSVM(solver=solver).fit(*sides[0])
    X_test, y_test, _ = sides[1]
    return svm.C_, float(roc_auc_score(y_test, svm.decision_function(X_test)))


def _pool(
    X: np.ndarray, y: np.ndarray, groups: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One row per object: the mean of its trials' features (rows B and D)."""
    objects = np.unique(groups)
    first = [np.flatnonzero(groups == o)[0] for o in objects]
    return np.array([X[groups == o].mean(axis=0) for o in objects]), y[first], objects


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
    hmm_em_speed(table, model)


def hmm_em_speed(table, model: DynamicFeatures) -> None:
    """The 16 final chains' HMM fits of the last adjective: hmmlearn's CategoricalHMM vs
    ``fit_categorical_hmm`` on the same symbols, interleaved, and their largest difference."""
    from hmmlearn import hmm  # dev dependency: the reference the EM reproduces

    idx = table.index(model.fit_trials_)
    seconds, worst = {"hmmlearn": 0.0, "ours": 0.0}, 0.0
    for c, (chain, (n, T, k)) in enumerate(zip(model.chains_, model.params_, strict=True)):
        symbols = chain.symbols(table.seqs[T][c][idx])
        t0 = time.perf_counter()
        ref = hmm.CategoricalHMM(
            n_components=n,
            n_features=k,
            n_iter=dyn.HMM_ITER,
            tol=dyn.HMM_TOL,
            random_state=chain.seed,
            implementation="scaling",
        ).fit(symbols.reshape(-1, 1), lengths=[T] * len(symbols))
        t1 = time.perf_counter()
        ours = dyn.fit_categorical_hmm(symbols, n, k, seed=chain.seed)
        seconds["hmmlearn"] += t1 - t0
        seconds["ours"] += time.perf_counter() - t1
        theirs = (ref.startprob_, ref.transmat_, ref.emissionprob_)
        worst = max(worst, *(float(np.abs(a - b).max()) for a, b in zip(ours, theirs, strict=True)))
    print(
        f"HMM EM of the 16 final chains: hmmlearn {seconds['hmmlearn']:.2f} s, ours "
        f"{seconds['ours']:.2f} s ({seconds['hmmlearn'] / seconds['ours']:.1f}x); largest "
        f"parameter difference {worst:.1e}"
    )


if __name__ == "__main__":
    main()

"""Where is the haptic information: in signal levels or in their dynamics?

All feature sets come from the same ConvNet inputs: ``HapticPreprocessor`` (P1-P6) fitted on each
adjective's published training trials, both fingers, offset 0 of the 5 (the others are shifted
copies), i.e. (2, 32, 150) per trial. Per trial, per finger and channel:

- levels: mean and std over the 150 steps;
- diff: mean and std of the first difference (how fast a channel moves, not where it sits);
- shape: the channel with its own mean and std removed (level- and amplitude-free), described
  by the energy fractions of 5 frequency bands (squeeze pressure rise and relaxation, hold
  transients and slide vibration alike) and its 10 block means (the curve's shape);
- dynamics: diff + shape;
- flat: the whole flattened input (9,600 values).

Each: StandardScaler + LogisticRegression (C=0.1 for every set: one setting, no tuning on the
test objects), trained on the training trials, ROC AUC of the test trials (E1, E2). A set that
only sees dynamics scoring near chance while levels score high means a static generator.

    PYTHONPATH=$PWD .venv/bin/python bench/bench_dynamics.py [--file PATH] [--cache-dir DIR]
"""

from __future__ import annotations

import argparse
import itertools
import time
import warnings
from pathlib import Path

import numpy as np
from sklearn.linear_model import LogisticRegression
from sklearn.metrics import roc_auc_score
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from tactile_exp.data.layout import ADJECTIVES
from tactile_exp.data.phac2 import PHAC2, default_cache_dir
from tactile_exp.data.splits import SPLITS
from tactile_exp.data.synthetic import SyntheticSpec, default_file
from tactile_exp.preprocess.haptic import HapticPreprocessor, load_haptic_arrays

SETS = ("levels", "diff", "shape", "dynamics", "flat")
_BANDS = (1, 4, 10, 25, 50, 76)  # rFFT bin edges of a 150-step series: 5 bands
_BLOCKS = 10


def features(x: np.ndarray) -> dict[str, np.ndarray]:
    """(n, 2, 32, 150) preprocessed trials -> feature set name -> (n, d)."""
    n = len(x)
    d = np.diff(x, axis=-1)
    z = (x - x.mean(-1, keepdims=True)) / (x.std(-1, keepdims=True) + 1e-6)
    power = np.abs(np.fft.rfft(z, axis=-1)) ** 2
    bands = np.stack([power[..., a:b].sum(-1) for a, b in itertools.pairwise(_BANDS)], -1)
    bands /= bands.sum(-1, keepdims=True) + 1e-12
    blocks = z.reshape(*z.shape[:-1], _BLOCKS, -1).mean(-1)
    out = {
        "levels": np.concatenate([x.mean(-1), x.std(-1)], -1),
        "diff": np.concatenate([d.mean(-1), d.std(-1)], -1),
        "shape": np.concatenate([bands, blocks], -1),
        "flat": x,
    }
    out = {k: v.reshape(n, -1) for k, v in out.items()}
    out["dynamics"] = np.concatenate([out["diff"], out["shape"]], 1)
    return out


def auc(train_x, train_y, test_x, test_y) -> float:
    model = make_pipeline(StandardScaler(), LogisticRegression(C=0.1, max_iter=3000))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # convergence notes on the 9,600-d flat input
        model.fit(train_x, train_y)
    return float(roc_auc_score(test_y, model.decision_function(test_x)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--file", type=Path, default=None)
    ap.add_argument("--cache-dir", type=Path, default=None, help="default: $TACTILE_EXP_CACHE")
    ap.add_argument("--split", default="published")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    cache = args.cache_dir or default_cache_dir()
    path = args.file or default_file(cache, SyntheticSpec())
    start = time.perf_counter()
    data = PHAC2(path)
    arrays = load_haptic_arrays(data, steps=150, offsets=5, cache_dir=cache / "preprocessed")
    print(f"{data}: preprocessed arrays ready in {time.perf_counter() - start:.1f} s")

    print(f"{'adjective':<13}" + "".join(f"{s:>10}" for s in SETS))
    rows = {}
    for adj in ADJECTIVES:
        split = SPLITS[args.split](data, adj, args.seed)
        pre = HapticPreprocessor(arrays, n_components=4, per_finger=True).fit(split.train)
        parts = {}
        for part in ("train", "test"):
            names = getattr(split, part)
            x = pre.transform(names)[:, :, 0].astype(np.float64)  # offset 0: (n, 2, 32, 150)
            parts[part] = (features(x), np.array([split.labels[t] for t in names]))
        (ftr, ytr), (fte, yte) = parts["train"], parts["test"]
        rows[adj] = [auc(ftr[s], ytr, fte[s], yte) for s in SETS]
        print(f"{adj:<13}" + "".join(f"{v:10.3f}" for v in rows[adj]), flush=True)
    mean = np.mean(list(rows.values()), axis=0)
    print(f"{'mean':<13}" + "".join(f"{v:10.3f}" for v in mean))
    print(f"total {time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()

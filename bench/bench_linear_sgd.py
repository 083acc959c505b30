"""The classification layer's compiled SGD on the T4 head's shape: the row path against the Gram
path, side by side.

The head of a haptic ConvNet at combine=1 trains a one-output layer on 530 standardised rows of
24,320 features, batches of 32, lr 0.001, momentum 0.9: 200 logistic epochs, then 100 hinge
epochs (conf/schedule/paper.yaml's ``head``). Both stages run through ``linear_sgd_epochs`` on
the rows (``gram=False``: an epoch reads the 51.5 MB of features) and on their Gram matrix
(``gram=True``: G = X X^T once per stage, then epochs of n^2 in cache), interleaved (every
repetition times each item once, in turn, so load changes hit all of them alike; best of
``--repeats``). Also timed alone: G's product (with X w0, on one thread, as the fit computes
it), so that the Gram path's epochs are its fit less G, and G's cost reads as a number of
row-path epochs: the ``uses_gram`` rule wants it well below the stage's epochs.

The features are random (a label signal in five columns), so both stages learn and the hinge
stage's zero-gradient rows are skipped as in training; the figures also give the largest
difference of the two paths' weights.

Run: ``.venv/bin/python bench/bench_linear_sgd.py [--repeats 5] [--json
bench/results/bench_linear_sgd.json]``
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import torch
from torch import nn

from tactile_exp.models.linear_sgd import linear_sgd_epochs

N, D, BATCH, LR, MOMENTUM = 530, 24_320, 32, 0.001, 0.9
STAGES = (("logistic", 200), ("hinge", 100))


def _data() -> tuple[torch.Tensor, torch.Tensor]:
    rng = np.random.default_rng(0)
    X = rng.standard_normal((N, D), dtype=np.float32)
    y = (rng.random(N) > 0.5).astype(np.float32)
    X[y == 1, :5] += 0.5
    return torch.from_numpy(X), torch.from_numpy(y)


def _head(X: torch.Tensor, y: torch.Tensor, gram: bool) -> tuple[float, torch.Tensor]:
    """Both stages of the head from the same initial layer; (seconds, final weights)."""
    torch.manual_seed(0)
    layer = nn.Linear(X.shape[1], 1)
    generator = torch.Generator().manual_seed(0)
    start = time.perf_counter()
    for loss, epochs in STAGES:
        linear_sgd_epochs(
            layer,
            X,
            y,
            loss=loss,
            epochs=epochs,
            batch_size=BATCH,
            lr=LR,
            momentum=MOMENTUM,
            generator=generator,
            gram=gram,
        )
    return time.perf_counter() - start, layer.weight.detach().clone()


def _gram_product(X: torch.Tensor, w: torch.Tensor) -> float:
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        start = time.perf_counter()
        X @ X.T, X @ w
        return time.perf_counter() - start
    finally:
        torch.set_num_threads(threads)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--json", type=Path, default=None, help="also write the figures here")
    args = parser.parse_args()
    X, y = _data()
    _head(X[:40, :200], y[:40], False), _head(X[:40, :200], y[:40], True)  # compile
    best = {"rows": np.inf, "gram": np.inf, "G": np.inf}
    weights = {}
    for _ in range(args.repeats):
        for path in ("rows", "gram"):
            seconds, weights[path] = _head(X, y, path == "gram")
            best[path] = min(best[path], seconds)
        best["G"] = min(best["G"], _gram_product(X, X[0]))
    epochs = sum(e for _, e in STAGES)
    row_epoch = best["rows"] / epochs
    gram_epoch = (best["gram"] - len(STAGES) * best["G"]) / epochs
    gap = float((weights["gram"] - weights["rows"]).abs().max() / weights["rows"].abs().max())
    print(f"T4 head, {N} x {D}, batch {BATCH}, {STAGES}: best of {args.repeats}, interleaved")
    print(f"  row path:  {best['rows']:6.2f} s ({row_epoch * 1e3:6.2f} ms per epoch)")
    print(
        f"  Gram path: {best['gram']:6.2f} s ({gram_epoch * 1e3:6.3f} ms per epoch, "
        f"G {best['G'] * 1e3:.0f} ms per stage = {best['G'] / row_epoch:.1f} row-path epochs)"
    )
    print(
        f"  rows / Gram: x{best['rows'] / best['gram']:.1f} for the head, "
        f"x{row_epoch / gram_epoch:.0f} per epoch"
    )
    print(f"  largest weight difference / largest weight: {gap:.1e}")
    if args.json:
        from record import write

        figures = {
            "row path, head s": round(best["rows"], 2),
            "Gram path, head s": round(best["gram"], 2),
            "rows / Gram, head": round(best["rows"] / best["gram"], 1),
            "row path, ms per epoch": round(row_epoch * 1e3, 2),
            "Gram path, ms per epoch": round(gram_epoch * 1e3, 3),
            "rows / Gram, per epoch": round(row_epoch / gram_epoch),
            "G product, ms (one thread)": round(best["G"] * 1e3),
            "G product, in row-path epochs": round(best["G"] / row_epoch, 1),
            "largest weight difference / largest weight": float(f"{gap:.1e}"),
        }
        notes = (
            f"{N} x {D}, batch {BATCH}, 200 logistic + 100 hinge epochs, best of {args.repeats}, "
            "interleaved; shared machine: compare the ratios"
        )
        write(args.json, "bench_linear_sgd", figures, notes)


if __name__ == "__main__":
    main()

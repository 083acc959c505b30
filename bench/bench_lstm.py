"""Haptic LSTM (Table I row G) training speed on CPU: compiled kernels vs ``nn.LSTM``.

Both implementations train the same network from the same init at the paper's settings (hidden
10, FC(10), batch 1000, 5,300 x C x 150 instances per split); each is timed for whole epochs of
forward, backward and SGD step, alternating in one run so the ratio holds on a noisy machine
(the best of ``--repeats``). Prints per-epoch seconds, their ratio, the row G estimate they imply
(24 adjectives x 200 epochs; the 100 fine-tuning epochs train the output layer alone on features
computed once and are left out) and the largest difference in the loss curve of a short run.

Run: ``.venv/bin/python bench/bench_lstm.py [--repeats 2] [--threads N] [--channels 32 64]
[--json OUT]``
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import torch

from tactile_exp.models.haptic_lstm import LSTMBody
from tactile_exp.models.losses import LOSSES
from tactile_exp.train import sgd_epochs

N_TRAIN, STEPS, BATCH, ADJECTIVES, EPOCHS = 5300, 150, 1000, 24, 200
IMPLS = ("torch", "compiled")


def train(
    impl: str, X: torch.Tensor, y: torch.Tensor, epochs: int
) -> tuple[float, list[float], torch.Tensor]:
    """Seconds per epoch, the loss curve of ``epochs`` epochs from a fixed init and the trained
    network's scores of the first 100 rows."""
    torch.manual_seed(0)
    body = LSTMBody(X.shape[1], impl=impl)
    head = torch.nn.Linear(10, 1)
    start = time.perf_counter()
    curve = sgd_epochs(
        lambda X_, index: head(body(X_[index])).squeeze(1),
        [*body.parameters(), *head.parameters()],
        X,
        y,
        loss=LOSSES["logistic"],
        epochs=epochs,
        batch_size=BATCH,
        lr=0.01,
        momentum=0.9,
        generator=torch.Generator().manual_seed(0),
    )
    seconds = (time.perf_counter() - start) / epochs
    with torch.no_grad():
        return seconds, curve, head(body(X[:100])).squeeze(1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--threads", type=int, default=None, help="torch threads (default: all)")
    parser.add_argument("--channels", type=int, nargs="+", default=[32, 64])
    parser.add_argument("--json", type=Path, default=None, help="also write the figures here")
    args = parser.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads")
    rng = np.random.default_rng(0)
    figures: dict[str, float] = {}
    for channels in args.channels:
        X = torch.as_tensor(rng.standard_normal((N_TRAIN, channels, STEPS), dtype=np.float32))
        y = torch.as_tensor((rng.random(N_TRAIN) < 0.5).astype(np.float32))
        small = slice(0, 2 * BATCH)
        runs = {impl: train(impl, X[small], y[small], epochs=3) for impl in IMPLS}  # + warm-up
        (_, curve_a, scores_a), (_, curve_b, scores_b) = runs.values()
        loss_gap = max(abs(a - b) for a, b in zip(curve_a, curve_b, strict=True))
        score_gap = float((scores_a - scores_b).abs().max())
        best = dict.fromkeys(IMPLS, float("inf"))
        for _ in range(args.repeats):
            for impl in IMPLS:
                best[impl] = min(best[impl], train(impl, X, y, epochs=1)[0])
        for impl in IMPLS:
            hours = ADJECTIVES * EPOCHS * best[impl] / 3600
            print(f"C={channels} {impl:>8}: {best[impl]:.2f} s/epoch -> row G ~{hours:.1f} h")
        print(
            f"C={channels} compiled is x{best['torch'] / best['compiled']:.1f} faster; "
            f"after 3 epochs on 2,000 instances the loss curves differ by at most {loss_gap:.1e}, "
            f"the scores by {score_gap:.1e}"
        )
        for impl in IMPLS:
            figures[f"C={channels} {impl}, s/epoch"] = round(best[impl], 3)
        figures[f"C={channels} torch / compiled"] = round(best["torch"] / best["compiled"], 2)
        figures[f"C={channels} loss curve difference, 3 epochs"] = float(f"{loss_gap:.1e}")
    if args.json:
        from record import write

        threads = torch.get_num_threads()
        write(args.json, "bench_lstm", figures, f"best of {args.repeats}, {threads} threads")


if __name__ == "__main__":
    main()

"""Haptic CNN training speed: grouped convolution as batched matmul vs ``Conv1d(groups=32)``.

Everything is measured in one run, so the ratios hold even on a noisy machine. Prints:
1. one SGD step (batch 1000, 32 x 150 input) per implementation and lever: median of repeats;
2. each implementation's full epoch on full-size tensors (5,300 x 32 x 150, the paper's training set
   for one adjective) and the Table I row I estimate it implies: 24 adjectives x 200 epochs,
   plus the fine-tuning stage and feature extraction, measured, not assumed;
3. the AUC of the two implementations after a few epochs from the same init on one case.

Run: ``.venv/bin/python bench/bench_haptic_cnn.py [--repeats 5] [--threads 2]``
"""

from __future__ import annotations

import argparse
import statistics
import time
from contextlib import nullcontext

import numpy as np
import torch
from sklearn.metrics import roc_auc_score

from tactile_exp.data.layout import Instances
from tactile_exp.models.haptic_cnn import GroupedTemporalConvNet, HapticCNN
from tactile_exp.models.losses import LOSSES

N_TRAIN, CHANNELS, STEPS, BATCH = 5300, 32, 150, 1000
ADJECTIVES, EPOCHS, FINETUNE_EPOCHS = 24, 200, 100


def step_time(net_args: dict, repeats: int, bf16: bool = False) -> float:
    """Median seconds of one SGD step (forward, backward, update) at batch 1000."""
    torch.manual_seed(0)
    net = GroupedTemporalConvNet(CHANNELS, STEPS, **net_args)
    head = torch.nn.Linear(net.n_features, 1)
    params = [*net.parameters(), *head.parameters()]
    optimiser = torch.optim.SGD(params, lr=0.01, momentum=0.9)
    x, y = torch.randn(BATCH, CHANNELS, STEPS), (torch.rand(BATCH) > 0.5).float()
    autocast = torch.autocast("cpu", dtype=torch.bfloat16) if bf16 else nullcontext()
    times = []
    for _ in range(repeats + 1):  # the first step warms up
        start = time.perf_counter()
        with autocast:
            loss = LOSSES["logistic"](head(net(x)).squeeze(1).float(), y)
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
        times.append(time.perf_counter() - start)
    return statistics.median(times[1:])


def levers(repeats: int) -> None:
    """Each architecture: plain grouped Conv1d vs batched matmul, then bf16 on the default."""
    default = dict(kernel_sizes=(5, 5, 5), widths=(4, 4, 4), strides=(2, 2, 2))
    architectures = [
        ("default: k 5/5/5, width 4, stride 2", default),
        ("stride 1 (no time reduction)", {**default, "strides": (1, 1, 1)}),
        ("width 8 per group", {**default, "widths": (8, 8, 8)}),
        ("kernels 9/5/3", {**default, "kernel_sizes": (9, 5, 3)}),
    ]
    header = f"{'architecture':38s} {'conv1d ms':>10s} {'bmm ms':>8s} {'bmm inst/s':>11s}"
    print(header + f" {'bmm speed-up':>12s}")
    for name, arch in architectures:
        conv1d = step_time({**arch, "impl": "conv1d"}, repeats)
        bmm = step_time({**arch, "impl": "bmm"}, repeats)
        print(
            f"{name:38s} {conv1d * 1e3:10.1f} {bmm * 1e3:8.1f} {BATCH / bmm:11.0f} "
            f"{conv1d / bmm:11.1f}x"
        )
    fp32 = step_time(default, repeats)
    bf16 = step_time(default, repeats, bf16=True)
    print(f"default (conv1d), bf16 autocast: {bf16 * 1e3:.1f} ms vs float32 {fp32 * 1e3:.1f} ms")


def row_estimate(rng: np.random.Generator, impl: str) -> None:
    X = rng.standard_normal((N_TRAIN, CHANNELS, STEPS), dtype=np.float32)
    y = (rng.random(N_TRAIN) > 0.5).astype(int)
    train = Instances(X, y, np.zeros(N_TRAIN), np.zeros(N_TRAIN, dtype=int))
    timings = {}
    for epochs, finetune in ((1, 0), (3, 0), (1, 50)):
        model = HapticCNN(impl=impl, epochs=epochs, finetune_epochs=finetune, seed=0, device="cpu")
        start = time.perf_counter()
        model.fit(train)
        timings[(epochs, finetune)] = time.perf_counter() - start
    epoch = (timings[(3, 0)] - timings[(1, 0)]) / 2
    setup = timings[(1, 0)] - epoch
    finetune_epoch = (timings[(1, 50)] - timings[(1, 0)]) / 50
    per_adj = setup + EPOCHS * epoch + FINETUNE_EPOCHS * finetune_epoch
    print(
        f"\n{impl}: full-size fit, {N_TRAIN} instances: {epoch:.2f} s per epoch "
        f"({N_TRAIN / epoch:.0f} inst/s), setup {setup:.2f} s, "
        f"fine-tune {finetune_epoch * 1e3:.1f} ms per epoch"
    )
    print(
        f"row I estimate (extrapolated, not run): {ADJECTIVES} x ({EPOCHS} epochs + "
        f"{FINETUNE_EPOCHS} fine-tune epochs) = {ADJECTIVES * per_adj / 60:.1f} min "
        f"({per_adj:.0f} s per adjective)"
    )


def auc_equivalence(rng: np.random.Generator) -> None:
    n = 400
    X = rng.standard_normal((n, CHANNELS, STEPS), dtype=np.float32)
    y = (rng.random(n) > 0.5).astype(int)
    X[y == 1, 5, 40:80] *= 2.0
    train = Instances(X[:300], y[:300], np.zeros(300), np.zeros(300, dtype=int))
    aucs = {}
    for impl in ("bmm", "conv1d"):
        model = HapticCNN(impl=impl, epochs=5, finetune_epochs=5, batch_size=100, device="cpu")
        model.fit(train)
        aucs[impl] = roc_auc_score(y[300:], model.decision_function(X[300:]))
    diff = abs(aucs["bmm"] - aucs["conv1d"])
    print(f"\nAUC bmm {aucs['bmm']:.6f} conv1d {aucs['conv1d']:.6f} |diff| {diff:.2e}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads")
    levers(args.repeats)
    rng = np.random.default_rng(0)
    for impl in ("conv1d", "bmm"):
        row_estimate(rng, impl)
    auc_equivalence(rng)


if __name__ == "__main__":
    main()

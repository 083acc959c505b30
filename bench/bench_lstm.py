"""Haptic LSTM (Table I row G): one adjective's training at the paper's settings, the compiled
earlier kernels (``bench/lstm_before.py``) and now, side by side in one run.

Both train ``haptic_lstm`` (``impl=compiled``, seed 0) at the paper's settings (hidden 10,
FC(10), 200 logistic + 100 hinge epochs, batch 1000, lr 0.01, momentum 0.9) on the same data of
one adjective's size (5,300 training and 700 test instances x C x 150; positives, ~17%, carry a
level shift of one signal in noise), then score the test instances: what the engine does per
adjective. Prints each one's wall and CPU seconds, their ratios, both test AUCs and the largest
differences of the scores and the loss curves. On a shared machine the seconds vary from run
to run; the two are timed back to back (alternating with ``--repeats``, best of), so compare
their ratio.

``--data embedded`` trains on one adjective's row G instances of the embedded default instead
(``--adjective``, published split: the haptic modality's instances, as a job builds them). The
random signals make the kernels from before slower than the embedded data do (likely float32
denormals in their backward, which the kernels now flush), so the ratio on random data is larger
than the one a row G job sees: quote the embedded one for the grid.

The two kernels sum in different orders, so their gradients differ by float rounding (~4e-7
relative), and 200 epochs of SGD with momentum amplify that: the loss curves part after some
tens of epochs and the test AUCs differ by more than rounding. To show the size of that spread,
a third run trains the kernels from before on the training data moved by one float32 ulp
(``np.nextafter``): the AUC difference between the kernels is to be read against it.

Run: ``.venv/bin/python bench/bench_lstm.py [--data random|embedded] [--adjective hard]
[--repeats 1] [--channels 32] [--epochs 200] [--finetune-epochs 100] [--json OUT]``
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Iterator
from contextlib import contextmanager, nullcontext
from pathlib import Path

import lstm_before
import numpy as np
import torch
from sklearn.metrics import roc_auc_score

from tactile_exp.data.layout import Instances
from tactile_exp.models import MODELS, haptic_lstm, sgd
from tactile_exp.models.schedule import Schedule

N_TRAIN, N_TEST, STEPS, POSITIVE = 5300, 700, 150, 0.17
KERNELS = ("before", "now")
NUDGED = "before, data + 1 ulp"


def embedded(adjective: str) -> tuple[Instances, Instances]:
    """One adjective's training and test instances of row G on the embedded default (published
    split, the haptic modality at its defaults, fitted on the training trials)."""
    from tactile_exp.data.phac2 import PHAC2, default_cache_dir
    from tactile_exp.data.splits import make_split
    from tactile_exp.data.synthetic import default_file
    from tactile_exp.modalities import MODALITIES

    cache = default_cache_dir()
    dataset = PHAC2(default_file(cache))
    split = make_split(dataset, adjective)
    haptic = MODALITIES.build("haptic", cache_dir=cache / "preprocessed")
    haptic.check(dataset)
    train, test = split.trials("train", dataset), split.trials("test", dataset)
    haptic.fit(train)
    return haptic.transform(train), haptic.transform(test)


def instances(n: int, channels: int, rng: np.random.Generator) -> Instances:
    X = rng.standard_normal((n, channels, STEPS), dtype=np.float32)
    y = (rng.random(n) < POSITIVE).astype(int)
    X[y == 1, 3, STEPS * 3 // 4 :] += 0.5
    return Instances(X, y, np.array([f"t{i}" for i in range(n)]), np.arange(n) // 100)


@contextmanager
def kernels(which: str) -> Iterator[None]:
    """Train with the earlier kernels (the batch copied out of the training set, the FC layers
    and the loss through autograd, and torch's ops on all its threads, as the engine did then:
    those kernels' matrix products are torch's) or with the package's own."""
    if which == "now":
        yield
        return
    model = haptic_lstm.HapticLSTM
    package, threads = haptic_lstm.lstm_last_hidden, sgd.SGDModel._torch_threads
    step = model._train_step

    def before(x: torch.Tensor, lstm: torch.nn.LSTM, rows: torch.Tensor | None = None):
        return lstm_before.lstm_last_hidden(x if rows is None else x[rows], lstm)

    haptic_lstm.lstm_last_hidden = before
    sgd.SGDModel._torch_threads = lambda self: nullcontext()
    model._train_step = sgd.SGDModel._train_step  # the loss on the scores, as then
    try:
        yield
    finally:
        haptic_lstm.lstm_last_hidden, sgd.SGDModel._torch_threads = package, threads
        model._train_step = step


def train(
    which: str, train_set: Instances, test: Instances, epochs: int, finetune: int
) -> tuple[float, float, dict[str, list[float]], np.ndarray]:
    """Wall and CPU seconds of fit + scoring, the training history and the test scores."""
    schedule = Schedule(epochs=epochs, finetune_epochs=finetune)  # the paper's otherwise
    model = MODELS.build("haptic_lstm", impl="compiled", device="cpu", schedule=schedule)
    with kernels(which):
        wall, cpu = time.perf_counter(), time.process_time()
        history = model.fit(train_set)
        scores = model.decision_function(test.X)
        return time.perf_counter() - wall, time.process_time() - cpu, history, scores


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", choices=("random", "embedded"), default="random")
    parser.add_argument("--adjective", default="hard", help="--data embedded: whose split")
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--channels", type=int, default=32)
    parser.add_argument("--epochs", type=int, default=200)
    parser.add_argument("--finetune-epochs", type=int, default=100)
    parser.add_argument("--json", type=Path, default=None, help="also write the figures here")
    args = parser.parse_args()
    if args.data == "embedded":
        train_set, test = embedded(args.adjective)
    else:
        rng = np.random.default_rng(0)
        train_set = instances(N_TRAIN, args.channels, rng)
        test = instances(N_TEST, args.channels, rng)
    channels = train_set.X.shape[1]
    small = Instances(
        train_set.X[:200], train_set.y[:200], train_set.trial[:200], train_set.object_id[:200]
    )
    for which in KERNELS:  # compile (or load the compiled code) before timing
        train(which, small, test, epochs=1, finetune=1)
    best = {k: (float("inf"), float("inf")) for k in KERNELS}
    runs = {}
    for _ in range(args.repeats):
        for which in KERNELS:
            wall, cpu, history, scores = train(
                which, train_set, test, args.epochs, args.finetune_epochs
            )
            best[which] = (min(best[which][0], wall), min(best[which][1], cpu))
            runs[which] = (history, scores)
    nudged = Instances(
        np.nextafter(train_set.X, np.float32(np.inf)),
        train_set.y,
        train_set.trial,
        train_set.object_id,
    )
    runs[NUDGED] = train("before", nudged, test, args.epochs, args.finetune_epochs)[2:]
    aucs = {k: roc_auc_score(test.y, runs[k][1]) for k in runs}
    data = "random signals" if args.data == "random" else f"embedded default, {args.adjective}"
    score_gap = float(np.abs(runs["before"][1] - runs["now"][1]).max())
    curve_gap = max(
        float(np.abs(np.subtract(runs["before"][0][key], runs["now"][0][key])).max())
        for key in runs["now"][0]
    )
    print(
        f"one adjective ({data}), C={channels}, {args.epochs}+{args.finetune_epochs} epochs, "
        f"numba {lstm_before.numba.get_num_threads()} / torch {torch.get_num_threads()} threads"
    )
    for which in KERNELS:
        wall, cpu = best[which]
        print(f"{which:>6}: {wall:7.1f} s wall, {cpu:7.1f} s CPU, test AUC {aucs[which]:.4f}")
    wall_ratio = best["before"][0] / best["now"][0]
    cpu_ratio = best["before"][1] / best["now"][1]
    print(f"before / now: x{wall_ratio:.2f} wall, x{cpu_ratio:.2f} CPU")
    spread = abs(aucs["before"] - aucs[NUDGED])
    print(
        f"test AUCs differ by {abs(aucs['before'] - aucs['now']):.1e}, scores by at most "
        f"{score_gap:.1e}, loss curves by at most {curve_gap:.1e}; the kernels from before on "
        f"data moved by 1 ulp: test AUC {aucs[NUDGED]:.4f}, {spread:.1e} from theirs"
    )
    if args.json:
        from record import write

        figures = {
            "before, s wall": round(best["before"][0], 1),
            "now, s wall": round(best["now"][0], 1),
            "before / now, wall": round(wall_ratio, 2),
            "before / now, CPU": round(cpu_ratio, 2),
            "test AUC before": round(aucs["before"], 4),
            "test AUC now": round(aucs["now"], 4),
            "test AUC difference": float(f"{abs(aucs['before'] - aucs['now']):.1e}"),
            "largest score difference": float(f"{score_gap:.1e}"),
            "largest loss-curve difference": float(f"{curve_gap:.1e}"),
            "test AUC before, data + 1 ulp": round(aucs[NUDGED], 4),
            "test AUC difference, before vs before on data + 1 ulp": float(f"{spread:.1e}"),
        }
        notes = (
            f"one adjective ({data}) at C={channels}, {args.epochs}+{args.finetune_epochs} epochs, "
            f"best of {args.repeats}; shared machine: compare the ratios"
        )
        write(args.json, "bench_lstm", figures, notes)


if __name__ == "__main__":
    main()

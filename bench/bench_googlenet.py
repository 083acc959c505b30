"""GoogLeNet trunk speed on CPU (M3 features): NCHW against channels_last, and the Caffe layout
against the torchvision one, in one run.

Times ``pooled_features`` (inception (5a), average pooling, L2 normalisation; inference mode) on
random 224x224 images, batch 32, and prints images/s per memory format and layout and their
ratios, plus the one-pass cost of the visual modality on 530 photographs (PHAC-2) they imply.

Run: ``.venv/bin/python bench/bench_googlenet.py [--batches 4] [--threads 2] [--json OUT]``
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np
import torch

from tactile_exp.preprocess.trunk import (
    CaffeGoogLeNet,
    GoogLeNet,
    Trunk,
    pooled_features,
    xavier_init,
)

BATCH, SIZE, PHOTOGRAPHS = 32, 224, 530


def images_per_second(model: Trunk, x: np.ndarray, channels_last: bool, batches: int) -> float:
    """Median throughput over ``batches`` timed batches, after one warm-up batch."""
    times = []
    for _ in range(batches + 1):
        start = time.perf_counter()
        pooled_features(model, x, batch_size=BATCH, channels_last=channels_last)
        times.append(time.perf_counter() - start)
    return BATCH / statistics.median(times[1:])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batches", type=int, default=4, help="timed batches per format")
    parser.add_argument("--threads", type=int, default=2, help="torch CPU threads")
    parser.add_argument("--json", type=Path, default=None, help="also write the figures here")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    model = xavier_init(GoogLeNet(transform_input=True), seed=0).eval()
    x = np.random.default_rng(0).normal(size=(BATCH, 3, SIZE, SIZE)).astype(np.float32)
    same = np.abs(
        pooled_features(model, x[:4], channels_last=True)
        - pooled_features(model, x[:4], channels_last=False)
    ).max()
    print(f"GoogLeNet to inception (5a), batch {BATCH}, {SIZE}x{SIZE}, {args.threads} threads")
    print(f"max |channels_last - NCHW| feature difference: {same:.2e}")
    caffe = xavier_init(CaffeGoogLeNet(), seed=0).eval()
    rates = {}
    for name, net, channels_last in (
        ("NCHW", model, False),
        ("channels_last", model, True),
        ("caffe layout", caffe, True),
    ):
        rates[name] = images_per_second(net, x, channels_last, args.batches)
        print(f"{name:>14}: {rates[name]:6.1f} images/s")
    ratio = rates["channels_last"] / rates["NCHW"]
    print(f"channels_last / NCHW: {ratio:.2f}x")
    print(
        f"caffe / torchvision layout (both channels_last): "
        f"{rates['caffe layout'] / rates['channels_last']:.2f}x"
    )
    for name, rate in rates.items():
        print(f"one pass over {PHOTOGRAPHS} photographs, {name}: {PHOTOGRAPHS / rate:.0f} s")
    if args.json:
        from record import write

        figures = {f"{name}, images/s": round(rate, 1) for name, rate in rates.items()}
        figures["channels_last / NCHW"] = round(ratio, 2)
        figures["caffe / torchvision layout"] = round(
            rates["caffe layout"] / rates["channels_last"], 2
        )
        figures["max feature difference, channels_last vs NCHW"] = float(f"{same:.2e}")
        write(args.json, "bench_googlenet", figures, f"batch {BATCH}, {args.threads} threads")


if __name__ == "__main__":
    main()

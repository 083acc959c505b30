"""bench/bench_roofline_gpu.py's FLOP and traffic counts, which the CPU-only suite can check
(the timings need a CUDA GPU)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest
import torch

BENCH = Path(__file__).resolve().parent.parent / "bench" / "bench_roofline_gpu.py"
_spec = importlib.util.spec_from_file_location("bench_roofline_gpu", BENCH)
bench = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(bench)
cpu = bench.cpu


def test_every_timed_pass_has_its_flops():
    """Each pass the bench times has a FLOP count (a renamed or dropped count in
    bench_roofline.py failed the GPU run only after its ceilings were timed)."""
    timed = set(bench.pass_timers(torch.device("cpu"), 100))
    assert timed == set(bench.PASSES)
    assert set(bench.PASSES) <= set(bench.gflop())
    assert {n for n in bench.PASSES if n.startswith("convnet")} == set(bench.conv_gbytes())


def test_backward_flops_are_counted_from_the_shapes():
    """The LSTM's backward: 2 x 4H(C + H) (weight gradient) + 2 x 4H x H (the state's gradient)
    per step and instance; the ConvNet's: every layer's weight gradient, the input gradients of
    conv2 and conv3 and the head's two."""
    h, c = cpu.HIDDEN, cpu.CHANNELS
    lstm = (2 * 4 * h * (c + h) + 2 * 4 * h * h) * cpu.STEPS * cpu.BATCH / 1e9
    assert bench.gflop()["lstm backward"] == pytest.approx(lstm, rel=1e-12)
    convs = [
        2 * cpu.GROUPS * cpu.WIDTH * c_in * cpu.KERNEL * t_out * cpu.BATCH / 1e9
        for c_in, _, t_out in cpu.conv_layers()
    ]
    head = 2 * cpu.GROUPS * cpu.WIDTH * cpu.conv_layers()[-1][2] * cpu.BATCH / 1e9
    conv = sum(convs) + sum(convs[1:]) + 2 * head
    assert bench.gflop()["convnet backward"] == pytest.approx(conv, rel=1e-12)


def test_the_convnets_traffic_is_its_arrays_through_memory():
    """At the paper's shapes (32 x 150 in; 4 channels x 75, 38, 19 steps out per group) the
    forward moves 0.106 GB per 1000 rows and the backward 0.106: what the GPU run of the
    bench's docs page divides by."""
    gbytes = bench.conv_gbytes()
    assert [t for *_, t in cpu.conv_layers()] == [75, 38, 19]
    assert gbytes["convnet forward"] == pytest.approx(0.105984, rel=1e-9)
    assert gbytes["convnet backward"] == pytest.approx(0.10624, rel=1e-9)

"""The ConvNet's and the LSTM's training passes on a CUDA GPU against the GPU's roofline.

The GPU counterpart of ``bench_roofline.py``: the same shapes and the same useful FLOPs (imported
from it; a backward's are the forward+backward's less the forward's), the passes that
``device=cuda`` trains with (cuDNN's grouped ``conv1d`` through
``GroupedTemporalConvNet.scores`` with ``impl="torch"``; ``nn.LSTM``), float32 with TF32 off as
training runs them (``train.resolve_device``). In one run, interleaved, best of
``--repeats``, each timing closed by ``torch.cuda.synchronize``:

- ceilings: an 8192^3 float32 matrix product (IEEE, TF32 off) and a 1 GiB device-to-device copy
  (bytes read + written per second); a pass's attainable rate is the lower of the product's rate
  and the copy's times the pass's FLOP per byte (``conv_gbytes``: torch runs the ConvNet layer by
  layer through memory, where the CPU's fused training step keeps a tile's activations in cache);
- each pass at the paper's batch of 1000 (what a training step runs) and over the whole
  5,300-instance training set in one batch (where a pass has enough work to fill the GPU): at
  1000 rows the passes take tens of microseconds of arithmetic and the step is bound by kernel
  launches, not by the GPU's arithmetic or memory.

Run on a GPU machine: ``python bench/bench_roofline_gpu.py [--repeats 20] [--json OUT]``.
"""

from __future__ import annotations

import argparse
import itertools
import sys
import time
from collections.abc import Callable
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).parent))
import bench_roofline as cpu  # noqa: E402  (the shapes and FLOP counts)

MATMUL = 8192
COPY_GIB = 1
PASSES = tuple(
    f"{net} {part}"
    for net in ("convnet", "lstm")
    for part in ("forward", "backward", "forward+backward")
)
SGEMM = f"sgemm {MATMUL}^3 (float32, TF32 off)"
COPY = f"copy {COPY_GIB} GiB (device to device)"


def _timed(fn: Callable[[], object]) -> Callable[[], float]:
    def timer() -> float:
        torch.cuda.synchronize()
        start = time.perf_counter()
        fn()
        torch.cuda.synchronize()
        return time.perf_counter() - start

    return timer


def ceilings(device: torch.device) -> tuple[dict[str, Callable[[], float]], dict[str, float]]:
    """Timers and their work (GFLOP, or GB moved for the copy) of the two ceilings."""
    a = torch.randn(MATMUL, MATMUL, device=device)
    src = torch.empty(COPY_GIB * 2**30 // 4, device=device)
    dst = torch.empty_like(src)
    timers = {SGEMM: _timed(lambda: torch.mm(a, a)), COPY: _timed(lambda: dst.copy_(src))}
    work = {SGEMM: 2 * MATMUL**3 / 1e9, COPY: 2 * COPY_GIB * 2**30 / 1e9}
    return timers, work


def gflop() -> dict[str, float]:
    """Useful GFLOP per pass of 1000 rows, counted as bench_roofline.py counts them."""
    flops = {**cpu.conv_gflop(), **cpu.lstm_gflop()}
    for net in ("convnet", "lstm"):
        flops[f"{net} backward"] = flops[f"{net} forward+backward"] - flops[f"{net} forward"]
    return flops


def conv_gbytes() -> dict[str, float]:
    """GB the ConvNet's passes must move to and from GPU memory per 1000 rows, float32: the
    forward reads the batch and writes the layout's input and each layer's output; the backward
    reads each back and writes and reads the last layer's gradient (a lower bound: the inner
    layers' gradients go through memory too)."""
    rows = cpu.BATCH * 4 / 1e9
    sizes = [cpu.CHANNELS * cpu.STEPS * rows]  # the layout's input
    sizes += [cpu.GROUPS * cpu.WIDTH * t_out * rows for *_, t_out in cpu.conv_layers()]
    forward = sizes[0] + sum(sizes)
    backward = sum(sizes) + 2 * sizes[-1]
    return {
        "convnet forward": forward,
        "convnet backward": backward,
        "convnet forward+backward": forward + backward,
    }


def pass_timers(device: torch.device, batch: int) -> dict[str, Callable[[], float]]:
    """Forward, backward and both of the ConvNet and the LSTM at ``batch`` rows, each call on
    the next batch of one shuffled epoch of the training set kept on the GPU."""
    from tactile_exp.models.haptic_cnn import GroupedTemporalConvNet

    torch.manual_seed(0)
    X = torch.randn(cpu.N_TRAIN, cpu.CHANNELS, cpu.STEPS, device=device)
    order = torch.randperm(cpu.N_TRAIN, device=device).split(batch)
    epoch = itertools.cycle(order[: max(1, cpu.N_TRAIN // batch)])
    net = GroupedTemporalConvNet(cpu.CHANNELS, cpu.STEPS, impl="torch").to(device)
    head = torch.nn.Linear(net.n_features, 1).to(device)
    lstm = torch.nn.LSTM(cpu.CHANNELS, cpu.HIDDEN, batch_first=True).to(device)
    g_scores = torch.randn(batch, device=device)
    g_hidden = torch.randn(batch, cpu.HIDDEN, device=device)

    def conv_forward() -> torch.Tensor:
        return net.scores(X, head, rows=next(epoch))

    def lstm_forward() -> torch.Tensor:
        return lstm(X[next(epoch)].transpose(1, 2))[1][0][-1]

    def backward_of(forward: Callable[[], torch.Tensor], grad: torch.Tensor) -> Callable:
        def timer() -> float:
            out = forward()
            return _timed(lambda: out.backward(grad))()

        return timer

    return {
        "convnet forward": _timed(conv_forward),
        "convnet backward": backward_of(conv_forward, g_scores),
        "convnet forward+backward": _timed(lambda: conv_forward().backward(g_scores)),
        "lstm forward": _timed(lstm_forward),
        "lstm backward": backward_of(lstm_forward, g_hidden),
        "lstm forward+backward": _timed(lambda: lstm_forward().backward(g_hidden)),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--json", type=Path, default=None, help="also write the figures here")
    args = parser.parse_args()
    if not torch.cuda.is_available():
        raise SystemExit("error: bench_roofline_gpu needs a CUDA GPU (torch sees none)")
    from tactile_exp.train import resolve_device

    device = resolve_device("cuda")  # TF32 off, as a training job on the GPU
    timers, work = ceilings(device)
    batches = (cpu.BATCH, cpu.N_TRAIN)
    scale = {b: b / cpu.BATCH for b in batches}  # FLOP counts are per 1000 rows
    flops = gflop()
    passes = list(PASSES)
    for b in batches:
        for name, timer in pass_timers(device, b).items():
            timers[f"{name}, batch {b}"] = timer
            work[f"{name}, batch {b}"] = flops[name] * scale[b]
    # No pause between timings: one process, and each timing ends synchronised with the GPU.
    walls = {n: (lambda t=t: (t(), 0.0)) for n, t in timers.items()}
    best = cpu.interleaved(walls, args.repeats, settle_s=0.0)
    seconds = {n: wall for n, (wall, _) in best.items()}
    peak = work[SGEMM] / seconds[SGEMM]
    bandwidth = work[COPY] / seconds[COPY]
    props = torch.cuda.get_device_properties(device)
    print(
        f"{props.name}, torch {torch.__version__}, best of {args.repeats} (interleaved): "
        f"sgemm {peak:.0f} GFLOP/s, copy {bandwidth:.0f} GB/s"
    )
    print(f"{'':40s} {'ms':>9s} {'GFLOP/s':>9s} {'% sgemm':>8s} {'% attainable':>12s}")
    figures: dict[str, float] = {
        "sgemm float32 (TF32 off), GFLOP/s": round(peak, 1),
        "copy device to device, GB/s": round(bandwidth, 1),
    }
    gbytes = conv_gbytes()
    for b in batches:
        for name in passes:
            key = f"{name}, batch {b}"
            rate = work[key] / seconds[key]
            bound = peak
            if name in gbytes:  # the LSTM's traffic is not modelled: held against sgemm only
                bound = min(peak, bandwidth * flops[name] / gbytes[name])
            share, attainable = 100 * rate / peak, 100 * rate / bound
            print(
                f"{key:40s} {seconds[key] * 1e3:9.3f} {rate:9.1f} {share:7.2f}% {attainable:11.2f}%"
            )
            figures[f"{key}, ms"] = round(seconds[key] * 1e3, 3)
            figures[f"{key}, GFLOP/s"] = round(rate, 1)
            figures[f"{key}, % of sgemm"] = round(share, 2)
            if name in gbytes:
                figures[f"{key}, % of attainable"] = round(attainable, 2)
    if args.json:
        from record import write

        notes = (
            f"{props.name}; best of {args.repeats} interleaved; float32, TF32 off (as training "
            "on the GPU); FLOPs and memory traffic counted as bench_roofline.py counts them; "
            "attainable: the lower of sgemm and the copy's GB/s x the pass's FLOP per byte"
        )
        write(args.json, "bench_roofline_gpu", figures, notes)


if __name__ == "__main__":
    main()

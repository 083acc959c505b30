"""Haptic CNN training speed on CPU: compiled numba kernels vs ``F.conv1d(groups=32)``.

Everything is measured in one run, the two implementations interleaved, so the ratios hold even
on a shared machine. Prints:
1. the first-use compile time (a fresh numba cache in a subprocess) and the cached load time;
2. training throughput (forward, backward, SGD step; default architecture, batch 1000) of both
   through the same step as ``HapticCNN`` (``net.batch_step``: compiled, the whole step, loss
   included, in tiles of instances in cache), in wall and CPU time per step, and the ratio;
3. each whole-batch layer kernel's GFLOP/s at batch 1000 (the stack that scores), the tiled
   training step's, beside torch's dense matmul (sgemm) rate;
4. each implementation's full epoch on full-size tensors (5,300 x 32 x 150, the paper's training
   set for one adjective) and the Table I row I estimate it implies: 24 adjectives x (200 epochs
   + 100 fine-tuning epochs + the T4 head on combined units) + setup, measured, not assumed, plus
   the compile time once (the job adds data loading, transforms, scoring and logging: time it
   with ``python -m tactile_exp experiment=table1_i_haptic_cnn_1trial``);
5. the AUC of the two implementations after a few epochs from the same init on one case;
6. the plainest well-written torch of the same architecture and data size (``plain_torch``:
   ``F.conv1d(groups=32)`` on inputs already laid out by group, SGD, batch 1000, 5,300 instances,
   ``torch.set_num_threads``), its epoch timed as the difference of two epoch counts, and the
   ratio to the compiled ``HapticCNN``'s epoch (a row H job's), the two timed interleaved.

Run: ``.venv/bin/python bench/bench_haptic_cnn.py [--repeats 7] [--threads 2] [--json OUT]``
(``--json``: the headline figures with the machine and the date, ``bench/record.py``).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from sklearn.metrics import roc_auc_score

from tactile_exp.data.layout import Instances
from tactile_exp.models import grouped_conv_autograd as backward
from tactile_exp.models import grouped_conv_numba as kernels
from tactile_exp.models.haptic_cnn import GroupedTemporalConvNet, HapticCNN
from tactile_exp.models.schedule import Schedule

N_TRAIN, CHANNELS, STEPS, BATCH = 5300, 32, 150, 1000
ADJECTIVES, EPOCHS, FINETUNE_EPOCHS = 24, 200, 100
HEAD_SCHEDULE = Schedule(epochs=200, finetune_epochs=100, batch_size=32, lr=0.001)  # schedule.head
IMPLS = ("torch", "compiled")


def sgd_step(impl: str) -> Callable[[], None]:
    """One SGD step (forward, backward, update) of the default net + linear head at batch 1000,
    on a fresh shuffled batch of a full-size training set each step, as ``HapticCNN`` trains."""
    torch.manual_seed(0)
    net = GroupedTemporalConvNet(CHANNELS, STEPS, impl=impl)
    head = torch.nn.Linear(net.n_features, 1)
    optimiser = torch.optim.SGD([*net.parameters(), *head.parameters()], lr=0.01, momentum=0.9)
    X, y = torch.randn(N_TRAIN, CHANNELS, STEPS), (torch.rand(N_TRAIN) > 0.5).float()

    def step() -> None:  # HapticCNN's stage 1 step (compiled: in tiles, the loss included)
        rows = torch.randperm(N_TRAIN)[:BATCH]
        optimiser.zero_grad()
        net.batch_step(X, y, head, "logistic", rows)
        optimiser.step()

    return step


def throughput(repeats: int, figures: dict[str, float]) -> float:
    """Prints both implementations' steps, interleaved; returns the wall-time speed-up."""
    steps = {impl: sgd_step(impl) for impl in IMPLS}
    wall: dict[str, list[float]] = {impl: [] for impl in IMPLS}
    cpu: dict[str, list[float]] = {impl: [] for impl in IMPLS}
    for impl in IMPLS:
        steps[impl]()  # warm-up (and the compiled kernels' cache load)
    for _ in range(repeats):
        for impl in IMPLS:
            start, start_cpu = time.perf_counter(), time.process_time()
            steps[impl]()
            wall[impl].append(time.perf_counter() - start)
            cpu[impl].append(time.process_time() - start_cpu)
    print(f"\n2. training step, default net, batch {BATCH}, median of {repeats} (interleaved)")
    for impl in IMPLS:
        step_wall, step_cpu = statistics.median(wall[impl]), statistics.median(cpu[impl])
        print(
            f"   {impl:9s} {step_wall * 1e3:7.1f} ms/step wall, {BATCH / step_wall:7.0f} inst/s; "
            f"{step_cpu * 1e3:7.1f} ms CPU time/step"
        )
    ratio = statistics.median(wall["torch"]) / statistics.median(wall["compiled"])
    cpu_ratio = statistics.median(cpu["torch"]) / statistics.median(cpu["compiled"])
    print(f"   compiled / torch throughput: {ratio:.1f}x wall time, {cpu_ratio:.1f}x CPU time")
    for impl in IMPLS:
        figures[f"training step, {impl}, ms wall"] = round(statistics.median(wall[impl]) * 1e3, 1)
    figures["training step, compiled / torch throughput, wall"] = round(ratio, 2)
    figures["training step, compiled / torch throughput, CPU time"] = round(cpu_ratio, 2)
    return ratio


def best_time(fn: Callable[..., object], args: tuple, repeats: int) -> tuple[float, float]:
    """Best wall seconds and best CPU seconds (all threads) of one call, over ``repeats``."""
    fn(*args)
    wall, cpu = [], []
    for _ in range(repeats):
        start, start_cpu = time.perf_counter(), time.process_time()
        fn(*args)
        wall.append(time.perf_counter() - start)
        cpu.append(time.process_time() - start_cpu)
    return min(wall), min(cpu)


def rate(gflop: float, times: tuple[float, float]) -> str:
    wall, cpu = times
    return f"{wall * 1e3:.1f} ms = {gflop / wall:.1f} wall, {gflop / cpu:.1f} per core"


@kernels.numba.njit(parallel=True)
def _all_groups_forward(x, w, b, stride, out):
    for g in kernels.numba.prange(x.shape[0]):
        kernels._conv_relu(x[g], w[g], b[g], stride, out[g])


@kernels.numba.njit(parallel=True)
def _all_groups_grad_weight(grad, x, stride, grad_w, grad_b):
    for g in kernels.numba.prange(x.shape[0]):
        backward._grad_weight_bias(grad[g], x[g], stride, grad_w[g], grad_b[g])


@kernels.numba.njit(parallel=True)
def _all_groups_grad_input(grad, w, stride, y, work):
    for g in kernels.numba.prange(grad.shape[0]):
        backward._conv_grad_input(grad[g], w[g], stride, y[g], work[kernels.numba.get_thread_id()])


def kernel_rates(repeats: int) -> None:
    """GFLOP/s of each layer's compiled kernels at batch 1000 (best of ``repeats``), each run
    alone over all 32 groups (in training one task per group runs them all in sequence, so
    these rates are a lower bound), the fused forward and backward of the whole stack with the
    classification layer, and a 2000 x 2000 sgemm, in the same run and threads: per wall
    second and per CPU second (the rate of one core while it runs, less sensitive to load)."""
    n, groups = BATCH, 32
    n_pad = -(-n // kernels.LANES) * kernels.LANES
    threads = kernels.numba.get_num_threads()
    rng = np.random.default_rng(0)
    print(f"\n3. GFLOP/s at batch {BATCH} (best of {repeats}; 2 FLOP per FMA)")
    c_in, length, layer_gflop = 1, STEPS, []
    for layer in (1, 2, 3):
        t_out = kernels.conv_out_len(length, 5, 2)
        x = rng.standard_normal((groups, c_in, length, n_pad), dtype=np.float32)
        w = rng.standard_normal((groups, 4, c_in, 5), dtype=np.float32)
        b = np.zeros((groups, 4), np.float32)
        out = np.empty((groups, 4, t_out, n_pad), np.float32)
        grad = rng.standard_normal(out.shape, dtype=np.float32)
        grad_w, grad_b = np.empty_like(w), np.empty_like(b)
        work = np.empty((threads, *x.shape[1:]), np.float32)
        gflop = 2 * groups * 4 * c_in * 5 * t_out * n / 1e9
        layer_gflop.append(gflop)
        rates = {
            "forward+ReLU": best_time(_all_groups_forward, (x, w, b, 2, out), repeats),
            "weight+bias grad": best_time(
                _all_groups_grad_weight, (grad, x, 2, grad_w, grad_b), repeats
            ),
        }
        if layer > 1:  # conv1's input needs no gradient
            rates["ReLU-masked input grad"] = best_time(
                _all_groups_grad_input, (grad, w, 2, x, work), repeats
            )
        print(f"   conv{layer} ({c_in}->4 per group, {gflop * 1e3:.0f} MFLOP):")
        for name, times in rates.items():
            print(f"     {name:28s} {rate(gflop, times)}")
        c_in, length = 4, t_out
    net_gflop = sum(layer_gflop)
    step_gflop = 3 * net_gflop - layer_gflop[0]  # forward, weight grads, input grads but conv1's
    x, y = torch.randn(N_TRAIN, CHANNELS, STEPS), (torch.rand(N_TRAIN) > 0.5).float()
    net = GroupedTemporalConvNet(CHANNELS, STEPS, impl="compiled")
    head = torch.nn.Linear(net.n_features, 1)

    def tiled() -> None:
        net.batch_step(x, y, head, "logistic", torch.randperm(N_TRAIN)[:BATCH])

    whole = best_time(tiled, (), repeats)
    print(f"   {'tiled training step, fwd + bwd':32s} {rate(step_gflop, whole)}")
    x, net = torch.randn(BATCH, CHANNELS, STEPS), GroupedTemporalConvNet(CHANNELS, STEPS)
    net.impl = "torch"
    with torch.no_grad():
        conv1d = best_time(net, (x,), repeats)
    a = torch.randn(2000, 2000)
    sgemm = best_time(torch.mm, (a, a), repeats)
    print(f"   {'dense matmul, torch sgemm 2000^3':32s} {rate(2 * 2000**3 / 1e9, sgemm)}")
    print(f"   {'torch F.conv1d(groups=32) fwd':32s} {rate(net_gflop, conv1d)}")


def compile_time(figures: dict[str, float]) -> float:
    """Seconds for the first compiled forward + backward (the scoring stack's and the tiled
    training step's) with an empty numba cache (fresh process), then with the cache that run
    left."""
    code = (
        "import time, torch; from tactile_exp.models.haptic_cnn import GroupedTemporalConvNet; "
        "net = GroupedTemporalConvNet(32, 20); x = torch.randn(3, 32, 20); "
        "head = torch.nn.Linear(net.n_features, 1); y = torch.tensor([0.0, 1.0, 1.0]); "
        "start = time.perf_counter(); net(x).sum().backward(); "
        "net.batch_step(x, y, head, 'logistic', torch.arange(3)); "
        "print(time.perf_counter() - start)"
    )
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache}
        first, cached = (
            float(
                subprocess.run(
                    [sys.executable, "-c", code],
                    env=env,
                    capture_output=True,
                    text=True,
                    check=True,
                ).stdout
            )
            for _ in range(2)
        )
    print(f"1. first use: compile {first:.1f} s (once per machine); cached load {cached:.1f} s")
    figures["first-use compile, s"] = round(first, 1)
    figures["cached kernel load, s"] = round(cached, 1)
    return first


def row_estimate(
    rng: np.random.Generator, impl: str, compile_s: float, figures: dict[str, float]
) -> None:
    X = rng.standard_normal((N_TRAIN, CHANNELS, STEPS), dtype=np.float32)
    y = (rng.random(N_TRAIN) > 0.5).astype(int)
    train = Instances(X, y, np.zeros(N_TRAIN), np.zeros(N_TRAIN, dtype=int))
    timings = {}
    # The first fit pays one-off allocations; epochs and fine-tuning epochs are differences of
    # fits 5 and 50 epochs apart, so one slow epoch moves them little.
    for epochs, finetune in ((1, 0), (1, 0), (6, 0), (1, 50)):
        model = HapticCNN(impl=impl, schedule=Schedule(epochs, finetune), seed=0, device="cpu")
        start = time.perf_counter()
        model.fit(train)
        timings[(epochs, finetune)] = time.perf_counter() - start
    epoch = (timings[(6, 0)] - timings[(1, 0)]) / 5
    setup = timings[(1, 0)] - epoch
    finetune_epoch = (timings[(1, 50)] - timings[(1, 0)]) / 50
    head = head_fit(rng, impl)
    per_adj = setup + EPOCHS * epoch + FINETUNE_EPOCHS * finetune_epoch + head
    total = ADJECTIVES * per_adj + (compile_s if impl == "compiled" else 0.0)
    print(
        f"   {impl:9s} {epoch:.2f} s per epoch ({N_TRAIN / epoch:.0f} inst/s), setup "
        f"{setup:.2f} s, fine-tune {finetune_epoch * 1e3:.1f} ms per epoch, T4 head {head:.1f} s"
        f" -> row I {total / 60:.1f} min ({per_adj:.0f} s per adjective"
        f"{', + compile once' if impl == 'compiled' else ''})"
    )
    figures[f"full-size epoch, {impl}, s"] = round(epoch, 2)
    figures[f"row I estimate at the paper's settings, {impl}, min"] = round(total / 60, 1)


def head_fit(rng: np.random.Generator, impl: str) -> float:
    """Seconds to train row I's T4 head (``model.head()``: the classification layer retrained on
    the 530 training units of 2 fingers x 5 offsets x conv3, 24,320 columns; conf/schedule's
    ``head``: 200 + 100 epochs, batch 32) through ``impl``'s layer-only SGD."""
    units = N_TRAIN // 10
    X = np.maximum(rng.standard_normal((units, 10 * 2432), dtype=np.float32), 0)  # ReLU'd
    train = Instances(X, (rng.random(units) > 0.8).astype(int), np.zeros(units), np.zeros(units))
    head = HapticCNN(impl=impl, device="cpu", schedule=Schedule(head=HEAD_SCHEDULE)).head()
    start = time.perf_counter()
    head.fit(train)
    return time.perf_counter() - start


def auc_equivalence(rng: np.random.Generator, figures: dict[str, float]) -> None:
    n = 400
    X = rng.standard_normal((n, CHANNELS, STEPS), dtype=np.float32)
    y = (rng.random(n) > 0.5).astype(int)
    X[y == 1, 5, 40:80] *= 2.0
    train = Instances(X[:300], y[:300], np.zeros(300), np.zeros(300, dtype=int))
    aucs = {}
    for impl in IMPLS:
        model = HapticCNN(
            impl=impl, schedule=Schedule(epochs=5, finetune_epochs=5, batch_size=100), device="cpu"
        )
        model.fit(train)
        aucs[impl] = roc_auc_score(y[300:], model.decision_function(X[300:]))
    diff = abs(aucs["compiled"] - aucs["torch"])
    print(f"\n5. AUC compiled {aucs['compiled']:.6f} torch {aucs['torch']:.6f} |diff| {diff:.2e}")
    figures["AUC after 5 + 5 epochs, |compiled - torch|"] = float(f"{diff:.2e}")


def plain_torch(epochs: int) -> float:
    """Seconds for ``epochs`` epochs of the default architecture written as plain torch: three
    ``F.conv1d(groups=32)`` + ReLU layers (kernel 5, stride 2, 4 channels per group), a linear
    classification layer, logistic loss, SGD with momentum, shuffled batches of 1000. The input
    is made in the grouped layout ``F.conv1d`` wants; nothing else is arranged for it."""
    torch.manual_seed(0)
    X, y = torch.randn(N_TRAIN, CHANNELS, STEPS), (torch.rand(N_TRAIN) > 0.5).float()
    shapes, length = [(4 * CHANNELS, 1, 5), (4 * CHANNELS, 4, 5), (4 * CHANNELS, 4, 5)], STEPS
    weights = [torch.nn.init.xavier_uniform_(torch.empty(s)).requires_grad_() for s in shapes]
    biases = [torch.zeros(s[0], requires_grad=True) for s in shapes]
    for _ in shapes:
        length = (length + 2 * 2 - 5) // 2 + 1
    head = torch.nn.Linear(4 * CHANNELS * length, 1)
    optimiser = torch.optim.SGD([*weights, *biases, *head.parameters()], lr=0.01, momentum=0.9)
    start = time.perf_counter()
    for _ in range(epochs):
        for rows in torch.randperm(N_TRAIN).split(BATCH):
            h = X[rows]
            for w, b in zip(weights, biases, strict=True):
                h = F.conv1d(h, w, b, stride=2, padding=2, groups=CHANNELS).relu()
            logits = head(h.flatten(1)).squeeze(1)
            loss = F.binary_cross_entropy_with_logits(logits, y[rows])
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
    return time.perf_counter() - start


def compiled_fit(train: Instances, epochs: int) -> float:
    """Seconds of a compiled ``HapticCNN`` fit of ``epochs`` epochs (no fine-tuning): a row H
    job's training."""
    model = HapticCNN(impl="compiled", schedule=Schedule(epochs, 0), seed=0, device="cpu")
    start = time.perf_counter()
    model.fit(train)
    return time.perf_counter() - start


def plain_torch_ratio(rng: np.random.Generator, figures: dict[str, float]) -> None:
    """Plain torch's epoch against the compiled HapticCNN's, both as the difference of 6- and
    1-epoch runs (one-off costs cancel), the two interleaved so load changes hit both."""
    X = rng.standard_normal((N_TRAIN, CHANNELS, STEPS), dtype=np.float32)
    y = (rng.random(N_TRAIN) > 0.5).astype(int)
    train = Instances(X, y, np.zeros(N_TRAIN), np.zeros(N_TRAIN, dtype=int))
    runs = {"plain torch": plain_torch, "compiled": lambda n: compiled_fit(train, n)}
    times: dict[str, dict[int, list[float]]] = {name: {1: [], 6: []} for name in runs}
    for fit in runs.values():
        fit(1)  # warm-up: allocator, thread pool, kernels
    for epochs in (1, 6, 1, 6):
        for name, fit in runs.items():
            times[name][epochs].append(fit(epochs))
    epoch = {name: (statistics.mean(t[6]) - statistics.mean(t[1])) / 5 for name, t in times.items()}
    ratio = epoch["plain torch"] / epoch["compiled"]
    print(f"\n6. plain torch (F.conv1d(groups={CHANNELS}), SGD, batch {BATCH}, {N_TRAIN} inst)")
    print(
        f"   {epoch['plain torch']:.2f} s per epoch; the compiled HapticCNN's "
        f"{epoch['compiled']:.2f} s (interleaved): {ratio:.1f}x"
    )
    figures["full-size epoch, plain torch reference, s"] = round(epoch["plain torch"], 2)
    figures["full-size epoch, compiled, interleaved with plain torch, s"] = round(
        epoch["compiled"], 2
    )
    figures["full-size epoch, plain torch / compiled"] = round(ratio, 2)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--json", type=Path, default=None, help="also write the figures here")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    kernels.numba.set_num_threads(args.threads)
    print(
        f"torch {torch.__version__}, numba {kernels.numba.__version__} "
        f"({kernels.numba.config.THREADING_LAYER}), {args.threads} threads, "
        f"load average {os.getloadavg()[0]:.1f}"
    )
    figures: dict[str, float] = {}
    compile_s = compile_time(figures)
    throughput(args.repeats, figures)
    kernel_rates(args.repeats)
    rng = np.random.default_rng(0)
    print(f"\n4. full-size fit, {N_TRAIN} instances, paper settings extrapolated (not run)")
    print("   (impl also picks the layer-only SGD of the fine-tuning and the head: linear_sgd)")
    for impl in IMPLS:
        row_estimate(rng, impl, compile_s, figures)
    auc_equivalence(rng, figures)
    plain_torch_ratio(rng, figures)
    print(f"load average at the end {os.getloadavg()[0]:.1f}")
    if args.json:
        from record import write

        notes = f"median/best of {args.repeats}, {args.threads} threads"
        write(args.json, "bench_haptic_cnn", figures, notes)


if __name__ == "__main__":
    main()

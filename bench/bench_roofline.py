"""The ConvNet's and the LSTM's compiled passes against the machine's roofline: their GFLOP/s
beside the same run's sgemm rate.

In one run, interleaved (every repetition times each item once, in turn, so load changes hit all
of them alike, each timed call after untimed ones for 0.2 s: steady rates, as in training; best
of ``--repeats``):

- sgemm: torch's and numpy's BLAS on a 2000^3 single-precision product (the machine's rate, the
  ceiling the kernels are held against: the larger of the two), and BLAS at the shapes an im2col
  or projection GEMM of the kernels would have, on one thread (conv2's per-group product
  batched over the 32 groups; the LSTM's input projection over a chunk's time steps; its
  recurrence per step): the rate BLAS itself reaches at those shapes, per core;
- the haptic ConvNet at the paper's size (32 signals x 150 steps, kernels 5, widths 4, strides
  2, batches of 1000 of a 5,300-instance training set; each call takes the next batch of one
  shuffled epoch, as training does, so no call finds its batch in cache; the training set where
  a fit keeps it, on huge pages where the revision puts it there): the forward that
  scores (the whole-batch conv stack + classification layer, no gradient) and the training step,
  forward + backward (``batch_step``: in tiles of instances, the loss included; a ``--before``
  revision without it runs its own training step), the parameters' gradients set to None
  first, as training's ``zero_grad(set_to_none=True)`` does (a backward into gradients left
  from the last call would add to them: eight additions training does not run);
- the haptic LSTM (hidden 10, 32 inputs, 150 steps, batch 1000): the forward that scores
  (``lstm_last_hidden``) and the training step, forward + backward through the recurrence, both
  FC layers and the loss (``lstm_step``; a ``--before`` revision without it runs its own), its
  gradients set to None first as the ConvNet's.

- what the ConvNet's shapes permit (``attainable``): with 4 output channels per group no pass is
  a large matrix product, so beside sgemm the bench measures two ceilings of its own and holds
  each ConvNet pass against the lowest: the training step's inner loop (``tap_sums`` as it runs
  conv2's forward for one group and tile: 4 rows x 20 taps, the 38 output steps as slots, one
  vector of lanes) on rows in L1, one thread; and memory: a 64 MB copy's bytes per second times
  the pass's FLOPs per byte of the traffic it cannot avoid (the scoring forward: read the batch,
  write the layout's input and the three activations; the training step: read the batch once,
  every activation of a tile staying in cache);
- what the LSTM's kernels permit: their gate sums' inner loop (``tap_sums`` over the 42 inputs,
  four gates a tile) for all 40 gates of one step, on a chunk's rows in L1, one thread: each
  LSTM pass is held against the lower of it and sgemm (a chunk's working set stays in cache, so
  memory sets no lower bound);

FLOPs are counted from the shapes, 2 per multiply-add, only the arithmetic a pass needs: forward
convolutions and the head; the training step adds the weight gradients of every layer, the input
gradients of conv2 and conv3 (conv1's input needs none) and the head's; LSTM forward 2 x 4H(C + H)
per step and instance, backward 2 x 4H(C + H) (weight gradient) + 2 x 4H x H (the state's
gradient). Nonlinearities, layout changes and any pass a kernel runs again (a backward that
recomputes the forward) are not counted: they are the kernels' overhead, so a rate here is the
useful arithmetic per second.

The compiled passes run in a child process, this checkout's and, with ``--before REV``, the
package's at git revision ``REV`` (exported once per commit under the cache folder, with its own
numba cache) in another, interleaved item by item: a before/after in one run, half its rounds
with each child started first (``compared``: the order moved the ratio by ~10%). This process runs
only the BLAS products and the bounds: with the kernels timed here, the same ConvNet step took
1.33x the wall time it took in a child (the same code on both sides, CPU time equal; 2-core
Xeon, 2026-11-27).

Run: ``.venv/bin/python bench/bench_roofline.py [--repeats 7] [--threads 2] [--before REV]
[--json bench/results/bench_roofline.json]``
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch
from revision import package_at

N_TRAIN, CHANNELS, STEPS, BATCH = 5300, 32, 150, 1000
GROUPS, KERNEL, WIDTH, STRIDE = 32, 5, 4, 2
HIDDEN = 10
SGEMM = 2000
ROOT = Path(__file__).resolve().parent.parent

Timer = Callable[[], tuple[float, float]]  # one timed call -> (wall s, CPU s)


def _one_thread(fn: Callable[[], object]) -> Callable[[], object]:
    """``fn`` on one torch thread: a kernel would run such small products inside each of its
    threads, and two threads on a product this small mostly wait for each other."""

    def run() -> object:
        threads = torch.get_num_threads()
        torch.set_num_threads(1)
        try:
            return fn()
        finally:
            torch.set_num_threads(threads)

    return run


def _timed(fn: Callable[[], object]) -> Timer:
    def timer() -> tuple[float, float]:
        start, start_cpu = time.perf_counter(), time.process_time()
        fn()
        return time.perf_counter() - start, time.process_time() - start_cpu

    return timer


def conv_layers() -> list[tuple[int, int, int]]:
    """(c_in, t_in, t_out) per group of conv1..conv3 at the paper's size."""
    layers, c_in, length = [], CHANNELS // GROUPS, STEPS
    for _ in range(3):
        t_out = (length + 2 * (KERNEL // 2) - KERNEL) // STRIDE + 1
        layers.append((c_in, length, t_out))
        c_in, length = WIDTH, t_out
    return layers


def conv_gflop() -> dict[str, float]:
    """Useful GFLOP per pass of one batch (see the module docstring)."""
    convs = [
        2 * GROUPS * WIDTH * c_in * KERNEL * t_out * BATCH / 1e9 for c_in, _, t_out in conv_layers()
    ]
    head = 2 * GROUPS * WIDTH * conv_layers()[-1][2] * BATCH / 1e9
    forward = sum(convs) + head
    backward = sum(convs) + sum(convs[1:]) + 2 * head
    return {"convnet forward": forward, "convnet forward+backward": forward + backward}


def lstm_gflop() -> dict[str, float]:
    per_step = 2 * 4 * HIDDEN * (CHANNELS + HIDDEN)
    forward = per_step * STEPS * BATCH / 1e9
    backward = (per_step + 2 * 4 * HIDDEN * HIDDEN) * STEPS * BATCH / 1e9
    return {"lstm forward": forward, "lstm forward+backward": forward + backward}


def conv_gbytes() -> dict[str, float]:
    """GB a pass must move to and from memory (see the module docstring), float32."""
    sizes = [GROUPS * CHANNELS // GROUPS * STEPS * BATCH * 4 / 1e9]  # the layout's input
    sizes += [GROUPS * WIDTH * t_out * BATCH * 4 / 1e9 for _, _, t_out in conv_layers()]
    forward = sizes[0] + sum(sizes)  # the batch read, the four layout arrays written
    return {"convnet forward": forward, "convnet forward+backward": sizes[0]}


LOOP_TAPS = WIDTH * KERNEL  # conv2's taps per output row
LOOP_CALLS = 20000
COPY_MB = 64


def vector_lanes() -> int:
    """The kernels' vector width (``vector_tiles.WIDTH``), imported when asked: a ``--before``
    child imports the package of another revision, so this module imports none at its top."""
    from tactile_exp.models.vector_tiles import WIDTH

    return WIDTH


def loop_name() -> str:
    steps, lanes = conv_layers()[1][2], vector_lanes()
    return f"conv inner loop, 4 rows x {LOOP_TAPS} taps x {steps} steps x {lanes} lanes (in L1)"


COPY = f"copy {COPY_MB} MB (numpy), 1 thread"
LSTM_INPUTS = CHANNELS + HIDDEN  # a gate's sum runs over the inputs x_t, then the states h_t-1
LSTM_LOOP_CALLS = 2000


def lstm_loop_name() -> str:
    from tactile_exp.models.lstm_kernels import CHUNK

    return (
        f"lstm inner loop, {4 * HIDDEN} gates x {LSTM_INPUTS} inputs x {CHUNK} lanes (in L1), "
        "1 thread"
    )


def bound_gflop() -> dict[str, float]:
    """GFLOP of the inner-loop timers; GB (read + written) of the copy."""
    from tactile_exp.models.lstm_kernels import CHUNK

    conv2 = 2 * 4 * LOOP_TAPS * conv_layers()[1][2] * vector_lanes() * LOOP_CALLS / 1e9
    gates = 2 * 4 * HIDDEN * LSTM_INPUTS * CHUNK * LSTM_LOOP_CALLS / 1e9
    return {loop_name(): conv2, lstm_loop_name(): gates, COPY: 2 * COPY_MB * 2**20 / 1e9}


def bound_timers() -> dict[str, Timer]:
    """The inner loops of the conv and LSTM kernels on resident rows, and a memory copy."""
    from tactile_exp.models import lstm_kernels as lstm
    from tactile_exp.models.numba_setup import numba
    from tactile_exp.models.vector_tiles import RELU, tap_sums

    lanes = vector_lanes()  # a constant of the compiled loop below

    @numba.njit
    def gate_sums(w, inputs, acts, bias, calls):  # one step's gates, as _chunk_forward runs them
        G, K = w.shape
        taps, w_flat = np.arange(K) * lstm.CHUNK, w.ravel()
        x_flat, acts_flat = inputs.ravel(), acts.ravel()
        for _ in range(calls):
            lstm._gate_sums(w_flat, G, K, bias, x_flat, 0, acts_flat, taps, 0)

    @numba.njit
    def loop(w, x, taps, out, bias, steps, calls):  # as convnet_tiles runs conv2's forward
        for _ in range(calls):
            tap_sums(w, 0, LOOP_TAPS, 1, x, 0, taps, LOOP_TAPS, out, 0, steps * lanes, bias, 0,
                     steps, STRIDE * lanes, lanes, RELU, out)  # fmt: skip

    rng = np.random.default_rng(0)
    c_in, t_in, t_out = conv_layers()[1]
    rows = t_in + 2 * KERNEL  # each channel's steps with zero rows either side
    x = rng.standard_normal(c_in * rows * lanes, dtype=np.float32)
    taps = np.array([(i * rows + j) * lanes for i in range(c_in) for j in range(KERNEL)])
    w = rng.standard_normal(4 * LOOP_TAPS, dtype=np.float32)
    out = np.zeros(4 * t_out * lanes, np.float32)
    args = (w, x, taps, out, np.zeros(4, np.float32), t_out, LOOP_CALLS)
    timers = {loop_name(): _timed(lambda: loop(*args))}
    w = rng.standard_normal((4 * HIDDEN, LSTM_INPUTS), dtype=np.float32)
    inputs = rng.standard_normal((1, LSTM_INPUTS, lstm.CHUNK), dtype=np.float32)  # one step
    acts = np.zeros((1, 4 * HIDDEN, lstm.CHUNK), np.float32)
    bias = np.zeros(4 * HIDDEN, np.float32)
    timers[lstm_loop_name()] = _timed(lambda: gate_sums(w, inputs, acts, bias, LSTM_LOOP_CALLS))
    a = np.ones(COPY_MB * 2**20 // 4, np.float32)
    b = np.empty_like(a)
    timers[COPY] = _timed(lambda: np.copyto(b, a))
    return timers


def blas_gflop() -> dict[str, float]:
    conv2 = conv_layers()[1]
    return {
        "sgemm torch 2000^3": 2 * SGEMM**3 / 1e9,
        "sgemm numpy 2000^3": 2 * SGEMM**3 / 1e9,
        "bmm conv2 im2col (32 x 4x20 @ 20x38000), 1 thread": 2
        * GROUPS
        * WIDTH
        * WIDTH
        * KERNEL
        * conv2[2]
        * BATCH
        / 1e9,
        "sgemm lstm projection (40x32 @ 32x9600), 1 thread": 2
        * 4
        * HIDDEN
        * CHANNELS
        * STEPS
        * 64
        / 1e9,
        "sgemm lstm step (40x10 @ 10x1000), 1 thread": 2 * 4 * HIDDEN * HIDDEN * BATCH / 1e9,
    }


def blas_timers() -> dict[str, Timer]:
    rng = np.random.default_rng(0)
    a = torch.randn(SGEMM, SGEMM)
    an = rng.standard_normal((SGEMM, SGEMM), dtype=np.float32)
    c_in, _, t_out = conv_layers()[1]
    w = torch.randn(GROUPS, WIDTH, c_in * KERNEL)
    cols = torch.randn(GROUPS, c_in * KERNEL, t_out * BATCH)
    wl, xl = torch.randn(4 * HIDDEN, CHANNELS), torch.randn(CHANNELS, STEPS * 64)
    wh, hl = torch.randn(4 * HIDDEN, HIDDEN), torch.randn(HIDDEN, BATCH)
    return {
        "sgemm torch 2000^3": _timed(lambda: torch.mm(a, a)),
        "sgemm numpy 2000^3": _timed(lambda: an @ an),
        "bmm conv2 im2col (32 x 4x20 @ 20x38000), 1 thread": _timed(
            _one_thread(lambda: torch.bmm(w, cols))
        ),
        "sgemm lstm projection (40x32 @ 32x9600), 1 thread": _timed(
            _one_thread(lambda: torch.mm(wl, xl))
        ),
        "sgemm lstm step (40x10 @ 10x1000), 1 thread": _timed(
            _one_thread(lambda: torch.mm(wh, hl))
        ),
    }


def kernel_timers() -> dict[str, Timer]:
    """Timers of the compiled passes of the ``tactile_exp`` this process imports."""
    from tactile_exp.models import lstm_kernels
    from tactile_exp.models.haptic_cnn import GroupedTemporalConvNet
    from tactile_exp.models.haptic_lstm import LSTMBody
    from tactile_exp.models.losses import LOSSES

    torch.manual_seed(0)
    X, y = torch.randn(N_TRAIN, CHANNELS, STEPS), (torch.rand(N_TRAIN) > 0.5).float()
    try:  # the training set where a fit keeps it (a --before revision may predate that)
        from tactile_exp.models.scratch import on_huge_pages

        X = torch.from_numpy(on_huge_pages(X.numpy()))
    except ImportError:
        pass
    epoch = itertools.cycle(torch.randperm(N_TRAIN).split(BATCH)[: N_TRAIN // BATCH])

    def batch() -> torch.Tensor:
        return next(epoch)

    net = GroupedTemporalConvNet(CHANNELS, STEPS, impl="compiled")
    head = torch.nn.Linear(net.n_features, 1)
    body, out = LSTMBody(CHANNELS, HIDDEN, impl="compiled"), torch.nn.Linear(HIDDEN, 1)
    conv_params = [*net.parameters(), *head.parameters()]
    lstm_params = [*body.parameters(), *out.parameters()]

    def no_grads(params: list[torch.nn.Parameter]) -> None:  # as the optimiser's zero_grad
        for p in params:
            p.grad = None

    def conv_forward() -> None:
        with torch.no_grad():
            head(net(X[batch()]))

    def conv_both() -> None:
        rows = batch()
        no_grads(conv_params)
        if hasattr(net, "batch_step"):
            net.batch_step(X, y, head, "logistic", rows)
        elif hasattr(net, "batch_loss"):  # a --before revision whose step ran through autograd
            net.batch_loss(X, y, head, "logistic", rows).backward()
        else:  # a --before revision from before the tiled step: its training step
            LOSSES["logistic"](net.scores(X, head, rows=rows), y[rows]).backward()

    def lstm_forward() -> None:
        with torch.no_grad():
            lstm_kernels.lstm_last_hidden(X, body.lstm, batch())

    def lstm_both() -> None:
        rows = batch()
        no_grads(lstm_params)
        if hasattr(lstm_kernels, "lstm_step"):
            lstm_kernels.lstm_step(X, rows, y, body.lstm, body.fc, out, loss="logistic")
        elif hasattr(lstm_kernels, "lstm_loss"):  # a --before revision: through autograd
            lstm_kernels.lstm_loss(X, rows, y, body.lstm, body.fc, out, loss="logistic").backward()
        else:  # a --before revision from before the fused step: its training step
            LOSSES["logistic"](out(body(X, rows)).squeeze(1), y[rows]).backward()

    timers: dict[str, Timer] = {
        "convnet forward": _timed(conv_forward),
        "convnet forward+backward": _timed(conv_both),
        "lstm forward": _timed(lstm_forward),
        "lstm forward+backward": _timed(lstm_both),
    }
    return timers


def _set_threads(threads: int) -> None:
    from tactile_exp.models.numba_setup import numba

    torch.set_num_threads(threads)
    numba.set_num_threads(threads)


def serve(threads: int) -> None:
    """Child mode: time the named kernel pass once per line of stdin, answer on stdout."""
    _set_threads(threads)
    timers = kernel_timers()
    print(json.dumps(sorted(timers)), flush=True)
    for line in sys.stdin:
        print(json.dumps(timers[line.strip()]()), flush=True)


class Package:
    """``tactile_exp`` at a git revision (``None``: this checkout), timing its passes in a child
    process on request."""

    def __init__(self, rev: str | None, threads: int) -> None:
        env = dict(os.environ)
        folder = ROOT
        self.subject = "this checkout"
        if rev is not None:
            self.subject = subprocess.run(  # names the revision in the result file's notes
                ["git", "-C", str(ROOT), "log", "-1", "--format=%s", rev],
                check=True,
                capture_output=True,
                text=True,
            ).stdout.strip()
            folder = package_at(rev)
            env["NUMBA_CACHE_DIR"] = str(folder / "numba")
        env["PYTHONPATH"] = str(folder)
        self.child = subprocess.Popen(
            [sys.executable, str(Path(__file__).resolve()), "--serve", "--threads", str(threads)],
            env=env,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            cwd=folder,
        )
        self.names = json.loads(self.child.stdout.readline())

    def timer(self, name: str) -> Timer:
        def timer() -> tuple[float, float]:
            self.child.stdin.write(name + "\n")
            self.child.stdin.flush()
            return tuple(json.loads(self.child.stdout.readline()))

        return timer

    def close(self) -> None:
        self.child.stdin.close()
        self.child.wait()


# Idle BLAS and OpenMP threads spin for up to ~0.2 s after their work before they sleep: with
# ``--before``, two processes take turns on the cores, and one's spinning threads took a core
# from the other's next pass (the ConvNet's backward ran at half speed in the child, the same code
# on both sides). A pause before each timing lets them sleep first. After a pause the cores run
# slower for a while, however many calls that takes: the ConvNet's training step (two threads,
# median of 10 rounds) took 26.7, 14.1, 12.2, 11.2, 11.2, 10.2 ms in its first six calls after
# 0.25 s idle, then ~10 (one thread: 42.1, 25.3, 22.7, 21.3, 20.1, 18.9, then ~19; 2-core Xeon,
# 2026-11-27), while a 2000^3 sgemm, 50 ms a call, ran at its rate from its second call. So each
# timed call follows untimed ones for ``WARM_S`` (at least one), as a training step follows the
# steps before it (with one untimed call the ConvNet's step read 26-32% of sgemm, taking 8.4-8.7
# ms back to back in the same hour).
SETTLE_S = 0.25
WARM_S = 0.2


def interleaved(
    timers: dict[str, Timer], repeats: int, settle_s: float = SETTLE_S, warm_s: float = WARM_S
) -> dict[str, tuple[float, float]]:
    """Best wall and CPU seconds of each timer: ``repeats`` rounds, each timing a call that
    follows a pause of ``settle_s`` and untimed calls for ``warm_s`` (at least one)."""
    best = {name: (float("inf"), float("inf")) for name in timers}
    for _ in range(repeats):
        for name, timer in timers.items():
            time.sleep(settle_s)
            warm = 0.0
            while True:
                warm += timer()[0]
                if warm >= warm_s:
                    break
            wall, cpu = timer()
            best[name] = (min(best[name][0], wall), min(best[name][1], cpu))
    return best


def compared(
    timers: dict[str, Timer], repeats: int, threads: int, rev: str | None
) -> tuple[dict[str, tuple[float, float]], Package | None]:
    """``interleaved`` over ``timers`` and the passes of this checkout and, with ``rev``, of the
    package at ``rev``: half the rounds with this checkout's child started first, half with
    the other's. With one pair of children, the one started second ran the same code faster
    (``--before`` this checkout's own commit: before / now x0.77-0.98 when this checkout's
    started first, x1.08-1.23 when it started second; 2-core Xeon, 2026-11-27); both orders
    gave x0.95-1.14 in two runs. Returns the best times and the ``rev`` package (closed)."""
    orders = [(None, rev), (rev, None)] if rev is not None else [(None,)]
    best: dict[str, tuple[float, float]] = {}
    before = None
    for k, order in enumerate(orders):
        packages = {version: Package(version, threads) for version in order}
        now, before = packages[None], packages.get(rev) if rev is not None else None
        round_timers = dict(timers)
        for name in now.names:
            if before is not None and name in before.names:
                round_timers[f"{name} (before)"] = before.timer(name)
            round_timers[name] = now.timer(name)
        rounds = repeats // len(orders) + (k < repeats % len(orders))
        for name, (wall, cpu) in interleaved(round_timers, rounds).items():
            old_wall, old_cpu = best.get(name, (float("inf"), float("inf")))
            best[name] = (min(old_wall, wall), min(old_cpu, cpu))
        for package in packages.values():
            package.close()
    return best, before


def _attained(
    figures: dict[str, float],
    best: dict[str, tuple[float, float]],
    name: str,
    gflop: float,
    bound: float,
) -> list[tuple[str, float]]:
    """(name, % of ``bound``) for the pass ``name`` and its ``--before`` version where timed:
    GFLOP per CPU s against the attainable ``bound``; recorded in ``figures`` too."""
    shares = []
    for key in (name, f"{name} (before)"):
        if key in best:
            share = 100 * gflop / best[key][1] / bound
            figures[f"{key}, % of attainable per CPU s"] = round(share, 1)
            shares.append((key, share))
    return shares


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--before", default=None, help="also time the package at this git rev")
    parser.add_argument("--json", type=Path, default=None, help="also write the figures here")
    parser.add_argument("--serve", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.serve:
        serve(args.threads)
        return
    _set_threads(args.threads)
    gflop = {**blas_gflop(), **bound_gflop(), **conv_gflop(), **lstm_gflop()}
    timers = {**blas_timers(), **bound_timers()}
    best, before = compared(timers, args.repeats, args.threads, args.before)
    sgemm = ("sgemm torch 2000^3", "sgemm numpy 2000^3")
    ceiling = max(gflop[n] / best[n][0] for n in sgemm)
    ceiling_cpu = max(gflop[n] / best[n][1] for n in sgemm)
    load = os.getloadavg()[0]
    print(
        f"torch {torch.__version__}, {args.threads} threads, best of {args.repeats} "
        f"(interleaved), load average {load:.1f} at the end; per CPU s: FLOPs over the CPU "
        "time of all threads (steadier than wall time on a loaded machine)"
    )
    print(f"{'':48s} {'ms':>8s} {'GFLOP/s':>8s} {'% sgemm':>8s} {'per CPU s':>9s} {'% sgemm':>8s}")
    figures: dict[str, float] = {
        "sgemm, GFLOP/s (the ceiling: the faster BLAS)": round(ceiling, 1),
        "sgemm, GFLOP per CPU s": round(ceiling_cpu, 1),
    }
    loop_cpu = gflop[loop_name()] / best[loop_name()][1]
    copy_cpu = gflop[COPY] / best[COPY][1]
    figures[f"{COPY}, GB per CPU s"] = round(copy_cpu, 1)
    for name, (wall, cpu) in best.items():
        work = gflop[name.removesuffix(" (before)")]
        rate, rate_cpu = work / wall, work / cpu
        share, share_cpu = 100 * rate / ceiling, 100 * rate_cpu / ceiling_cpu
        print(
            f"{name:48s} {wall * 1e3:8.2f} {rate:8.1f} {share:7.0f}% {rate_cpu:9.1f} "
            f"{share_cpu:7.0f}%"
        )
        if name in sgemm:
            continue
        if name == COPY:
            print(f"{'':48s} {work / wall:8.1f} GB/s, {work / cpu:.1f} GB per CPU s")
            continue
        figures[f"{name}, GFLOP/s"] = round(rate, 1)
        figures[f"{name}, % of sgemm"] = round(share, 1)
        figures[f"{name}, % of sgemm per CPU s"] = round(share_cpu, 1)
    print(
        f"attainable per CPU s (the lowest of sgemm {ceiling_cpu:.1f}, the inner loop "
        f"{loop_cpu:.1f}, memory {copy_cpu:.1f} GB/s x FLOP per byte):"
    )
    for name, gbytes in conv_gbytes().items():
        intensity = conv_gflop()[name] / gbytes
        bound = min(ceiling_cpu, loop_cpu, copy_cpu * intensity)
        figures[f"{name}, FLOP per byte of memory traffic"] = round(intensity, 2)
        figures[f"{name}, attainable GFLOP per CPU s"] = round(bound, 1)
        for key, share in _attained(figures, best, name, conv_gflop()[name], bound):
            print(f"  {key:46s} {intensity:5.2f} FLOP/B, bound {bound:6.1f}: {share:5.1f}%")
    lstm_loop_cpu = gflop[lstm_loop_name()] / best[lstm_loop_name()][1]
    bound = min(ceiling_cpu, lstm_loop_cpu)
    print(f"attainable per CPU s for the LSTM: {bound:.1f} (the lower of sgemm and its inner loop)")
    for name in lstm_gflop():
        figures[f"{name}, attainable GFLOP per CPU s"] = round(bound, 1)
        for key, share in _attained(figures, best, name, lstm_gflop()[name], bound):
            print(f"  {key:46s} {share:5.1f}%")
    for name in ("convnet forward+backward", "lstm forward+backward"):
        if f"{name} (before)" in best:
            speedup = best[f"{name} (before)"][0] / best[name][0]
            print(f"{name}: before / now x{speedup:.2f} wall")
            figures[f"{name}, before / now, wall"] = round(speedup, 2)
    if args.json:
        sys.path.insert(0, str(Path(__file__).parent))
        from record import write

        notes = (
            f"best of {args.repeats} interleaved, each timed call after untimed ones for "
            f"{WARM_S} s, {args.threads} threads, batch {BATCH}; % of "
            "sgemm per CPU s compares FLOPs per CPU second of all threads, steadier than wall "
            "time when other work shares the cores; attainable per CPU s: the lowest of sgemm, "
            "the conv kernels' inner loop on resident rows and memory bandwidth x the pass's "
            "FLOP per byte; for the LSTM the lower of sgemm and its gate sums' inner loop on "
            "rows in L1 (the script's docstring); the targets are against sgemm; the compiled "
            "passes timed in child processes"
        )
        if before is not None:
            notes += (
                f"; before = the package at --before {args.before} (the commit '{before.subject}')"
            )
        write(args.json, "bench_roofline", figures, notes)


if __name__ == "__main__":
    main()

"""Minibatch SGD of a one-output linear layer on fixed features, compiled (numba) for the CPU.

The classification layer is trained alone on frozen features twice per adjective: the
fine-tuning stage (T2) and the T4 head on combined units (24,320 columns at combine=1, batches
of 32). Through autograd each of those small steps pays for a gathered batch copy and torch's
per-call overhead: row I's head took ~8 s of an adjective's ~49 s. Here a step reads its rows in
place, and each row's score, loss and gradient share one visit to the row (the weights move only
after the batch), so an epoch is one pass over the features.

Same algorithm as ``train.sgd_epochs`` with ``torch.optim.SGD`` (momentum, no dampening) and
the losses of ``models/losses.py``, on the same ``torch.randperm`` orders: the results agree with
the torch path to float rounding (tests).

With momentum and no weight decay the weights stay in span{w0, rows of X}: w = w0 + X^T a and
the momentum buffer X^T v for n-vectors a and v. A head with few rows of many features (T4: 530
rows x 24,320 features) therefore trains on the Gram matrix G = X X^T instead (``uses_gram``): a
row's score is b + (X w0)_i + G_i . a, a batch's gradient is its rows' coefficients in v, and w
is formed once at the end. An epoch then costs n^2 (in cache) instead of n x d read from memory;
G costs one matrix product, computed as two halves of its rows side by side (one BLAS thread
each, so the sums do not depend on the thread count) and kept for the next stage on the same
features (the head's hinge stage after its logistic one). Both paths compute the same trajectory
up to float rounding (tests).
"""

from __future__ import annotations

import weakref
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager

import numpy as np
import torch
from torch import nn

from tactile_exp.models.numba_setup import ensure_compiled, numba

LOSSES = ("logistic", "hinge")  # the registered losses loss_slope computes (others: impl=torch)
SOFTPLUS_THRESHOLD = 20.0  # torch's F.softplus: the identity above it
GRAM_MAX_ROWS = 4096  # G as float32 in at most 64 MB
# The Gram path from n / 8 epochs on: G's product costs about n / 25 row-path epochs (21 at the
# T4 head's 530 rows, bench_linear_sgd), so it is then under a third of the row path's time.
GRAM_ROWS_PER_EPOCH = 8


FASTMATH = {"reassoc", "contract", "nsz"}


@numba.njit(nogil=True, cache=True, fastmath=FASTMATH, error_model="numpy")
def loss_slope(m, hinge, one):
    """The loss at margin ``m`` (label x score) and its derivative in ``m``, in ``one``'s type."""
    if hinge:
        slack = one - m
        return (slack, -one) if slack > 0 else (one - one, one - one)
    x = -m
    if x > SOFTPLUS_THRESHOLD:
        return x, -one
    z = np.exp(x)
    return np.log1p(z), -(z / (z + one))


@numba.njit(nogil=True, cache=True, fastmath=FASTMATH, error_model="numpy")
def _epoch(X, sign, order, w, b, vel_w, vel_b, lr, momentum, batch, hinge, grad):
    """One epoch over ``order``; updates w, b and their momentum buffers in place, returns the
    summed loss."""
    n, d = X.shape
    total = 0.0
    for start in range(0, n, batch):
        size = min(batch, n - start)
        scale = np.float32(1.0) / np.float32(size)  # the mean's gradient
        grad_b = np.float32(0.0)
        touched = False
        for r in range(start, start + size):
            i = order[r]
            row = X[i]
            s = b[0]
            for j in range(d):
                s += row[j] * w[j]
            loss, slope = loss_slope(sign[i] * s, hinge, np.float32(1.0))
            total += loss
            g = sign[i] * scale * slope
            if g == 0:
                continue
            grad_b += g
            if touched:
                for j in range(d):
                    grad[j] += g * row[j]
            else:  # the first row writes the gradient: never zeroed first
                for j in range(d):
                    grad[j] = g * row[j]
                touched = True
        if not touched:
            grad[:] = 0.0
        for j in range(d):  # from zero buffers: torch's first step (buffer = gradient)
            vel_w[j] = momentum * vel_w[j] + grad[j]
        vel_b[0] = momentum * vel_b[0] + grad_b
        for j in range(d):
            w[j] -= lr * vel_w[j]
        b[0] -= lr * vel_b[0]
    return total


@numba.njit(nogil=True, cache=True, fastmath=FASTMATH, error_model="numpy")
def _gram_epoch(G, p, sign, order, a, b, vel_a, vel_b, lr, momentum, batch, hinge, coef):
    """``_epoch`` on the Gram matrix ``G`` = X X^T and ``p`` = X w0, in float64: the weights are
    w0 + X^T a and their momentum buffer X^T vel_a; updates a, b, vel_a and vel_b in place."""
    n = len(order)
    total = 0.0
    for start in range(0, n, batch):
        size = min(batch, n - start)
        scale = 1.0 / size
        grad_b = 0.0
        for r in range(size):  # every score of the batch before the weights move
            i = order[start + r]
            s = b[0] + p[i]
            for k in range(n):
                s += G[i, k] * a[k]
            loss, slope = loss_slope(sign[i] * s, hinge, 1.0)
            total += loss
            coef[r] = sign[i] * scale * slope  # the gradient's coefficient on row i
            grad_b += coef[r]
        for k in range(n):  # from zero buffers: torch's first step (buffer = gradient)
            vel_a[k] *= momentum
        for r in range(size):
            vel_a[order[start + r]] += coef[r]
        vel_b[0] = momentum * vel_b[0] + grad_b
        for k in range(n):
            a[k] -= lr * vel_a[k]
        b[0] -= lr * vel_b[0]
    return total


def check_loss(loss: str) -> None:
    """Raise ValueError unless this loop computes ``loss``."""
    if loss not in LOSSES:
        raise ValueError(
            f"the compiled linear SGD computes the losses {', '.join(LOSSES)}, not {loss!r}: "
            "use impl=torch"
        )


@contextmanager
def _one_torch_thread() -> Iterator[None]:
    """torch's matrix products on one thread: MKL sums in an order that depends on the thread
    count (a model's fit already runs its compiled stages so)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)


_LAST_GRAM: list[tuple[weakref.ref, int, np.ndarray]] = []  # (features tensor, its version, G)


def _gram(X: torch.Tensor, rows: torch.Tensor) -> np.ndarray:
    """G = rows rows^T for the float32 ``rows`` of the features tensor ``X``: the two halves of
    its rows on two threads, each product on one BLAS thread (see ``_one_torch_thread``). Kept
    for the next call on the same ``X`` while it lives unmodified (torch's version counter)."""
    if _LAST_GRAM and _LAST_GRAM[0][0]() is X and _LAST_GRAM[0][1] == X._version:
        return _LAST_GRAM[0][2]
    n = len(rows)
    G = torch.empty(n, n)
    halves = (slice(0, n // 2), slice(n // 2, n))
    # A pool's thread runs its BLAS on the process's default thread count (OMP_NUM_THREADS, else
    # every core), not on the caller's: left so, row M's Gram matrix differs in its last bits
    # between a job on two threads and one on one, and three of the row's 24 AUCs with it.
    # Each thread sets its own count to one as it starts.
    with ThreadPoolExecutor(2, initializer=torch.set_num_threads, initargs=(1,)) as pool:
        for done in [pool.submit(torch.matmul, rows[h], rows.T, out=G[h]) for h in halves]:
            done.result()
    _LAST_GRAM[:] = [(weakref.ref(X), X._version, G.numpy())]
    return _LAST_GRAM[0][2]


def uses_gram(n: int, d: int, epochs: int) -> bool:
    """Whether ``linear_sgd_epochs`` trains on the Gram matrix ``n`` rows of ``d`` features for
    ``epochs`` epochs: when an epoch on it (n^2 in cache) is well below one on the rows (n x d
    from memory), it fits memory, and the epochs repay its matrix product."""
    return 4 * n <= d and n <= GRAM_MAX_ROWS and n <= GRAM_ROWS_PER_EPOCH * epochs


def linear_sgd_epochs(
    layer: nn.Linear,
    X: torch.Tensor,
    y: torch.Tensor,
    *,
    loss: str,
    epochs: int,
    batch_size: int,
    lr: float,
    momentum: float,
    generator: torch.Generator,
    report: Callable[[float], None] | None = None,
    gram: bool | None = None,
) -> list[float]:
    """``train.sgd_epochs`` for ``layer`` (one output, on CPU) applied to the rows of ``X``:
    the same shuffles from ``generator``, updates and per-epoch mean losses. ``gram``: train on
    the Gram matrix (True) or the rows (False); None: as ``uses_gram`` says.

    G is float32 (one BLAS product, on one thread): each entry carries the rounding of one
    float32 dot product over the features, as every score of the row path does every epoch; the
    coefficients, their momentum, the scores and the bias are float64, so the n-term sums and the
    many updates add no rounding of their own."""
    if layer.out_features != 1 or layer.weight.device.type != "cpu":
        raise ValueError("the compiled linear SGD trains a one-output layer on CPU")
    check_loss(loss)
    ensure_compiled(__name__)
    features = np.ascontiguousarray(X.detach().numpy().reshape(len(X), -1), dtype=np.float32)
    sign = (2.0 * y.detach().numpy() - 1.0).astype(np.float32)
    n, hinge = len(features), loss == "hinge"
    if gram is None:
        gram = uses_gram(*features.shape, epochs)
    # updated in place through numpy views of the parameters
    with torch.no_grad(), _one_torch_thread():
        w, b = layer.weight.detach().numpy().reshape(-1), layer.bias.detach().numpy()
        if gram:
            rows = torch.from_numpy(features)
            G = _gram(X, rows)
            p = (rows @ torch.from_numpy(w)).numpy().astype(np.float64)
            a, vel_a = np.zeros(n), np.zeros(n)
            b64, vel_b, coef = b.astype(np.float64), np.zeros(1), np.empty(min(batch_size, n))

            def epoch(order: np.ndarray) -> float:
                return _gram_epoch(
                    G, p, sign, order, a, b64, vel_a, vel_b, lr, momentum, batch_size, hinge, coef
                )
        else:
            vel_w, vel_b, grad = np.zeros_like(w), np.zeros_like(b), np.empty_like(w)
            lr32, momentum32 = np.float32(lr), np.float32(momentum)

            def epoch(order: np.ndarray) -> float:
                return _epoch(
                    features,
                    sign,
                    order,
                    w,
                    b,
                    vel_w,
                    vel_b,
                    lr32,
                    momentum32,
                    batch_size,
                    hinge,
                    grad,
                )

        curve = []
        for _ in range(epochs):
            order = torch.randperm(n, generator=generator).numpy()
            curve.append(epoch(order) / n)
            if report is not None:
                report(curve[-1])
        if gram:  # w = w0 + X^T a
            w += (torch.from_numpy(a.astype(np.float32)) @ rows).numpy()
            b[:] = b64
    return curve


def warm_up() -> None:
    """Compile the epochs on the rows and on the Gram matrix (into numba's cache) on toy rows."""
    X, y = torch.randn(6, 4), torch.tensor([0.0, 1.0] * 3)
    for gram in (False, True):
        linear_sgd_epochs(
            nn.Linear(4, 1),
            X,
            y,
            loss="hinge",
            epochs=1,
            batch_size=4,
            lr=0.01,
            momentum=0.9,
            generator=torch.Generator().manual_seed(0),
            gram=gram,
        )

"""The compiled SGD of the classification layer on fixed features against torch's autograd loop."""

import hashlib
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from test_models import FAST, easy_case
from torch import nn

from tactile_exp.models import MODELS, linear_sgd
from tactile_exp.models.linear_sgd import linear_sgd_epochs
from tactile_exp.models.losses import LOSSES
from tactile_exp.train import autograd_step, caffe_xavier_, sgd_epochs


def _train(impl: str, X, y, *, loss: str, gram: bool | None = None, **schedule):
    torch.manual_seed(0)
    layer = nn.Linear(X.shape[1], 1)
    caffe_xavier_(layer.weight, X.shape[1])
    nn.init.uniform_(layer.bias, -0.1, 0.1)
    generator = torch.Generator().manual_seed(5)
    if impl == "torch":
        curve = sgd_epochs(
            autograd_step(lambda F, y, index: LOSSES[loss](layer(F[index]).squeeze(1), y[index])),
            list(layer.parameters()),
            X,
            y,
            generator=generator,
            **schedule,
        )
    else:
        curve = linear_sgd_epochs(
            layer, X, y, loss=loss, generator=generator, gram=gram, **schedule
        )
    after = torch.randperm(50, generator=generator)  # where the shuffles left the generator
    return layer.weight.detach().clone(), layer.bias.detach().clone(), curve, after


@pytest.mark.parametrize("gram", [False, True])
@pytest.mark.parametrize("loss", ["logistic", "hinge"])
@pytest.mark.parametrize(
    ("n", "d", "batch_size", "momentum", "scale", "lr"),
    [
        (101, 40, 7, 0.9, 1.0, 0.05),  # a short last batch
        (60, 300, 1000, 0.9, 1.0, 0.05),  # one batch larger than the data (d > n)
        (33, 5, 1, 0.0, 1.0, 0.05),  # batch 1, no momentum
        (80, 20, 16, 0.5, 30.0, 1e-4),  # large margins: softplus's linear branch, hinge's flat part
    ],
)
def test_compiled_layer_sgd_equals_torchs(gram, loss, n, d, batch_size, momentum, scale, lr):
    """Either path, on the rows or on their Gram matrix, whatever the shape."""
    rng = np.random.default_rng(n + d)
    X = torch.from_numpy(scale * rng.standard_normal((n, d), dtype=np.float32))
    y = torch.from_numpy((rng.random(n) > 0.6).astype(np.float32))
    X[y == 1, :3] += 0.5 * scale
    schedule = dict(epochs=12, batch_size=batch_size, lr=lr, momentum=momentum)
    w, b, curve, after = _train("torch", X, y, loss=loss, **schedule)
    w2, b2, curve2, after2 = _train("compiled", X, y, loss=loss, gram=gram, **schedule)
    assert not torch.equal(w, _train("torch", X, y, loss=loss, **{**schedule, "epochs": 0})[0])
    torch.testing.assert_close(w2, w, rtol=1e-4, atol=1e-6)
    torch.testing.assert_close(b2, b, rtol=1e-4, atol=1e-6)
    np.testing.assert_allclose(curve2, curve, rtol=1e-4, atol=1e-7)
    assert torch.equal(after2, after)  # the same shuffles, so later stages see the same orders
    assert curve[-1] < curve[0]  # a run that learns (a diverging one amplifies any rounding)


def _separable(n: int, d: int, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    rng = np.random.default_rng(seed)
    X = torch.from_numpy(rng.standard_normal((n, d), dtype=np.float32))
    y = torch.from_numpy((rng.random(n) > 0.6).astype(np.float32))
    X[y == 1, :5] += 0.5
    return X, y


@pytest.mark.parametrize("loss", ["logistic", "hinge"])
@pytest.mark.parametrize("momentum", [0.0, 0.5, 0.9, 0.99])
@pytest.mark.parametrize(("n", "d", "batch_size"), [(70, 600, 16), (45, 2000, 7)])
def test_gram_path_equals_the_row_path(loss, momentum, n, d, batch_size):
    """Fewer rows than features, batches that do not divide them, 60 epochs: the Gram path's
    float32 G and float64 coefficients against the row path's float32 weights agree to float
    rounding (weights and bias to 1e-4 relative, the loss curve to 1e-5), on the same
    shuffles."""
    X, y = _separable(n, d, seed=n)
    schedule = dict(epochs=60, batch_size=batch_size, lr=0.002, momentum=momentum)
    w, b, curve, after = _train("compiled", X, y, loss=loss, gram=False, **schedule)
    w2, b2, curve2, after2 = _train("compiled", X, y, loss=loss, gram=True, **schedule)
    w0 = _train("compiled", X, y, loss=loss, **{**schedule, "epochs": 0})[0]
    assert (w - w0).abs().max() > 100 * (w2 - w).abs().max()  # the weights moved far more
    torch.testing.assert_close(w2, w, rtol=1e-4, atol=1e-6)
    torch.testing.assert_close(b2, b, rtol=1e-4, atol=1e-6)
    np.testing.assert_allclose(curve2, curve, rtol=1e-5, atol=1e-7)
    assert torch.equal(after2, after)
    assert curve[-1] < 0.5 * curve[0]


@pytest.mark.parametrize(
    ("n", "d", "epochs", "gram"),
    [
        (530, 24_320, 300, True),  # the T4 head on combined units
        (530, 2_000, 300, False),  # an epoch on G (n^2) not well below one on the rows (n d)
        (530, 24_320, 20, False),  # too few epochs to repay G's product
        (5_000, 100_000, 10_000, False),  # G too large
        (100, 400, 13, True),
        (101, 400, 13, False),
        (100, 400, 12, False),
    ],
)
def test_the_gram_path_is_taken_where_it_pays(n, d, epochs, gram, monkeypatch):
    assert linear_sgd.uses_gram(n, d, epochs) is gram
    if n * d > 1_000_000:
        return
    X, y = _separable(n, d, seed=0)
    calls = []
    for kernel in ("_epoch", "_gram_epoch"):
        compiled = getattr(linear_sgd, kernel)
        monkeypatch.setattr(
            linear_sgd, kernel, lambda *a, k=kernel, c=compiled: calls.append(k) or c(*a)
        )
    _train("compiled", X, y, loss="hinge", epochs=epochs, batch_size=32, lr=0.01, momentum=0.9)
    assert set(calls) == {"_gram_epoch" if gram else "_epoch"} and len(calls) == epochs


def _gram_fit_digest() -> str:
    """A Gram-path fit's weights, bias and loss curve, hashed."""
    X, y = _separable(200, 3000, seed=1)
    schedule = dict(loss="logistic", gram=True, epochs=20, batch_size=32, lr=0.01, momentum=0.9)
    w, b, curve, _ = _train("compiled", X, y, **schedule)
    fitted = w.numpy().tobytes() + b.numpy().tobytes() + repr(curve).encode()
    return hashlib.sha1(fitted).hexdigest()


def test_the_gram_path_does_not_depend_on_torchs_thread_count():
    """G's product sums in an order that depends on MKL's thread count, and the threads that
    compute its halves start with the process's default count (OMP_NUM_THREADS: one per job
    under joblib, every core in a plain job): each computes on one thread, so a fit is the same
    bits in a process of one thread and one of two, and as torch's setting changes in-process."""
    script = f"import sys; sys.path.insert(0, {str(Path(__file__).parent)!r}); "
    script += "from test_linear_sgd import _gram_fit_digest; print(_gram_fit_digest())"
    digests = []
    for count in ("1", "2"):
        env = {**os.environ, "OMP_NUM_THREADS": count, "MKL_NUM_THREADS": count}
        done = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True,
                              text=True, check=True)  # fmt: skip
        digests.append(done.stdout.strip())
    threads = torch.get_num_threads()
    for count in (1, 2):
        torch.set_num_threads(count)
        try:
            digests.append(_gram_fit_digest())
        finally:
            torch.set_num_threads(threads)
    assert len(set(digests)) == 1, digests


def test_compiled_layer_sgd_trains_only_a_one_output_cpu_layer():
    X, y = torch.zeros(4, 3), torch.ones(4)
    with pytest.raises(ValueError, match="one-output layer on CPU"):
        linear_sgd_epochs(
            nn.Linear(3, 2),
            X,
            y,
            loss="hinge",
            epochs=1,
            batch_size=2,
            lr=0.1,
            momentum=0.9,
            generator=torch.Generator(),
        )


@pytest.mark.parametrize(("name", "stages"), [("linear", 2), ("haptic_cnn", 1)])
def test_auto_on_cpu_trains_the_layer_compiled_and_torch_stays_selectable(
    name, stages, monkeypatch
):
    """``impl=auto`` on CPU runs the layer-only stages (both for ``linear``, the fine-tuning for
    the ConvNet) through the compiled loop; ``impl=torch`` never does; both score alike."""
    calls = []
    compiled = linear_sgd.linear_sgd_epochs
    monkeypatch.setattr(
        linear_sgd, "linear_sgd_epochs", lambda *a, **k: calls.append(1) or compiled(*a, **k)
    )
    train = easy_case(60, steps=40)
    scores = {}
    for impl in ("auto", "torch"):
        model = MODELS.build(name, impl=impl, seed=2, **FAST)
        model.fit(train)
        scores[impl] = model.decision_function(train.X)
        assert len(calls) == stages
        assert model.head().impl == impl  # the T4 head follows the model's choice
    np.testing.assert_allclose(scores["auto"], scores["torch"], rtol=1e-3, atol=1e-4)


def test_a_loss_the_loop_does_not_compute_takes_torchs_path_or_is_refused(monkeypatch):
    """A newly registered loss: ``impl=auto`` trains the layer through autograd with it,
    ``impl=compiled`` refuses it by name when the model is built instead of computing another
    loss."""
    hinge = LOSSES["hinge"]
    settings = {**FAST, "loss": "squared_hinge", "pretrain_loss": None}
    calls = []
    with (
        LOSSES.temporary(squared_hinge=lambda s, y: hinge(s, y) ** 2),
        monkeypatch.context() as patch,
    ):
        patch.setattr(linear_sgd, "linear_sgd_epochs", lambda *a, **k: calls.append(1))
        model = MODELS.build("linear", impl="auto", **settings)
        assert list(model.fit(easy_case(40, steps=10))) == ["train_loss"] and calls == []
        for name in ("linear", "haptic_cnn"):  # refused when built, before any training
            with pytest.raises(ValueError, match="not 'squared_hinge': use impl=torch"):
                MODELS.build(name, impl="compiled", **settings)


def test_the_gram_matrix_is_computed_once_for_stages_on_the_same_features(monkeypatch):
    """The head's hinge stage reuses its logistic stage's G (same tensor, unmodified), and gets
    what a fresh product gives; features modified in place, or other features, get a new G."""
    X, y = _separable(80, 400, seed=4)
    products = []
    matmul = torch.matmul
    monkeypatch.setattr(
        linear_sgd.torch, "matmul", lambda *a, **k: products.append(a[0].shape) or matmul(*a, **k)
    )
    schedule = dict(gram=True, epochs=5, batch_size=16, lr=0.01, momentum=0.9)
    layer = nn.Linear(400, 1)
    for loss in ("logistic", "hinge"):
        linear_sgd_epochs(layer, X, y, loss=loss, generator=torch.Generator(), **schedule)
    assert products == [(40, 400), (40, 400)]  # G's two halves, once
    fresh = nn.Linear(400, 1)
    fresh.load_state_dict(layer.state_dict())
    again = nn.Linear(400, 1)
    again.load_state_dict(layer.state_dict())
    linear_sgd_epochs(fresh, X.clone(), y, loss="hinge", generator=torch.Generator(), **schedule)
    linear_sgd_epochs(again, X, y, loss="hinge", generator=torch.Generator(), **schedule)
    assert torch.equal(fresh.weight, again.weight)  # the kept G is the fresh product
    products.clear()
    X.mul_(2.0)
    linear_sgd_epochs(layer, X, y, loss="hinge", generator=torch.Generator(), **schedule)
    assert products == [(40, 400), (40, 400)]

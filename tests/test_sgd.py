"""The classification layer retrained on combined units (T4) converges with its own schedule."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml
from sklearn.linear_model import LogisticRegression
from sklearn.metrics import log_loss, roc_auc_score
from sklearn.preprocessing import StandardScaler

from tactile_exp.data.layout import Instances
from tactile_exp.models import sgd
from tactile_exp.models.registry import MODELS
from tactile_exp.models.schedule import Schedule
from tactile_exp.models.scratch import HUGE_PAGE, empty_on_huge_pages
from tactile_exp.models.sgd import FinetuneWarning

SCHEDULES = Path(__file__).resolve().parents[1] / "conf" / "schedule"


def _paper_head() -> Schedule:
    """A one-epoch network whose head trains by paper.yaml's ``head`` schedule."""
    head = yaml.safe_load((SCHEDULES / "paper.yaml").read_text())["head"]
    return Schedule.of({"epochs": 1, "head": head})


@pytest.fixture(autouse=True)
def _finetune_warning_not_yet_shown(monkeypatch):
    """The warning is shown once per process: each test starts as a fresh process would."""
    monkeypatch.setattr(sgd, "FINETUNE_WARNED", set())


def _separable(n: int, d: int, seed: int = 0) -> Instances:
    """Many correlated columns driven by a few latents, like concatenated conv3 activations."""
    rng = np.random.default_rng(seed)
    z = rng.normal(size=(n, 8))
    X = z @ rng.normal(size=(8, d)) + 0.5 * rng.normal(size=(n, d))
    X = np.maximum(X, 0) * rng.uniform(0.01, 10, size=d)  # ReLU-like, columns of mixed scale
    y = (z @ rng.normal(size=8) > 0).astype(np.int64)
    return Instances(X.astype(np.float32), y, np.array([f"u{i}" for i in range(n)]), np.arange(n))


@pytest.mark.parametrize("n,d", [(120, 2000), (30, 6000)])  # ~combine=1 and ~combine=10 shapes
def test_head_reaches_logistic_regression_training_loss(n, d):
    network = MODELS.build("linear", schedule=_paper_head(), device="cpu")
    head = network.head()
    units = _separable(n, d)
    with pytest.warns(FinetuneWarning):  # separable: the hinge stage cannot move the layer
        history = head.fit(units)

    Xs = StandardScaler().fit_transform(units.X)  # the head standardises its inputs too
    reference = LogisticRegression(max_iter=5000).fit(Xs, units.y)
    reference_loss = log_loss(units.y, reference.predict_proba(Xs)[:, 1])
    assert history["train_loss"][-1] <= reference_loss + 0.01
    assert roc_auc_score(units.y, head.decision_function(units.X)) == 1.0  # hinge keeps the fit


@pytest.mark.parametrize(
    "n,d,separable",
    [(120, 2000, True), (2000, 20, False)],  # a combine=1 head's shape; fewer columns than rows
)
def test_hinge_finetuning_is_a_no_op_on_separable_units_and_warns(n, d, separable):
    """Why loss=hinge and loss=logistic heads can score identically: after the logistic stage on
    separable units every margin is >= 1, hinge's gradient is zero, the layer does not move.
    Where a margin stays below 1 the hinge stage changes the scores, and nothing warns."""
    units, test = _separable(n, d), _separable(200, d, seed=1)
    scores, caught = {}, {}
    for loss, pretrain in (("hinge", "logistic"), ("logistic", None)):
        network = MODELS.build(
            "linear",
            schedule=_paper_head(),
            loss=loss,
            pretrain_loss=pretrain,
            device="cpu",
        )
        head = network.head()
        with warnings.catch_warnings(record=True) as caught[loss]:
            warnings.simplefilter("always")
            history = head.fit(units)
        scores[loss] = head.decision_function(test.X)
    finetune_warnings = [w for w in caught["hinge"] if issubclass(w.category, FinetuneWarning)]
    assert not [w for w in caught["logistic"] if issubclass(w.category, FinetuneWarning)]
    if separable:
        assert history["train_loss"][-1] < 0.05  # the last fit: the logistic head
        np.testing.assert_array_equal(scores["hinge"], scores["logistic"])
        assert len(finetune_warnings) == 1
        assert "scores equal loss=logistic's" in str(finetune_warnings[0].message)
    else:
        assert np.abs(scores["hinge"] - scores["logistic"]).max() > 1.0
        assert not finetune_warnings


def test_the_finetune_warning_is_shown_once_per_process_not_per_adjective():
    """A job fits one head per adjective: 24 identical warnings would flood its log."""
    network = MODELS.build("linear", schedule=_paper_head(), device="cpu")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for seed in (0, 1, 2):
            network.head().fit(_separable(60, 500, seed))
    assert [issubclass(w.category, FinetuneWarning) for w in caught].count(True) == 1


@pytest.mark.parametrize("name", ["haptic_lstm", "haptic_cnn"])
def test_compiled_training_does_not_depend_on_torch_threads(name):
    """The compiled kernels sum in a fixed order whatever numba's thread count; the torch layers
    around them (the LSTM's FC(10)) must not reintroduce a thread-dependent sum: a joblib grid
    runs each job on one thread (loky sets OMP_NUM_THREADS), a plain grid on all cores."""
    import torch

    rng = np.random.default_rng(0)
    X = rng.standard_normal((1100, 32, 12)).astype(np.float32)
    y = (rng.random(1100) < 0.3).astype(int)
    X[y == 1, 3] += 0.5
    data = Instances(X, y, np.array([f"t{i}" for i in range(1100)]), np.arange(1100) // 10)
    schedule = Schedule(epochs=3, finetune_epochs=2, batch_size=1000, lr=0.05)
    threads, scores = torch.get_num_threads(), []
    try:
        for n in (1, 2):
            torch.set_num_threads(n)
            model = MODELS.build(name, impl="compiled", schedule=schedule, device="cpu", seed=1)
            model.fit(data)
            scores.append(model.decision_function(X))
    finally:
        torch.set_num_threads(threads)
    assert torch.get_num_threads() == threads
    np.testing.assert_array_equal(scores[0], scores[1])


def test_a_cpu_fit_reads_its_training_set_from_huge_pages(monkeypatch):
    """The kernels read each batch's rows in place, scattered over the training set: on 4 kB
    pages the ConvNet's step ran ~8% slower (``scratch.on_huge_pages``). Scoring does not copy."""
    real, copies = sgd.on_huge_pages, []
    monkeypatch.setattr(sgd, "on_huge_pages", lambda X: copies.append(real(X)) or copies[-1])
    rng = np.random.default_rng(0)
    X = rng.standard_normal((1500, 32, 12))  # float64: the model trains on float32
    y = (rng.random(1500) < 0.5).astype(int)
    data = Instances(X, y, np.array([f"t{i}" for i in range(1500)]), np.arange(1500) // 10)
    model = MODELS.build("haptic_cnn", schedule=Schedule(epochs=1), device="cpu", seed=1)
    model.fit(data)
    (copy,) = copies
    assert copy.ctypes.data % HUGE_PAGE == 0  # 2.3 MB as float32: on huge pages
    np.testing.assert_array_equal(copy, model._preprocess(X).astype(np.float32))
    model.decision_function(X)  # scoring reads rows in order: no copy
    assert len(copies) == 1


def test_features_in_batches_equal_one_batch_and_a_fit_on_huge_pages_does_not_copy(monkeypatch):
    """Scoring ``INFERENCE_BATCH`` rows a call gives each row's features as one call does (the
    compiled ConvNet and LSTM compute every row on its own), and a training set already on huge
    pages, as the haptic modality writes its instances, is trained on in place."""
    rng = np.random.default_rng(0)
    X = empty_on_huge_pages(700, 32, 24)
    X[...] = rng.standard_normal(X.shape)
    y = (rng.random(700) < 0.5).astype(int)
    data = Instances(X, y, np.array([f"t{i}" for i in range(700)]), np.arange(700) // 10)
    real, taken = sgd.on_huge_pages, []
    monkeypatch.setattr(sgd, "on_huge_pages", lambda X: taken.append(real(X)) or taken[-1])
    for name in ("haptic_cnn", "haptic_lstm"):
        model = MODELS.build(name, schedule=Schedule(epochs=1, finetune_epochs=1), device="cpu")
        model.fit(data)
        assert taken.pop() is X
        monkeypatch.setattr(sgd, "INFERENCE_BATCH", 1024)  # one call
        whole = model.transform(X)
        monkeypatch.setattr(sgd, "INFERENCE_BATCH", 256)  # 3 calls, the last of 188 rows
        np.testing.assert_array_equal(model.transform(X), whole)


@pytest.mark.parametrize("n", [513, 600])
def test_the_linear_head_scores_blocks_of_rows_as_the_whole_matrix(monkeypatch, n):
    """Scoring preprocesses a block of rows at a time (no standardised copy of the whole input),
    and the scores are the bits that standardising and scoring all rows at once gives, a last
    block of one row (513 = 2 x 256 + 1) included: torch multiplies a lone row another way."""
    rng = np.random.default_rng(0)
    X = rng.standard_normal((n, 40, 6)).astype(np.float32) * 3 + 1
    y = (X[:, 0, 0] + rng.standard_normal(n) > 1).astype(int)
    data = Instances(X, y, np.array([f"t{i}" for i in range(n)]), np.arange(n))
    model = MODELS.build("linear", schedule=Schedule(epochs=2, finetune_epochs=1), device="cpu")
    model.fit(data)
    with torch.no_grad(), model._torch_threads():
        whole = model.classifier_(model._tensor(X)).squeeze(1).double().numpy()
    blocks = []
    real = model._tensor
    monkeypatch.setattr(model, "_tensor", lambda rows: blocks.append(len(rows)) or real(rows))
    monkeypatch.setattr(sgd, "INFERENCE_BATCH", 256)
    np.testing.assert_array_equal(model.decision_function(X), whole)
    assert max(blocks) <= 257 and sum(blocks) == n

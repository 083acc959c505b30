"""Haptic CNN, LSTM, linear head and random guess: shapes, grouping, schedule, learning."""

import dataclasses

import numpy as np
import pytest
import torch
from sklearn.metrics import roc_auc_score

from tactile_exp.data.layout import Instances
from tactile_exp.models import MODELS
from tactile_exp.models.haptic_cnn import GroupedTemporalConvNet
from tactile_exp.models.linear import LinearModel
from tactile_exp.models.random_guess import RandomGuess
from tactile_exp.models.schedule import Schedule
from tactile_exp.testing import check_model

FAST_SCHEDULE = Schedule(epochs=3, finetune_epochs=2, batch_size=50)
FAST = dict(schedule=FAST_SCHEDULE, device="cpu")


def fast(**changes) -> dict:
    """FAST with some of its schedule's values changed."""
    return {**FAST, "schedule": dataclasses.replace(FAST_SCHEDULE, **changes)}


def easy_case(n: int, channels: int = 32, steps: int = 150, seed: int = 0, noise: float = 1.0):
    """Noise; positives carry a level shift of one signal (channel 3) in one EP window."""
    rng = np.random.default_rng(seed)
    X = noise * rng.standard_normal((n, channels, steps)).astype(np.float32)
    y = (np.arange(n) % 2).astype(int)
    rng.shuffle(y)
    X[y == 1, 3, steps * 3 // 4 :] += 1.5  # the last EP window (fast slide)
    return Instances(X, y, np.array([f"t{i}" for i in range(n)]), np.arange(n) // 10)


@pytest.mark.parametrize("channels", [32, 64])
def test_cnn_shapes(channels):
    train = easy_case(40, channels)
    model = MODELS.build(
        "haptic_cnn", schedule=Schedule(epochs=1, finetune_epochs=1, batch_size=20), device="cpu"
    )
    model.fit(train)
    assert model.conv3_shape_ == (128, 19)
    assert model.transform(train.X[:7]).shape == (7, 128 * 19)
    scores = model.decision_function(train.X[:7])
    assert scores.shape == (7,) and np.isfinite(scores).all()


def test_lstm_shapes_and_transform_is_relu_fc10():
    train = easy_case(30, steps=20)
    model = MODELS.build(
        "haptic_lstm", schedule=Schedule(epochs=1, finetune_epochs=1, batch_size=10), device="cpu"
    )
    model.fit(train)
    features = model.transform(train.X)
    assert features.shape == (30, 10) and (features >= 0).all()
    assert model.decision_function(train.X).shape == (30,)


@pytest.mark.parametrize(("channels", "perturbed", "group"), [(32, 5, 5), (64, 37, 5)])
def test_grouping_keeps_signals_separate(channels, perturbed, group):
    torch.manual_seed(0)
    net = GroupedTemporalConvNet(channels, 150)
    x = torch.randn(4, channels, 150)
    x2 = x.clone()
    x2[:, perturbed] += torch.randn(4, 150)
    with torch.no_grad():
        changed = (net(x2) - net(x)).abs().view(4, 32, 4 * 19).amax(dim=(0, 2)) > 0
    assert changed.tolist() == [g == group for g in range(32)]


def test_the_convnet_compiles_its_stacks_backward_only_for_a_loss_the_tiled_step_lacks():
    """A job compiles ahead what ``kernels()`` lists: the tiled step trains with the registered
    losses, so the stack's backward (``grouped_conv_autograd``) is listed only when stage 1
    trains with another (a plugin's), and nothing is listed where no kernel runs."""
    from tactile_exp.models.losses import LOSSES, hinge

    usual = (
        "tactile_exp.models.linear_sgd",
        "tactile_exp.models.grouped_conv_numba",
        "tactile_exp.models.convnet_tiles",
    )
    assert MODELS.build("haptic_cnn").kernels() == usual
    assert MODELS.build("haptic_cnn", loss="logistic", pretrain_loss=None).kernels() == usual
    with LOSSES.temporary(squared_hinge=lambda s, y: hinge(s, y) ** 2):
        # stage 2 trains the layer alone (``linear_sgd``): its loss needs no backward of the stack
        assert MODELS.build("haptic_cnn", loss="squared_hinge").kernels() == usual
        for plugin in (
            dict(pretrain_loss="squared_hinge"),
            dict(loss="squared_hinge", pretrain_loss=None),
        ):
            kernels = MODELS.build("haptic_cnn", **plugin).kernels()
            assert kernels == (*usual, "tactile_exp.models.grouped_conv_autograd"), plugin
    assert MODELS.build("haptic_cnn", impl="torch").kernels() == ()


def test_auto_is_compiled_on_cpu_and_torch_still_selectable():
    net = GroupedTemporalConvNet(32, 30)
    x = torch.randn(3, 32, 30)
    assert type(net(x).grad_fn).__name__ == "GroupedConvStackBackward"
    net.impl = "torch"
    assert type(net(x).grad_fn).__name__ != "GroupedConvStackBackward"
    net.impl = "auto"  # an input that needs a gradient goes through torch, which gives one
    x.requires_grad_()
    net(x).sum().backward()
    assert x.grad is not None and x.grad.abs().sum() > 0
    net.impl = "compiled"
    with pytest.raises(ValueError, match="impl='torch'"):
        net(x)


def test_compiled_and_torch_training_give_the_same_auc():
    train, test = easy_case(120, steps=60), easy_case(60, steps=60, seed=1)
    scores = {}
    for impl in ("compiled", "torch"):
        model = MODELS.build("haptic_cnn", impl=impl, seed=3, **FAST)
        model.fit(train)
        scores[impl] = model.decision_function(test.X)
    np.testing.assert_allclose(scores["compiled"], scores["torch"], rtol=1e-3, atol=1e-4)
    auc = {k: roc_auc_score(test.y, v) for k, v in scores.items()}
    assert auc["torch"] > 0.7  # it learnt something, so equal AUCs mean something
    assert abs(auc["compiled"] - auc["torch"]) < 0.01


def test_logistic_then_hinge_schedule_reports_every_epoch_and_lowers_loss():
    calls = []
    model = MODELS.build("haptic_cnn", **fast(epochs=6, finetune_epochs=4))
    history = model.fit(easy_case(100, steps=60), lambda e, n, m: calls.append((e, n, *m)))
    assert [c[:2] for c in calls] == [(e, 10) for e in range(1, 11)]
    assert [c[2] for c in calls] == ["train_loss"] * 6 + ["finetune_loss"] * 4
    assert len(history["train_loss"]) == 6 and len(history["finetune_loss"]) == 4
    assert history["train_loss"][-1] < history["train_loss"][0]
    assert history["finetune_loss"][-1] < history["finetune_loss"][0]


def test_finetune_moves_only_the_classifier():
    model = MODELS.build("haptic_cnn", **fast(epochs=1, finetune_epochs=0))
    model.fit(easy_case(60))
    body_after_stage1 = [p.detach().clone() for p in model.body_.parameters()]
    tuned = MODELS.build("haptic_cnn", **fast(epochs=1, finetune_epochs=3))
    tuned.fit(easy_case(60))
    for a, b in zip(body_after_stage1, tuned.body_.parameters(), strict=True):
        assert torch.equal(a, b)


def test_no_pretrain_loss_trains_one_stage():
    model = MODELS.build("haptic_cnn", **{**FAST, "pretrain_loss": None})
    assert list(model.fit(easy_case(60))) == ["train_loss"]


@pytest.mark.parametrize("name", ["haptic_cnn", "haptic_lstm", "linear"])
def test_same_seed_same_scores(name):
    train = easy_case(60, steps=40)
    runs = []
    for seed in (7, 7, 8):
        model = MODELS.build(name, seed=seed, **FAST)
        model.fit(train)
        runs.append(model.decision_function(train.X))
    np.testing.assert_array_equal(runs[0], runs[1])
    assert not np.array_equal(runs[0], runs[2])


@pytest.mark.parametrize(
    ("name", "steps", "schedule"),
    [
        ("haptic_cnn", 150, Schedule(epochs=10, finetune_epochs=5, batch_size=50)),
        ("haptic_lstm", 20, Schedule(epochs=15, finetune_epochs=5, batch_size=25, lr=0.05)),
        ("linear", 150, Schedule(epochs=10, finetune_epochs=5, batch_size=50)),
    ],
)
def test_learns_easy_case_well_above_chance(name, steps, schedule):
    train, test = easy_case(300, steps=steps), easy_case(200, steps=steps, seed=1)
    model = MODELS.build(name, device="cpu", schedule=schedule)
    model.fit(train)
    assert roc_auc_score(test.y, model.decision_function(test.X)) > 0.9


def test_linear_standardises_so_feature_scale_does_not_matter():
    train, test = easy_case(200), easy_case(100, seed=1)
    aucs = []
    for scale in (1.0, 1000.0):
        model = LinearModel(
            schedule=Schedule(epochs=5, finetune_epochs=2, batch_size=50), device="cpu"
        )
        model.fit(Instances(train.X * scale, train.y, train.trial, train.object_id))
        aucs.append(roc_auc_score(test.y, model.decision_function(test.X * scale)))
    assert min(aucs) > 0.9
    assert aucs[0] == pytest.approx(aucs[1], abs=0.02)


@pytest.mark.parametrize("n", [1, 63, 64, 65, 200])
def test_linear_standardisation_is_numpys_float64_mean_and_std_bit_for_bit(n):
    """The statistics are summed in blocks of rows (no float64 copy of the features), in the
    order numpy sums them: the same bits as ``astype(float64).mean/std(axis=0)``, also for
    columns far from zero (catastrophic cancellation in a one-pass formula) and constant ones."""
    rng = np.random.default_rng(n)
    X = rng.normal(size=(n, 300)) * rng.uniform(0, 50, 300) + 1e4 * rng.normal(size=300)
    X = X.astype(np.float32)
    X[:, 7] = 3.0  # constant: std 0, kept as scale 1
    model = LinearModel(device="cpu")
    model._fit_preprocessing(X.reshape(n, 3, 100))
    f64 = X.astype(np.float64)
    std = f64.std(axis=0)
    np.testing.assert_array_equal(model.mean_, f64.mean(axis=0).astype(np.float32))
    np.testing.assert_array_equal(model.scale_, np.where(std > 0, std, 1.0).astype(np.float32))
    assert model.scale_[7] == 1.0
    np.testing.assert_array_equal(model._preprocess(X), (X - model.mean_) / model.scale_)


def test_head_is_a_linear_model_with_the_same_settings():
    model = MODELS.build("haptic_cnn", seed=4, loss="logistic", **fast(lr=0.05))
    head = model.head()
    assert isinstance(head, LinearModel)
    assert (head.seed, head.loss) == (4, "logistic")
    assert head.schedule == dataclasses.replace(FAST_SCHEDULE, lr=0.05)
    features = easy_case(40).X.reshape(40, -1)[:, :200]
    head.fit(Instances(features, easy_case(40).y, np.zeros(40), np.zeros(40)))
    assert head.decision_function(features).shape == (40,)


def test_random_guess_is_chance_and_seeded():
    y = np.arange(100) % 2
    X = np.zeros((100, 32, 150), dtype=np.float32)
    aucs = [roc_auc_score(y, RandomGuess(seed=s).decision_function(X)) for s in range(300)]
    assert abs(np.mean(aucs) - 0.5) < 0.01
    np.testing.assert_array_equal(
        RandomGuess(seed=1).decision_function(X), RandomGuess(seed=1).decision_function(X)
    )
    model = MODELS.build("random", seed=1)
    assert model.fit(Instances(X, y, y, y)) == {} and not model.learns_representation
    assert isinstance(model.head(), RandomGuess)


@pytest.mark.parametrize(
    ("name", "kwargs", "argument"),
    [
        ("haptic_cnn", dict(schedule={"lr": 0}), "schedule.lr: lr must be > 0"),
        ("haptic_cnn", dict(schedule={"epochs": 0}), "schedule.epochs: epochs must be"),
        ("haptic_cnn", dict(schedule={"batch_size": 0}), "schedule.batch_size: batch_size"),
        ("haptic_cnn", dict(schedule={"head": {"lr": -1}}), "schedule.head.lr: lr must be"),
        ("haptic_cnn", dict(loss="squared"), "loss"),
        ("haptic_cnn", dict(pretrain_loss="squared"), "pretrain_loss"),
        ("haptic_cnn", dict(impl="cuda_magic"), "impl"),
        ("haptic_cnn", dict(widths=(4, 0, 4)), "widths"),
        ("haptic_cnn", dict(kernel_sizes=(5, 5)), "kernel_sizes"),
        ("haptic_lstm", dict(hidden=0), "hidden"),
        ("linear", dict(schedule={"momentum": -0.1}), "schedule.momentum: momentum must be"),
        ("linear", dict(device="tpu"), "device"),
    ],
)
def test_bad_arguments_raise_naming_the_argument(name, kwargs, argument):
    with pytest.raises(ValueError, match=argument):
        MODELS.build(name, **kwargs)


def test_bad_inputs_raise_clear_errors():
    model = MODELS.build("haptic_cnn", **FAST)
    with pytest.raises(RuntimeError, match="not fitted"):
        model.decision_function(np.zeros((2, 32, 150), dtype=np.float32))
    bad = easy_case(10)
    with pytest.raises(ValueError, match="multiple of groups=32"):
        model.fit(Instances(bad.X[:, :30], bad.y, bad.trial, bad.object_id))
    model.fit(easy_case(20))
    with pytest.raises(ValueError, match=r"fitted on rows of shape \(32, 150\)"):
        model.decision_function(np.zeros((2, 64, 150), dtype=np.float32))


@pytest.mark.parametrize("name", MODELS.names())
def test_every_registered_model_keeps_the_contract(name):
    """Built from its own YAML on the tiny schedule (``tactile_exp.testing.check_model``): fits,
    scores, clones, is deterministic for a seed, gives a head, declares what the engine reads
    and, when storable, round-trips through the store with the same scores. A new model is
    tested here the moment it is registered; a plugin runs the same check."""
    check_model(name)


def test_a_model_that_breaks_the_contract_is_named_by_the_check(monkeypatch):
    """The check fails, naming the promise, for a model whose seed does not make it
    deterministic, and for one that does not hold a parameter under its own name."""
    from tactile_exp.models.random_guess import RandomGuess

    class Unseeded(RandomGuess):
        learns_representation = True

        def fit(self, train, on_epoch=None):
            self._rng = np.random.default_rng()
            return {}

    class Renamed(RandomGuess):
        def __init__(self, *, seed: int = 0) -> None:
            super().__init__(seed=seed)
            self.seed = seed + 1

    for broken, promise in ((Unseeded, "same seed"), (Renamed, "under its own name")):
        with MODELS.temporary(random=broken), pytest.raises(AssertionError, match=promise):
            check_model("random")


TINY = Schedule(epochs=1, finetune_epochs=1, batch_size=16)


@pytest.mark.parametrize("name", ["haptic_cnn", "haptic_lstm", "linear"])
def test_haptic_models_take_any_sensor(name):
    """Another sensor's instances (6 channels x 40 steps, e.g. 50 Hz for 0.8 s): the ConvNet with
    one group per channel, the LSTM and the linear model fit one epoch and score them."""
    rng = np.random.default_rng(0)
    n = 24
    y = np.arange(n) % 2
    X = rng.standard_normal((n, 6, 40)).astype(np.float32) + y[:, None, None]
    train = Instances(X, y, np.array([f"t{i}" for i in range(n)], dtype=object), np.arange(n))
    extra = {"groups": 6} if name == "haptic_cnn" else {}
    model = MODELS.build(name, schedule=TINY, device="cpu", **extra)
    history = model.fit(train)
    assert len(history["train_loss"]) == 1
    scores = model.decision_function(X)
    assert scores.shape == (n,) and np.isfinite(scores).all()
    assert model.input_shape_ == (6, 40)
    if name == "haptic_cnn":
        assert model.conv3_shape_ == (6 * 4, 5)  # 4 maps per signal; 40 -> 20 -> 10 -> 5 steps
        assert model.transform(X).shape == (n, 6 * 4 * 5)


def test_one_group_per_channel_is_the_groups_of_that_count_on_any_sensor():
    """groups=channels is groups=C for C-channel rows (the same net, the same scores), on 6
    channels as on 10; a string other than `channels` is refused naming the parameter."""
    rng = np.random.default_rng(1)
    for channels in (6, 10):
        X = rng.standard_normal((24, channels, 40)).astype(np.float32)
        names = np.array([f"t{i}" for i in range(24)], dtype=object)
        train = Instances(X, np.arange(24) % 2, names, np.arange(24))
        fitted = []
        for groups in ("channels", channels):
            model = MODELS.build("haptic_cnn", schedule=TINY, device="cpu", groups=groups)
            model.fit(train)
            fitted.append(model)
        np.testing.assert_array_equal(
            fitted[0].decision_function(X), fitted[1].decision_function(X)
        )
        assert fitted[0].conv3_shape_ == (channels * 4, 5)
    with pytest.raises(ValueError, match="groups: expected a whole number or 'channels'"):
        MODELS.build("haptic_cnn", groups="per_channel")


def test_head_schedule_is_its_own():
    head = {"epochs": 7, "batch_size": 64, "lr": 0.1}
    own = {"epochs": 3, "finetune_epochs": 2, "momentum": 0.5}
    model = MODELS.build("haptic_cnn", schedule={**own, "head": head})
    head = model.head()
    assert head.schedule == Schedule(7, 2, 64, 0.1, 0.5)  # what the head's node lacks: the model's
    assert head.seed == model.seed and head.head().schedule == head.schedule
    assert MODELS.build("haptic_cnn", **FAST).head().schedule == FAST_SCHEDULE  # no head: its own
    with pytest.raises(ValueError, match=r"^schedule.head.epoch: unknown key; allowed: epochs,"):
        MODELS.build("haptic_cnn", schedule={"head": {"epoch": 7}})

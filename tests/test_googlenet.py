"""The visual rows' loss layer (M3, T4; ``visual_googlenet``): directly on the L2-normalised
features, with a step that learns on them; only the loss layer trains."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import CONF
from hydra import compose, initialize_config_dir
from sklearn.metrics import roc_auc_score

from tactile_exp.config import settings_from_config
from tactile_exp.data.layout import Instances
from tactile_exp.models import MODELS
from tactile_exp.models.schedule import Schedule

ONE_EPOCH = Schedule(epochs=1, finetune_epochs=0)


def _unit_norm_features(n: int, seed: int, views: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Separable rows like the trunk's: unit norm, cosine ~0.95 to a shared direction, the label
    in a small orthogonal component; ``views`` unit-norm rows per unit concatenated."""
    rng = np.random.default_rng(seed)
    d = 832
    common = np.abs(rng.normal(size=d))
    common /= np.linalg.norm(common)
    direction = rng.normal(size=d)
    direction -= direction @ common * common
    direction /= np.linalg.norm(direction)
    y = (np.arange(n) % 3 == 0).astype(np.int64)  # a third positive
    rows = []
    for _ in range(views):
        noise = rng.normal(size=(n, d))
        noise -= np.outer(noise @ common, common)
        noise /= np.linalg.norm(noise, axis=1, keepdims=True)
        x = 0.95 * common + 0.31 * (0.5 * noise + 0.5 * np.outer(2 * y - 1, direction))
        rows.append(x / np.linalg.norm(x, axis=1, keepdims=True))
    return np.concatenate(rows, axis=1).astype(np.float32), y


def _instances(X: np.ndarray, y: np.ndarray) -> Instances:
    return Instances(X, y, np.arange(len(X)).astype(str).astype(object), np.arange(len(X)))


def _entropy(y: np.ndarray) -> float:
    p = y.mean()
    return -(p * math.log(p) + (1 - p) * math.log(1 - p))


@pytest.fixture(scope="module")
def visual_model_params():
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose(
            "config",
            overrides=[
                "experiment=table1_l_image_googlenet_8views",
                "schedule=quick",
                "device=cpu",
            ],
        )
    return dict(settings_from_config(cfg).model.params)


def test_visual_schedule_learns_on_unit_norm_features(visual_model_params):
    X, y = _unit_norm_features(420, seed=0)  # a split's ~420 training photographs
    entropy = _entropy(y)
    model = MODELS.build("visual_googlenet", **visual_model_params)
    history = model.fit(_instances(X, y))
    assert history["train_loss"][-1] < 0.6 * entropy  # it left the intercept
    assert history["finetune_loss"][-1] < 0.1
    # T3's step (lr 0.01, batch 1000 = full batch) on the same rows learns only the intercept
    t3_step = {**visual_model_params["schedule"], "lr": 0.01, "batch_size": 1000}
    t3 = MODELS.build("visual_googlenet", **{**visual_model_params, "schedule": t3_step})
    assert t3.fit(_instances(X, y))["train_loss"][-1] > 0.9 * entropy


def test_row_l_head_learns_on_concatenated_unit_norm_views(visual_model_params):
    X, y = _unit_norm_features(53, seed=1, views=8)  # ~53 objects x 8 concatenated views
    head = MODELS.build("visual_googlenet", **visual_model_params).head()
    assert head.standardize is False
    history = head.fit(_instances(X, y))
    assert history["train_loss"][-1] < 0.6 * _entropy(y)


def test_visual_head_puts_the_loss_directly_on_the_features():
    X, y = _unit_norm_features(40, seed=2, views=2)
    head = MODELS.build("visual_googlenet", schedule=ONE_EPOCH, device="cpu").head()
    head.fit(_instances(X, y))
    np.testing.assert_array_equal(head._preprocess(X), X)  # no standardisation
    linear = MODELS.build("linear", schedule=ONE_EPOCH, device="cpu")
    linear.fit(_instances(X, y))
    assert not np.allclose(linear._preprocess(X), X)  # the haptic heads keep standardising
    assert MODELS.build("haptic_cnn", schedule=ONE_EPOCH, device="cpu").head().standardize is True
    with pytest.raises(ValueError, match="standardize"):
        MODELS.build("linear", standardize="no")


def _features(n: int, seed: int) -> Instances:
    """Unit-norm 832-d rows whose direction depends on the label."""
    rng = np.random.default_rng(seed)
    y = np.arange(n) % 2
    X = np.abs(rng.normal(size=(n, 832))) + 0.6 * y[:, None] * (np.arange(832) < 50)
    X /= np.linalg.norm(X, axis=1, keepdims=True)
    return Instances(X.astype(np.float32), y, np.arange(n).astype(str), np.arange(n))


def test_loss_layer_learns_on_l2_features_and_rejects_other_rows():
    model = MODELS.build(
        "visual_googlenet", schedule=Schedule(epochs=60, finetune_epochs=20, batch_size=64)
    )
    train, test = _features(200, 0), _features(100, 1)
    history = model.fit(train)
    assert len(history["train_loss"]) == 60 and len(history["finetune_loss"]) == 20
    assert history["train_loss"][-1] < history["train_loss"][0]
    assert roc_auc_score(test.y, model.decision_function(test.X)) > 0.9
    trained = [*model.body_.parameters(), *model.classifier_.parameters()]
    assert sum(p.numel() for p in trained) == 833  # only the loss layer: the trunk stays frozen
    np.testing.assert_array_equal(model.transform(test.X), test.X)  # the trunk is upstream
    assert type(model.head()).__name__ == "LinearModel"
    y = np.array([0, 1, 0, 1])
    bad = Instances(np.zeros((4, 1024), np.float32), y, np.zeros(4), np.zeros(4))
    with pytest.raises(ValueError, match=r"visual_googlenet expects .* \(n, 832\)"):
        model.fit(bad)

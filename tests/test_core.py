"""The pure core: one adjective fitted and scored from a model cache, with no tracking store;
and the extensions it takes with no engine file touched (a modality with a new output kind, a
new reusable part, a new model-cache back-end)."""

from __future__ import annotations

import dataclasses
import json
import weakref
from pathlib import Path
from typing import Any, Self

import numpy as np
import pytest
from sklearn.metrics import average_precision_score, roc_auc_score

from tactile_exp import artifacts, core
from tactile_exp.cache import MemoryCache, Train, Trained
from tactile_exp.config import settings_from_config
from tactile_exp.data.layout import Instances, Trials
from tactile_exp.modalities import MODALITIES, Modality
from tactile_exp.modalities.haptic import Haptic
from tactile_exp.models.linear import LinearModel
from tactile_exp.pipeline import AdjectivePipeline
from tactile_exp.registry import Component

ROW_I = ["experiment=table1_i_haptic_cnn_1trial"]


@pytest.fixture
def row_i(tiny_config):
    """Row I on tiny data (one adjective), its data set and split: nothing opened in MLflow."""
    settings = settings_from_config(tiny_config(ROW_I, adjectives="[hard]"))
    dataset, _, splits = core.load(settings)
    return settings, dataset, splits["hard"]


def test_fit_adjective_scores_every_side_and_a_cache_gives_the_same_model_back(row_i):
    settings, dataset, split = row_i
    cache = MemoryCache()
    first = core.fit_adjective(settings, dataset, split, cache)
    test = first.test
    assert first.metrics["auc"] == roc_auc_score(test.y, test.scores)
    assert first.metrics["average_precision"] == pytest.approx(
        average_precision_score(test.y, test.scores), abs=1e-12
    )
    assert set(first.sides) == {"test", "train"}  # no validation objects held out
    assert set(test.objects) <= split.objects("test")  # test metrics: test objects only
    assert first.history["train_loss"] and len(cache.keys) == 1  # the ConvNet, trained once
    again = core.fit_adjective(settings, dataset, split, cache)
    assert len(cache.keys) == 1 and "train_loss" not in again.history  # found, not trained
    np.testing.assert_array_equal(again.test.scores, test.scores)
    # The fitted pipeline scores new trials as it scored the test side.
    scores, _ = first.pipeline.decision_function(split.trials("test", dataset))
    np.testing.assert_array_equal(scores, test.scores)


def test_the_training_instances_are_freed_before_the_head_trains(row_i, monkeypatch):
    """Row I's head trains on the units of the ConvNet's features: the modality's training
    instances (the ConvNet's input, the larger array) are gone by then, whether the ConvNet is
    trained or found in the cache."""
    settings, dataset, split = row_i
    made, alive_at_head = [], []
    transform = Haptic.transform

    def tracked(self, trials):
        out = transform(self, trials)
        made.append(weakref.ref(out.X.base if out.X.base is not None else out.X))
        return out

    monkeypatch.setattr(Haptic, "transform", tracked)
    fit = LinearModel.fit

    def head_fit(self, train, on_epoch=None):
        alive_at_head.append(made[0]() is not None)
        return fit(self, train, on_epoch)

    monkeypatch.setattr(LinearModel, "fit", head_fit)
    cache = MemoryCache()
    for _ in range(2):  # trained, then found by its training key
        made.clear()
        core.fit_adjective(settings, dataset, split, cache)
    assert alive_at_head == [False, False] and len(cache.keys) == 1


def test_validation_side_has_its_own_metrics(tiny_config):
    settings = settings_from_config(
        tiny_config([*ROW_I, "validation.fraction=0.3"], adjectives="[hard]")
    )
    dataset, _, splits = core.load(settings)
    result = core.fit_adjective(settings, dataset, splits["hard"], MemoryCache())
    val = result.sides["val"]
    assert not set(val.objects) & set(result.test.objects)  # never a test object
    assert val.metrics["auc"] == roc_auc_score(val.y, val.scores)
    assert result.sizes["n_val_objects"] == len(set(val.objects))


class OnHaptic(Modality):
    """What both new modalities below share: the haptic modality's check, fit and state."""

    def __init__(self, *, cache_dir: Path | None = None, **haptic: Any) -> None:
        super().__init__(cache_dir=cache_dir)
        self.haptic = Haptic(cache_dir=cache_dir, **haptic)

    def check(self, dataset: Any) -> None:
        self.haptic.check(dataset)

    def fit(self, trials: Trials) -> Self:
        self.haptic.fit(trials)
        return self

    def get_state(self) -> tuple[dict, dict]:
        return self.haptic.get_state()

    def set_state(self, settings: dict, arrays: dict) -> Self:
        self.haptic.set_state(settings, arrays)
        return self


class TrialStats(OnHaptic):
    """A new output kind: per trial, each channel's mean and spread (a flat feature row)."""

    def transform(self, trials: Trials) -> Instances:
        signals = self.haptic.transform(trials)
        X = np.concatenate([signals.X.mean(-1), signals.X.std(-1)], axis=1)
        return Instances(X, signals.y, signals.trial, signals.object_id)


class ConvFeatures(OnHaptic):
    """A new reusable part: row I's ConvNet (trained on the haptic modality) as a feature map."""

    def __init__(self, *, cache_dir: Path | None = None, haptic: dict, net: dict) -> None:
        super().__init__(cache_dir=cache_dir, **haptic)
        self.part = (Component("haptic", haptic), Component("haptic_cnn", net))

    def parts(self) -> dict[str, tuple[Component, Component]]:
        return {"net": self.part}

    def set_parts(self, parts: dict) -> None:
        self.net_ = parts["net"]

    def transform(self, trials: Trials) -> Instances:
        signals = self.haptic.transform(trials)
        return Instances(
            self.net_.transform(signals.X), signals.y, signals.trial, signals.object_id
        )


@pytest.fixture
def registered():
    with MODALITIES.temporary(trial_stats=TrialStats, conv_features=ConvFeatures):
        yield


def test_a_modality_with_a_new_output_kind_fits_with_no_engine_change(row_i, registered):
    settings, dataset, split = row_i
    stats = dataclasses.replace(
        settings,
        modality=Component("trial_stats", settings.modality.params),
        model=Component("linear_svm", {}),
    )
    result = core.fit_adjective(stats, dataset, split, MemoryCache())
    assert result.pipeline.n_train_instances_ == result.sizes["n_train_instances"]
    assert result.metrics["auc"] == roc_auc_score(result.test.y, result.test.scores)
    assert len(np.unique(result.test.scores)) > 1


def test_a_new_reusable_part_is_trained_once_kept_and_stored_with_the_pipeline(
    row_i, registered, tiny_config, tmp_path
):
    settings, dataset, split = row_i
    params = {"haptic": settings.modality.params, "net": settings.model.params}
    layer = settings_from_config(tiny_config([*ROW_I, "model=linear"], adjectives="[hard]")).model
    features = dataclasses.replace(
        settings, modality=Component("conv_features", params), model=layer
    )  # row M's shape: a classification layer on the part's conv3 features
    cache = MemoryCache()
    first = core.fit_adjective(features, dataset, split, cache)
    part_key = cache.keys[0]
    again = core.fit_adjective(features, dataset, split, cache)
    assert cache.keys.count(part_key) == 1  # the part was found the second time
    np.testing.assert_array_equal(again.test.scores, first.test.scores)
    # Row I trains the same ConvNet (same training key): it finds the part, trains nothing.
    row = core.fit_adjective(settings, dataset, split, cache)
    assert "train_loss" not in row.history and cache.keys.count(part_key) == 1
    first.pipeline.save(tmp_path)
    loaded = AdjectivePipeline.load(tmp_path, "here")
    scores, _ = loaded.decision_function(split.trials("test", dataset))
    np.testing.assert_allclose(scores, first.test.scores, rtol=0, atol=1e-6)


class FolderStore:
    """A new model-cache back-end: trained models kept in a folder (any process finds them) and
    what it was asked recorded in a JSON log, with no MLflow."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.log = root / "log.json"

    def get_or_train(
        self, key: str, train: Train, *, part: str | None = None, overrides: Any = None
    ) -> Trained:
        folder = self.root / key
        asked = json.loads(self.log.read_text()) if self.log.exists() else []
        found = folder.is_dir()
        self.log.write_text(json.dumps([*asked, {"key": key, "part": part, "found": found}]))
        if found:
            return Trained(artifacts.read_model(folder, str(folder), overrides), source=str(folder))
        model, history = train()
        folder.mkdir(parents=True)
        artifacts.write_model(folder, artifacts.model_name(model), model)
        return Trained(model, history)


def test_a_new_cache_back_end_keeps_models_across_instances(row_i, tmp_path):
    settings, dataset, split = row_i
    first = core.fit_adjective(settings, dataset, split, FolderStore(tmp_path))
    again = core.fit_adjective(settings, dataset, split, FolderStore(tmp_path))
    asked = json.loads((tmp_path / "log.json").read_text())
    assert [a["found"] for a in asked] == [False, True] and asked[0]["key"] == asked[1]["key"]
    np.testing.assert_array_equal(again.test.scores, first.test.scores)


@pytest.mark.parametrize(
    ("overrides", "expected"),
    [
        (ROW_I, {"linear_sgd", "grouped_conv_numba", "convnet_tiles"}),
        ([*ROW_I, "model.impl=torch"], set()),
        (["experiment=table1_g_haptic_lstm"], {"linear_sgd", "lstm_kernels"}),
        (["experiment=table1_a_haptic_static_1trial"], set()),
        (
            ["experiment=table1_m_multimodal_i_l"],
            {"linear_sgd", "grouped_conv_numba", "convnet_tiles"},
        ),
    ],
    ids=["convnet", "convnet in torch", "lstm", "svm", "multimodal (its part's ConvNet)"],
)
def test_a_jobs_compiled_kernels_are_its_models_and_its_parts_models(
    tiny_config, overrides, expected
):
    """What a job compiles ahead (``numba_setup.compile_ahead``) while its data load."""
    settings = settings_from_config(tiny_config(overrides, adjectives="[hard]"))
    _, modality, _ = core.open_data(settings)
    assert {k.rsplit(".", 1)[-1] for k in core.kernels(settings, modality)} == expected


def test_the_haptic_check_reads_the_biotac_frames_alone(tiny_config, monkeypatch, tmp_path):
    """Preprocessing the whole data set (``Haptic.check``) reads no gripper, accelerometer or
    transform arrays (a sixth of the reading): the arrays are those of a full read."""
    settings = settings_from_config(tiny_config(ROW_I, adjectives="[hard]"))
    dataset, _, _ = core.load(settings)
    asked = []
    iter_trials = type(dataset).iter_trials

    def spy(self, names=None, optional=True):
        asked.append(optional)
        return iter_trials(self, names, optional=optional)

    monkeypatch.setattr(type(dataset), "iter_trials", spy)
    modality = MODALITIES.build("haptic", cache_dir=tmp_path / "empty")
    modality.check(dataset)
    assert asked == [False]
    from tactile_exp.preprocess.haptic import compute_haptic_arrays

    monkeypatch.setattr(type(dataset), "iter_trials", iter_trials)
    full = compute_haptic_arrays(dataset)
    checked = modality.arrays(Trials(dataset, tuple(t.name for t in dataset.trials)))
    np.testing.assert_array_equal(checked.signals, full.signals)
    np.testing.assert_array_equal(checked.scatter, full.scatter)


@pytest.mark.parametrize(
    ("overrides", "ignored"),
    [
        # linear learns no representation: under concat only its head trains, by schedule.head
        (
            [
                "model=linear",
                "schedule.epochs=50",
                "schedule.batch_size=8",
                "schedule.head.lr=0.01",
            ],
            ("schedule.epochs", "schedule.batch_size"),
        ),
        (
            ["model=linear", "combine_instances=mean", "schedule.finetune_epochs=30"],
            ("schedule.finetune_epochs",),
        ),
        # a head node without lr takes the model's: schedule.lr reaches the head
        (["model=linear", "~schedule.head.lr", "schedule.lr=0.05"], ()),
        # separate trains the model and no head
        (
            [
                "model=linear",
                "combine_instances=separate",
                "schedule.epochs=3",
                "schedule.head.epochs=50",
            ],
            ("schedule.head.epochs",),
        ),
        # a ConvNet learns its features: both its schedule and its head's are read
        (["schedule.epochs=3", "schedule.head.epochs=50"], ()),
    ],
)
def test_schedule_overrides_that_nothing_trained_reads_are_named(tiny_config, overrides, ignored):
    settings = settings_from_config(tiny_config(overrides), overrides=tuple(overrides))
    assert core.ignored_schedule_keys(settings) == ignored

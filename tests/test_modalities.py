"""The modality contract, checked for every registered modality (beside tests/test_models.py's):
hyperparameters in the constructor and no data, ``check`` before any fit, ``fit`` on training
trials only, ``transform`` of any trials, and ``get_state``/``set_state`` that give a fresh
instance the very same preprocessing (what a stored pipeline relies on)."""

from __future__ import annotations

import inspect

import numpy as np
import pytest

from tactile_exp.config import settings_from_config
from tactile_exp.data.dataset import Sensor
from tactile_exp.data.folder import FolderDataSet, write_folder
from tactile_exp.data.layout import Instances, Split, Trials
from tactile_exp.data.splits import make_split
from tactile_exp.experiment import load
from tactile_exp.modalities import MODALITIES, Modality
from tactile_exp.models.base import Model
from tactile_exp.models.registry import MODELS

# modality -> the overrides of a tiny job that uses it (all but signals read PHAC-2 files)
ON_PHAC2 = {
    "haptic": ["modality=haptic"],
    "haptic_features": ["experiment=table1_a_haptic_static_1trial"],
    "visual": ["experiment=table1_k_image_googlenet_1view", "modality.size=32"],
    "multimodal": ["experiment=table1_m_multimodal_i_l", "modality.visual.size=32"],
}


def test_every_registered_modality_is_checked_here():
    assert set(MODALITIES.names()) == {*ON_PHAC2, "signals"}


@pytest.mark.parametrize("name", sorted(MODALITIES.names()))
def test_the_constructor_takes_hyperparameters_not_data(name):
    cls = MODALITIES[name]
    assert issubclass(cls, Modality)
    parameters = inspect.signature(cls.__init__).parameters
    assert "dataset" not in parameters and "split" not in parameters
    assert all(p.kind is p.KEYWORD_ONLY for n, p in parameters.items() if n != "self")
    for flag in ("pad_units", "takes_trials", "takes_photographs"):
        assert isinstance(getattr(cls, flag), bool)


def _parts(modality: Modality, train: Trials) -> dict[str, Model]:
    """Each declared part trained on its own modality's instances of ``train``, as the core
    trains a part that no model cache holds."""
    out = {}
    for part, (part_modality, part_model) in modality.parts().items():
        pre = MODALITIES.build(
            part_modality.name, cache_dir=modality.cache_dir, **part_modality.params
        )
        out[part] = MODELS.build(part_model.name, **part_model.params)
        out[part].fit(pre.fit(train).transform(train))
    return out


def _assert_contract(build, dataset, split: Split):
    """Fit on the training trials, transform both sides, and a fresh instance given the state
    transforms the test trials to the same instances."""
    fitted = build()
    fitted.check(dataset)
    train, test = split.trials("train", dataset), split.trials("test", dataset)
    parts = _parts(fitted, train)
    fitted.set_parts(parts)
    first = fitted.fit(train).transform(test)
    assert isinstance(first, Instances) and len(first) > 0
    if fitted.takes_trials:  # instances named by their trial carry its label
        np.testing.assert_array_equal(first.y, [split.labels[str(t)] for t in first.trial])
    assert len(fitted.fit(train).transform(train)) > 0
    settings, arrays = fitted.get_state()
    fresh = build()
    fresh.set_state(settings, arrays)
    fresh.set_parts(parts)
    again = fresh.transform(test)
    np.testing.assert_array_equal(again.trial, first.trial)
    np.testing.assert_allclose(again.X, first.X, rtol=0, atol=1e-6)


@pytest.mark.parametrize("name", sorted(ON_PHAC2))
def test_fit_transform_and_state_on_a_phac2_file(name, tiny_config):
    settings = settings_from_config(tiny_config([*ON_PHAC2[name], "schedule=tiny"], "[hard]"))
    dataset, _, splits = load(settings)
    params = settings.modality.params

    def build():
        return MODALITIES.build(name, cache_dir=settings.cache_dir / "preprocessed", **params)

    _assert_contract(build, dataset, splits["hard"])


def test_fit_transform_and_state_on_another_sensor(tmp_path):
    rng = np.random.default_rng(0)
    labels = {f"o{i}": {"big": i % 2} for i in range(6)}
    trials = {o: [rng.normal(size=(3, 30 + k)) for k in range(2)] for o in labels}
    root = write_folder(tmp_path / "d", Sensor("pad", ("a", "b", "c"), 50.0), labels, trials)
    dataset = FolderDataSet(root)
    split = make_split(dataset, "big", "random", 0)
    _assert_contract(lambda: MODALITIES.build("signals", steps=16), dataset, split)

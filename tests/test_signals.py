"""The ``signals`` modality: resampling, standardisation fitted on training trials only, state."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from phac2_fixture import write_file

from tactile_exp.data.dataset import Sensor
from tactile_exp.data.folder import FolderDataSet, write_folder
from tactile_exp.data.layout import DataError, Trials
from tactile_exp.data.phac2 import PHAC2
from tactile_exp.modalities import MODALITIES
from tactile_exp.modalities.signals import Signals, resample

SENSOR = Sensor("pad", ("p", "q"), 20.0)


def _folder(root: Path, sensor: Sensor = SENSOR) -> FolderDataSet:
    """Four objects of two trials; channel q is constant (its std is 0)."""
    rng = np.random.default_rng(0)
    labels = {f"o{i}": {"big": i % 2} for i in range(4)}
    trials = {
        o: [np.vstack([rng.normal(3.0, 2.0, n), np.full(n, 5.0)]) for n in (7, 10)] for o in labels
    }
    return FolderDataSet(write_folder(root, sensor, labels, trials))


def _trials(ds, names, labels=None) -> Trials:
    return Trials(ds, tuple(names), labels)


@pytest.mark.parametrize("length,steps", [(2, 5), (7, 100), (150, 150), (301, 40)])
def test_resample_is_linear_interpolation_end_to_end(length: int, steps: int) -> None:
    x = np.random.default_rng(length).normal(size=(3, length))
    got = resample(x, steps)
    grid = np.linspace(0, length - 1, steps)
    want = np.stack([np.interp(grid, np.arange(length), row) for row in x])
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    assert got[:, 0].tolist() == x[:, 0].tolist() and np.allclose(got[:, -1], x[:, -1])


def test_standardised_on_the_training_trials_only(tmp_path: Path) -> None:
    ds = _folder(tmp_path / "d")
    names = [t.name for t in ds.trials]
    train, test = names[:6], names[6:]
    labels = {t: int(ds.trial_name(t).object_id % 2 == 0) for t in names}
    modality = MODALITIES.build("signals", steps=12)
    modality.check(ds)
    modality.fit(_trials(ds, train, labels))
    raw = np.stack([resample(ds.signals(t), 12) for t in train])
    np.testing.assert_allclose(modality.mean_, raw.mean(axis=(0, 2)))
    assert modality.scale_[1] == 1.0  # the constant channel: centred, not divided by 0
    fitted = modality.transform(_trials(ds, train, labels))
    assert fitted.X.shape == (6, 2, 12) and fitted.X.dtype == np.float32
    np.testing.assert_allclose(fitted.X[:, 0].mean(), 0.0, atol=1e-6)
    np.testing.assert_allclose(fitted.X[:, 0].std(), 1.0, atol=1e-5)
    assert fitted.X[:, 1].tolist() == np.zeros((6, 12)).tolist()
    assert list(fitted.trial) == train and list(fitted.y) == [labels[t] for t in train]
    assert list(fitted.object_id) == [ds.trial_name(t).object_id for t in train]
    # the test trials are transformed with the training statistics, whatever their own are
    held_out = modality.transform(_trials(ds, test))
    want = (np.stack([resample(ds.signals(t), 12) for t in test])[:, 0] - modality.mean_[0]) / (
        modality.scale_[0]
    )
    np.testing.assert_allclose(held_out.X[:, 0], want, rtol=1e-5)
    assert held_out.y.tolist() == [0, 0]  # unlabelled: zeros


def test_state_round_trip_and_unchecked_data_read_on_demand(tmp_path: Path) -> None:
    ds = _folder(tmp_path / "d")
    names = tuple(t.name for t in ds.trials)
    fitted = Signals(steps=9).fit(_trials(ds, names[:4]))  # never checked: read when needed
    settings, arrays = fitted.get_state()
    assert settings == {"channels": ["p", "q"]} and set(arrays) == {"mean", "scale"}
    loaded = Signals(steps=9).set_state(settings, arrays)
    other = FolderDataSet(ds.path)  # as predict opens it
    np.testing.assert_array_equal(
        loaded.transform(_trials(other, names[4:])).X, fitted.transform(_trials(ds, names[4:])).X
    )
    with pytest.raises(ValueError, match=r"mean \(3,\) and scale \(2,\): expected \(2,\) each"):
        Signals().set_state(settings, {"mean": np.zeros(3), "scale": np.ones(2)})
    with pytest.raises(ValueError, match="scale > 0"):
        Signals().set_state(settings, {"mean": np.zeros(2), "scale": np.zeros(2)})


def test_another_sensor_is_refused_at_transform(tmp_path: Path) -> None:
    ds = _folder(tmp_path / "d")
    fitted = Signals(steps=5).fit(_trials(ds, [t.name for t in ds.trials]))
    other = _folder(tmp_path / "e", Sensor("pad", ("p", "r"), 20.0))
    with pytest.raises(DataError, match=r"channels \['p', 'r'\], but modality=signals was fitted"):
        fitted.transform(_trials(other, [other.trials[0].name]))


def test_a_bad_trial_file_fails_check_before_any_fit(tmp_path: Path) -> None:
    ds = _folder(tmp_path / "d")
    np.save(ds.trial_file(ds.trials[3]), np.zeros((3, 8)))
    with pytest.raises(DataError, match=r"shape \(3, 8\), expected a \(2, time\) array"):
        Signals().check(FolderDataSet(ds.path))


def test_a_data_set_without_signals_is_refused_when_it_opens(tmp_path: Path) -> None:
    phac2 = PHAC2(write_file(tmp_path / "tiny.h5"))
    assert Signals.lacks(phac2) == "trials as (channels, time) arrays"  # declared, not probed
    folder = _folder(tmp_path / "d")
    assert Signals.lacks(folder) is None
    assert Signals().max_combine(folder) == (2, "trials")


@pytest.mark.parametrize("steps", [1, 0, 2.5, True, "100"])
def test_steps_must_be_a_whole_number_of_at_least_two(steps) -> None:
    with pytest.raises(ValueError, match="steps must be a whole number of samples >= 2"):
        Signals(steps=steps)

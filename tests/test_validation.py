"""Object-grouped validation objects: held out of training, stratified, never a test object."""

from __future__ import annotations

import numpy as np
import pytest
from phac2_fixture import OBJECTS, write_file

from tactile_exp.data.layout import ADJECTIVES, Instances, TrialName
from tactile_exp.data.phac2 import PHAC2
from tactile_exp.data.splits import make_split
from tactile_exp.validation import take_trials, validation_split


@pytest.fixture(scope="module")
def full(tmp_path_factory: pytest.TempPathFactory) -> PHAC2:
    path = tmp_path_factory.mktemp("full") / "plain.h5"
    return PHAC2(write_file(path, tuple(OBJECTS), 10, signals=False, adjective_links=False))


def _objects(trials) -> set[int]:
    return {TrialName.parse(t).object_id for t in trials}


@pytest.mark.parametrize("rule,seed", [("published", 0), ("random", 1), ("random", 2)])
def test_validation_objects_are_training_objects_of_both_classes(full, rule, seed):
    for adjective in ADJECTIVES:
        split = make_split(full, adjective, rule, seed)
        reduced, held = validation_split(split, fraction=0.15, seed=seed)
        val_objects = _objects(held)
        assert not val_objects & split.objects("test")  # never a test object
        assert not val_objects & reduced.objects("train")  # left out of training, whole objects
        assert set(held) | set(reduced.train) == set(split.train)
        assert reduced.test == split.test
        for label in (0, 1):  # stratified: a class is held out whenever training can spare it
            only_train = _objects(t for t in split.train if split.labels[t] == label)
            spare = len(only_train - split.objects("test")) >= 2
            assert spare == any(split.labels[t] == label for t in held)
        assert {reduced.labels[t] for t in reduced.train} == {0, 1}
        n_train = len(split.objects("train"))
        assert 0.1 * n_train <= len(val_objects) <= 0.25 * n_train


def test_validation_is_seeded_and_fraction_zero_holds_nothing(full):
    split = make_split(full, "soft")
    assert validation_split(split, fraction=0.15, seed=3) == validation_split(
        split, fraction=0.15, seed=3
    )
    assert validation_split(split, fraction=0.15, seed=3) != validation_split(
        split, fraction=0.15, seed=4
    )
    assert validation_split(split, fraction=0.0, seed=3) == (split, ())
    with pytest.raises(ValueError, match="fraction"):
        validation_split(split, fraction=1.0, seed=0)


def test_take_trials_partitions_rows():
    trials = np.array(["a", "a", "b", "c"])
    inst = Instances(
        np.arange(4.0)[:, None], np.array([0, 0, 1, 1]), trials, np.array([1, 1, 2, 3])
    )
    picked, rest = take_trials(inst, ("a", "c"))
    assert picked.trial.tolist() == ["a", "a", "c"] and rest.trial.tolist() == ["b"]
    assert picked.X[:, 0].tolist() == [0.0, 1.0, 3.0]

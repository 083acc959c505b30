import numpy as np
import pytest

from tactile_exp.combine import COMBINERS, unit_members
from tactile_exp.data.layout import Instances


def _instances(trials_per_object: dict[int, int], per_trial: int) -> Instances:
    trial, obj, y = [], [], []
    for o, n in trials_per_object.items():
        for t in range(1, n + 1):
            trial += [f"thing_{o}_{t:02d}"] * per_trial
            obj += [o] * per_trial
            y += [o % 2] * per_trial
    X = np.arange(len(trial), dtype=np.float32)[:, None]
    return Instances(X, np.array(y), np.array(trial, dtype=object), np.array(obj))


def test_one_trial_units_hold_that_trials_instances_in_order():
    inst = _instances({101: 3, 102: 2}, per_trial=10)
    units = COMBINERS.build("concat")(inst.X, inst, 1)
    assert units.X.shape == (5, 10)
    np.testing.assert_array_equal(units.X[0], np.arange(10))
    assert list(units.object_id) == [101, 101, 101, 102, 102]


def test_object_units_pad_short_objects_by_repeating_their_own_trials():
    inst = _instances({101: 10, 102: 5}, per_trial=2)
    members = unit_members(inst, 10)
    assert [len(m) for m in members] == [20, 20]
    padded = inst.trial[members[1]]
    assert set(padded) == {f"thing_102_{t:02d}" for t in range(1, 6)}  # never another object's
    units = COMBINERS.build("concat")(inst.X, inst, 10)
    assert units.X.shape == (2, 20)
    assert list(units.y) == [1, 0]


def test_mean_and_separate():
    inst = _instances({101: 2, 102: 2}, per_trial=3)
    mean = COMBINERS.build("mean")(inst.X, inst, 2)
    np.testing.assert_allclose(mean.X[:, 0], [2.5, 8.5])
    sep = COMBINERS.build("separate")(inst.X, inst, 1)
    assert len(sep) == len(inst)


def test_mixed_labels_in_a_unit_are_an_error():
    inst = _instances({101: 2}, per_trial=2)
    inst.y[0] = 1 - inst.y[0]
    with pytest.raises(ValueError, match="disagree"):
        COMBINERS.build("concat")(inst.X, inst, 1)
    with pytest.raises(ValueError, match="combine must be >= 1"):
        unit_members(inst, 0)


def test_unpadded_units_hold_an_objects_first_views_and_drop_the_rest():
    # row L: 10 views -> one unit of views 0-7 (no second unit of 8, 9 repeated); an object with
    # only 6 views (shared between train and test) keeps one unit
    inst = _instances({1: 10, 2: 6, 3: 8}, per_trial=1)
    members = unit_members(inst, 8, pad=False)
    assert len(members) == 3
    assert [inst.object_id[m[0]] for m in members] == [1, 2, 3]
    members = [members[0], members[2]]
    first8 = np.unique(inst.trial[inst.object_id == 1])[:8]
    np.testing.assert_array_equal(inst.trial[members[0]], first8)
    assert all(len(set(inst.trial[m])) == 8 for m in members)  # no view repeated
    assert len(unit_members(inst, 1, pad=False)) == 24  # every view its own unit
    units = COMBINERS.build("concat")(inst.X, inst, 8, pad=False)
    assert units.X.shape == (3, 8 * inst.X.shape[1])

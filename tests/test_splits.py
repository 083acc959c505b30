"""Per-adjective splits: the published table, the file's split groups, the seeded rule, checks."""

from __future__ import annotations

import re
from pathlib import Path

import h5py
import numpy as np
import pytest
from phac2_fixture import OBJECTS, published_groups, write_file

from tactile_exp.data.layout import ADJECTIVES, Split, published_test_split
from tactile_exp.data.phac2 import PHAC2, DataError
from tactile_exp.data.splits import (
    SPLITS,
    check_split,
    declared_split,
    divide_views,
    folds_for,
    make_split,
)

ALL = tuple(OBJECTS)
# PHAC2_FORMAT §2: trial counts of the published split (train, test).
PUBLISHED_SIZES = {a: (530, 70) for a in ADJECTIVES} | {
    "rough": (540, 60),
    "nice": (535, 65),
    "sticky": (535, 65),
    "unpleasant": (535, 65),
}


@pytest.fixture(scope="module")
def full(tmp_path_factory: pytest.TempPathFactory) -> PHAC2:
    """60 objects x 10 trials, labels only, no split groups: the published table applies."""
    path = tmp_path_factory.mktemp("full") / "plain.h5"
    return PHAC2(write_file(path, ALL, 10, signals=False, adjective_links=False))


@pytest.fixture(scope="module")
def full_groups(tmp_path_factory: pytest.TempPathFactory) -> PHAC2:
    """The same with the published split as hard-linked split groups, like the real file."""
    path = tmp_path_factory.mktemp("groups") / "groups.h5"
    groups = published_groups(ALL, 10)
    return PHAC2(write_file(path, ALL, 10, False, adjective_links=False, split_groups=groups))


def assert_no_leak(split: Split) -> None:
    assert not set(split.train) & set(split.test)
    shared = split.objects("train") & split.objects("test")
    for obj in shared:  # allowed only for the single object of its class
        label = OBJECTS[obj].labels[split.adjective]
        assert sum(o.labels[split.adjective] == label for o in OBJECTS.values()) == 1


def test_published_table_reproduced_without_groups(full: PHAC2) -> None:
    for adj in ADJECTIVES:
        split = make_split(full, adj)
        want = {
            (r.object_id, t)
            for r in published_test_split()
            if r.adjective == adj
            for t in (r.trials or range(1, 11))
        }
        got = {(int(n[-6:-3]), int(n[-2:])) for n in split.test}
        assert got == want, adj
        assert (len(split.train), len(split.test)) == PUBLISHED_SIZES[adj], adj
        assert set(split.train) | set(split.test) == {t.name for t in full.trials}
        assert all(split.labels[n] == OBJECTS[int(n[-6:-3])].labels[adj] for n in split.labels)
        assert_no_leak(split)


def test_published_groups_read_from_file(full: PHAC2, full_groups: PHAC2) -> None:
    for adj in ADJECTIVES:
        assert make_split(full_groups, adj) == make_split(full, adj)


def test_groups_take_precedence_over_table(tmp_path: Path) -> None:
    names = [f"{OBJECTS[o].group_stem}_{t:02d}" for o in (101, 410, 508, 211) for t in (1, 2)]
    # soft: positives 101, 410; negatives 508, 211. The table would test 410 and 508.
    groups = {"soft": ([names[2], names[3], names[4], names[5]], [*names[:2], *names[6:]])}
    path = write_file(tmp_path / "f.h5", (101, 410, 508, 211), 2, split_groups=groups)
    split = make_split(PHAC2(path), "soft")
    assert split.test == tuple(sorted(groups["soft"][1]))
    assert split.objects("test") == {101, 211}


def test_random_is_deterministic_and_seed_dependent(full: PHAC2) -> None:
    a = [make_split(full, adj, "random", seed=3) for adj in ADJECTIVES]
    assert a == [make_split(full, adj, "random", seed=3) for adj in ADJECTIVES]
    b = [make_split(full, adj, "random", seed=4) for adj in ADJECTIVES]
    assert sum(x.test != y.test for x, y in zip(a, b, strict=True)) >= 20


def test_random_follows_the_authors_rule(full: PHAC2) -> None:
    for adj in ADJECTIVES:
        split = make_split(full, adj, "random", seed=1)
        assert_no_leak(split)
        for label in (0, 1):
            n = sum(o.labels[adj] == label for o in OBJECTS.values())
            train = {o for o in split.objects("train") if OBJECTS[o].labels[adj] == label}
            if n == 1:  # the single positive object is split by trial, 5/5
                assert sum(split.labels[t] == label for t in split.test) == 5
            else:
                assert len(train) == min(max(int(0.9 * n), 1), n - 1), (adj, label)
    nice = make_split(full, "nice", "random", seed=1)
    assert nice.objects("train") & nice.objects("test") == {111}


def test_published_falls_back_to_random_when_objects_missing(tmp_path: Path) -> None:
    ds = PHAC2(write_file(tmp_path / "f.h5", (101, 410, 508, 211, 114), 2, signals=False))
    warning = (
        r": published test object \d+ \(soft=[01]\) is not in the file; "
        "falling back to the random split with seed 0$"
    )
    with pytest.warns(UserWarning, match=warning):
        split = make_split(ds, "soft")
    assert split == make_split(ds, "soft", "random", seed=0)
    assert_no_leak(split)


def test_random_with_one_object_of_a_class_per_side_fails_clearly(tmp_path: Path) -> None:
    ds = PHAC2(write_file(tmp_path / "f.h5", (101, 508), 1, signals=False))
    with pytest.raises(DataError, match=re.escape(str(ds.path)) + ".*'soft': test has no positive"):
        make_split(ds, "soft", "random")


def test_split_with_no_positive_in_test(tmp_path: Path) -> None:
    names = [f"{OBJECTS[o].group_stem}_{t:02d}" for o in (101, 410, 508, 211) for t in (1, 2)]
    groups = {"soft": (names[:6], names[6:])}  # positives 101 and 410 both in train
    path = write_file(tmp_path / "f.h5", (101, 410, 508, 211), 2, split_groups=groups)
    where = re.escape(f"{path} (published split): split of 'soft': test has no positive")
    with pytest.raises(DataError, match=where):
        make_split(PHAC2(path), "soft")


def test_split_group_with_wrong_label(tmp_path: Path) -> None:
    path = write_file(tmp_path / "f.h5", (101, 508), 2, split_groups={"soft": ([], [])})
    with h5py.File(path, "a") as f:
        f["train_test_sets/soft/test/brick_508_01"] = f["brick_508_01"]
    with pytest.raises(
        DataError, match="/train_test_sets/soft/test links brick_508_01.*label is 0"
    ):
        make_split(PHAC2(path), "soft")


def test_check_split_rejects_shared_object() -> None:
    names = ["a_101_01", "a_101_02", "b_410_01", "c_508_01", "d_211_01"]
    labels = dict(zip(names, [1, 1, 1, 0, 0], strict=True))
    leaky = Split("soft", ("a_101_01", "b_410_01", "c_508_01"), ("a_101_02", "d_211_01"), labels)
    with pytest.raises(DataError, match="^f.h5: split of 'soft': object 101 in both"):
        check_split(leaky, "f.h5")
    message = (
        r"^split of 'soft': object 101 in both train and test \(expected no shared object "
        r"unless it is the only object of its class\)$"
    )
    with pytest.raises(DataError, match=message):
        check_split(leaky)
    del labels["b_410_01"]  # now 101 is the only positive object: a by-trial split is allowed
    ok = Split("soft", ("a_101_01", "c_508_01"), ("a_101_02", "d_211_01"), labels)
    assert check_split(ok) is ok


def test_unknown_rule_and_adjective(full: PHAC2) -> None:
    assert SPLITS.names() == ["declared", "folds", "published", "random"]
    with pytest.raises(KeyError, match="unknown split 'nope'"):
        make_split(full, "soft", "nope")
    with pytest.raises(DataError, match="unknown adjective 'gritty'"):
        make_split(full, "gritty")


@pytest.mark.parametrize(
    "n_train,n_test,views,k",
    [(1, 1, 4, 2), (9, 1, 4, 3), (1, 9, 4, 1), (3, 1, 2, 1), (1, 3, 5, 1), (2, 1, 3, 2)],
)
def test_an_object_split_by_trial_splits_its_photographs_in_proportion(
    n_train: int, n_test: int, views: int, k: int
) -> None:
    photos = np.arange(10, 10 + views)
    first, rest = divide_views(photos, n_train, n_test, "'soft': object 101")
    assert first.tolist() == photos[:k].tolist()  # first views to train, at least one per side
    assert rest.tolist() == photos[k:].tolist()


def test_an_object_split_by_trial_needs_two_photographs() -> None:
    with pytest.raises(
        ValueError,
        match=r"'soft': object 101 is split by trial \(1 train, 1 test\) "
        r"but has 1 photograph\(s\); at least 2",
    ):
        divide_views(np.array([0]), 1, 1, "'soft': object 101")


def test_a_missing_split_group_falls_back_to_the_table(
    full: PHAC2, full_groups: PHAC2, tmp_path: Path
) -> None:
    path = tmp_path / "partial.h5"
    path.write_bytes(full_groups.path.read_bytes())
    with h5py.File(path, "a") as f:
        del f["train_test_negative_sets/hard/test"]
    with pytest.warns(UserWarning) as record:
        split = make_split(PHAC2(path), "hard")
    assert split == make_split(full, "hard")
    (warning,) = record
    assert (
        str(warning.message)
        == f"{path}: /train_test_negative_sets/hard/test missing; using the table"
    )


def test_a_split_group_linking_an_unknown_trial_is_an_error(tmp_path: Path) -> None:
    path = write_file(tmp_path / "f.h5", (101, 508), 2, split_groups={"soft": ([], [])})
    with h5py.File(path, "a") as f:
        f["train_test_sets/soft/train/ghost_999_01"] = f["brick_508_01"]
    with pytest.raises(
        DataError,
        match=f"^{re.escape(str(path))}: /train_test_sets/soft/train/ghost_999_01 is not one of "
        "the file's trial groups$",
    ):
        make_split(PHAC2(path), "soft")


def test_a_table_split_that_fails_its_check_names_the_rule_and_falls_back(tmp_path: Path) -> None:
    test_objects = (410, 114, 508, 507, 509, 503, 120)  # the table's soft test objects, only
    ds = PHAC2(write_file(tmp_path / "f.h5", test_objects, 2, signals=False))
    message = re.escape(f"{ds.path} (published split): split of 'soft': train has no positive")
    with pytest.warns(UserWarning, match=message):
        split = make_split(ds, "soft")
    assert split == make_split(ds, "soft", "random", seed=0)


def test_check_split_rejects_shared_trials_and_one_class_sides() -> None:
    pos = [f"a_101_{t:02d}" for t in range(1, 8)]
    neg = ["c_508_01", "c_508_02", "d_211_01", "d_211_02"]
    labels = {n: 1 for n in pos} | {n: 0 for n in neg}
    shared = Split("soft", (*pos[:6], "c_508_01"), (*pos, "d_211_01"), labels)
    first_five = re.escape(str(pos[:5]))
    with pytest.raises(DataError, match=f"^split of 'soft': trial\\(s\\) {first_five} in both "):
        check_split(shared)
    one_class = {
        "train has no negative trial": Split("soft", (pos[0],), (pos[1], neg[0]), labels),
        "train has no positive trial": Split("soft", (neg[0],), (pos[1], neg[1]), labels),
        "test has no negative trial": Split("soft", (pos[0], neg[0]), (pos[1],), labels),
    }
    for message, split in one_class.items():
        with pytest.raises(DataError, match=f"^split of 'soft': {message} \\(expected at least"):
            check_split(split)


def _n_positive(adj: str) -> int:
    return sum(o.labels[adj] == 1 for o in OBJECTS.values())


# Adjectives with at least 5 objects of each class (PHAC-2 has 17 such): 5 folds fit them.
FOLDABLE = [a for a in ADJECTIVES if 5 <= _n_positive(a) <= len(OBJECTS) - 5]


def test_folds_test_every_object_once_and_never_on_both_sides(full: PHAC2) -> None:
    assert len(FOLDABLE) >= 10
    for adj in FOLDABLE:
        for seed in (0, 1):
            tested: list[int] = []
            for fold in range(5):
                split = make_split(full, adj, "folds", seed, folds=5, fold=fold)
                assert not split.objects("train") & split.objects("test"), (adj, seed, fold)
                assert set(split.train) | set(split.test) == set(split.labels)
                tested += sorted(split.objects("test"))
                positives = {o for o in split.objects("test") if OBJECTS[o].labels[adj] == 1}
                assert positives and positives != split.objects("test")  # both classes tested
            assert sorted(tested) == sorted(ALL), (adj, seed)  # each object exactly once


def test_folds_are_stratified_balanced_and_seeded(full: PHAC2) -> None:
    adj = FOLDABLE[0]
    n_pos = _n_positive(adj)
    sizes, positives = [], []
    for fold in range(5):
        split = make_split(full, adj, "folds", 0, folds=5, fold=fold)
        sizes.append(len(split.objects("test")))
        positives.append(sum(OBJECTS[o].labels[adj] for o in split.objects("test")))
    assert max(sizes) - min(sizes) <= 1
    assert max(positives) - min(positives) <= 1 and sum(positives) == n_pos
    again = make_split(full, adj, "folds", 0, folds=5, fold=2)
    assert again == make_split(full, adj, "folds", 0, folds=5, fold=2)
    other = make_split(full, adj, "folds", 1, folds=5, fold=2)
    assert other.test != again.test  # another seed deals the objects anew


def test_folds_refuse_a_class_smaller_than_k(full: PHAC2) -> None:
    adj = FOLDABLE[0]
    n_pos = _n_positive(adj)
    with pytest.raises(DataError, match=rf"{n_pos} positive object\(s\), fewer than split.folds"):
        make_split(full, adj, "folds", 0, folds=n_pos + 1, fold=0)


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        (["split=folds", "split.fold=5"], r"^split\.fold: must be a whole number in 0\.\.4"),
        (["split=folds", "split.folds=1"], r"^split\.folds: must be a whole number of folds >= 2"),
        (["split=random", "+split.fold=1"], r"^split\.fold: not a parameter of split=random"),
    ],
)
def test_folds_parameters_checked_before_a_job(
    compose_config, overrides: list[str], message: str
) -> None:
    from tactile_exp.config import settings_from_config
    from tactile_exp.errors import ConfigError

    with pytest.raises(ConfigError, match=message):
        settings_from_config(compose_config(overrides))


def test_folds_of_one_seed_share_a_row_and_keep_their_own_models(compose_config) -> None:
    from tactile_exp.config import settings_from_config

    a, b = (
        settings_from_config(compose_config(["split=folds", f"split.fold={k}"])) for k in (0, 1)
    )
    assert a.row_hash == b.row_hash and a.config_hash != b.config_hash
    assert a.split_key == "folds(fold=0,folds=5)" != b.split_key  # no model reused across folds
    assert settings_from_config(compose_config([])).split_key == "published"


@pytest.fixture(scope="module")
def sixty_objects(tmp_path_factory: pytest.TempPathFactory) -> PHAC2:
    path = tmp_path_factory.mktemp("sixty") / "labels.h5"
    return PHAC2(write_file(path, tuple(OBJECTS), 4, signals=False, adjective_links=False))


@pytest.mark.parametrize("rule,seed", [("published", 0), ("random", 0), ("random", 7)])
def test_no_object_on_both_sides_of_any_split(sixty_objects, rule, seed):
    """Every adjective, both rules: trials disjoint, and an object on both sides only when it is
    the single object of its class (the authors then split it by trial)."""
    labels = sixty_objects.labels()
    for adjective in ADJECTIVES:
        split = make_split(sixty_objects, adjective, rule, seed)
        assert not set(split.train) & set(split.test)
        assert len(split.train) + len(split.test) == 4 * len(OBJECTS)
        for obj in split.objects("train") & split.objects("test"):
            label = labels[obj][adjective]
            assert sum(v[adjective] == label for v in labels.values()) == 1, (adjective, obj)
        for side in (split.train, split.test):
            assert {split.labels[t] for t in side} == {0, 1}


def _lab(tmp_path: Path, positives: dict[str, int], objects: int = 6, trials: int = 2):
    """A folder data set whose label ``a`` has ``positives[a]`` positive objects."""
    from tactile_exp.data.dataset import Sensor
    from tactile_exp.data.folder import FolderDataSet, write_folder

    names = [f"o{i}" for i in range(objects)]
    labels = {o: {a: int(i < k) for a, k in positives.items()} for i, o in enumerate(names)}
    arrays = {o: [np.zeros((1, 4))] * trials for o in names}
    return FolderDataSet(write_folder(tmp_path / "d", Sensor("s", ("x",), 10.0), labels, arrays))


def test_every_label_a_split_cannot_evaluate_is_listed_at_once(tmp_path: Path) -> None:
    from tactile_exp.data.splits import label_splits

    ds = _lab(tmp_path, {"a": 3, "b": 1, "c": 0, "d": 2})
    with pytest.raises(DataError) as err:
        label_splits(ds, ds.label_names, "folds", 0, folds=3, fold=0)
    assert str(err.value) == (
        f"{ds.path}: 3 label(s) cannot be evaluated under split=folds (each class needs "
        "split.folds=3 objects): b (+1/-5 objects), c (+0/-6 objects), d (+2/-4 objects); "
        "labels.min_objects=3 drops them, or adjectives=[a]"
    )
    splits = label_splits(ds, ds.label_names, "folds", 0, 3, folds=3, fold=0)
    assert list(splits) == ["a"]
    # split=random evaluates b (its one positive object split by trial), not c
    with pytest.raises(DataError, match=r"1 label\(s\) .* c \(\+0/-6 objects\); labels.min_"):
        label_splits(ds, ds.label_names, "random", 0)
    assert list(label_splits(ds, ds.label_names, "random", 0, 1)) == ["a", "b", "d"]


def test_folds_never_advise_fewer_than_two_folds(tmp_path: Path) -> None:
    ds = _lab(tmp_path, {"a": 1})
    with pytest.raises(DataError) as err:
        make_split(ds, "a", "folds", 0, folds=5, fold=0)
    assert "split.folds<=" not in str(err.value)
    ds3 = _lab(tmp_path / "x", {"a": 3})
    with pytest.raises(DataError, match=r"use split.folds<=3,"):
        make_split(ds3, "a", "folds", 0, folds=5, fold=0)


def test_when_no_label_would_be_left_other_folds_are_advised(tmp_path: Path) -> None:
    from tactile_exp.data.splits import label_splits

    ds = _lab(tmp_path, {"a": 3, "b": 3})
    with pytest.raises(DataError, match="dropping them leaves no label; split.folds=3 or split="):
        label_splits(ds, ds.label_names, "folds", 0, folds=5, fold=0)
    with pytest.raises(DataError, match="labels.min_objects=4 leaves no label: a"):
        label_splits(ds, ds.label_names, "folds", 0, 4, folds=3, fold=0)


@pytest.mark.parametrize(
    "counts,expected",
    [
        ({"a": (9, 12), "b": (6, 20)}, (5, "every label has at least 5 positive and 5 negative")),
        ({"a": (9, 12), "b": (3, 20)}, (3, "label b has 3 positive objects")),
        ({"a": (9, 2), "b": (3, 20)}, (2, "label a has 2 negative objects")),
    ],
)
def test_folds_for_takes_the_largest_k_every_label_allows(counts, expected) -> None:
    k, why = folds_for(counts)
    assert k == expected[0] and why.startswith(expected[1])


def test_folds_for_refuses_a_label_with_one_object_of_a_class() -> None:
    with pytest.raises(DataError, match=r"no folds split fits: label b has 1 positive object \("):
        folds_for({"a": (4, 4), "b": (1, 7)})


def test_a_folder_data_set_declares_folds_with_the_k_its_labels_allow(tmp_path: Path) -> None:
    from tactile_exp.data.dataset import Sensor
    from tactile_exp.data.folder import FolderDataSet, write_folder

    labels = {f"o{i}": {"a": int(i < 3), "b": int(i % 2)} for i in range(7)}
    trials = {o: [np.zeros((1, 4))] * 2 for o in labels}
    path = write_folder(tmp_path / "ds", Sensor("s", ("c",), 1.0), labels, trials)
    ds = FolderDataSet(path)
    node, note = declared_split(ds, None, None)
    assert node == {"name": "folds", "folds": 3, "fold": 0}
    assert note == "folds K=3 (label a has 3 positive objects)"
    assert declared_split(ds, ("b",), None)[0]["folds"] == 3  # b alone: +3/-4
    with pytest.raises(DataError, match=r"labels.min_objects=4 leaves no label: a \(\+3/-4"):
        declared_split(ds, None, 4)
    split = make_split(ds, "a", "declared", seed=1)
    assert split.test == make_split(ds, "a", "folds", seed=1, folds=3, fold=0).test


def test_the_declared_rule_of_phac2_is_its_published_split(full: PHAC2) -> None:
    for adj in ("hard", "soft"):
        assert make_split(full, adj, "declared") == make_split(full, adj, "published")

"""Per-adjective splits: the published table, the file's split groups, the seeded rule, checks."""

from __future__ import annotations

import re
from pathlib import Path

import h5py
import pytest
from phac2_fixture import OBJECTS, published_groups, write_file

from tactile_exp.data.layout import ADJECTIVES, Split, published_test_split
from tactile_exp.data.phac2 import PHAC2, DataError
from tactile_exp.data.splits import SPLITS, check_split, make_split

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
    with pytest.warns(UserWarning, match="published test object .* not in the file"):
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
    with pytest.raises(DataError, match=re.escape(str(path)) + ".*'soft': test has no positive"):
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
    with pytest.raises(DataError, match="f.h5: split of 'soft': object 101 in both"):
        check_split(leaky, "f.h5")
    del labels["b_410_01"]  # now 101 is the only positive object: a by-trial split is allowed
    ok = Split("soft", ("a_101_01", "c_508_01"), ("a_101_02", "d_211_01"), labels)
    assert check_split(ok) is ok


def test_unknown_rule_and_adjective(full: PHAC2) -> None:
    assert SPLITS.names() == ["published", "random"]
    with pytest.raises(KeyError, match="unknown split 'nope'"):
        make_split(full, "soft", "nope")
    with pytest.raises(DataError, match="unknown adjective 'gritty'"):
        make_split(full, "gritty")

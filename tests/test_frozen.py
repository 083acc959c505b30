"""Frozen folds: the shipped files are the recipes' label tables dealt into object-grouped,
class-stratified folds with the largest K each allows, and a malformed file is one line."""

from __future__ import annotations

from pathlib import Path

import pytest

from tactile_exp.data.frozen import FrozenFolds, check_stratified, deal
from tactile_exp.data.layout import DataError
from tactile_exp.data.recipe import FOLDS_DIR, RECIPES
from tactile_exp.data.splits import folds_for

DEALT = [n for n in RECIPES.names() if RECIPES.build(n).described is None]


@pytest.mark.parametrize("name", DEALT)
def test_shipped_folds_are_the_recipes_labels_dealt_with_the_largest_k(name: str) -> None:
    recipe = RECIPES.build(name)
    table = recipe.label_table()
    shipped = FrozenFolds.read(FOLDS_DIR / f"{name}.yaml")
    assert (shipped.folds, shipped.resamples) == (recipe.folds, recipe.resamples)
    assert shipped.labels == deal(table, recipe.folds, recipe.resamples)
    assert check_stratified(shipped, table) == []
    positives = {a: sum(row[a] for row in table.values()) for a in recipe.labels}
    assert folds_for({a: (p, len(table) - p) for a, p in positives.items()})[0] == recipe.folds
    first = next(iter(recipe.labels))
    assert len({str(resample) for resample in shipped.labels[first]}) > 1  # resamples differ


def test_deal_keeps_each_fold_two_classed_and_sizes_within_one() -> None:
    table = {f"o{i}": {"a": int(i < 4), "b": int(i % 3 == 0)} for i in range(11)}
    folds = FrozenFolds(3, 4, deal(table, 3, 4))
    assert check_stratified(folds, table) == []
    for resample in folds.labels["a"]:
        assert max(map(len, resample)) - min(map(len, resample)) <= 1


def test_a_fold_without_both_classes_is_reported() -> None:
    table = {"x": {"a": 1}, "y": {"a": 0}, "z": {"a": 0}}
    folds = FrozenFolds(2, 1, {"a": [[["x", "y"], ["z"]]]})
    assert check_stratified(folds, table) == ["a resample 0 fold 1: not both classes"]


@pytest.mark.parametrize(
    "text,expected",
    [
        ("folds: 2\n", "expected folds: K, resamples: R, labels:"),
        ("folds: 1\nresamples: 1\nlabels: {a: [[[x], [y]]]}\n", "folds=1, resamples=1; expected"),
        ("folds: 2\nresamples: 2\nlabels: {a: [[[x], [y]]]}\n", "label 'a': expected 2 resamples"),
        ("folds: 2\nresamples: 1\nlabels: {a: [[[x], [x]]]}\n", "an object in two folds"),
    ],
)
def test_a_malformed_folds_file_is_one_line_naming_it(tmp_path: Path, text, expected) -> None:
    file = tmp_path / "folds.yaml"
    file.write_text(text)
    with pytest.raises(DataError, match=f"^{file}: .*") as err:
        FrozenFolds.read(file)
    assert expected in str(err.value) and "\n" not in str(err.value)


def test_the_digest_follows_the_file(tmp_path: Path) -> None:
    file = tmp_path / "folds.yaml"
    FrozenFolds(2, 1, {"a": [[["x"], ["y"]]]}).write(file)
    first = FrozenFolds.read(file)
    FrozenFolds(2, 1, {"a": [[["y"], ["x"]]]}).write(file)
    assert FrozenFolds.read(file).digest != first.digest
    assert first.test_objects("a", 0, 2, 1, "here") == ["y"]
    with pytest.raises(DataError, match="holds frozen folds with K=2, the job asks for"):
        first.test_objects("a", 0, 5, 1, "here")
    with pytest.raises(DataError, match=r"holds 1 frozen resamples \(seed=0..0\)"):
        first.test_objects("a", 1, 2, 1, "here")

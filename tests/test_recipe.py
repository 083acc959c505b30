"""Public data set recipes: every shipped recipe loads, says where each label comes from and
pins its upstream; a recipe file of one's own is checked key by key, in one line."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from tactile_exp.data.layout import DataError
from tactile_exp.data.readers import READERS
from tactile_exp.data.recipe import RECIPE_DIR, RECIPES, find


@pytest.mark.parametrize("name", RECIPES.names())
def test_every_recipe_loads_and_pins_its_upstream(name: str) -> None:
    recipe = RECIPES.build(name)
    assert recipe.name == name and recipe.licence and recipe.holds
    if "repository" in recipe.upstream:
        assert len(recipe.upstream["commit"]) == 40
        assert recipe.sha256 is not None and len(recipe.sha256) == 64
    if recipe.described is None:
        assert recipe.reader in READERS
        assert len(set(recipe.channels)) == len(recipe.channels)
        for label, spec in recipe.labels.items():
            assert spec.source in ("upstream", "ours") and spec.origin, label
            assert 0 < len(spec.positive) < len(recipe.objects), label


def test_the_four_upstreams_named_by_the_benchmark_have_recipes() -> None:
    assert set(RECIPES.names()) >= {"phac2", "penn_bolt", "biotac_slide", "icub_grasp"}
    assert RECIPES.build("icub_grasp").count == 200  # 10 objects x 20 grasps
    assert len(RECIPES.build("icub_grasp").channels) == 69  # 60 taxels + 9 joint encoders
    assert RECIPES.build("biotac_slide").count == 1000  # 20 materials x 50 slides
    assert len(RECIPES.build("penn_bolt").objects) == 5


def _write(tmp_path: Path, **change: object) -> Path:
    node = yaml.safe_load((RECIPE_DIR / "penn_bolt.yaml").read_text())
    node.update(change)
    file = tmp_path / "mine.yaml"
    file.write_text(yaml.safe_dump(node))
    return file


@pytest.mark.parametrize(
    "change,expected",
    [
        ({"labels": {}}, "no label table (labels: label -> {source: upstream | ours"),
        ({"extra": 1}, "unknown key(s) ['extra']"),
        ({"count": "many"}, "a value of the wrong kind (invalid literal for int()"),
        ({"files": "a/(b"}, "files: not a regular expression"),
        ({"files": "x/.*\\.h5"}, "has no group 'object'"),
        (
            {"labels": {"a": {"source": "mine", "from": "x", "positive": ["cork"]}}},
            "labels.a.source: 'mine', expected upstream or ours",
        ),
        (
            {"labels": {"a": {"source": "ours", "from": "x", "positive": ["oak"]}}},
            "labels.a.positive: ['oak'] are not objects of the recipe",
        ),
    ],
)
def test_a_bad_recipe_file_is_one_line_naming_it(tmp_path: Path, change, expected) -> None:
    file = _write(tmp_path, **change)
    with pytest.raises(DataError) as err:
        find(str(file))
    assert str(err.value).startswith(f"{file}: ") and expected in str(err.value)


def test_an_unknown_name_lists_the_known_ones() -> None:
    with pytest.raises(DataError, match="unknown public data set 'nope'; known: biotac_slide, "):
        find("nope")

"""Reliability (issue 10): one-line config errors before any run, stale RUNNING runs ended at
start, an unreachable tracking server named at once, and small data sets (5 objects)."""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest
from mlflow.tracking import MlflowClient

from tactile_exp.config import ConfigError, settings_from_config
from tactile_exp.data.layout import DataError
from tactile_exp.experiment import run

# 5 objects x 3 trials: absorbent 2 positive objects, squishy 3, cool none.
FIVE_OBJECTS = (101, 116, 214, 316, 501)


@pytest.fixture(scope="module")
def five_objects(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from tactile_exp.data.synthetic import SyntheticSpec, generate

    spec = SyntheticSpec(
        object_ids=FIVE_OBJECTS,
        trials=3,
        duration_scale=0.1,
        views=1,
        image_width=96,
        image_height=64,
    )
    return generate(tmp_path_factory.mktemp("five") / "five.h5", spec)


def _all_runs(uri: str):
    client = MlflowClient(uri)
    exp = client.get_experiment_by_name("tactile_exp")
    return [] if exp is None else client.search_runs([exp.experiment_id], max_results=1000)


def test_combine_beyond_the_file_fails_before_a_run_is_created(tiny_config, mlflow_uri):
    settings = settings_from_config(tiny_config(["combine=3", "model=random"]))
    with pytest.raises(ConfigError, match="^combine: 3 trials per unit"):
        run(settings)
    assert _all_runs(mlflow_uri) == []


@pytest.mark.parametrize(
    "row,adjectives",
    [
        ("table1_a_haptic_static_1trial", "[absorbent,squishy]"),
        ("table1_i_haptic_cnn_1trial", "[absorbent,squishy]"),
    ],
)
def test_rows_a_and_i_run_on_five_objects(tiny_config, five_objects, row, adjectives):
    settings = settings_from_config(
        tiny_config(
            [f"experiment={row}", "data=phac2", f"data.path={five_objects}"],
            adjectives=adjectives,
        )
    )
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = run(settings)
    assert set(result.results) == {"absorbent", "squishy"}
    assert all(0.0 <= r.auc <= 1.0 for r in result.results.values())
    messages = " ".join(str(w.message) for w in caught)
    assert "falling back to the random split" in messages  # published test objects are absent


def test_adjective_without_positive_objects_is_refused_before_a_run(
    tiny_config, five_objects, mlflow_uri
):
    settings = settings_from_config(
        tiny_config(
            ["experiment=table1_a_haptic_static_1trial", "data=phac2", f"data.path={five_objects}"],
            adjectives="[absorbent,cool]",
        )
    )
    with pytest.raises(DataError, match="'cool'"):
        run(settings)
    assert _all_runs(mlflow_uri) == []

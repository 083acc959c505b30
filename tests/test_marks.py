"""The settings' marks: hashes and training keys of stored jobs unchanged, unmarked keys refused."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tactile_exp import config, keys, marks, search
from tactile_exp.config import config_hash, settings_from_config
from tactile_exp.errors import ConfigError
from tactile_exp.marks import Mark
from tactile_exp.modalities import MODALITIES
from tactile_exp.registry import Component

# config_hash, row_hash, run name and training keys of every Table I row and of overrides that
# touch each kind of mark, as the hand-kept lists computed them before the marks replaced them.
# Stored jobs are skipped and their models reused by these values: they never change.
PINNED = json.loads((Path(__file__).parent / "marks_pinned.json").read_text())


def _training_keys(settings: config.Settings, tmp_path: Path) -> dict[str, str]:
    """The job's model's training key and each part's (row M's ConvNet), on one dataset."""
    pairs = {"model": (settings.modality, settings.model)}
    modality = MODALITIES.build(
        settings.modality.name, cache_dir=tmp_path, **settings.modality.params
    )
    pairs.update(modality.parts())
    return {
        name: keys.training_key(
            dataset="dataset-identity",
            modality=modality_part,
            model=model_part,
            split=settings.split_key,
            validation=settings.validation_fraction,
            seed=settings.seed,
            adjective="hard",
        )
        for name, (modality_part, model_part) in pairs.items()
    }


@pytest.mark.parametrize("job", PINNED, ids=lambda job: " ".join(job["overrides"]) or "defaults")
def test_hashes_and_training_keys_of_existing_jobs_are_unchanged(
    compose_config, job, tmp_path, monkeypatch
):
    # cache_dir is hashed and defaults to $TACTILE_EXP_CACHE or ~/.cache/tactile_exp: composed
    # where the pins were computed (HOME=/root, no $TACTILE_EXP_CACHE), whatever this machine's
    monkeypatch.delenv("TACTILE_EXP_CACHE", raising=False)
    monkeypatch.setenv("HOME", "/root")
    overrides = job["overrides"]
    settings = settings_from_config(compose_config(overrides), overrides=tuple(overrides))
    assert settings.config_hash == job["config_hash"]
    assert settings.row_hash == job["row_hash"]
    assert settings.run_name == job["run_name"]
    assert _training_keys(settings, tmp_path) == job["training_keys"]


def test_the_pinned_jobs_cover_every_row_and_every_kind_of_mark():
    rows = {o.removeprefix("experiment=") for job in PINNED for o in job["overrides"]}
    experiments = Path(__file__).parents[1] / "conf" / "experiment"
    assert {p.stem for p in experiments.glob("*.yaml")} <= rows
    touched = {
        o.lstrip("+").split("=")[0].split(".")[0] for job in PINNED for o in job["overrides"]
    }
    # every top-level key set on the command line, but Hydra's own and the rows' paper figures
    assert set(marks.top_level()) - {"hydra", "paper", "experiment"} <= touched


def test_an_unmarked_top_level_key_is_refused(compose_config):
    with pytest.raises(ConfigError) as err:
        settings_from_config(compose_config(["+epochs=3"]))
    assert str(err.value) == (
        "epochs: not a setting of tactile_exp; a new top-level key is declared in "
        "conf/config.yaml and marked in tactile_exp/marks.py (docs/configuration.md)"
    )


def test_an_unmarked_component_parameter_is_hashed_and_keyed(compose_config):
    """A new parameter of a model or modality needs no mark: it makes a new job and a new model."""
    resolved = settings_from_config(compose_config()).resolved
    changed = {**resolved, "model": {**resolved["model"], "new_param": 1}}
    assert config_hash(changed) != config_hash(resolved)
    model = Component("haptic_cnn", resolved["model"])
    key = {"dataset": "d", "modality": Component("haptic", {}), "split": "published"}
    key |= {"validation": 0.0, "seed": 0, "adjective": "hard"}
    changed_model = Component("haptic_cnn", changed["model"])
    assert keys.training_key(model=changed_model, **key) != keys.training_key(model=model, **key)
    reused = Component("haptic_cnn", {**resolved["model"], "impl": "torch", "device": "cpu"})
    assert keys.training_key(model=reused, **key) == keys.training_key(model=model, **key)


def test_a_new_mark_reaches_every_list():
    table = {
        **marks.MARKS,
        "progress": Mark(hashed=False, named=False),
        "model.threads": Mark(keyed=False),
        "data.shuffle": Mark(fixed="it changes the data"),
        "labels.weights": Mark(hashed_unless=None),
    }
    marks.check(table)
    assert "progress" in marks.unhashed(table) and "progress" in marks.unnamed(table)
    assert marks.unkeyed("model", table) == (*keys.MODEL_UNKEYED, "threads")
    assert marks.fixed(table)["data.shuffle"] == "it changes the data"
    assert marks.added_at_default(table) == {"labels": {"min_objects": None, "weights": None}}


@pytest.mark.parametrize(
    ("table", "line"),
    [
        ({"model": Mark(), "model.x": Mark(hashed=False)}, "model.x: hashed/named mark only"),
        ({"seed": Mark(keyed=False)}, "seed: keyed marks a parameter of model or modality"),
        ({"labels": Mark(hashed_unless=None)}, "labels: hashed_unless marks a key inside"),
        ({"model.x": Mark(keyed=False)}, "model.x: its top-level key model has no mark"),
    ],
)
def test_a_mark_that_would_do_nothing_is_refused(table, line):
    with pytest.raises(ValueError, match=line):
        marks.check(table)


def test_search_lists_follow_the_marks():
    assert search.fixed_reason("+data") == marks.MARKS["data"].fixed
    assert search.fixed_reason("modality.fit_on") == marks.MARKS["modality.fit_on"].fixed
    assert search.fixed_reason("modality.trials") == ""
    for own in ("validation.fraction=0.2", "study.name=s", "hydra/launcher=joblib"):
        assert own.startswith(search.SEARCH_ONLY)
    assert not "model.lr=0.1".startswith(search.SEARCH_ONLY)
    assert not "validation.other=1".startswith(search.SEARCH_ONLY)


def test_a_model_without_epochs_carries_no_schedule_or_loss(compose_config):
    """linear_svm reads neither group (``Model.reads``): a schedule or loss set for its job
    changes neither its hash, nor its row, nor its name, nor its logged config."""
    row = ["experiment=table1_a_haptic_static_1trial"]
    plain = settings_from_config(compose_config(row), overrides=tuple(row))
    quick = [*row, "schedule=quick", "loss=logistic", "schedule.lr=0.5"]
    other = settings_from_config(compose_config(quick), overrides=tuple(quick))
    assert (other.config_hash, other.row_hash) == (plain.config_hash, plain.row_hash)
    assert other.run_name == plain.run_name
    assert "schedule" not in other.resolved and "loss" not in other.resolved
    assert "schedule" not in other.choices and "loss" not in other.choices
    assert other.overrides == tuple(row)  # the run's overrides tag: what the report compares
    cnn = settings_from_config(compose_config(["schedule=quick"]), overrides=("schedule=quick",))
    assert "quick" in cnn.run_name and cnn.resolved["schedule"]["epochs"] == 2  # it reads them


def test_a_parameter_the_model_declares_speed_only_stays_out_of_its_training_key():
    """The estimator declares its estimators' ``n_jobs`` speed-only (``Model.speed_params``):
    a job that changes them reuses the model; a learning parameter makes a new one."""
    ridge = {"_target_": "sklearn.linear_model.RidgeClassifierCV"}
    key = {"dataset": "d", "modality": Component("haptic", {}), "split": "published"}
    key |= {"validation": 0.0, "seed": 0, "adjective": "hard"}

    def trained_key(transformer: dict) -> str:
        model = Component("estimator", {"classifier": ridge, "transformer": transformer})
        return keys.training_key(model=model, **key)

    pca = {"_target_": "sklearn.decomposition.PCA", "n_components": 4}
    assert trained_key({**pca, "n_jobs": 2}) == trained_key(pca)
    assert trained_key({**pca, "n_components": 5}) != trained_key(pca)
    assert keys.unkeyed(Component("estimator", {"classifier": ridge, "transformer": pca})) == {}
    assert keys.unkeyed(Component("estimator", {"classifier": {**ridge, "n_jobs": 2}})) == {
        "classifier.n_jobs": 2
    }

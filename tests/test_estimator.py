"""model=estimator: scikit-learn-style estimators named in YAML; their scores, head, seeds,
refusals before any run, storage (skops, pickle only opted in) and the representation-only
fit under concat."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.decomposition import PCA
from sklearn.linear_model import LogisticRegression, RidgeClassifierCV
from sklearn.naive_bayes import GaussianNB

from tactile_exp import artifacts
from tactile_exp.config import settings_from_config
from tactile_exp.core import open_data
from tactile_exp.data.layout import Instances, InstanceSpec
from tactile_exp.errors import ConfigError
from tactile_exp.models import MODELS
from tactile_exp.models.estimator import TRUST_PICKLE, EstimatorModel
from tactile_exp.pipeline import AdjectivePipeline
from tactile_exp.registry import Component
from tactile_exp.testing import toy_instances

RIDGE = {"_target_": "sklearn.linear_model.RidgeClassifierCV"}
PCA4 = {"_target_": "sklearn.decomposition.PCA", "n_components": 4}


def test_scores_are_the_decision_function_else_the_positive_probability():
    train = toy_instances((4, 8))
    flat = train.X.reshape(len(train), -1)
    ridge = EstimatorModel(classifier=RIDGE, layout="flat")
    ridge.fit(train)
    expected = RidgeClassifierCV().fit(flat, train.y).decision_function(flat)
    np.testing.assert_allclose(ridge.decision_function(train.X), expected)
    nb = EstimatorModel(classifier={"_target_": "sklearn.naive_bayes.GaussianNB"}, layout="flat")
    nb.fit(train)
    proba = GaussianNB().fit(flat, train.y).predict_proba(flat)[:, 1]
    np.testing.assert_allclose(nb.decision_function(train.X), proba)


def test_the_transformer_feeds_the_classifier_and_unset_seeds_are_the_jobs():
    train = toy_instances((4, 8))
    flat = train.X.reshape(len(train), -1)
    pca = {**PCA4, "svd_solver": "randomized"}
    logistic = {"_target_": "sklearn.linear_model.LogisticRegression", "C": 0.5}
    model = EstimatorModel(transformer=pca, classifier=logistic, layout="flat", seed=7)
    model.fit(train)
    assert model.transformer_.random_state == 7 and model.classifier_.random_state == 7
    reference = PCA(4, svd_solver="randomized", random_state=7)
    features = reference.fit_transform(flat)  # what the classifier is fitted on
    new = train.X[:5].copy()  # rows other than the fitted ones go through transform
    np.testing.assert_allclose(model.transform(new), reference.transform(flat[:5]), rtol=1e-5)
    logistic_ = LogisticRegression(C=0.5, random_state=7).fit(features, train.y)
    np.testing.assert_allclose(
        model.decision_function(train.X), logistic_.decision_function(features), rtol=1e-4
    )
    fixed = EstimatorModel(
        transformer={**pca, "random_state": 3}, classifier=RIDGE, layout="flat", seed=7
    )
    fixed.fit(toy_instances((4, 8)))
    assert fixed.transformer_.random_state == 3  # set in the YAML: kept


def test_the_training_rows_transform_is_the_one_kept_from_fitting():
    train = toy_instances((4, 8))
    model = EstimatorModel(transformer=PCA4, classifier=RIDGE, layout="flat")
    model.fit(train)
    kept = model.transform(train.X)
    assert kept is model.transform(train.X)  # the fit's features, not computed again
    np.testing.assert_allclose(kept, model.transform(train.X.copy()), atol=1e-5)


def test_its_head_is_the_classifier_alone_on_combined_features():
    model = EstimatorModel(transformer=PCA4, classifier=RIDGE, layout="series", seed=3)
    head = model.head()
    assert isinstance(head, EstimatorModel)
    assert head.get_params() == {
        "classifier": RIDGE, "transformer": None, "layout": "flat", "storage": "skops", "seed": 3
    }  # fmt: skip
    assert artifacts.model_name(head) == "estimator"


@pytest.mark.parametrize(
    ("params", "line"),
    [
        ({"classifier": {"_target_": "sklearn.linear_model.NoSuchModel"}}, "classifier: _target_"),
        ({"classifier": {"_target_": "no_such_package.Model"}}, "does not import"),
        ({"classifier": {"_target_": "math.sqrt"}}, "classifier: _target_ 'math.sqrt'"),
        ({"classifier": "RidgeClassifierCV"}, "classifier: expected a mapping with _target_"),
        ({"classifier": RIDGE, "layout": "wide"}, "layout: must be one of series, flat"),
        ({"classifier": RIDGE, "storage": "joblib"}, "storage: must be one of skops, pickle"),
    ],
)
def test_bad_settings_raise_naming_the_parameter(params, line):
    with pytest.raises(ValueError, match=line):
        EstimatorModel(**params)


def test_a_target_that_does_not_import_is_one_config_line_before_any_run(compose_config):
    bad = ["model=estimator", "model.classifier._target_=sklearn.linear_model.Ridge_CV"]
    with pytest.raises(ConfigError) as err:
        settings_from_config(compose_config(bad))
    message = str(err.value)
    assert message.startswith(
        "model.classifier: classifier: _target_ 'sklearn.linear_model.Ridge_CV' does not import"
    )
    assert "\n" not in message


def test_one_hot_probabilities_are_refused_in_one_line_when_the_data_opens(tiny_config):
    knn = ["model=estimator", "+model.classifier.n_neighbors=1"]
    knn += ["model.classifier._target_=sklearn.neighbors.KNeighborsClassifier"]
    settings = settings_from_config(tiny_config(knn, "[hard]"))
    with pytest.raises(ConfigError) as err:
        open_data(settings)  # before any run is created (experiment.run opens data first)
    message = str(err.value)
    assert message.startswith("model.classifier: classifier: sklearn.neighbors.KNeighbors")
    assert "one-hot" in message and "\n" not in message


def test_the_series_layout_refuses_flat_rows_naming_the_fix():
    model = EstimatorModel(classifier=RIDGE, layout="series")
    with pytest.raises(ValueError, match="^layout: series .* set model.layout=flat$"):
        model.check_input(InstanceSpec("features", (832,)))
    model.check_input(InstanceSpec("signals", (32, None)))


def test_arguments_an_estimator_rejects_are_refused_when_the_data_opens():
    model = EstimatorModel(classifier={**RIDGE, "alphas_": 1}, layout="flat")
    with pytest.raises(ValueError, match="^classifier: sklearn.linear_model.RidgeClassifierCV re"):
        model.check_input(InstanceSpec("signals", (4, 8)))


def _stored(model: EstimatorModel, folder) -> EstimatorModel:
    folder.mkdir(exist_ok=True)
    artifacts.write_model(folder, "estimator", model)
    return artifacts.read_model(folder, "run r: artifact model")


def test_stored_as_skops_it_loads_without_unpickling_and_scores_the_same(tmp_path, monkeypatch):
    import pickle

    train = toy_instances((4, 8))
    model = EstimatorModel(transformer=PCA4, classifier=RIDGE, layout="flat")
    model.fit(train)
    monkeypatch.setattr(pickle, "loads", None)  # any unpickling would fail
    loaded = _stored(model, tmp_path)
    new = train.X.copy()  # not the fitted rows, whose transform the fitted model keeps
    np.testing.assert_array_equal(loaded.decision_function(new), model.decision_function(new))


class _Outsider(RidgeClassifierCV):
    """A classifier of a package the stored model's config does not name (this test module)."""


def test_a_skops_file_holding_types_its_config_does_not_name_is_refused(tmp_path):
    train = toy_instances((4, 8))
    model = EstimatorModel(classifier=RIDGE, layout="flat")
    model.fit(train)
    model.classifier_ = _Outsider().fit(train.X.reshape(len(train), -1), train.y)
    with pytest.raises(artifacts.ArtifactError) as err:
        _stored(model, tmp_path)
    message = str(err.value)
    assert message.startswith("run r: artifact model: the stored estimator model does not load")
    assert "test_estimator._Outsider; not loaded" in message and "\n" not in message


def test_pickle_storage_is_an_explicit_opt_in_at_saving_and_at_loading(tmp_path, monkeypatch):
    train = toy_instances((4, 8))
    model = EstimatorModel(classifier=RIDGE, layout="flat", storage="pickle")
    model.fit(train)
    monkeypatch.delenv(TRUST_PICKLE, raising=False)
    with pytest.raises(artifacts.ArtifactError, match=f"set {TRUST_PICKLE}=1 to load it"):
        _stored(model, tmp_path / "refused")
    monkeypatch.setenv(TRUST_PICKLE, "1")
    loaded = _stored(model, tmp_path / "trusted")
    np.testing.assert_array_equal(
        loaded.decision_function(train.X), model.decision_function(train.X)
    )


def _pipeline(combiner: str, combine: int) -> AdjectivePipeline:
    model = Component("estimator", {"transformer": PCA4, "classifier": RIDGE, "layout": "flat"})
    return AdjectivePipeline(Component("signals", {}), model, combiner, combine)


def _combinable(n: int = 48) -> Instances:
    train = toy_instances((4, 8), n)
    train.object_id = np.arange(n) // 2  # two instances per object, of one label
    return train


def test_under_concat_only_the_representation_is_fitted_and_the_scores_are_the_same():
    """The head scores combined units; the model's own classifier would score nothing, so it is
    not fitted. The head's scores equal those of a pipeline that also fits it."""
    train = _combinable()
    pipeline = _pipeline("concat", 2)
    assert pipeline.fits_representation_only and pipeline.stores_model
    pipeline.fit_instances(train)
    assert pipeline.model_.classifier_ is None and pipeline.model_.transformer_ is not None
    whole = _pipeline("concat", 2)
    model = MODELS.build("estimator", **whole.model.params)
    model.fit(train)  # the classifier too, as before
    whole.fit_instances(train, model)
    np.testing.assert_array_equal(pipeline.score(train)[0], whole.score(train)[0])
    assert not _pipeline("separate", 1).fits_representation_only


def test_a_model_fitted_for_a_head_alone_has_its_own_training_key():
    from tactile_exp import keys

    key = {"dataset": "d", "modality": Component("signals", {}), "split": "random()"}
    key |= {"validation": 0.0, "seed": 0, "adjective": "hard"}
    model = Component("estimator", {"transformer": PCA4, "classifier": RIDGE})
    whole = keys.training_key(model=model, **key)
    assert keys.training_key(model=model, representation_only=True, **key) != whole
    cnn = Component("haptic_cnn", {})
    assert not AdjectivePipeline(Component("haptic", {}), cnn, "concat", 2).fits_representation_only


def _bursts(y: np.ndarray, seed: int) -> np.ndarray:
    """Series (n, 6, 100) of noise; those with y = 1 carry one period of a sine, 12 steps long,
    at a random time: found by its shape (it adds nothing to a series' mean), not its level."""
    rng = np.random.default_rng(seed)
    X = rng.standard_normal((len(y), 6, 100)).astype(np.float32)
    for i in np.flatnonzero(y):
        start = rng.integers(0, 88)
        X[i, :, start : start + 12] += 1.5 * np.sin(np.linspace(0, 2 * np.pi, 12))
    return X


def _planted(n: int, seed: int) -> Instances:
    y = np.arange(n) % 2
    names = np.array([f"t{seed}_{i}" for i in range(n)], dtype=object)
    return Instances(_bursts(y, seed), y, names, np.arange(n) + 1000 * seed)


@pytest.mark.slow  # aeon's kernels compiled on first use
@pytest.mark.parametrize("name", ["minirocket", "multirocket"])
def test_the_shipped_rocket_models_rank_and_find_a_planted_signal(name):
    """conf/model/{minirocket,multirocket}.yaml as shipped: the scores of held-out series take
    many values (a ranking, not one-hot votes) and find the planted burst; the model contract
    (tactile_exp.testing.check_model) holds."""
    from sklearn.metrics import roc_auc_score

    from tactile_exp.testing import check_model, model_params

    params = model_params(name)
    model = MODELS.build(params.pop("name"), **params)
    model.fit(_planted(60, seed=0))
    test = _planted(40, seed=1)
    scores = model.decision_function(test.X)
    assert len(np.unique(scores)) > 20
    assert roc_auc_score(test.y, scores) > 0.9
    check_model(name)


@pytest.mark.slow
@pytest.mark.job
def test_minirocket_on_the_embedded_data_logs_rankings(tiny_config, mlflow_uri):
    """A MiniRocket job on the default (synthetic PHAC-2) data, each trial scored on its own:
    every adjective's test scores take more than two values and its AUC is theirs."""
    import mlflow
    from sklearn.metrics import roc_auc_score

    from tactile_exp import experiment
    from tactile_exp.jobs import StoredJob

    config = tiny_config(["model=minirocket", "combine_instances=separate"], "[hard,soft]")
    job_id = experiment.run(settings_from_config(config)).run_id
    stored = StoredJob.open(job_id, tracking_uri=mlflow_uri)
    client = mlflow.MlflowClient(mlflow_uri)
    children = client.search_runs(
        [client.get_run(job_id).info.experiment_id], f"tags.mlflow.parentRunId = '{job_id}'"
    )
    assert len(children) == 2
    for child in children:
        units = stored.scores(child.info.run_id)
        scores = np.array([u.score for u in units])
        assert len(np.unique(scores)) > 2
        truth = np.array([u.label for u in units])
        assert child.data.metrics["auc"] == pytest.approx(roc_auc_score(truth, scores))


@pytest.mark.slow
@pytest.mark.job
def test_minirocket_finds_a_planted_burst_in_a_folder_data_set(tiny_config, mlflow_uri, tmp_path):
    """A MiniRocket job on a folder data set (12 objects x 4 trials of 6 channels): the positive
    objects' trials carry the burst of `_bursts`; two folds of the declared split (K=5: six
    objects of each class) score their test trials with more than two values and find it
    (AUC > 0.9)."""
    from tactile_exp import experiment
    from tactile_exp.data.dataset import Sensor
    from tactile_exp.data.folder import write_folder

    labels = {f"obj{o:02d}": {"burst": o % 2} for o in range(12)}
    trials = {name: list(_bursts(np.full(4, o % 2), seed=10 + o)) for o, name in enumerate(labels)}
    data = write_folder(tmp_path / "bursts", Sensor("s", tuple("abcdef"), 100.0), labels, trials)
    for fold in (0, 1):
        overrides = ["data=folder", f"data.path={data}", "modality=signals", "model=minirocket"]
        overrides += ["combine_instances=separate", "split.fold=" + str(fold)]
        result = experiment.run(settings_from_config(tiny_config(overrides, adjectives="null")))
        (res,) = result.results.values()
        assert len(np.unique(res.test.scores)) > 2
        assert res.metrics["auc"] > 0.9

"""The README's promises, checked through the public entry points so they survive refactors.

Each test here fails when its behaviour is broken (each was shown to, by breaking the code):
preprocessing fitted on training trials only, no object on both sides of a split, AUC with ties,
resume semantics, impossible values stopping before any run, the MLflow store, caches.
"""

from __future__ import annotations

import os
import shutil
import threading
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest
from mlflow.tracking import MlflowClient
from phac2_fixture import OBJECTS, write_file

from tactile_exp import evaluate, tracking
from tactile_exp.config import ConfigError, settings_from_config
from tactile_exp.data.layout import ADJECTIVES
from tactile_exp.data.phac2 import PHAC2
from tactile_exp.data.sources import DATA_SOURCES
from tactile_exp.data.splits import make_split
from tactile_exp.experiment import run
from tactile_exp.models import MODELS
from tactile_exp.preprocess.cache import load_arrays, save_arrays
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


# ---------------------------------------------------------------- splits
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


# ---------------------------------------------------------------- AUC
def test_auc_counts_ties_as_half_against_a_hand_computed_value():
    # positives 0.5, 0.9, 0.2 against negatives 0.1, 0.5, 0.5:
    # 0.5 beats 0.1 and ties twice (1 + 0.5 + 0.5), 0.9 beats all 3, 0.2 beats 0.1 -> 6 / 9
    y = np.array([1, 0, 1, 0, 1, 0])
    scores = np.array([0.5, 0.1, 0.9, 0.5, 0.2, 0.5])
    assert evaluate.auc(y, scores) == pytest.approx(6 / 9, abs=1e-12)
    assert evaluate.auc(y, np.zeros(6)) == 0.5  # all tied: chance, not 0 or 1
    assert evaluate.auc(y == 1, -scores) == pytest.approx(3 / 9, abs=1e-12)


@pytest.mark.parametrize(
    "y,scores,message",
    [
        ([1, 1, 1], [0.1, 0.2, 0.3], r"^AUC needs positives and negatives; labels present: \[1\]$"),
        ([0, 0], [0.1, 0.2], r"^AUC needs positives and negatives; labels present: \[0\]$"),
        ([0, 1, 1], [0.1, np.nan, 0.3], "^scores contain NaN or infinite values$"),
        ([0, 1, 1], [0.1, np.inf, 0.3], "^scores contain NaN or infinite values$"),
    ],
)
def test_auc_rejects_one_class_and_non_finite_scores(y, scores, message):
    with pytest.raises(ValueError, match=message):
        evaluate.auc(np.array(y), np.array(scores))


def test_roc_figure_has_one_panel_per_adjective_with_its_curve_and_auc():
    from sklearn.metrics import roc_curve

    y = np.array([1, 0, 1, 0, 1, 0])
    scores = np.array([0.5, 0.1, 0.9, 0.5, 0.2, 0.5])
    fig = evaluate.roc_figure({f"adj{i}": (y, scores) for i in range(8)}, "job on data.h5")
    assert tuple(fig.get_size_inches()) == pytest.approx((2.2 * 6, 2.2 * 2))  # 6 per row
    shown = [ax for ax in fig.axes if ax.axison]
    assert len(fig.axes) == 12 and len(shown) == 8
    assert [ax.get_title() for ax in shown] == [f"adj{i} 0.67" for i in range(8)]
    fpr, tpr, _ = roc_curve(y, scores)
    np.testing.assert_array_equal(shown[0].lines[0].get_xydata(), np.column_stack([fpr, tpr]))
    assert fig.get_suptitle() == "job on data.h5"


def test_mean_auc_is_the_plain_mean():
    assert evaluate.mean_auc({"a": 0.5, "b": 1.0, "c": 0.6}) == pytest.approx(0.7)


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


# ---------------------------------------------------------------- MLflow store
def test_tracking_uri_is_config_then_environment_then_the_checkout(monkeypatch, tmp_path):
    monkeypatch.delenv("MLFLOW_TRACKING_URI", raising=False)
    root = Path(tracking.__file__).resolve().parents[1]
    assert (root / "pyproject.toml").exists()
    assert tracking.resolve_uri(None) == f"sqlite:///{root / 'mlflow.db'}"
    env = f"sqlite:///{tmp_path / 'env.db'}"
    monkeypatch.setenv("MLFLOW_TRACKING_URI", env)
    assert tracking.resolve_uri(None) == env
    assert tracking.resolve_uri("") == env
    assert tracking.resolve_uri("sqlite:///given.db") == "sqlite:///given.db"


@pytest.mark.job
def test_job_without_tracking_uri_logs_to_mlflow_tracking_uri(
    compose_config, cache_dir, mlflow_uri, monkeypatch
):
    from conftest import TINY_DATA

    monkeypatch.setenv("MLFLOW_TRACKING_URI", mlflow_uri)
    cfg = compose_config([*TINY_DATA, f"cache_dir={cache_dir}", "adjectives=[hard]", *FAST])
    settings = settings_from_config(cfg)
    assert settings.tracking.uri in (None, "")
    result = run(settings)
    runs = _all_runs(mlflow_uri)
    assert result.run_id in {r.info.run_id for r in runs}
    artifacts = Path(mlflow_uri.removeprefix("sqlite:///")).parent / "mlartifacts"
    assert list(artifacts.rglob("auc_per_adjective.csv"))  # artifacts beside the database


# ---------------------------------------------------------------- caches
def _tiny_file(path: Path, seed: int) -> Path:
    from tactile_exp.data.synthetic import SyntheticSpec, generate

    spec = SyntheticSpec(seed=seed, object_ids=(101, 201), trials=1, duration_scale=0.05, views=0)
    return generate(path, spec)


def test_haptic_cache_is_invalidated_by_a_changed_data_file(tmp_path):
    from tactile_exp.preprocess.haptic import compute_haptic_arrays, load_haptic_arrays

    path, cache = tmp_path / "data.h5", tmp_path / "cache"
    first = load_haptic_arrays(PHAC2(_tiny_file(path, 0)), steps=8, offsets=1, cache_dir=cache)
    other = tmp_path / "other.h5"
    _tiny_file(other, 1)
    shutil.copyfile(other, path)  # same name, new content
    again = load_haptic_arrays(PHAC2(path), steps=8, offsets=1, cache_dir=cache)
    fresh = compute_haptic_arrays(PHAC2(path), steps=8, offsets=1)
    np.testing.assert_array_equal(again.signals, fresh.signals)
    assert not np.array_equal(again.signals, first.signals)
    coarser = load_haptic_arrays(PHAC2(path), steps=6, offsets=1, cache_dir=cache)
    assert coarser.steps == 6  # changed settings: a new entry, not the steps=8 one
    assert len(list(cache.glob("haptic-*.npz"))) == 3


class _Unwritable:
    """An array-like that fails when numpy converts it: a crash in the middle of a cache write."""

    def __array__(self, dtype=None, copy=None):
        raise RuntimeError("disk gone")


@pytest.mark.parametrize("error", [RuntimeError, KeyboardInterrupt])
def test_a_crash_while_writing_a_cache_entry_leaves_the_old_entry_and_no_debris(tmp_path, error):
    path = tmp_path / "entry.npz"
    save_arrays(path, {"a": np.arange(3)})
    big = np.ones((256, 1024))  # written to the file before the crash
    with pytest.raises(error):
        if error is KeyboardInterrupt:
            save_arrays(path, {"a": big, "b": _Interrupting()})
        else:
            save_arrays(path, {"a": big, "b": _Unwritable()})
    np.testing.assert_array_equal(load_arrays(path, ("a",))["a"], np.arange(3))
    assert os.listdir(tmp_path) == ["entry.npz"]
    fresh = tmp_path / "new" / "entry.npz"
    with pytest.raises(RuntimeError):
        save_arrays(fresh, {"a": big, "b": _Unwritable()})
    assert load_arrays(fresh, ("a",)) is None and os.listdir(fresh.parent) == []


class _Interrupting:
    def __array__(self, dtype=None, copy=None):
        raise KeyboardInterrupt


# ---------------------------------------------------------------- baselines: HMM grid, CV
@pytest.fixture
def small_grid():
    from tactile_exp.baselines import dynamic

    dynamic.GRIDS["behaviour"] = {"n_states": (2, 4), "length": (6, 10), "symbols": (3,)}
    yield "behaviour"
    del dynamic.GRIDS["behaviour"]


def _hmm_data():
    """Positives 101-105 (105 in test) ramp up in every channel; negatives 201-203."""
    from baselines_fixture import make_trial

    from tactile_exp.data.layout import Split

    objects = (101, 102, 103, 104, 105, 201, 202, 203)
    names = [f"o_{o}_{t:02d}" for o in objects for t in (1, 2)]
    trials = [make_trial(n, lengths=(30, 40, 30, 20), seed=i) for i, n in enumerate(names)]
    for t in trials:
        if t.name.object_id < 200:
            ramp = np.linspace(0, 800 * (t.name.object_id % 3 + 1), t.n_rows).astype(np.int64)
            for f in t.fingers:
                f.pdc += ramp
                f.electrodes += ramp[:, None]
    labels = {n: int(n.split("_")[1] < "200") for n in names}
    test = tuple(n for n in names if "_105_" in n or "_203_" in n)
    return trials, Split("hard", tuple(n for n in names if n not in test), test, labels)


def _rows(table_seqs: np.ndarray, seqs: np.ndarray) -> list[int]:
    return [int(np.flatnonzero((table_seqs == s).all(axis=(1, 2)))[0]) for s in seqs]


def test_hmm_settings_are_chosen_by_held_out_likelihood(small_grid, monkeypatch):
    """Each chain's (N, T, K) maximises the mean log-likelihood of held-out training positives:
    whole objects, never in the candidates' fit, never a test or negative trial."""
    from tactile_exp.baselines import dynamic

    trials, split = _hmm_data()
    lengths = dynamic.GRIDS[small_grid]["length"]
    table = dynamic.SequenceTable.from_trials(trials, lengths)
    # Chains are fitted on threads: each call is filed under the chain its thread is fitting.
    current = threading.local()
    fitted: dict[int, list] = defaultdict(list)
    scored: dict[int, list] = defaultdict(list)
    chain, fit, score = dynamic.DynamicFeatures._chain, dynamic.HMMChain.fit, dynamic.HMMChain.score

    def chain_spy(self, table, c, idx, cand):
        current.c = c
        return chain(self, table, c, idx, cand)

    def fit_spy(self, count, mean, scatter, seqs):
        fitted[current.c].append(seqs)
        return fit(self, count, mean, scatter, seqs)

    def score_spy(self, seqs):
        out = score(self, seqs)
        scored[current.c].append(((self.n_states, seqs.shape[1], self.n_symbols), seqs, out.mean()))
        return out

    monkeypatch.setattr(dynamic.DynamicFeatures, "_chain", chain_spy)
    monkeypatch.setattr(dynamic.HMMChain, "fit", fit_spy)
    monkeypatch.setattr(dynamic.HMMChain, "score", score_spy)
    model = dynamic.DynamicFeatures(small_grid, seed=0).fit(table, split)

    n_cand = 4
    assert sorted(scored) == list(range(len(dynamic.CHAINS)))
    chosen = []
    for c in range(len(dynamic.CHAINS)):
        calls = scored[c]
        assert len(calls) == n_cand and len(fitted[c]) == n_cand + 1
        best = max(calls, key=lambda call: call[2])[0]
        assert model.params_[c] == best
        chosen.append(best)
        for j, ((_, T, _), seqs, _) in enumerate(calls):
            held = {table.trials[i] for i in _rows(table.seqs[T][c], seqs)}
            fit_rows = fitted[c][j]  # each candidate's fit, then the final refit
            fit_set = {table.trials[i] for i in _rows(table.seqs[T][c], fit_rows)}
            assert held and not held & fit_set
            assert held <= {t for t in split.train if split.labels[t] == 1}
            objects = {t.split("_")[1] for t in held}
            assert {t for t in split.train if t.split("_")[1] in objects} == held
    assert len(set(chosen)) > 1  # the likelihood picked different settings for different chains


def test_svm_cross_validation_never_splits_an_object(monkeypatch):
    """C is chosen on folds that hold out whole objects (groups = the instances' object ids)."""
    from tactile_exp.data.layout import Instances
    from tactile_exp.models import linear_svm as svm

    rng = np.random.default_rng(0)
    objects = np.repeat(np.arange(12), 5)
    y = (objects % 2).astype(np.int64)
    X = rng.normal(size=(60, 4)) + y[:, None] * 0.7 + objects[:, None] * 0.05
    trials = np.array([f"o_{o}_{i}" for i, o in enumerate(objects)], dtype=object)
    folds = []
    split = svm.LeavePObjectsOut.split

    def spy(self, X, y, groups):
        for tr, te in split(self, X, y, groups):
            folds.append((tr, te))
            yield tr, te

    monkeypatch.setattr(svm.LeavePObjectsOut, "split", spy)
    model = MODELS.build("linear_svm", n_draws=8, p_out=3)
    model.fit(Instances(X, y, trials, objects))
    assert folds
    for tr, te in folds:
        assert len(set(objects[te])) == 3 and not set(objects[tr]) & set(objects[te])
        assert set(y[tr]) == {0, 1}
    cv = model.svm.cv_scores_
    assert model.svm.Cs[int(np.argmax(cv))] == model.svm.C_

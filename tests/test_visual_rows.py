"""The visual modality and Table I rows K and L end to end on tiny generated data (2 views)."""

from __future__ import annotations

import csv
import io
import logging
import shutil

import numpy as np
import pytest
import torch
from conftest import TINY_DATA
from mlflow.tracking import MlflowClient
from sklearn.metrics import roc_auc_score

from tactile_exp.config import param_error, settings_from_config
from tactile_exp.data.layout import TrialName, objects
from tactile_exp.data.phac2 import PHAC2
from tactile_exp.data.sources import DATA_SOURCES
from tactile_exp.data.splits import SPLITS
from tactile_exp.errors import ConfigError
from tactile_exp.experiment import run
from tactile_exp.modalities import MODALITIES
from tactile_exp.preprocess import trunk
from tactile_exp.preprocess.trunk import GoogLeNet, pooled_features, xavier_init

VIEWS = 2  # photographs per object: enough to test grouping and split-by-trial objects
FAST = ["schedule=tiny"]
LABELS = {o.object_id: o.labels for o in objects()}


DATA = [o for o in TINY_DATA if not o.startswith("data.views=")] + [f"data.views={VIEWS}"]


@pytest.fixture
def visual_config(compose_config, cache_dir, mlflow_uri):
    def _compose(overrides: list[str]):
        base = [*DATA, f"cache_dir={cache_dir}", f"tracking.uri={mlflow_uri}"]
        return compose_config([*base, "adjectives=[hard,thick]", *FAST, *overrides])

    return _compose


@pytest.fixture(scope="module")
def dataset(compose_config, cache_dir) -> PHAC2:
    settings = settings_from_config(compose_config([*DATA, f"cache_dir={cache_dir}"]))
    return DATA_SOURCES.build(settings.data.name, **settings.data.params)


def _small_visual(cache_dir, **kwargs):
    """32x32 crops (5a is 1x1): the modality's logic at a fraction of the 224x224 trunk cost."""
    return MODALITIES.build("visual", cache_dir=cache_dir, size=32, batch_size=128, **kwargs)


def _instances(visual, dataset: PHAC2, split):
    """Training and test instances of ``split``, the modality fitted on its training trials."""
    train = split.trials("train", dataset)
    return visual.fit(train).transform(train), visual.transform(split.trials("test", dataset))


def _children(uri: str, parent_id: str):
    client = MlflowClient(uri)
    exp = client.get_experiment_by_name("tactile_exp")
    runs = client.search_runs([exp.experiment_id], f"tags.mlflow.parentRunId = '{parent_id}'")
    return client, runs


@pytest.mark.parametrize(
    ("row", "combine"),
    [("table1_k_image_googlenet_1view", 1), ("table1_l_image_googlenet_8views", VIEWS)],
)
def test_visual_rows_run_end_to_end(visual_config, mlflow_uri, row, combine):
    # 32x32 crops, as _small_visual: the checks below count units, views and epochs and
    # recompute the AUC from the logged scores, so none depends on the crop size, and the trunk
    # runs at a fraction of its 224x224 cost (that geometry: tests/test_preprocess_trunk.py)
    overrides = [f"experiment={row}", f"combine={combine}", "modality.batch_size=64"]
    settings = settings_from_config(visual_config([*overrides, "modality.size=32"]))
    assert (settings.modality.name, settings.model.name) == ("visual", "visual_googlenet")
    result = run(settings)
    client, children = _children(mlflow_uri, result.run_id)
    parent = client.get_run(result.run_id)
    assert parent.info.status == "FINISHED"
    assert parent.data.params["modality.weights"] == "None"
    assert {c.info.run_name for c in children} == {"adj=hard", "adj=thick"}
    for child in children:
        r = result.results[child.data.params["adjective"]]
        with open(client.download_artifacts(child.info.run_id, "scores.csv")) as f:
            rows = list(csv.DictReader(io.StringIO(f.read())))
        y, s = [int(x["label"]) for x in rows], [float(x["score"]) for x in rows]
        assert child.data.metrics["auc"] == pytest.approx(roc_auc_score(y, s), abs=1e-12)
        assert all(x["unit"].rsplit("_", 1)[1] in ("v00", "v01") for x in rows)
        n_objects = r.sizes["n_test_objects"]
        assert r.sizes["n_test_instances"] == VIEWS * n_objects  # every view of a test object
        assert len(rows) == (VIEWS * n_objects if combine == 1 else n_objects)
        assert r.sizes["n_train_instances"] == VIEWS * r.sizes["n_train_objects"]
        assert [LABELS[o][r.adjective] for o in r.test.objects] == list(r.test.y)
        assert len(client.get_metric_history(child.info.run_id, "train_loss")) == (
            settings.model.params["schedule"]["epochs"] if combine == 1 else 0  # row L: head only
        )
    aucs = [r.metrics["auc"] for r in result.results.values()]
    assert parent.data.metrics["mean_auc"] == pytest.approx(np.mean(aucs))


def test_combine_is_checked_against_views(visual_config):
    settings = settings_from_config(
        visual_config(["experiment=table1_l_image_googlenet_8views", f"combine={VIEWS + 1}"])
    )
    with pytest.raises(ConfigError, match=f"combine: {VIEWS + 1} views per unit.*1..{VIEWS}"):
        run(settings)


def test_views_follow_their_objects_trials(dataset, cache_dir):
    visual = _small_visual(cache_dir)
    visual.check(dataset)
    for adjective in ("hard", "nice"):  # nice: its only positive object is split by trial
        split = SPLITS["published"](dataset, adjective, 0)
        train, test = _instances(visual, dataset, split)
        assert not set(train.trial) & set(test.trial)
        assert {n.rsplit("_", 1)[1] for n in [*train.trial, *test.trial]} == {"v00", "v01"}
        for part, inst in (("train", train), ("test", test)):
            np.testing.assert_array_equal(inst.y, [LABELS[o][adjective] for o in inst.object_id])
            shared = split.objects("train") & split.objects("test")
            assert set(inst.object_id) == split.objects(part)
            for obj in set(inst.object_id):
                assert np.sum(inst.object_id == obj) == (1 if obj in shared else VIEWS)
        if adjective == "nice":
            (obj,) = split.objects("train") & split.objects("test")
            assert LABELS[obj]["nice"] == 1 and obj in train.object_id and obj in test.object_id


def test_features_are_the_frozen_trunks_and_cached(dataset, cache_dir, monkeypatch):
    visual = _small_visual(cache_dir, seed=4)
    visual.check(dataset)
    train, _ = _instances(visual, dataset, SPLITS["published"](dataset, "hard", 0))
    arrays = visual.trunk(dataset).arrays
    rows = [int(np.flatnonzero((arrays.object_id == o) & (arrays.view == 1))[0])
            for o in train.object_id[:3]]  # fmt: skip
    model = xavier_init(GoogLeNet(), seed=4)
    images = trunk.network_input(arrays.images[rows], trunk.IMAGENET_MEAN_RGB, "torchvision")
    expected = pooled_features(model, images)
    index = [int(np.flatnonzero((train.object_id == o) & np.char.endswith(
        train.trial.astype(str), "_v01"))[0]) for o in train.object_id[:3]]  # fmt: skip
    np.testing.assert_allclose(train.X[index], expected, atol=1e-5)
    np.testing.assert_allclose(np.linalg.norm(train.X, axis=1), 1.0, rtol=1e-5)

    def no_trunk(*args, **kwargs):
        raise AssertionError("the trunk ran again although its features are cached")

    monkeypatch.setattr(trunk, "build_trunk", no_trunk)
    again = _small_visual(cache_dir, seed=4)
    again.check(dataset)
    split = SPLITS["published"](dataset, "hard", 0)
    np.testing.assert_array_equal(_instances(again, dataset, split)[0].X, train.X)


def test_weights_file_and_fitted_mean(dataset, cache_dir, tmp_path):
    path = tmp_path / "googlenet.pth"
    torch.save(xavier_init(GoogLeNet(), seed=7).state_dict(), path)
    split = SPLITS["published"](dataset, "thick", 0)
    from_file = _small_visual(cache_dir, weights=str(path), seed=0)
    random7 = _small_visual(cache_dir, seed=7)
    fitted = _small_visual(cache_dir, seed=7, mean="train")
    for m in (from_file, random7, fitted):
        m.check(dataset)
    a, b, c = (_instances(m, dataset, split)[0].X for m in (from_file, random7, fitted))
    np.testing.assert_allclose(a, b, atol=1e-5)
    assert np.abs(c - b).max() > 1e-3  # a different mean is subtracted before the trunk
    with pytest.raises(ValueError, match=r"trunk.weights .*missing.pth not found") as missing:
        _small_visual(cache_dir, weights=str(tmp_path / "missing.pth"))
    line = str(param_error("modality", {"weights": None}, missing.value))
    assert line.startswith("modality: modality.weights") and "\n" not in line
    with pytest.raises(ValueError, match="modality.mean must be"):
        _small_visual(cache_dir, mean="dataset")


def test_objects_without_photographs_are_left_out(dataset, cache_dir, tmp_path, caplog):
    """Also after the same data file was checked with all its photographs in this process: the
    trunk's in-memory cache tells the photograph folders apart."""
    _small_visual(cache_dir).check(dataset)
    photos = dataset.photographs()
    dropped = sorted(photos)[:3]
    folder = tmp_path / "photographs"
    folder.mkdir()
    for obj, paths in photos.items():
        for p in paths if obj not in dropped else []:
            shutil.copy(p, folder / p.name)
    partial = PHAC2(dataset.path, photo_dir=folder)
    visual = _small_visual(cache_dir)
    with caplog.at_level(logging.WARNING, logger="tactile_exp.modalities"):
        visual.check(partial)
    assert f"3 of {len(photos)} objects have no photographs" in caplog.text
    train, test = _instances(visual, partial, SPLITS["published"](partial, "hard", 0))
    assert not set(dropped) & {*train.object_id, *test.object_id}
    assert {TrialName.parse(t.name).object_id for t in partial.trials} - set(dropped) == {
        *train.object_id,
        *test.object_id,
    }


def test_caffe_layout_features_come_from_the_caffe_trunk(dataset, cache_dir, tmp_path):
    """modality.layout=caffe: BGR minus Caffe's mean through the Caffe trunk of the weights
    file; the same file with the torchvision layout fails before any trunk pass."""
    path = tmp_path / "caffe.pth"
    trunk.save_weights(
        path, xavier_init(trunk.CaffeGoogLeNet(), seed=8).state_dict(), layout="caffe"
    )
    visual = _small_visual(cache_dir, weights=str(path), layout="caffe")
    visual.check(dataset)
    train, _ = _instances(visual, dataset, SPLITS["published"](dataset, "thick", 0))
    arrays = visual.trunk(dataset).arrays
    rows = [int(np.flatnonzero((arrays.object_id == o) & (arrays.view == 0))[0])
            for o in train.object_id[:3]]  # fmt: skip
    images = trunk.network_input(arrays.images[rows], (123.0, 117.0, 104.0), "caffe")
    expected = pooled_features(trunk.build_trunk(path, layout="caffe"), images)
    index = [int(np.flatnonzero((train.object_id == o) & np.char.endswith(
        train.trial.astype(str), "_v00"))[0]) for o in train.object_id[:3]]  # fmt: skip
    np.testing.assert_allclose(train.X[index], expected, atol=1e-5)
    wrong = _small_visual(cache_dir, weights=str(path), layout="torchvision")
    with pytest.raises(ValueError, match="caffe-layout .* set modality.layout=caffe"):
        wrong.check(dataset)
    with pytest.raises(ValueError, match="modality.layout must be"):
        _small_visual(cache_dir, layout="bgr")

"""Prediction from a finished job's kept models: equal to the logged scores, clear errors."""

from __future__ import annotations

import csv
import io
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
from mlflow.tracking import MlflowClient

from tactile_exp import artifacts
from tactile_exp.config import settings_from_config
from tactile_exp.data.layout import DataError, TrialName
from tactile_exp.data.phac2 import PHAC2
from tactile_exp.data.photos import PhotoFolder
from tactile_exp.data.sources import DATA_SOURCES
from tactile_exp.experiment import run
from tactile_exp.predict import PredictError, predict
from tactile_exp.predict.__main__ import main
from tactile_exp.preprocess.visual import compute_visual_arrays


@pytest.fixture
def job(tiny_config, mlflow_uri):
    settings = settings_from_config(tiny_config([], "[hard,soft]"))
    result = run(settings)
    data = DATA_SOURCES.build(settings.data.name, **settings.data.params).path
    return result, data


def _logged(uri: str, parent: str) -> dict[str, dict[str, float]]:
    client = MlflowClient(uri)
    exp = client.get_experiment_by_name("tactile_exp")
    runs = client.search_runs(
        [exp.experiment_id],
        f"tags.mlflow.parentRunId = '{parent}' and tags.run_level = 'child'",
    )
    out = {}
    for child in runs:
        with open(client.download_artifacts(child.info.run_id, "scores.csv")) as f:
            rows = csv.DictReader(io.StringIO(f.read()))
            out[child.data.tags["adjective"]] = {r["unit"]: float(r["score"]) for r in rows}
    return out


def test_predict_equals_the_logged_score_of_held_out_trials(job, mlflow_uri, capsys):
    result, data = job
    logged = _logged(mlflow_uri, result.run_id)
    trials = sorted(logged["hard"])[:2]  # test units of `hard` (one trial each at combine=1)
    got = predict(run_id=result.run_id, tracking_uri=mlflow_uri, data=data, trials=trials)
    assert got.units == trials and got.adjectives == ["hard", "soft"]
    for i, trial in enumerate(trials):
        assert got.scores[i, 0] == pytest.approx(logged["hard"][trial], abs=1e-5)
        assert got.predicted()[i] == [
            a for a, s in zip(got.adjectives, got.scores[i], strict=True) if s > 0
        ]
        if trial in logged["soft"]:
            assert got.scores[i, 1] == pytest.approx(logged["soft"][trial], abs=1e-5)
    args = ["--tracking-uri", mlflow_uri, "--data", str(data), "--format", "csv"]
    assert main([*args, "--trial", trials[0]]) == 0  # newest job: this one
    rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    assert float(rows[0]["hard"]) == pytest.approx(logged["hard"][trials[0]], abs=1e-5)


def test_predict_errors_are_clear(job, mlflow_uri, tmp_path, capsys):
    result, data = job
    trial = sorted(_logged(mlflow_uri, result.run_id)["hard"])[0]
    base = ["--tracking-uri", mlflow_uri, "--data", str(data), "--trial", trial]

    def error(argv: list[str]) -> str:
        assert main(argv) == 2
        return capsys.readouterr().err

    assert "unknown run id nope" in error(["nope", *base])
    assert "not photographs" in error(
        [result.run_id, "--tracking-uri", mlflow_uri, "--photos", "x"]
    )

    client = MlflowClient(mlflow_uri)
    exp = client.get_experiment_by_name("tactile_exp")
    running = client.create_run(exp.experiment_id, tags={"run_level": "parent"}).info.run_id
    assert f"run {running} is RUNNING, not FINISHED" in error([running, *base])

    broken = tmp_path / "broken.h5"
    shutil.copy(data, broken)
    with h5py.File(broken, "a") as f:
        del f[trial]["biotacs/finger_0/pdc"]
    message = error([result.run_id, *base[:2], "--data", str(broken), "--trial", trial])
    assert trial in message and "pdc" in message and "artifact" not in message  # data, not job

    child = client.search_runs([exp.experiment_id], f"tags.mlflow.parentRunId = '{result.run_id}'")[
        0
    ]
    head = Path(child.info.artifact_uri.removeprefix("file://"), "head", "weights.pt")
    head.write_bytes(b"garbage")
    message = error([result.run_id, *base])
    assert f"run {child.info.run_id}: artifact head/weights.pt" in message
    assert "Traceback" not in message
    with pytest.raises(artifacts.ArtifactError):
        predict(run_id=result.run_id, tracking_uri=mlflow_uri, data=data, trials=[trial])


def test_photographs_missing_or_not_images(tmp_path):
    with pytest.raises(DataError, match="no such folder"):
        PhotoFolder(tmp_path / "none")
    with pytest.raises(DataError, match="no photographs"):
        PhotoFolder(tmp_path)
    (tmp_path / "view.jpg").write_text("not an image")
    with pytest.raises(DataError, match="view.jpg"):
        compute_visual_arrays(PhotoFolder(tmp_path), 32)


@pytest.mark.slow  # prepares photographs and runs the GoogLeNet trunk
def test_predict_from_photographs_equals_the_logged_scores(tiny_config, mlflow_uri, tmp_path):
    small = ["data.views=2", "modality.size=32", "modality.batch_size=64"]
    overrides = ["experiment=table1_k_image_googlenet_1view", *small]
    settings = settings_from_config(tiny_config(overrides, "[hard]"))
    result = run(settings)
    dataset = DATA_SOURCES.build(settings.data.name, **settings.data.params)
    logged = _logged(mlflow_uri, result.run_id)["hard"]
    stem = sorted(logged)[0].rsplit("_v", 1)[0]  # a test object's photographs
    obj = next(t.object_id for t in dataset.trials if t.stem == stem)
    folder = tmp_path / stem
    folder.mkdir()
    for path in dataset.photographs()[obj]:
        shutil.copy(path, folder / path.name)
    got = predict(run_id=result.run_id, tracking_uri=mlflow_uri, photos=folder)
    assert got.units == [f"{stem}_v00", f"{stem}_v01"]
    for unit, score in zip(got.units, got.scores[:, 0], strict=True):
        assert score == pytest.approx(logged[unit], abs=1e-5)
    with pytest.raises(PredictError, match="visual models"):
        predict(run_id=result.run_id, tracking_uri=mlflow_uri, data=dataset.path, trials=[stem])


def _test_object(logged: dict[str, float], dataset) -> tuple[int, list[str]]:
    """A test object of the job and its logged units."""
    by_name = {t.name: t.object_id for t in dataset.trials}
    obj = by_name[sorted(logged)[0]]
    return obj, sorted(u for u in logged if by_name[u] == obj)


@pytest.mark.parametrize(
    "row",
    [
        "table1_a_haptic_static_1trial",
        pytest.param("table1_b_haptic_static_10trials", marks=pytest.mark.slow),
        pytest.param("table1_e_haptic_static_dynamic_1trial", marks=pytest.mark.slow),
        pytest.param("table1_f_haptic_static_1trial_dynamic_10trials", marks=pytest.mark.slow),
    ],
)
def test_predict_baseline_rows_equal_the_logged_scores(tiny_config, mlflow_uri, row):
    """Rows A-F: the stored static PCA, HMM chains and SVM (or head) score a test object's
    trials as the job scored them."""
    settings = settings_from_config(tiny_config([f"experiment={row}"], "[hard]"))
    result = run(settings)
    dataset = DATA_SOURCES.build(settings.data.name, **settings.data.params)
    logged = _logged(mlflow_uri, result.run_id)["hard"]
    obj, units = _test_object(logged, dataset)
    got = predict(run_id=result.run_id, tracking_uri=mlflow_uri, data=dataset.path, object_id=obj)
    # a unit of several trials is named by its object (tiny data: one unit per object)
    assert got.units == (units if settings.combine == 1 else [TrialName.parse(units[0]).stem])
    np.testing.assert_allclose(got.scores[:, 0], [logged[u] for u in units], atol=1e-5)


def test_baseline_artifacts_corrupt_or_missing_are_clear_errors(tiny_config, mlflow_uri):
    settings = settings_from_config(
        tiny_config(["experiment=table1_c_haptic_dynamic_1trial"], "[hard]")
    )
    result = run(settings)
    data = DATA_SOURCES.build(settings.data.name, **settings.data.params).path
    trial = sorted(_logged(mlflow_uri, result.run_id)["hard"])[0]
    client = MlflowClient(mlflow_uri)
    child = client.search_runs(
        [client.get_experiment_by_name("tactile_exp").experiment_id],
        f"tags.mlflow.parentRunId = '{result.run_id}'",
    )[0]
    folder = Path(child.info.artifact_uri.removeprefix("file://"))
    for path, expected in (
        ("preprocess/arrays.npz", "preprocess/arrays.npz is not a readable npz"),
        ("model/arrays.npz", "model/arrays.npz is not a readable npz"),
    ):
        kept = (folder / path).read_bytes()
        (folder / path).write_bytes(b"garbage")
        with pytest.raises(
            artifacts.ArtifactError, match=f"run {child.info.run_id}: artifact {expected}"
        ):
            predict(run_id=result.run_id, tracking_uri=mlflow_uri, data=data, trials=[trial])
        (folder / path).write_bytes(kept)
    (folder / "preprocess" / "arrays.npz").unlink()
    with pytest.raises(artifacts.ArtifactError, match=r"artifact preprocess/ lacks arrays.npz"):
        predict(run_id=result.run_id, tracking_uri=mlflow_uri, data=data, trials=[trial])


def test_random_guess_job_is_refused(tiny_config, mlflow_uri):
    overrides = ["experiment=table1_o_random"]
    settings = settings_from_config(tiny_config(overrides, "[hard]"))
    result = run(settings)
    data = DATA_SOURCES.build(settings.data.name, **settings.data.params).path
    with pytest.raises(PredictError, match="random-guess job.*keeps no model"):
        predict(run_id=result.run_id, tracking_uri=mlflow_uri, data=data, object_id=1)


@pytest.mark.slow  # a multimodal job: trains the ConvNet part and prepares photographs
def test_predict_multimodal_row_equals_the_logged_scores(tiny_config, mlflow_uri, tmp_path):
    small = ["modality.visual.size=32", "modality.visual.batch_size=128"]
    overrides = ["experiment=table1_m_multimodal_i_l", *small]
    settings = settings_from_config(tiny_config(overrides, "[hard]"))
    result = run(settings)
    dataset = DATA_SOURCES.build(settings.data.name, **settings.data.params)
    logged = _logged(mlflow_uri, result.run_id)["hard"]
    obj, units = _test_object(logged, dataset)
    folder = tmp_path / "photos"
    folder.mkdir()
    for path in dataset.photographs()[obj]:
        shutil.copy(path, folder / path.name)
    args = {"run_id": result.run_id, "tracking_uri": mlflow_uri, "data": dataset.path}
    got = predict(**args, object_id=obj, photos=folder)
    assert got.units == units
    np.testing.assert_allclose(got.scores[:, 0], [logged[u] for u in units], atol=1e-5)

    with pytest.raises(PredictError, match="give a folder of photographs and the object's"):
        predict(**args, object_id=obj)
    (tmp_path / "empty").mkdir()
    with pytest.raises(PredictError, match="no photographs"):
        predict(**args, object_id=obj, photos=tmp_path / "empty")
    other = next(t.name for t in dataset.trials if t.object_id != obj)
    with pytest.raises(PredictError, match="trials of one object"):
        predict(**args, trials=[units[0], other], photos=folder)


def test_the_table_names_the_job_its_data_and_what_the_scores_mean(job, mlflow_uri, capsys):
    """No run id, no --data: the newest job and its own data file, both said; whole trial
    names as column headers; one line per object against the file's true adjectives."""
    result, data = job
    trials = sorted(_logged(mlflow_uri, result.run_id)["hard"])[:2]
    assert main(["--tracking-uri", mlflow_uri, *(f"--trial={t}" for t in trials)]) == 0
    out = capsys.readouterr().out
    lines = out.splitlines()
    assert lines[0] == (
        f"job {result.run_id}: haptic_cnn-concat-c1-s0 (model haptic_cnn on modality haptic, "
        "one trial per unit)"
    )
    assert lines[1] == "  no run id given: the newest FINISHED job of experiment 'tactile_exp'"
    assert lines[2].startswith(f"data {Path(data).resolve()} (the job's own data file")
    assert "decision value; > 0 means the adjective is predicted" in lines[3]
    assert [line.split() for line in lines].count(trials) == 1  # the header: whole names
    labels = PHAC2(data).labels()
    got = predict(run_id=result.run_id, tracking_uri=mlflow_uri, data=data, trials=trials)
    for obj, chosen in got.object_predictions().items():
        true = [a for a in ("hard", "soft") if labels[obj][a]]
        line = next(x for x in lines if x.startswith(f"  object {obj} ("))
        assert f"predicted {', '.join(chosen) or '(none)'}; true {', '.join(true) or '(none)'}" in (
            line
        )


def test_missing_trials_name_the_flags(job, mlflow_uri, capsys):
    result, _ = job
    assert main([result.run_id, "--tracking-uri", mlflow_uri]) == 2
    assert "give trials (--trial NAME, repeated, or --object ID)" in capsys.readouterr().err


def test_a_combined_unit_is_its_object_and_a_gone_data_file_asks_for_data(
    tiny_config, mlflow_uri, tmp_path, capsys
):
    """combine=2 (all of a tiny object's trials): the unit is named by its object, its score
    is the logged one; the job's own data file is used until it is gone, then --data is asked."""
    copy = tmp_path / "phac2.h5"
    settings = settings_from_config(tiny_config(["combine=2"], "[hard]"))
    shutil.copy(DATA_SOURCES.build(settings.data.name, **settings.data.params).path, copy)
    settings = settings_from_config(
        tiny_config(["data=phac2", f"data.path={copy}", "combine=2"], "[hard]")
    )
    result = run(settings)
    (unit, score), *_ = _logged(mlflow_uri, result.run_id)["hard"].items()
    name = TrialName.parse(unit)
    got = predict(run_id=result.run_id, tracking_uri=mlflow_uri, object_id=name.object_id)
    assert got.units == [name.stem] and got.scores[0, 0] == pytest.approx(score, abs=1e-5)
    assert got.data.startswith(f"{copy} (the job's own data file")
    copy.unlink()
    assert main([result.run_id, "--tracking-uri", mlflow_uri, f"--object={name.object_id}"]) == 2
    assert f"the job's data file {copy} is no longer there: give --data" in (
        capsys.readouterr().err
    )

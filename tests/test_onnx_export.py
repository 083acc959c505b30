"""ONNX networks of a finished job: onnxruntime gives predict's decision values on a held-out
object, from the manifest's inputs and the stored preprocessing; rows without a network refused."""

from __future__ import annotations

import csv
import io
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from tactile_exp.combine import unit_members
from tactile_exp.config import settings_from_config
from tactile_exp.data.layout import Trials
from tactile_exp.data.photos import PhotoFolder
from tactile_exp.data.sources import DATA_SOURCES
from tactile_exp.deploy.__main__ import main
from tactile_exp.deploy.onnx_export import export_job
from tactile_exp.experiment import run
from tactile_exp.jobs import StoredJob
from tactile_exp.modalities import MODALITIES
from tactile_exp.modalities.multimodal import visual_units
from tactile_exp.modalities.networks import channel_names
from tactile_exp.models import MODELS
from tactile_exp.predict import PredictError, predict
from tactile_exp.preprocess.haptic import trial_signals
from tactile_exp.preprocess.trunk import network_input
from tactile_exp.preprocess.visual import compute_visual_arrays

SMALL_VISUAL = ["modality.size=32", "modality.batch_size=64"]
SMALL_MULTIMODAL = ["modality.visual.size=32", "modality.visual.batch_size=128"]


def _session(path: Path):
    ort = pytest.importorskip("onnxruntime")
    return ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])


def _held_out(uri: str, job: str, dataset) -> tuple[int, list[str]]:
    """A test object of the job's one adjective and its trials (sorted by name)."""
    stored = StoredJob.open(job, tracking_uri=uri)
    (child,) = stored.children().values()
    scores = stored.tracker.client.download_artifacts(child, "scores.csv")
    units = [r["unit"] for r in csv.DictReader(io.StringIO(Path(scores).read_text()))]
    by_stem = {t.stem: t.object_id for t in dataset.trials}
    by_name = {t.name: t.object_id for t in dataset.trials}
    first = units[0].split("#")[0]
    obj = by_name.get(first, by_stem.get(first.rsplit("_v", 1)[0]))
    return obj, sorted(t.name for t in dataset.trials if t.object_id == obj)


def _docs_reference() -> dict[str, object]:
    """The numpy reference of the haptic preprocessing in docs/deployment.md, executed."""
    text = (Path(__file__).parents[1] / "docs" / "deployment.md").read_text()
    block = text.split("<!-- reference: haptic preprocessing -->\n```python\n")[1].split("```")[0]
    namespace: dict[str, object] = {}
    exec(compile(block, "docs/deployment.md", "exec"), namespace)
    return namespace


def _photos(dataset, obj: int, folder: Path) -> Path:
    folder.mkdir()
    for path in dataset.photographs()[obj]:
        shutil.copy(path, folder / path.name)
    return folder


@pytest.mark.job
@pytest.mark.parametrize(
    "row, overrides",
    [
        pytest.param("G", ["experiment=table1_g_haptic_lstm"], marks=pytest.mark.slow),
        ("I", ["experiment=table1_i_haptic_cnn_1trial"]),
        pytest.param("J", ["experiment=table1_j_haptic_cnn_10trials"], marks=pytest.mark.slow),
        pytest.param(
            "L",
            ["experiment=table1_l_image_googlenet_8views", "data.views=2", *SMALL_VISUAL],
            marks=pytest.mark.slow,
        ),
        pytest.param(
            "M", ["experiment=table1_m_multimodal_i_l", *SMALL_MULTIMODAL], marks=pytest.mark.slow
        ),
    ],
)
def test_onnxruntime_equals_predict_on_a_held_out_object(
    tiny_config, mlflow_uri, tmp_path, row, overrides
):
    onnx = pytest.importorskip("onnx")
    settings = settings_from_config(tiny_config(overrides, "[hard]"))
    job = run(settings).run_id
    dataset = DATA_SOURCES.build(settings.data.name, **settings.data.params)
    obj, trials = _held_out(mlflow_uri, job, dataset)
    out = tmp_path / "onnx"
    assert main(["--tracking-uri", mlflow_uri, "onnx", job, str(out)]) == 0
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["row"] == row and list(manifest["adjectives"]) == ["hard"]
    entry = manifest["adjectives"]["hard"]
    for path in out.glob("*.onnx"):
        onnx.checker.check_model(str(path), full_check=True)
    state = np.load(out / "preprocess.npz", allow_pickle=False)

    feeds: dict[str, np.ndarray] = {}
    photos = None
    if "haptic" in manifest:
        haptic = manifest["haptic"]
        assert len(haptic["channels"]) == 32 and haptic["channels"] == channel_names(4)
        stored = StoredJob.open(job, tracking_uri=mlflow_uri)
        preprocess = stored.pipelines(["hard"])["hard"].preprocess
        if manifest["modality"] == "multimodal":  # its haptic part's stored preprocessing
            preprocess = preprocess.haptic
        instances = preprocess.transform(Trials(dataset, tuple(trials)))
        reference = _docs_reference()
        trial = next(dataset.iter_trials([trials[0]]))
        x = trial_signals(trial, haptic["pac_downsample"])
        rows = trial.ep_segments()
        segments = [[x[f, rows[ep]] for ep in haptic["eps"]] for f in range(2)]
        ours = reference["trial_instances"](segments, state, "hard", haptic)
        np.testing.assert_allclose(ours, instances.X[: len(ours)], rtol=1e-4, atol=1e-4)
        per_unit = haptic["instances_per_unit"]
        if manifest["combine_instances"] == "separate" and manifest["modality"] == "haptic":
            feeds["instances"] = instances.X
        else:
            members = unit_members(instances, haptic["trials_per_unit"], pad=True)
            feeds["instances"] = np.stack([instances.X[m] for m in members])
            assert feeds["instances"].shape[1] == per_unit
        assert list(feeds["instances"].shape[1:]) == entry["inputs"]["instances"][1:]
    if "visual" in manifest:
        visual = manifest["visual"]
        photos = _photos(dataset, obj, tmp_path / "photos")
        images = compute_visual_arrays(PhotoFolder(photos), visual["size"]).images
        mean = state["hard.visual.channel_mean"]
        trunk = _session(out / visual["trunk"])
        (features,) = trunk.run(None, {"images": network_input(images, mean, visual["layout"])})
        views = visual["views_per_unit"]
        unit = visual_units(features, np.zeros(len(features), np.int64), views)[0]
        n = len(feeds["instances"]) if feeds else 1
        feeds["views"] = np.repeat(unit.reshape(1, views, -1), n, axis=0)
    (got,) = _session(out / entry["file"]).run(None, feeds)

    data = None if manifest["modality"] == "visual" else dataset.path
    expected = predict(
        run_id=job, tracking_uri=mlflow_uri, data=data, trials=trials if data else (), photos=photos
    )
    # float32 sums over ~25,000 standardised features (row M): numba kernels vs onnxruntime
    np.testing.assert_allclose(got, expected.scores[:, 0], atol=1e-5, rtol=1e-5)
    assert (got > 0).tolist() == [p == ["hard"] for p in expected.predicted()]


def test_rows_without_a_network_are_refused(tiny_config, mlflow_uri, tmp_path, capsys):
    settings = settings_from_config(
        tiny_config(["experiment=table1_a_haptic_static_1trial"], "[hard]")
    )
    job = run(settings).run_id
    with pytest.raises(PredictError, match="keeps no network.*linear SVM"):
        export_job(job, tmp_path / "out", tracking_uri=mlflow_uri)
    capsys.readouterr()  # the job's own warnings (shown once per process: order-dependent)
    assert main(["--tracking-uri", mlflow_uri, "onnx", job, str(tmp_path / "out")]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith(f"error: run {job} is a linear_svm job on modality haptic_features")
    assert not (tmp_path / "out").exists()


def test_a_component_that_declares_it_cannot_export_is_refused_in_one_line(
    tiny_config, mlflow_uri, tmp_path, capsys
):
    """A model registered outside the engine says why it has no network; export names it
    before writing anything (the haptic modality itself exports)."""

    class Lookup(MODELS["random"]):  # type: ignore[misc, valid-type]
        onnx_refusal = "its scores come from a lookup table"

    out = tmp_path / "out"
    with MODELS.temporary(lookup=Lookup):
        overrides = ["model=random", "model.name=lookup", "combine_instances=separate"]
        job = run(settings_from_config(tiny_config(overrides, "[hard]"))).run_id
        capsys.readouterr()
        assert main(["--tracking-uri", mlflow_uri, "onnx", job, str(out)]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line == (
        f"error: run {job} is a lookup job on modality haptic: it keeps no network to export to "
        "ONNX (model lookup: its scores come from a lookup table); `python -m tactile_exp.deploy "
        "log` makes an MLflow model of it instead"
    )
    assert not out.exists()


def test_a_modality_without_a_network_says_why():
    assert MODALITIES["haptic"].onnx_refusal is None
    with pytest.raises(NotImplementedError, match="^modality Signals: its features are computed"):
        MODALITIES["signals"].onnx_network(lambda path: None, {}, True, 1)

"""The `DataSet` protocol: PHAC-2 and the folder layout satisfy it; label names come from it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from mlflow.tracking import MlflowClient
from phac2_fixture import OBJECTS, write_file

from tactile_exp.config import settings_from_config
from tactile_exp.data.dataset import DataSet, Sensor, select_labels
from tactile_exp.data.folder import FolderDataSet, write_folder
from tactile_exp.data.layout import ADJECTIVES, DataError, TrialName
from tactile_exp.data.phac2 import PHAC2
from tactile_exp.data.sources import DATA_SOURCES
from tactile_exp.errors import EXIT_USER_ERROR, reported
from tactile_exp.experiment import run

GLOVE = Sensor("glove", ("ax", "ay", "az", "gx", "gy", "gz"), 50.0)


@pytest.fixture(scope="module")
def phac2(tmp_path_factory: pytest.TempPathFactory) -> PHAC2:
    return PHAC2(write_file(tmp_path_factory.mktemp("phac2") / "tiny.h5"))


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> FolderDataSet:
    labels = {f"obj{i}": {"grippy": i % 2, "warm": int(i < 2), "loud": 0} for i in range(4)}
    trials = {o: [np.zeros((6, 10))] * (1 + i) for i, o in enumerate(labels)}
    return FolderDataSet(write_folder(tmp_path_factory.mktemp("folder"), GLOVE, labels, trials))


@pytest.mark.parametrize("source", ["phac2", "folder"])
def test_every_source_satisfies_the_protocol(source: str, request: pytest.FixtureRequest) -> None:
    ds = request.getfixturevalue(source)
    assert isinstance(ds, DataSet)
    assert isinstance(ds.path, Path) and ds.path.exists()
    assert isinstance(ds.label_names, tuple) and len(set(ds.label_names)) == len(ds.label_names)
    assert isinstance(ds.sensor, Sensor) and ds.sensor.channels and ds.sensor.rate_hz > 0
    assert ds.trials == tuple(sorted(ds.trials)) and all(
        isinstance(t, TrialName) for t in ds.trials
    )
    assert ds.object_ids() == tuple(sorted({t.object_id for t in ds.trials}))
    labels = ds.labels()
    assert tuple(sorted(labels)) == ds.object_ids()
    assert all(set(row) == set(ds.label_names) for row in labels.values())
    assert {v for row in labels.values() for v in row.values()} <= {0, 1}
    for t in ds.trials:
        assert ds.trial_name(t.name) is ds.trial_name(t) == t
        assert TrialName.parse(t.name) == t  # what the splits and modalities parse
        assert t.name.startswith(ds.object_name(t.object_id))
    with pytest.raises(DataError):
        ds.trial_name("nothing_999_99")
    assert ds.identity().endswith(ds.digest()) and ds.identity() != ds.digest()
    assert set(ds.photographs()) <= set(ds.object_ids())


def test_phac2_is_the_paper_adjectives_on_the_biotac(phac2: PHAC2) -> None:
    assert phac2.label_names == ADJECTIVES  # the paper's order, which the report keeps
    assert len(phac2.sensor.channels) == 2 * (19 + 4) and phac2.sensor.rate_hz == 100.0
    assert phac2.sensor.channels[:2] == ("finger_0/electrode_01", "finger_0/electrode_02")
    assert phac2.sensor.channels[-1] == "finger_1/tdc"
    assert phac2.object_name(101) == OBJECTS[101].group_stem == "car_sponge_101"


def test_select_labels(folder: FolderDataSet) -> None:
    assert select_labels(folder, None) == ("grippy", "warm", "loud")  # null: all, in its order
    assert select_labels(folder, ["loud", "grippy"]) == ("loud", "grippy")  # as given
    with pytest.raises(DataError) as err:
        select_labels(folder, ["warm", "hard", "soft"])
    assert str(err.value) == (
        f"adjectives: unknown ['hard', 'soft'] for the data set {folder.path}; its labels: "
        "grippy, warm, loud (or adjectives=null for all of them)"
    )


def _runs(uri: str) -> list:
    client = MlflowClient(uri)
    return client.search_runs([e.experiment_id for e in client.search_experiments()])


@pytest.mark.parametrize(
    "overrides,line",
    [
        (
            ["data=phac2", "data.path={phac2}", "adjectives=[hard,fluffy,gritty]"],
            "error: adjectives: unknown ['fluffy', 'gritty'] for the data set {path}; its labels: "
            f"{', '.join(ADJECTIVES)} (or adjectives=null for all of them)",
        ),
        (
            [
                "data=folder",
                "data.path={folder}",
                "modality=signals",
                "model=linear",
                "split=published",
            ],
            "error: {path}: split=published is PHAC-2's published split and this data set is "
            "not PHAC-2; use split=random or split=folds",
        ),
        (
            ["data=folder", "data.path={folder}", "split=random"],  # modality=haptic: BioTac's
            "error: modality: modality=haptic needs trials in the phac2-biotac layout, which "
            "{path} (sensor 'glove', 6 channels at 50 Hz, no declared layout) does not give; "
            "modality=signals would fit",
        ),
        (
            [
                "data=folder",
                "data.path={folder}",
                "split=random",
                "modality=signals",
                "model=linear",
                "adjectives=[hard]",
            ],
            "error: adjectives: unknown ['hard'] for the data set {path}; its labels: grippy, "
            "warm, loud (or adjectives=null for all of them)",
        ),
    ],
)
def test_unknown_labels_a_foreign_split_or_sensor_are_one_error_line_before_any_run(
    tiny_config, mlflow_uri, phac2, folder, capsys, overrides, line
) -> None:
    overrides = [o.format(folder=folder.path, phac2=phac2.path) for o in overrides]
    settings = settings_from_config(tiny_config(overrides, adjectives="null"))
    with pytest.raises(SystemExit) as done, reported():
        run(settings)
    assert done.value.code == EXIT_USER_ERROR
    errors = [e for e in capsys.readouterr().err.splitlines() if e.startswith("error:")]
    dataset = DATA_SOURCES.build(settings.data.name, **settings.data.params)
    assert errors == [line.format(path=dataset.path)]
    assert _runs(mlflow_uri) == []

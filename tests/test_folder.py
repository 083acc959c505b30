"""The folder-layout data source (``data=folder``): reading, every refusal, laziness, identity."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from tactile_exp.data.dataset import DataSet, Sensor
from tactile_exp.data.folder import FolderDataSet, write_folder
from tactile_exp.data.layout import DataError, TrialName
from tactile_exp.data.splits import check_split, make_split

SENSOR = Sensor("glove", ("ax", "ay", "az"), 50.0)
OBJECTS = ("sponge", "brick", "felt", "cork")  # ids by sorted name: brick 1, cork 2, felt 3, ...
LABELS = {  # object -> label -> 0/1
    "sponge": {"soft": 1, "rough": 0},
    "brick": {"soft": 0, "rough": 1},
    "felt": {"soft": 1, "rough": 1},
    "cork": {"soft": 0, "rough": 0},
}


def _arrays(obj: str, n: int = 2) -> list[np.ndarray]:
    seed = OBJECTS.index(obj)
    return [np.random.default_rng([seed, t]).normal(size=(3, 20 + t)) for t in range(n)]


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    """Four objects, two labels, two trials each (20 and 21 samples), no photographs."""
    return write_folder(tmp_path / "ds", SENSOR, LABELS, {o: _arrays(o) for o in OBJECTS})


def _by_hand(root: Path) -> Path:
    """The documented layout written without `write_folder`: ids given, odd file names."""
    (root / "trials" / "cup").mkdir(parents=True)
    (root / "trials" / "mat").mkdir(parents=True)
    (root / "dataset.yaml").write_text("sensor: skin\nchannels: [p0, p1]\nrate_hz: 1000\n")
    (root / "labels.csv").write_text("object,object_id,hard,smooth\ncup,7,1,1\nmat,42,0,1\n")
    np.save(root / "trials" / "cup" / "take_b.npy", np.arange(10, dtype=np.int16).reshape(2, 5))
    np.save(root / "trials" / "cup" / "take_a.npy", np.ones((2, 4), dtype=np.float32))
    np.save(root / "trials" / "mat" / "x.npy", np.zeros((2, 3)))
    (root / "trials" / "mat" / ".DS_Store").write_text("hidden files are skipped")
    return root


def test_the_layout_reads_as_documented(tmp_path: Path) -> None:
    ds = FolderDataSet(_by_hand(tmp_path))
    assert ds.sensor == Sensor("skin", ("p0", "p1"), 1000.0)
    assert ds.label_names == ("hard", "smooth")  # the header's order
    assert ds.object_ids() == (7, 42)
    assert ds.labels() == {7: {"hard": 1, "smooth": 1}, 42: {"hard": 0, "smooth": 1}}
    assert [t.name for t in ds.trials] == ["cup_007_01", "cup_007_02", "mat_042_01"]
    assert ds.trials[0] == TrialName("cup_007_01", "cup_007", 7, 1)
    assert (ds.object_name(7), ds.object_name(42)) == ("cup", "mat")
    # trials numbered in file-name order: take_a is 01, take_b 02; ints come back as float64
    assert ds.trial_file("cup_007_01").name == "take_a.npy"
    got = ds.signals("cup_007_02")
    assert got.dtype == np.float64 and got.tolist() == [[0, 1, 2, 3, 4], [5, 6, 7, 8, 9]]
    assert ds.signals(ds.trials[0]).shape == (2, 4)
    assert ds.photographs() == {}
    with pytest.raises(DataError, match="no trial cup_007_03"):
        ds.trial_name("cup_007_03")
    with pytest.raises(DataError, match="no object with id 8"):
        ds.object_name(8)


def test_ids_follow_sorted_object_names_without_an_id_column(folder: Path) -> None:
    ds = FolderDataSet(folder)
    assert isinstance(ds, DataSet)
    assert [ds.object_name(i) for i in (1, 2, 3, 4)] == sorted(OBJECTS)
    assert ds.labels()[4] == LABELS["sponge"]
    assert ds.label_names == ("soft", "rough")
    assert ds.trial_name("felt_003_02").object_id == 3
    np.testing.assert_array_equal(ds.signals("felt_003_02"), _arrays("felt")[1])
    copy = ds.labels()
    copy[1]["soft"] = 1
    assert ds.labels()[1]["soft"] == 0  # labels() hands out a copy


def test_write_folder_writes_the_documented_files(folder: Path) -> None:
    assert (folder / "labels.csv").read_text().splitlines() == [
        "object,soft,rough",
        "sponge,1,0",
        "brick,0,1",
        "felt,1,1",
        "cork,0,0",
    ]
    assert sorted(p.name for p in (folder / "trials" / "cork").iterdir()) == [
        "trial_01.npy",
        "trial_02.npy",
    ]


def test_opening_reads_no_trial_array(folder: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Labels and names at open; each array when asked for, validated then."""
    (folder / "trials" / "cork" / "trial_02.npy").write_bytes(b"not an array")
    calls: list[Path] = []
    real_load = np.load
    monkeypatch.setattr(np, "load", lambda f, **kw: calls.append(Path(f)) or real_load(f, **kw))
    ds = FolderDataSet(folder)
    ds.identity()
    assert calls == []
    assert ds.signals("cork_002_01").shape == (3, 20)
    assert calls == [folder / "trials" / "cork" / "trial_01.npy"]
    with pytest.raises(DataError, match="trial_02.npy: cannot read as .npy"):
        ds.signals("cork_002_02")


def _edit(root: Path, file: str, text: str) -> None:
    (root / file).write_text(text)


# Problems found when the folder opens: (what to do to a good folder, the file named, message).
OPEN_ERRORS = {
    "dataset.yaml missing": (
        lambda d: (d / "dataset.yaml").unlink(),
        "dataset.yaml",
        "cannot read (No such file or directory); expected sensor: NAME",
    ),
    "dataset.yaml not YAML": (
        lambda d: _edit(d, "dataset.yaml", "sensor: [glove\n"),
        "dataset.yaml",
        "not valid YAML (",
    ),
    "dataset.yaml not a mapping": (
        lambda d: _edit(d, "dataset.yaml", "- glove\n"),
        "dataset.yaml",
        "holds list, expected sensor",
    ),
    "dataset.yaml key missing": (
        lambda d: _edit(d, "dataset.yaml", "sensor: glove\nchannels: [a, b, c]\n"),
        "dataset.yaml",
        "missing ['rate_hz']",
    ),
    "dataset.yaml unknown key": (
        lambda d: _edit(d, "dataset.yaml", "sensor: g\nchannels: [a]\nrate_hz: 5\nrate: 5\n"),
        "dataset.yaml",
        "unknown key(s) ['rate']",
    ),
    "channels not a list": (
        lambda d: _edit(d, "dataset.yaml", "sensor: g\nchannels: abc\nrate_hz: 50\n"),
        "dataset.yaml",
        "channels: 'abc', expected a list of channel names",
    ),
    "channel twice": (
        lambda d: _edit(d, "dataset.yaml", "sensor: g\nchannels: [a, b, a]\nrate_hz: 50\n"),
        "dataset.yaml",
        "channels: ['a'] listed twice",
    ),
    "rate not positive": (
        lambda d: _edit(d, "dataset.yaml", "sensor: g\nchannels: [a, b, c]\nrate_hz: 0\n"),
        "dataset.yaml",
        "rate_hz: 0, expected samples per second > 0",
    ),
    "labels.csv missing": (
        lambda d: (d / "labels.csv").unlink(),
        "labels.csv",
        "cannot read (No such file or directory)",
    ),
    "labels.csv empty": (lambda d: _edit(d, "labels.csv", "\n"), "labels.csv", "empty;"),
    "first column not object": (
        lambda d: _edit(d, "labels.csv", "name,soft\nsponge,1\n"),
        "labels.csv",
        "first column 'name'; expected a header object[,object_id],LABEL",
    ),
    "no label columns": (
        lambda d: _edit(d, "labels.csv", "object\nsponge\n"),
        "labels.csv",
        "no label columns",
    ),
    "label name with a space": (
        lambda d: _edit(d, "labels.csv", "object,very soft\nsponge,1\n"),
        "labels.csv",
        "label column 'very soft', expected a name of letters, digits, _ and -",
    ),
    "label twice": (
        lambda d: _edit(d, "labels.csv", "object,soft,soft\nsponge,1,1\n"),
        "labels.csv",
        "label column(s) ['soft'] twice",
    ),
    "no object rows": (
        lambda d: _edit(d, "labels.csv", "object,soft,rough\n"),
        "labels.csv",
        "no object rows",
    ),
    "label not 0/1": (
        lambda d: _edit(
            d, "labels.csv", "object,soft,rough\nsponge,1,0\nbrick,yes,1\nfelt,1,1\ncork,0,0\n"
        ),
        "labels.csv:3",
        "brick soft='yes', expected 0 or 1",
    ),
    "row too short": (
        lambda d: _edit(d, "labels.csv", "object,soft,rough\nsponge,1\n"),
        "labels.csv:2",
        "2 cells, expected 3",
    ),
    "object twice": (
        lambda d: _edit(d, "labels.csv", "object,soft,rough\nsponge,1,0\nsponge,1,0\n"),
        "labels.csv:3",
        "object 'sponge' has a second row",
    ),
    "missing labels row": (
        lambda d: _edit(d, "labels.csv", "object,soft,rough\nsponge,1,0\nbrick,0,1\nfelt,1,1\n"),
        "labels.csv",
        "no row for object 'cork'",
    ),
    "labels row without trials": (
        lambda d: (
            [p.unlink() for p in (d / "trials" / "cork").iterdir()]
            and (d / "trials" / "cork").rmdir()
        ),
        "trials/cork",
        "missing; labels.csv lists object 'cork', expected its trial files there",
    ),
    "object_id twice": (
        lambda d: _edit(d, "labels.csv", "object,object_id,soft\nsponge,1,1\nbrick,1,0\n"),
        "labels.csv",
        "objects 'sponge' and 'brick' share object_id 1",
    ),
    "object_id too large": (
        lambda d: _edit(d, "labels.csv", "object,object_id,soft\nsponge,1000,1\n"),
        "labels.csv:2",
        "object_id='1000', expected a whole number 0..999",
    ),
    "object name reserved": (
        lambda d: _edit(d, "labels.csv", "object,soft\nvalidation_cup,1\n"),
        "labels.csv",
        "object 'validation_cup' cannot start a trial name",
    ),
    "object name with a slash-like character": (
        lambda d: _edit(d, "labels.csv", "object,soft\nmy cup,1\n"),
        "labels.csv:2",
        "object 'my cup', expected a name of letters, digits, _ and -",
    ),
    "no trials folder": (
        lambda d: (d / "trials").rename(d / "recordings"),
        "trials",
        "no such folder, expected trials/<object>/<trial>.npy",
    ),
    "a file where an object folder belongs": (
        lambda d: _edit(d, "trials/notes.txt", "x"),
        "trials/notes.txt",
        "not a folder, expected trials/<object>/ folders",
    ),
    "not an .npy trial file": (
        lambda d: _edit(d, "trials/felt/trial_03.csv", "1,2,3"),
        "trials/felt/trial_03.csv",
        "not a .npy file, expected only <trial>.npy files",
    ),
    "object folder without trials": (
        lambda d: [p.unlink() for p in (d / "trials" / "felt").iterdir()],
        "trials/felt",
        "no trial files",
    ),
}


@pytest.mark.parametrize("case", sorted(OPEN_ERRORS))
def test_bad_layout_is_refused_at_open_naming_the_file(folder: Path, case: str) -> None:
    change, file, message = OPEN_ERRORS[case]
    change(folder)
    with pytest.raises(DataError) as err:
        FolderDataSet(folder)
    text = str(err.value)
    assert "\n" not in text
    assert text.startswith(f"{folder / file}: "), text
    assert message in text


def test_a_missing_folder_is_refused(tmp_path: Path) -> None:
    with pytest.raises(DataError, match="no such folder .*dataset.yaml, labels.csv, trials/"):
        FolderDataSet(tmp_path / "nope")


# Problems found when a trial is read: (array saved in cork's first trial, message).
SIGNAL_ERRORS = {
    "wrong channel count": (np.zeros((4, 20)), "shape (4, 20), expected a (3, time) array"),
    "time first": (np.zeros((20, 3)), "shape (20, 3), expected a (3, time) array"),
    "one dimension": (np.zeros(20), "shape (20,), expected a (3, time) array"),
    "one sample": (np.zeros((3, 1)), "1 sample(s), expected at least 2"),
    "NaN": (np.where(np.eye(3, 20) > 0, np.nan, 0.0), "3 NaN and 0 infinite value(s)"),
    "infinite": (np.full((3, 5), np.inf), "0 NaN and 15 infinite value(s)"),
    "text": (np.array([["a", "b"]] * 3), "dtype <U1, expected a (3, time) array of numbers"),
    "complex": (np.ones((3, 4), dtype=complex), "dtype complex128"),
}


@pytest.mark.parametrize("case", sorted(SIGNAL_ERRORS))
def test_bad_trial_array_is_refused_when_read(folder: Path, case: str) -> None:
    arr, message = SIGNAL_ERRORS[case]
    file = folder / "trials" / "cork" / "trial_01.npy"
    np.save(file, arr)
    ds = FolderDataSet(folder)  # opening does not read it
    with pytest.raises(DataError) as err:
        ds.signals("cork_002_01")
    assert str(err.value).startswith(f"{file}: ") and "\n" not in str(err.value)
    assert message in str(err.value)
    assert ds.signals("cork_002_02").shape == (3, 21)  # the object's other trial still reads


@pytest.mark.parametrize(
    "content,message",
    [
        (b"\x93NUMPY garbage", "cannot read as .npy"),
        (b"", "cannot read as .npy"),
        ("pickle", "cannot read as .npy (Object arrays cannot be loaded when allow_pickle=False)"),
        ("npz", "an .npz archive"),
    ],
)
def test_unreadable_npy_is_refused_and_never_unpickled(folder: Path, content, message) -> None:
    file = folder / "trials" / "cork" / "trial_01.npy"
    if content == "pickle":
        np.save(file, np.array([{"a": 1}, None], dtype=object), allow_pickle=True)
    elif content == "npz":
        with open(file, "wb") as f:
            np.savez(f, x=np.zeros((3, 5)))
    else:
        file.write_bytes(content)
    with pytest.raises(DataError) as err:
        FolderDataSet(folder).signals("cork_002_01")
    assert str(err.value).startswith(f"{file}: ") and "\n" not in str(err.value)
    assert message in str(err.value)


def test_photographs_by_object_folder(folder: Path) -> None:
    (folder / "photos" / "felt").mkdir(parents=True)
    for name in ("b.jpg", "a.JPEG", "notes.txt"):
        (folder / "photos" / "felt" / name).write_bytes(b"")
    (folder / "photos" / "cork").mkdir()  # a folder without photographs: no entry
    ds = FolderDataSet(folder)
    assert ds.photographs() == {3: [folder / "photos/felt/a.JPEG", folder / "photos/felt/b.jpg"]}
    (folder / "photos" / "glass").mkdir()
    with pytest.raises(DataError, match="photos/glass: expected photos/<object>/ folders of"):
        ds.photographs()


def _touch_later(path: Path) -> None:
    st = path.stat()
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000_000))


@pytest.mark.parametrize(
    "change",
    ["rewrite a trial", "touch labels", "add a photograph", "add a trial", "edit the sensor"],
)
def test_identity_changes_when_the_files_do(folder: Path, change: str) -> None:
    opened = FolderDataSet(folder)
    before = opened.digest()
    assert FolderDataSet(folder).identity() == opened.identity()  # stable when nothing changed
    assert opened.identity() == f"ds-{before}" and len(before) == 12
    if change == "rewrite a trial":
        np.save(folder / "trials/felt/trial_01.npy", np.zeros((3, 20)))  # same size
        _touch_later(folder / "trials/felt/trial_01.npy")
    elif change == "touch labels":
        _touch_later(folder / "labels.csv")
    elif change == "add a photograph":
        (folder / "photos" / "felt").mkdir(parents=True)
        (folder / "photos/felt/a.jpg").write_bytes(b"")
    elif change == "add a trial":
        np.save(folder / "trials/felt/trial_03.npy", np.zeros((3, 20)))
    else:
        (folder / "dataset.yaml").write_text("sensor: glove2\nchannels: [ax, ay, az]\nrate_hz: 50")
    assert FolderDataSet(folder).digest() != before


def test_random_and_folds_splits_work_and_published_is_refused(tmp_path: Path) -> None:
    """12 objects, each class of 'soft' 6 strong: the object-level rules need nothing else."""
    labels = {f"obj{i:02d}": {"soft": i % 2, "rough": int(i < 4)} for i in range(12)}
    trials = {o: [np.zeros((3, 5))] * 2 for o in labels}
    ds = FolderDataSet(write_folder(tmp_path / "d", SENSOR, labels, trials))
    random = make_split(ds, "soft", "random", seed=0)
    check_split(random)
    assert len(random.train) + len(random.test) == 24 and random.objects("test")
    assert not random.objects("train") & random.objects("test")
    tested = []
    for fold in range(3):
        split = make_split(ds, "soft", "folds", seed=0, folds=3, fold=fold)
        tested += sorted(split.objects("test"))
    assert sorted(tested) == list(range(1, 13))  # every object tested exactly once
    with pytest.raises(DataError, match="split=published is PHAC-2's published split and this"):
        make_split(ds, "soft", "published")
    with pytest.raises(DataError, match="unknown adjective 'hard'.*labels: soft, rough"):
        make_split(ds, "hard", "random")


@pytest.mark.parametrize(
    "text",
    [
        "\ufeffobject,soft,rough\r\nsponge,1,0\r\nbrick,0,1\r\nfelt,1,1\r\ncork,0,0\r\n",  # BOM
        "object;soft;rough\nsponge;TRUE;FALSE\nbrick;FALSE;TRUE\nfelt;TRUE;TRUE\ncork;FALSE;FALSE\n",
        "object\tsoft\trough\nsponge\t1.0\t0.0\nbrick\t0.0\t1.0\nfelt\t1.0\t1.0\ncork\t0.0\t0.0\n",
        ",object,soft,rough\n0,sponge,True,False\n1,brick,False,True\n2,felt,True,True\n"
        "3,cork,False,False\n",  # pandas' to_csv: index column, booleans
    ],
    ids=["bom", "semicolon-true-false", "tab-floats", "pandas-index"],
)
def test_labels_as_spreadsheets_and_pandas_write_them(folder: Path, text: str) -> None:
    (folder / "labels.csv").write_bytes(text.encode())
    ds = FolderDataSet(folder)
    assert ds.label_names == ("soft", "rough")
    assert {ds.object_name(i): row for i, row in ds.labels().items()} == LABELS


def test_labels_written_by_pandas_read_back(folder: Path) -> None:
    import pandas as pd

    frame = pd.DataFrame(LABELS).T.astype(float).rename_axis("object")
    frame.to_csv(folder / "labels.csv", sep=";")
    ds = FolderDataSet(folder)
    assert {ds.object_name(i): row for i, row in ds.labels().items()} == LABELS


@pytest.mark.parametrize(
    "declared,expected",
    [
        (None, None),
        ("folds", {"name": "folds"}),
        ({"name": "folds", "folds": 3}, {"name": "folds", "folds": 3}),
        ({"name": "random"}, {"name": "random"}),
    ],
)
def test_dataset_yaml_may_declare_its_split(folder: Path, declared, expected) -> None:
    import yaml

    node = yaml.safe_load((folder / "dataset.yaml").read_text())
    if declared is not None:
        node["split"] = declared
    (folder / "dataset.yaml").write_text(yaml.safe_dump(node))
    assert FolderDataSet(folder).declared_split == expected


@pytest.mark.parametrize(
    "declared",
    ["published", {"name": "folds", "folds": 1}, {"name": "random", "folds": 3}, {"rule": 1}],
)
def test_a_bad_declared_split_is_one_line_naming_dataset_yaml(folder: Path, declared) -> None:
    import yaml

    node = yaml.safe_load((folder / "dataset.yaml").read_text())
    (folder / "dataset.yaml").write_text(yaml.safe_dump({**node, "split": declared}))
    with pytest.raises(DataError) as err:
        FolderDataSet(folder)
    message = str(err.value)
    assert message.startswith(f"{folder / 'dataset.yaml'}: split: ")
    assert "expected split: {name: folds, folds: K}" in message and "\n" not in message


def test_write_folder_declares_the_split_and_ships_frozen_folds(tmp_path: Path) -> None:
    from tactile_exp.data.frozen import FrozenFolds, deal

    frozen = FrozenFolds(2, 1, deal(LABELS, 2, 1))
    trials = {o: _arrays(o) for o in OBJECTS}
    path = write_folder(tmp_path / "ds", SENSOR, LABELS, trials, {"name": "folds"}, frozen)
    ds = FolderDataSet(path)
    assert ds.declared_split == {"name": "folds"}
    assert ds.frozen_folds is not None and ds.frozen_folds.labels == frozen.labels
    before = ds.identity()
    (path / "folds.yaml").write_text((path / "folds.yaml").read_text() + "# changed\n")
    assert FolderDataSet(path).identity() != before  # the folds file is one of its data files

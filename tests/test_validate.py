"""Whole-file validation, the summary, the data CLI, and the generator -> reader round trip."""

from __future__ import annotations

import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
from phac2_fixture import EP_ROWS, N_ROWS, OBJECTS, write_file

from tactile_exp.data.__main__ import main
from tactile_exp.data.layout import ADJECTIVES
from tactile_exp.data.phac2 import PHAC2, load_photograph
from tactile_exp.data.splits import make_split
from tactile_exp.data.validate import summary, validate

ALL = tuple(OBJECTS)


@pytest.fixture(scope="module")
def clean_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """60 objects x 2 trials with one photograph each: every published split exists."""
    folder = tmp_path_factory.mktemp("clean")
    photos = {i: [f"{OBJECTS[i].group_stem}_01.jpg"] for i in ALL}
    write_file(folder / "f.h5", ALL, 2, adjective_links=False, photos=photos)
    return folder


@pytest.fixture
def clean(clean_dir: Path, tmp_path: Path) -> Path:
    """A private copy of the clean file and its photographs, free to damage."""
    shutil.copytree(clean_dir, tmp_path, dirs_exist_ok=True)
    return tmp_path / "f.h5"


def test_clean_file_has_no_problems(clean: Path) -> None:
    assert validate(clean) == []


def test_every_problem_is_listed(clean: Path) -> None:
    with h5py.File(clean, "a") as f:
        del f["car_sponge_101_02/biotacs/finger_1"]
        del f["brick_508_01/biotacs/finger_0/pdc"]
        f["brick_508_01/biotacs/finger_0/pdc"] = np.full(N_ROWS, np.nan)
    (clean.parent / "photographs" / "brick_508_01.jpg").unlink()
    problems = validate(clean)
    assert len(problems) == 3, problems
    assert f"{clean}: /brick_508_01/biotacs/finger_0/pdc: {N_ROWS} NaN" in problems[0]
    assert f"{clean}: /car_sponge_101_02/biotacs/finger_1: missing" in problems[1]
    assert "object 508 (brick_508) has no photograph" in problems[2]
    assert str(clean.parent / "photographs") in problems[2]
    assert validate(clean, photographs=False) == problems[:2]


def test_missing_photo_folder_and_unreadable_file(clean: Path) -> None:
    folder = clean.parent / "photographs"
    shutil.rmtree(folder)
    problems = validate(clean)
    assert problems == [f"{folder}: photograph folder missing (expected JPEGs of the objects)"]
    bad = clean.parent / "bad.h5"
    bad.write_bytes(b"\0" * 4096)
    assert validate(bad) == [f"{bad}: not an HDF5 file (expected the PHAC-2 .h5)"]


def test_unsplittable_adjective_is_a_problem(tmp_path: Path) -> None:
    names = [f"{OBJECTS[o].group_stem}_{t:02d}" for o in (101, 410, 508, 211) for t in (1, 2)]
    groups = {"soft": (names[:6], names[6:])}  # no positive in test
    path = write_file(tmp_path / "f.h5", (101, 410, 508, 211), split_groups=groups)
    problems = validate(path, photographs=False)
    soft = f"{path} (published split): split of 'soft': test has no positive"
    assert sum(soft in p for p in problems) == 1
    assert any("split of 'nice': train has no positive" in p for p in problems)  # no nice object
    assert not any("'absorbent'" in p for p in problems)  # 2 + 2 objects: the random rule works


def test_summary(clean: Path) -> None:
    with h5py.File(clean, "a") as f:
        del f["brick_508_02/biotacs/finger_1"]
    for view in ("brick_508_01.jpg", "acrylic_211_01.jpg"):
        (clean.parent / "photographs" / view).unlink()
    s = summary(PHAC2(clean))
    assert (s["objects"], s["trials"], s["bad_trials"]) == (60, 120, 1)
    for ep, (start, stop) in EP_ROWS.items():
        assert s["ep_rows"][ep] == {
            "min": stop - start,
            "median": stop - start,
            "max": stop - start,
        }
    assert s["positive_objects"] == {
        a: sum(o.labels[a] for o in OBJECTS.values()) for a in ADJECTIVES
    }
    assert s["positive_objects"]["hard"] == 23
    assert s["splits"]["hard"] == {"train": 106, "test": 14}  # 7 published test objects
    assert s["splits"]["rough"] == {"train": 108, "test": 12}
    assert (s["photographs"], s["objects_without_photographs"]) == (58, [211, 508])


def test_cli_validate_and_inspect(clean: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["validate", str(clean)]) == 0
    out, err = capsys.readouterr()
    assert (
        out.splitlines()[0] == f"OK: {clean}" and "  checked: a photograph of every object" in out
    )
    assert f"validate {clean}: 0/120 trials" in err and f"validate {clean}: 60/120 trials" in err
    with h5py.File(clean, "a") as f:
        del f["car_sponge_101_01/state"]
    assert main(["validate", str(clean)]) == 1
    assert "/car_sponge_101_01/state/controller_detail_state: missing" in capsys.readouterr().out
    assert main(["inspect", str(clean)]) == 0
    out = capsys.readouterr().out
    assert "60 objects, 120 trials (1 bad)" in out and "EP hold       rows 10..10" in out
    assert main(["inspect", str(clean.parent / "none.h5")]) == 1
    assert "file not found" in capsys.readouterr().err


def test_cli_rejects_bad_image_size() -> None:
    with pytest.raises(SystemExit):
        main(["generate", "--image-size", "96by64"])


# ---------------------------------------------------------------- generator -> reader
@pytest.fixture(scope="module")
def generated(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("synthetic") / "tiny.h5"
    args = ["generate", "--out", str(out), "--trials", "2", "--duration-scale", "0.1"]
    assert main([*args, "--views", "1", "--image-size", "96x64"]) == 0
    return out


@pytest.mark.filterwarnings("ignore:.*(using the table|falling back):UserWarning")
def test_generated_file_round_trip(generated: Path) -> None:
    assert validate(generated) == []
    ds = PHAC2(generated)
    assert len(ds.trials) == 120 and len(ds.object_ids()) == 60
    assert ds.labels() == {i: o.labels for i, o in OBJECTS.items()}
    trial = ds.read_trial("cologne_container__602_02")
    assert trial.fingers[1].pac.shape == (trial.n_rows * 22,)
    segs = trial.ep_segments()
    assert segs["squeeze"].stop <= segs["hold"].start < segs["slow_slide"].start
    assert segs["slow_slide"].stop <= segs["fast_slide"].start
    for adj in ADJECTIVES:
        split = make_split(ds, adj)
        assert split.objects("train") | split.objects("test") == set(OBJECTS)
    photos = ds.photographs()
    assert set(photos) == set(OBJECTS) and all(len(v) == 1 for v in photos.values())
    assert load_photograph(photos[101][0]).shape == (64, 96, 3)

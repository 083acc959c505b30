"""The PHAC-2 reader against tiny files written from PHAC2_FORMAT.md (tests/phac2_fixture.py)."""

from __future__ import annotations

import os
import re
from pathlib import Path

import h5py
import numpy as np
import pytest
from phac2_fixture import EP_ROWS, N_ROWS, OBJECTS, STATES, pac_value, write_file

from tactile_exp.data.layout import TrialName
from tactile_exp.data.phac2 import PHAC2, DataError, default_cache_dir, load_photograph

FIRST = "car_sponge_101_01"


@pytest.fixture
def h5(tmp_path: Path) -> Path:
    return write_file(tmp_path / "phac2.h5")


def edit(path: Path, key: str, value: np.ndarray | None) -> None:
    """Replace (or with None delete) one node of a written file."""
    with h5py.File(path, "a") as f:
        del f[key]
        if value is not None:
            f[key] = value


def states_with(change: dict[bytes, int]) -> np.ndarray:
    """The fixture's state column with the row counts of some states changed."""
    rows = [(s, change.get(s, r)) for s, _, r in STATES]
    pad = N_ROWS - sum(r for _, r in rows)
    rows.append((b"OPEN_GRIPPER_FAST_MAX", pad))
    return np.array([s for s, r in rows for _ in range(r)], dtype="S30")


# ---------------------------------------------------------------- discovery
def test_trials_discovered_once_despite_hard_links(tmp_path: Path) -> None:
    names = ["car_sponge_101_01", "car_sponge_101_02"]
    path = write_file(
        tmp_path / "f.h5", (101, 602), split_groups={"soft": (names, [])}, adjective_links=True
    )
    with h5py.File(path, "a") as f:
        f.create_group("validation_set_101_01")  # matches the pattern but is not a trial
    ds = PHAC2(path)
    assert [t.name for t in ds.trials] == [
        "car_sponge_101_01",
        "car_sponge_101_02",
        "cologne_container__602_01",
        "cologne_container__602_02",
    ]
    assert ds.object_ids() == (101, 602)
    assert {"adjectives", "adjectives_neg", "train_test_sets"} <= ds.groups


def test_double_underscore_stem_parses(tmp_path: Path) -> None:
    ds = PHAC2(write_file(tmp_path / "f.h5", (602,)))
    assert ds.trials[0] == TrialName("cologne_container__602_01", "cologne_container__602", 602, 1)


# ---------------------------------------------------------------- one trial
def test_read_trial_shapes_and_segments(h5: Path) -> None:
    trial = PHAC2(h5).read_trial(FIRST)
    assert trial.n_rows == N_ROWS
    for finger in trial.fingers:
        assert finger.electrodes.shape == (N_ROWS, 19)
        assert finger.pac.shape == (N_ROWS * 22,)
        np.testing.assert_array_equal(finger.pac, pac_value(N_ROWS).reshape(-1))
        assert finger.pdc.shape == finger.tac.shape == finger.tdc.shape == (N_ROWS,)
        assert finger.pdc.dtype == np.int64
    assert trial.detail_state.dtype == np.dtype("S30")
    assert {ep: (s.start, s.stop) for ep, s in trial.ep_segments().items()} == EP_ROWS
    assert trial.adjectives == OBJECTS[101].positives
    assert trial.controller_state is not None and trial.controller_state[EP_ROWS["hold"][0]] == 1
    assert set(trial.gripper) == {"joint_position", "joint_velocity", "joint_effort"}
    assert trial.accelerometer.shape == trial.translation.shape == (N_ROWS, 3)
    assert trial.rotation.shape == (N_ROWS, 4)


def test_optional_channels_skipped_or_absent(h5: Path) -> None:
    ds = PHAC2(h5)
    bare = ds.read_trial(FIRST, optional=False)
    assert bare.accelerometer is None and bare.gripper == {} and bare.controller_state is None
    with h5py.File(h5, "a") as f:
        del f[f"{FIRST}/accelerometer"], f[f"{FIRST}/transforms"]
    trial = ds.read_trial(FIRST)
    assert trial.accelerometer is None and trial.rotation is None and trial.gripper


def test_iter_trials_yields_each_named_trial(h5: Path) -> None:
    ds = PHAC2(h5)
    got = [t.name.name for t in ds.iter_trials(["brick_508_02", FIRST])]
    assert got == ["brick_508_02", FIRST]
    assert len(list(ds.iter_trials())) == 8


def test_labels_are_object_level_from_the_file(h5: Path) -> None:
    labels = PHAC2(h5).labels()
    assert set(labels) == {101, 211, 508, 602}
    for oid, lab in labels.items():
        assert lab == OBJECTS[oid].labels
    assert labels[602]["slippery"] == 1 and labels[508]["rough"] == 1 and labels[101]["hard"] == 0


def test_labels_from_links_when_trial_arrays_absent(tmp_path: Path) -> None:
    path = write_file(tmp_path / "f.h5", (101, 508), signals=False)
    with h5py.File(path, "a") as f:
        for name in list(f):
            if name[0].isalpha() and name.endswith(("_01", "_02")):
                del f[f"{name}/adjectives"]
    assert PHAC2(path).labels()[508] == OBJECTS[508].labels


def test_photographs_matched_by_stem_or_id(tmp_path: Path) -> None:
    photos = {101: ["car_sponge_101_01.jpg", "car_sponge_101_02.jpg"], 508: ["IMG_508-a.JPG"]}
    path = write_file(tmp_path / "f.h5", photos=photos)
    (tmp_path / "photographs" / "notes.txt").write_text("not a photo")
    (tmp_path / "photographs" / "999_x.jpg").write_bytes(b"")  # no such object
    found = PHAC2(path).photographs()
    assert {k: [p.name for p in v] for k, v in found.items()} == photos
    image = load_photograph(found[508][0])
    assert image.shape == (12, 16, 3) and image.dtype == np.uint8
    assert image[0, 0, 0] > 150 and image[0, 0, 2] < 50  # RGB, not OpenCV's BGR


def test_photo_dir_default_and_override(tmp_path: Path) -> None:
    path = write_file(tmp_path / "f.h5")
    assert PHAC2(path).photo_dir == tmp_path / "photographs"
    assert PHAC2(path).photographs() == {}
    assert PHAC2(path, tmp_path / "elsewhere").photo_dir == tmp_path / "elsewhere"


def test_identity_changes_with_the_file(h5: Path) -> None:
    first = PHAC2(h5).identity()
    assert first == PHAC2(h5).identity() and first.startswith("phac2-")
    with h5py.File(h5, "a") as f:
        f.attrs["touched"] = 1
    os.utime(h5, ns=(1, 1))
    assert PHAC2(h5).identity() != first


def test_default_cache_dir_honours_env(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("TACTILE_EXP_CACHE", str(tmp_path))
    assert default_cache_dir() == tmp_path
    monkeypatch.delenv("TACTILE_EXP_CACHE")
    assert default_cache_dir() == Path.home() / ".cache" / "tactile_exp"


# ---------------------------------------------------------------- bad input
def raises_naming(path: Path, key: str, what: str):
    return pytest.raises(
        DataError, match=re.escape(str(path)) + ".*" + re.escape(key) + ".*" + what
    )


def test_missing_file(tmp_path: Path) -> None:
    with raises_naming(tmp_path / "nope.h5", ":", "not found"):
        PHAC2(tmp_path / "nope.h5")


def test_not_hdf5(tmp_path: Path) -> None:
    path = tmp_path / "fake.h5"
    path.write_text("just text\n" * 100)
    with raises_naming(path, ":", "not an HDF5 file"):
        PHAC2(path)


def test_truncated_file(h5: Path) -> None:
    data = h5.read_bytes()
    h5.write_bytes(data[: len(data) // 2])
    with raises_naming(h5, ":", "truncated or corrupt"):
        PHAC2(h5)


def test_no_trial_groups(tmp_path: Path) -> None:
    path = tmp_path / "empty.h5"
    with h5py.File(path, "w") as f:
        f.create_group("adjectives")
    with raises_naming(path, ":", "no trial groups"):
        PHAC2(path)


def test_unknown_trial_name(h5: Path) -> None:
    with raises_naming(h5, "no trial group", "/car_sponge_101_07"):
        PHAC2(h5).read_trial("car_sponge_101_07")


@pytest.mark.parametrize(
    ("key", "value", "what"),
    [
        ("biotacs/finger_1", None, "missing, expected a group with electrodes"),
        ("biotacs/finger_0/pdc", None, "missing"),
        ("biotacs/finger_0/electrodes", np.full((N_ROWS, 18), 3000), rf"\({N_ROWS}, 19\)"),
        (
            "biotacs/finger_1/tac",
            np.full(N_ROWS - 1, 2000),
            rf"shape \({N_ROWS - 1},\), expected \({N_ROWS},\)",
        ),
        ("biotacs/finger_0/pdc", np.r_[np.nan, np.full(N_ROWS - 1, 800.0)], "1 NaN"),
        ("biotacs/finger_0/tdc", np.full(N_ROWS, 800.5), "expected an integer dtype"),
        ("biotacs/finger_1/tac", np.r_[5000, np.full(N_ROWS - 1, 2000)], "expected 12-bit"),
        ("biotacs/finger_0/pac", -np.ones((N_ROWS, 22), np.int64), "values -1..-1"),
        ("state/controller_detail_state", states_with({b"SLIDE_5CM": 0}), "slow_slide.*absent"),
        ("state/controller_detail_state", states_with({b"MOVE_DOWN_5CM": 1}), "has 1 row"),
        ("state/controller_detail_state", np.array([], "S30"), "N > 0"),
        ("accelerometer", np.full((N_ROWS, 3), np.nan), "NaN"),
        ("transforms/rotation", np.zeros((N_ROWS, 3)), rf"expected \({N_ROWS}, 4\)"),
        ("adjectives", np.array([b"soft", b"gritty"]), "unknown adjective"),
    ],
)
def test_bad_trial_content(h5: Path, key: str, value: np.ndarray | None, what: str) -> None:
    edit(h5, f"{FIRST}/{key}", value)
    ds = PHAC2(h5)
    with raises_naming(h5, f"/{FIRST}/", what):
        ds.read_trial(FIRST)
    good, problems = ds.check_trials()
    assert FIRST not in good and len(good) == 7
    assert len(problems) == 1 and FIRST in problems[0]


def test_split_ep_block(h5: Path) -> None:
    states = states_with({})
    states[EP_ROWS["hold"][0] + 3] = b"MOVE_UP_START_HEIGHT"
    edit(h5, f"{FIRST}/state/controller_detail_state", states)
    with raises_naming(h5, f"/{FIRST}/state/controller_detail_state", "several blocks"):
        PHAC2(h5).read_trial(FIRST)


def test_optional_bad_channel_ignored_when_not_requested(h5: Path) -> None:
    edit(h5, f"{FIRST}/accelerometer", np.full((N_ROWS, 3), np.nan))
    assert PHAC2(h5).read_trial(FIRST, optional=False).n_rows == N_ROWS


def test_unknown_adjective_in_labels(h5: Path) -> None:
    edit(h5, "brick_508_02/adjectives", np.array([b"hard", b"gritty"]))
    with raises_naming(h5, "/brick_508_02/adjectives", r"unknown adjective\(s\) \['gritty'\]"):
        PHAC2(h5).labels()


def test_unknown_adjective_link_group(h5: Path) -> None:
    with h5py.File(h5, "a") as f:
        f.create_group("adjectives/gritty")  # empty: tolerated (PHAC2_FORMAT §1.2)
    assert PHAC2(h5).labels()[101] == OBJECTS[101].labels
    with h5py.File(h5, "a") as f:
        f[f"adjectives/gritty/{FIRST}"] = f[FIRST]
    with raises_naming(h5, "/adjectives", "gritty"):
        PHAC2(h5).labels()


def test_links_disagreeing_with_trial_array(h5: Path) -> None:
    with h5py.File(h5, "a") as f:
        f[f"adjectives/hard/{FIRST}"] = f[FIRST]
    with raises_naming(h5, f"/{FIRST}/adjectives", "hard=0 but /adjectives/hard links"):
        PHAC2(h5).labels()


def test_trials_of_one_object_disagreeing(tmp_path: Path) -> None:
    h5 = write_file(tmp_path / "f.h5", adjective_links=False)
    edit(h5, "car_sponge_101_02/adjectives", np.array([b"hard"]))
    with raises_naming(h5, "/car_sponge_101_01 and /car_sponge_101_02", "disagree"):
        PHAC2(h5).labels()


def test_unreadable_photograph(tmp_path: Path) -> None:
    bad = tmp_path / "broken.jpg"
    bad.write_bytes(b"\xff\xd8 not really")
    with pytest.raises(DataError, match="broken.jpg.*cannot read"):
        load_photograph(bad)

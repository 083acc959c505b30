"""Tiny PHAC-2 files written with h5py straight from PHAC2_FORMAT.md §1, for the reader's tests.

Independent of `tactile_exp.data.synthetic` on purpose: the reader is tested against the
documented layout, not against another module's idea of it.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import h5py
import numpy as np

from tactile_exp.data.layout import ADJECTIVES, objects, published_test_split

OBJECTS = {o.object_id: o for o in objects()}
# (detail state, coarse code, rows); the EP rows are what tests check segments against.
STATES = (
    (b"DISABLED", 0, 3),
    (b"MOVE_ARM_START_POSITION", 7, 4),
    (b"FIND_CONTACT_CLOSE_GRIPPER_SLO", 3, 2),
    (b"SQUEEZE_SET_PRESSURE_SLOW", 3, 7),
    (b"OPEN_GRIPPER_BY_2CM_FAST", 3, 2),
    (b"HOLD_FOR_10_SECONDS", 1, 10),
    (b"MOVE_UP_START_HEIGHT", 1, 2),
    (b"SLIDE_5CM", 2, 6),
    (b"SLIDE_DONE_WAIT_5", 2, 2),
    (b"MOVE_DOWN_5CM", 6, 4),
    (b"OPEN_GRIPPER_FAST_MAX", 6, 3),
)
EP_ROWS = {"squeeze": (9, 16), "hold": (18, 28), "slow_slide": (30, 36), "fast_slide": (38, 42)}
N_ROWS = sum(r for _, _, r in STATES)


def pac_value(n_rows: int) -> np.ndarray:
    """PAC as stored, (N, 22): the flattened stream is 2000 + (k mod 97), so order is checkable."""
    return (2000 + np.arange(n_rows * 22) % 97).reshape(n_rows, 22).astype(np.int64)


def write_trial(f: h5py.File, name: str, positives: tuple[str, ...], seed: int) -> None:
    rng = np.random.default_rng(seed)
    g = f.create_group(name)
    for finger in ("finger_0", "finger_1"):
        fg = g.create_group(f"biotacs/{finger}")
        fg["electrodes"] = rng.integers(3000, 3700, (N_ROWS, 19), dtype=np.int64)
        fg["pac"] = pac_value(N_ROWS)
        for ch in ("pdc", "tac", "tdc"):
            fg[ch] = rng.integers(1800, 2100, N_ROWS, dtype=np.int64)
    g["state/controller_detail_state"] = np.array(
        [s for s, _, r in STATES for _ in range(r)], dtype="S30"
    )
    g["state/controller_state"] = np.array([c for _, c, r in STATES for _ in range(r)], np.int64)
    g["accelerometer"] = rng.normal(size=(N_ROWS, 3))
    for key in ("joint_position", "joint_velocity", "joint_effort"):
        g[f"gripper_aperture/{key}"] = rng.normal(size=N_ROWS)
    g["transforms/translation"] = rng.normal(size=(N_ROWS, 3))
    g["transforms/rotation"] = rng.normal(size=(N_ROWS, 4))
    g["timestamps"] = np.arange(7, dtype=np.int64)  # not row-aligned, as in the real file
    g["adjectives"] = np.array([a.encode() for a in positives], dtype="S12")


def trial_names(object_ids: tuple[int, ...], trials: int) -> list[str]:
    return [f"{OBJECTS[o].group_stem}_{t:02d}" for o in object_ids for t in range(1, trials + 1)]


def write_file(
    path: Path,
    object_ids: tuple[int, ...] = (101, 211, 508, 602),
    trials: int = 2,
    signals: bool = True,
    adjective_links: bool = True,
    split_groups: dict[str, tuple[list[str], list[str]]] | None = None,
    photos: dict[int, list[str]] | None = None,
) -> Path:
    """Write a PHAC-2 file; `signals=False` writes only each trial's `adjectives` (for splits).

    `split_groups`: adjective -> (train names, test names), written as hard links into the
    positive/negative split groups by each trial's label. `photos`: object id -> file names.
    """
    with h5py.File(path, "w") as f:
        for i, name in enumerate(trial_names(object_ids, trials)):
            positives = OBJECTS[int(name[-6:-3])].positives
            if signals:
                write_trial(f, name, positives, seed=i)
            else:
                f.create_group(name)["adjectives"] = np.array(
                    [a.encode() for a in positives], dtype="S12"
                )
            if adjective_links:
                for adj in ADJECTIVES:
                    group = "adjectives" if adj in positives else "adjectives_neg"
                    f.require_group(f"{group}/{adj}")[name] = f[name]
        for adj, (train, test) in (split_groups or {}).items():
            for part, names in (("train", train), ("test", test)):
                f.require_group(f"train_test_sets/{adj}/{part}")
                f.require_group(f"train_test_negative_sets/{adj}/{part}")
                for n in names:
                    pos = adj in OBJECTS[int(n[-6:-3])].positives
                    group = "train_test_sets" if pos else "train_test_negative_sets"
                    f[f"{group}/{adj}/{part}/{n}"] = f[n]
    if photos:
        folder = path.parent / "photographs"
        folder.mkdir(exist_ok=True)
        image = np.zeros((12, 16, 3), np.uint8)
        image[:, :, 2] = 200  # red in BGR: the reader must hand back RGB
        for names in photos.values():
            for n in names:
                cv2.imwrite(str(folder / n), image)
    return path


def published_groups(object_ids: tuple[int, ...], trials: int) -> dict:
    """The published split table, as the train/test names the real file's hard links hold."""
    names = trial_names(object_ids, trials)
    out = {}
    for adj in ADJECTIVES:
        test = [
            n
            for r in published_test_split()
            if r.adjective == adj
            for n in names
            if int(n[-6:-3]) == r.object_id and (r.trials is None or int(n[-2:]) in r.trials)
        ]
        out[adj] = ([n for n in names if n not in test], test)
    return out

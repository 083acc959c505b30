"""How one upstream file becomes trials: ``reader(file, channels) -> [(channels, time) array]``,
one entry per trial the file holds, registered in `READERS` under the name a recipe's ``reader:``
gives. A file that is not what the reader expects is a one-line `DataError` naming it (and the
line or group)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np

from tactile_exp.data.csv_import import read_trial
from tactile_exp.data.deflate import read_array
from tactile_exp.data.layout import DataError
from tactile_exp.registry import Registry

Reader = Callable[[Path, tuple[str, ...]], list[np.ndarray]]
READERS: Registry[list[np.ndarray]] = Registry("public data set reader")

ICUB_SLICE = (9, 5, 12, 12, 12, 12, 12)  # values per line of one time slice (README.txt)
ICUB_KEPT = (0, 2, 3, 4, 5, 6)  # the encoders and the five fingers' taxels; line 2 is derived
BOLT_PARTS = ("tdc", "tac", "pdc", "pac", "electrodes")  # per finger, in this channel order
BOLT_FINGERS = ("finger_0", "finger_1")


def _check(file: Path, arr: np.ndarray, channels: tuple[str, ...], where: str = "") -> np.ndarray:
    if arr.shape[0] != len(channels):
        raise DataError(
            f"{file}{where}: {arr.shape[0]} channels, expected the recipe's {len(channels)}"
        )
    if arr.shape[1] < 2 or not np.isfinite(arr).all():
        raise DataError(f"{file}{where}: {arr.shape[1]} samples or non-finite values")
    return arr


@READERS.register("icub_text")
def icub_text(file: Path, channels: tuple[str, ...]) -> list[np.ndarray]:
    """iCub grasp text file: a first line (-10000), then 7 lines per time slice: 9 joint
    encoders, the five fingers' max(255 - taxel) (derived, left out), then 12 taxels of each
    of thumb, index, middle, ring and little finger."""
    lines = [(n, line.split()) for n, line in enumerate(file.read_text().splitlines(), 1)]
    lines = [(n, cells) for n, cells in lines if cells]
    if not lines or lines[0][1] != ["-10000"]:
        raise DataError(f"{file}:1: expected the first line -10000 (README.txt)")
    body = lines[1:]
    if not body or len(body) % len(ICUB_SLICE):
        raise DataError(
            f"{file}: {len(body)} lines after the first, expected time slices of "
            f"{len(ICUB_SLICE)} lines"
        )
    rows = []
    for start in range(0, len(body), len(ICUB_SLICE)):
        row: list[float] = []
        for k, (n, cells) in enumerate(body[start : start + len(ICUB_SLICE)]):
            if len(cells) != ICUB_SLICE[k]:
                raise DataError(f"{file}:{n}: {len(cells)} values, expected {ICUB_SLICE[k]}")
            if k in ICUB_KEPT:
                try:
                    row += [float(c) for c in cells]
                except ValueError:
                    raise DataError(f"{file}:{n}: expected numbers") from None
        rows.append(row)
    return [_check(file, np.array(rows).T, channels)]


@READERS.register("biotac_csv")
def biotac_csv(file: Path, channels: tuple[str, ...]) -> list[np.ndarray]:
    """One BioTac CSV of a slide: a ``timestamp`` column, then the recipe's channels."""
    found, values, _ = read_trial(file, "timestamp")
    if tuple(found) != channels:
        raise DataError(f"{file}: columns {found[:4]}..., expected the recipe's {channels[:4]}...")
    return [_check(file, values, channels)]


@READERS.register("bolt_hdf5")
def bolt_hdf5(file: Path, channels: tuple[str, ...]) -> list[np.ndarray]:
    """A BOLT BioTac log (PyTables HDF5): one group per trial, sorted by name, each holding
    ``finger_0`` and ``finger_1`` with tdc, tac, pdc (one value per frame), pac (22 per frame)
    and electrodes (19 per frame)."""
    try:
        f = h5py.File(file, "r")
    except OSError as err:
        raise DataError(f"{file}: cannot read as HDF5 ({err})") from None
    out = []
    with f:
        for name in sorted(f):
            parts = []
            for finger in BOLT_FINGERS:
                for part in BOLT_PARTS:
                    node = f.get(f"{name}/{finger}/{part}")
                    if not isinstance(node, h5py.Dataset):
                        raise DataError(f"{file}: no dataset /{name}/{finger}/{part}")
                    arr = np.asarray(read_array(node), dtype=np.float64)
                    parts.append(arr.reshape(len(arr), -1))
            if len({len(p) for p in parts}) != 1:
                raise DataError(f"{file}: /{name}: the fingers' arrays differ in length")
            out.append(_check(file, np.hstack(parts).T, channels, f": /{name}"))
    if not out:
        raise DataError(f"{file}: no trial groups")
    return out

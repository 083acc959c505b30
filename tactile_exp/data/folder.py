"""Any sensor's recordings in a folder layout a lab can export to (``data=folder``).

::

    DIR/dataset.yaml                  sensor: NAME, channels: [CH, ...], rate_hz: R
                                      [split: {name: folds, folds: K} | {name: random}]
    DIR/labels.csv                    object[,object_id],LABEL,...   one row per object, 0/1 cells
                                      (as spreadsheets and pandas write it: a BOM, ; or tab
                                      separators, true/false or 1.0/0.0, pandas' index column)
    DIR/trials/<object>/<trial>.npy   one (channels, time) real array per trial (numpy.save)
    DIR/photos/<object>/*.jpg         optional photographs
    DIR/folds.yaml                    optional frozen folds (`tactile_exp.data.frozen`)

``split:`` is the split the data set declares, what the default ``split=declared`` runs (none:
object-grouped folds with the largest K its labels allow, `tactile_exp.data.splits.folds_for`).

Opening reads ``dataset.yaml`` and ``labels.csv`` and lists the folders; a trial's array is read
only when asked for (`FolderDataSet.signals`) and validated then, so a large data set opens in
the time it takes to list it. Every bad input raises a one-line `DataError` naming the file and
what was expected, as the HDF5 reader does.

Trial names are `TrialName` s ``<object>_<NNN>_<TT>``: ``NNN`` the object id (the optional
``object_id`` column, else 1, 2, ... in the sorted order of the object names: give ids when
objects will be added later, so that the old ones keep theirs), ``TT`` the trial's place (01, 02,
...) among its object's files sorted by file name.
"""

from __future__ import annotations

import csv
import hashlib
import re
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from tactile_exp.data.dataset import Sensor
from tactile_exp.data.frozen import FOLDS_FILE, FrozenFolds
from tactile_exp.data.layout import NON_TRIAL_PREFIXES, DataError, TrialName

SENSOR_FILE, LABELS_FILE, TRIALS_DIR, PHOTOS_DIR = "dataset.yaml", "labels.csv", "trials", "photos"
SENSOR_KEYS = ("sensor", "channels", "rate_hz")
SPLIT_KEY = "split"  # optional in dataset.yaml: the split the data set declares
DECLARABLE = ("folds", "random")  # the rules a folder data set may declare (published: PHAC-2's)
OBJECT_COLUMN, ID_COLUMN = "object", "object_id"
TRIAL_SUFFIX = ".npy"
PHOTO_SUFFIXES = (".jpg", ".jpeg")
NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]*")  # object and label names: safe in paths and MLflow
MAX_OBJECT_ID = 999  # three digits in a trial name
MAX_TRIALS = 99  # two digits in a trial name
MIN_SAMPLES = 2  # a trial needs a duration to be resampled


# A label cell as spreadsheets and pandas write it (1.0 for an int column that had a NaN).
FLAGS = {"0": 0, "1": 1, "0.0": 0, "1.0": 1, "false": 0, "true": 1}
SEPARATORS = (
    ",",
    ";",
    "\t",
)  # what spreadsheets export: comma, semicolon (decimal-comma locales), tab


def read_table(file: Path) -> list[tuple[int, list[str]]]:
    """A small CSV/TSV table as (line number, cells) of its non-blank lines: UTF-8 with or
    without a byte-order mark, the separator the header line uses most (``,``, ``;`` or tab).
    OSError, UnicodeDecodeError and csv.Error propagate."""
    with open(file, newline="", encoding="utf-8-sig") as f:
        text = f.read()
    first = next((line for line in text.splitlines() if line.strip()), "")
    separator = max(SEPARATORS, key=first.count)
    lines = enumerate(csv.reader(text.splitlines(), delimiter=separator), 1)
    return [(n, row) for n, row in lines if any(map(str.strip, row))]


def _one_line(err: Exception) -> str:
    return " ".join(str(err).split())


def _visible(folder: Path) -> list[Path]:
    """A folder's entries without hidden ones (``.DS_Store``, editors' files), sorted."""
    return sorted(p for p in folder.iterdir() if not p.name.startswith("."))


class FolderDataSet:
    """One data set in the folder layout; satisfies `tactile_exp.data.dataset.DataSet`."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path).expanduser()
        if not self.path.is_dir():
            raise DataError(
                f"{self.path}: no such folder (expected a data set in the folder layout: "
                f"{SENSOR_FILE}, {LABELS_FILE}, {TRIALS_DIR}/)"
            )
        self.sensor, self.declared_split = self._read_sensor(self.path / SENSOR_FILE)
        self.label_names, self._labels, self._names = self._read_labels(self.path / LABELS_FILE)
        self._files = self._list_trials(self.path / TRIALS_DIR)
        self.trials: tuple[TrialName, ...] = tuple(sorted(self._files))
        self._by_name = {t.name: t for t in self.trials}
        folds = self.path / FOLDS_FILE
        self.frozen_folds = FrozenFolds.read(folds) if folds.exists() else None

    def __repr__(self) -> str:
        return f"FolderDataSet({str(self.path)!r}, {len(self.trials)} trials)"

    # ---------------------------------------------------------------- opening
    @staticmethod
    def _read_sensor(file: Path) -> tuple[Sensor, dict[str, Any] | None]:
        """The sensor and the declared split (None: not declared) of ``dataset.yaml``."""
        expected = "expected sensor: NAME, channels: [CH, ...], rate_hz: SAMPLES_PER_SECOND"
        try:
            node = yaml.safe_load(file.read_text())
        except OSError as e:
            raise DataError(f"{file}: cannot read ({e.strerror}); {expected}") from e
        except yaml.YAMLError as e:
            raise DataError(f"{file}: not valid YAML ({_one_line(e)}); {expected}") from e
        if not isinstance(node, dict):
            raise DataError(f"{file}: holds {type(node).__name__}, {expected}")
        missing = [k for k in SENSOR_KEYS if k not in node]
        extra = sorted(str(k) for k in set(node) - {*SENSOR_KEYS, SPLIT_KEY})
        if missing or extra:
            what = f"missing {missing}" if missing else f"unknown key(s) {extra}"
            raise DataError(f"{file}: {what}; {expected}")
        name, channels, rate = node["sensor"], node["channels"], node["rate_hz"]
        if not isinstance(name, str) or not name.strip():
            raise DataError(f"{file}: sensor: {name!r}, expected the sensor's name")
        if (
            not isinstance(channels, list)
            or not channels
            or not all(isinstance(c, str) and c.strip() for c in channels)
        ):
            raise DataError(f"{file}: channels: {channels!r}, expected a list of channel names")
        if len(set(channels)) != len(channels):
            twice = sorted({c for c in channels if channels.count(c) > 1})
            raise DataError(f"{file}: channels: {twice} listed twice, expected unique names")
        if isinstance(rate, bool) or not isinstance(rate, int | float) or not rate > 0:
            raise DataError(f"{file}: rate_hz: {rate!r}, expected samples per second > 0")
        sensor = Sensor(name.strip(), tuple(c.strip() for c in channels), float(rate))
        return sensor, FolderDataSet._read_split(file, node.get(SPLIT_KEY))

    @staticmethod
    def _read_split(file: Path, node: Any) -> dict[str, Any] | None:
        expected = (
            "expected split: {name: folds, folds: K} (K >= 2; without K the largest its labels "
            "allow) or {name: random}"
        )
        if node is None:
            return None
        if isinstance(node, str):
            node = {"name": node}
        if not isinstance(node, dict) or node.get("name") not in DECLARABLE:
            raise DataError(f"{file}: split: {node!r}, {expected}")
        if node["name"] == "random" and set(node) != {"name"}:
            raise DataError(f"{file}: split: {node!r}, {expected}")
        folds = node.get("folds", 2)
        if set(node) - {"name", "folds"} or isinstance(folds, bool) or not isinstance(folds, int):
            raise DataError(f"{file}: split: {node!r}, {expected}")
        if folds < 2:
            raise DataError(f"{file}: split: {node!r}, {expected}")
        return dict(node)

    @staticmethod
    def _read_labels(
        file: Path,
    ) -> tuple[tuple[str, ...], dict[int, dict[str, int]], dict[int, str]]:
        """(label names, object id -> label -> 0/1, object id -> object name)."""
        expected = f"expected a header {OBJECT_COLUMN}[,{ID_COLUMN}],LABEL,... and a row per object"
        try:
            rows = read_table(file)
        except OSError as e:
            raise DataError(f"{file}: cannot read ({e.strerror}); {expected}") from e
        except (UnicodeDecodeError, csv.Error) as e:
            raise DataError(f"{file}: not a readable CSV ({_one_line(e)}); {expected}") from e
        if not rows:
            raise DataError(f"{file}: empty; {expected}")
        if rows[0][1][0].strip() == "" and len(rows[0][1]) > 1:  # pandas' unnamed index column
            rows = [(n, row[1:]) for n, row in rows]
        header = [h.strip() for h in rows[0][1]]
        if header[0] != OBJECT_COLUMN:
            raise DataError(f"{file}: first column {header[0]!r}; {expected}")
        has_ids = len(header) > 1 and header[1] == ID_COLUMN
        names = tuple(header[2 if has_ids else 1 :])
        if not names:
            raise DataError(f"{file}: no label columns; {expected}")
        for label in names:
            if not NAME.fullmatch(label):
                raise DataError(
                    f"{file}: label column {label!r}, expected a name of letters, digits, _ and -"
                )
        if len(set(names)) != len(names):
            twice = sorted({a for a in names if names.count(a) > 1})
            raise DataError(f"{file}: label column(s) {twice} twice, expected unique label names")
        if len(rows) == 1:
            raise DataError(f"{file}: no object rows; {expected}")
        labels: dict[str, dict[str, int]] = {}
        given: dict[str, int] = {}
        for line, raw in rows[1:]:
            row = [cell.strip() for cell in raw]
            where = f"{file}:{line}"
            if len(row) != len(header):
                raise DataError(f"{where}: {len(row)} cells, expected {len(header)} (the header's)")
            name = row[0]
            if not NAME.fullmatch(name):
                raise DataError(
                    f"{where}: object {name!r}, expected a name of letters, digits, _ and - "
                    f"(it names the folder {TRIALS_DIR}/<object>/)"
                )
            if name in labels:
                raise DataError(f"{where}: object {name!r} has a second row, expected one")
            if has_ids:
                given[name] = FolderDataSet._object_id(row[1], where)
            cells = row[2 if has_ids else 1 :]
            for label, cell in zip(names, cells, strict=True):
                if cell.lower() not in FLAGS:
                    raise DataError(
                        f"{where}: {name} {label}={cell!r}, expected 0 or 1 (true/false, 1.0/0.0)"
                    )
            labels[name] = {label: FLAGS[c.lower()] for label, c in zip(names, cells, strict=True)}
        if has_ids:
            ids = given
            seen: dict[int, str] = {}
            for name, i in ids.items():
                if i in seen:
                    raise DataError(
                        f"{file}: objects {seen[i]!r} and {name!r} share {ID_COLUMN} {i}, "
                        "expected one id per object"
                    )
                seen[i] = name
        else:
            ids = {name: i for i, name in enumerate(sorted(labels), 1)}
            if len(ids) > MAX_OBJECT_ID:
                raise DataError(
                    f"{file}: {len(ids)} objects, expected at most {MAX_OBJECT_ID} (trial names "
                    "hold a three-digit object id)"
                )
        reserved = sorted(n for n in ids if n.startswith(NON_TRIAL_PREFIXES))
        if reserved:
            raise DataError(
                f"{file}: object {reserved[0]!r} cannot start a trial name (names starting with "
                f"{', '.join(NON_TRIAL_PREFIXES)} are PHAC-2's link groups); rename it"
            )
        return (
            names,
            {ids[n]: labels[n] for n in sorted(labels, key=ids.__getitem__)},
            {i: n for n, i in sorted(ids.items(), key=lambda item: item[1])},
        )

    @staticmethod
    def _object_id(cell: str, where: str) -> int:
        if not cell.isdigit() or not 0 <= int(cell) <= MAX_OBJECT_ID:
            raise DataError(
                f"{where}: {ID_COLUMN}={cell!r}, expected a whole number 0..{MAX_OBJECT_ID}"
            )
        return int(cell)

    def _list_trials(self, root: Path) -> dict[TrialName, Path]:
        if not root.is_dir():
            raise DataError(f"{root}: no such folder, expected {TRIALS_DIR}/<object>/<trial>.npy")
        ids = {name: i for i, name in self._names.items()}
        out: dict[TrialName, Path] = {}
        for folder in _visible(root):
            if not folder.is_dir():
                raise DataError(f"{folder}: not a folder, expected {TRIALS_DIR}/<object>/ folders")
            if folder.name not in ids:
                raise DataError(
                    f"{self.path / LABELS_FILE}: no row for object {folder.name!r} (which has "
                    f"{folder}/); expected one labels row per object folder"
                )
            files = _visible(folder)
            for file in files:
                if file.suffix != TRIAL_SUFFIX or not file.is_file():
                    raise DataError(
                        f"{file}: not a {TRIAL_SUFFIX} file, expected only <trial>{TRIAL_SUFFIX} "
                        f"files in {TRIALS_DIR}/<object>/"
                    )
            if not files:
                raise DataError(f"{folder}: no trial files, expected <trial>{TRIAL_SUFFIX} files")
            if len(files) > MAX_TRIALS:
                raise DataError(
                    f"{folder}: {len(files)} trial files, expected at most {MAX_TRIALS} "
                    "(trial names hold a two-digit trial number)"
                )
            i = ids[folder.name]
            for number, file in enumerate(files, 1):
                name = f"{folder.name}_{i:03d}_{number:02d}"
                out[TrialName(name, f"{folder.name}_{i:03d}", i, number)] = file
        listed = {t.object_id for t in out}
        for i, name in self._names.items():
            if i not in listed:
                raise DataError(
                    f"{root / name}: missing; {LABELS_FILE} lists object {name!r}, expected its "
                    f"trial files there"
                )
        return out

    # ---------------------------------------------------------------- the DataSet protocol
    def object_ids(self) -> tuple[int, ...]:
        return tuple(sorted(self._names))

    def labels(self) -> dict[int, dict[str, int]]:
        return {i: dict(v) for i, v in self._labels.items()}

    def object_name(self, object_id: int) -> str:
        try:
            return self._names[object_id]
        except KeyError:
            raise DataError(f"{self.path / LABELS_FILE}: no object with id {object_id}") from None

    def trial_name(self, name: str | TrialName) -> TrialName:
        key = name.name if isinstance(name, TrialName) else name
        try:
            return self._by_name[key]
        except KeyError:
            raise DataError(f"{self.path / TRIALS_DIR}: no trial {key}") from None

    def trial_file(self, name: str | TrialName) -> Path:
        """The ``.npy`` file a trial is read from."""
        return self._files[self.trial_name(name)]

    def photographs(self) -> dict[int, list[Path]]:
        """Object id -> its sorted JPEGs in ``photos/<object>/``; no ``photos/``: none."""
        root = self.path / PHOTOS_DIR
        if not root.is_dir():
            return {}
        ids = {name: i for i, name in self._names.items()}
        out: dict[int, list[Path]] = {}
        for folder in _visible(root):
            if not folder.is_dir() or folder.name not in ids:
                raise DataError(
                    f"{folder}: expected {PHOTOS_DIR}/<object>/ folders of objects in {LABELS_FILE}"
                )
            found = [p for p in _visible(folder) if p.suffix.lower() in PHOTO_SUFFIXES]
            if found:
                out[ids[folder.name]] = found
        return dict(sorted(out.items()))

    def identity(self) -> str:
        return f"{self.path.name}-{self.digest()}"

    def digest(self) -> str:
        """Every file's name, size and modification time, hashed: a changed, added or removed
        trial, label or photograph changes it."""
        h = hashlib.sha1(str(self.path.resolve()).encode())
        for file in self._data_files():
            try:
                st = file.stat()
            except OSError as e:
                raise DataError(f"{file}: cannot read ({e.strerror}); was it removed?") from e
            h.update(f"|{file.relative_to(self.path)}|{st.st_size}|{st.st_mtime_ns}".encode())
        return h.hexdigest()[:12]

    def _data_files(self) -> Iterator[Path]:
        yield self.path / SENSOR_FILE
        yield self.path / LABELS_FILE
        if self.frozen_folds is not None:
            yield self.path / FOLDS_FILE
        yield from (self._files[t] for t in self.trials)
        for paths in self.photographs().values():
            yield from paths

    # ---------------------------------------------------------------- trials
    def signals(self, name: str | TrialName) -> np.ndarray:
        """One trial's (channels, time) float64 array, read now and validated."""
        file = self.trial_file(name)
        channels = len(self.sensor.channels)
        expected = f"expected a ({channels}, time) array of numbers saved by numpy.save"
        try:
            arr = np.load(file, allow_pickle=False)
        except (OSError, ValueError, EOFError) as e:
            raise DataError(f"{file}: cannot read as .npy ({_one_line(e)}); {expected}") from e
        if not isinstance(arr, np.ndarray):  # an .npz archive under a .npy name
            arr.close()
            raise DataError(f"{file}: an .npz archive, {expected}")
        if arr.dtype.kind not in "iuf":
            raise DataError(f"{file}: dtype {arr.dtype}, {expected}")
        if arr.ndim != 2 or arr.shape[0] != channels:
            raise DataError(
                f"{file}: shape {arr.shape}, {expected} (one row per channel of {SENSOR_FILE})"
            )
        if arr.shape[1] < MIN_SAMPLES:
            raise DataError(f"{file}: {arr.shape[1]} sample(s), expected at least {MIN_SAMPLES}")
        arr = arr.astype(np.float64, copy=False)
        bad = ~np.isfinite(arr)
        if bad.any():
            raise DataError(
                f"{file}: {int(np.isnan(arr).sum())} NaN and {int(np.isinf(arr).sum())} infinite "
                "value(s), expected none"
            )
        return arr


def write_folder(
    path: str | Path,
    sensor: Sensor,
    labels: Mapping[str, Mapping[str, int]],
    trials: Mapping[str, Sequence[np.ndarray]],
    split: Mapping[str, Any] | None = None,
    frozen: FrozenFolds | None = None,
) -> Path:
    """Export recordings to the folder layout: ``labels`` object -> label -> 0/1 (the label
    order is the first object's), ``trials`` object -> its (channels, time) arrays in order,
    ``split`` the split the data set declares, ``frozen`` its frozen folds."""
    path = Path(path)
    (path / TRIALS_DIR).mkdir(parents=True, exist_ok=True)
    node: dict[str, Any] = {
        "sensor": sensor.name,
        "channels": list(sensor.channels),
        "rate_hz": sensor.rate_hz,
    }
    if split is not None:
        node[SPLIT_KEY] = dict(split)
    if frozen is not None:
        frozen.write(path / FOLDS_FILE)
    (path / SENSOR_FILE).write_text(yaml.safe_dump(node, sort_keys=False))
    names = list(next(iter(labels.values())))
    with open(path / LABELS_FILE, "w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f)
        writer.writerow([OBJECT_COLUMN, *names])
        writer.writerows([obj, *(int(row[a]) for a in names)] for obj, row in labels.items())
    for obj, arrays in trials.items():
        folder = path / TRIALS_DIR / obj
        folder.mkdir(exist_ok=True)
        for number, arr in enumerate(arrays, 1):
            np.save(folder / f"trial_{number:02d}{TRIAL_SUFFIX}", np.asarray(arr))
    return path

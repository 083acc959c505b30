"""Per-trial CSV recordings -> the folder layout (``python -m tactile_exp.data import-csv``).

Many tactile data sets are published as one CSV file per trial: rows are samples, columns are
channels, often with a time column. ``import_csv`` reads such a tree, takes each file's object
from its path by a pattern the user gives (default: the folder it sits in), reads a labels table
(one row per object, 0/1 cells as spreadsheets and pandas write them) and writes the folder
layout (`tactile_exp.data.folder`). Every bad input stops it with a one-line `DataError` naming
the file (and line) and what was expected, before anything is written.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tactile_exp.data.dataset import Sensor
from tactile_exp.data.folder import (
    FLAGS,
    MAX_TRIALS,
    MIN_SAMPLES,
    NAME,
    OBJECT_COLUMN,
    FolderDataSet,
    read_table,
    write_folder,
)
from tactile_exp.data.layout import DataError
from tactile_exp.data.splits import folds_for

TIME_COLUMNS = ("time", "timestamp", "t", "time_s", "seconds")  # recognised, case-insensitive
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}
DEFAULT_PATTERN = r"(?P<object>[^/]+)/[^/]+$"  # the folder a trial file sits in
RATE_TOLERANCE = 0.1  # a file's sampling rate may differ this much from the others' median


@dataclass
class Imported:
    """What ``import_csv`` found and wrote."""

    path: Path  # the folder-layout data set written
    sensor: Sensor
    trials: dict[str, list[Path]]  # object -> its CSV files, in trial order
    samples: list[int]  # samples per trial
    labels: dict[str, dict[str, int]]  # object -> label -> 0/1
    split: str = ""  # the split dataset.yaml declares, and why (`declared_split_of`)

    def summary(self) -> list[str]:
        """What an import prints: objects, trials, channels, rate, labels and their balance."""
        per_object = [len(files) for files in self.trials.values()]
        channels = ", ".join(self.sensor.channels[:6])
        more = (
            f", ... ({len(self.sensor.channels)} in all)" if len(self.sensor.channels) > 6 else ""
        )
        lines = [
            f"wrote {self.path} (data=folder data.path={self.path})",
            f"  objects   {len(self.trials)}: {', '.join(self.trials)}",
            f"  trials    {sum(per_object)} ({min(per_object)}-{max(per_object)} per object), "
            f"{min(self.samples)}-{max(self.samples)} samples each "
            f"(median {int(np.median(self.samples))})",
            f"  channels  {len(self.sensor.channels)}: {channels}{more}",
            f"  rate      {self.sensor.rate_hz:g} Hz",
            "  label       +objects  -objects",
        ]
        for label in next(iter(self.labels.values())):
            pos = sum(row[label] for row in self.labels.values())
            lines.append(f"  {label:<12} {pos:>8}  {len(self.labels) - pos:>8}")
        if self.split:
            lines.append(f"  split     {self.split}")
        return lines


def _natural(path: Path) -> list[object]:
    """Sort key: ``trial_2`` before ``trial_10``."""
    return [int(p) if p.isdigit() else p for p in re.split(r"(\d+)", path.as_posix())]


def _objects(src: Path, pattern: str, glob: str, exclude: Path | None) -> dict[str, list[Path]]:
    """Object -> its trial files (natural order), the object from each file's path under
    ``src`` by ``pattern`` (its group ``object``, else its first group)."""
    try:
        regex = re.compile(pattern)
    except re.error as err:
        raise DataError(f"--object-pattern {pattern!r}: not a regular expression ({err})") from None
    files = sorted((p for p in src.glob(glob) if p.is_file() and p != exclude), key=_natural)
    if not files:
        raise DataError(f"{src}: no files match {glob!r}, expected one CSV file per trial")
    out: dict[str, list[Path]] = {}
    for file in files:
        rel = file.relative_to(src).as_posix()
        m = regex.search(rel)
        if m is None or not m.groups():
            raise DataError(
                f"{file}: --object-pattern {pattern!r} does not match {rel!r} (or has no group); "
                "expected a pattern whose group 'object' (or first group) is the object's name"
            )
        name = m.group("object") if "object" in regex.groupindex else m.group(1)
        if not NAME.fullmatch(name or ""):
            raise DataError(
                f"{file}: object {name!r} (from --object-pattern), expected a name of letters, "
                "digits, _ and -"
            )
        out.setdefault(name, []).append(file)
    for name, trial_files in out.items():
        if len(trial_files) > MAX_TRIALS:
            raise DataError(
                f"{trial_files[0].parent}: object {name!r} has {len(trial_files)} trial files, "
                f"expected at most {MAX_TRIALS} (pass --glob to pick fewer)"
            )
    return dict(sorted(out.items(), key=lambda item: _natural(Path(item[0]))))


def read_trial(file: Path, time_column: str | None) -> tuple[list[str], np.ndarray, np.ndarray]:
    """(channel names, (channels, samples) values, times or an empty array) of one CSV."""
    try:
        rows = read_table(file)
    except (OSError, UnicodeDecodeError) as err:
        raise DataError(f"{file}: cannot read ({err}); expected a UTF-8 CSV file") from None
    if len(rows) < 1 + MIN_SAMPLES:
        raise DataError(
            f"{file}: {max(len(rows) - 1, 0)} sample row(s), expected a header and at least "
            f"{MIN_SAMPLES} rows"
        )
    header = [h.strip() for h in rows[0][1]]
    while header and header[-1] == "":  # a trailing separator on the header line
        header.pop()
    if len(set(header)) != len(header) or "" in header:
        raise DataError(f"{file}: header {header}: expected unique, non-empty column names")
    lowered = [h.lower() for h in header]
    if time_column is not None:
        if time_column.lower() not in lowered:
            raise DataError(f"{file}: no column {time_column!r} (--time-column); has {header}")
        t_index: int | None = lowered.index(time_column.lower())
    else:
        t_index = next((lowered.index(c) for c in TIME_COLUMNS if c in lowered), None)
    values = np.empty((len(rows) - 1, len(header)))
    for k, (line, raw) in enumerate(rows[1:]):
        cells = [c.strip() for c in raw]
        if len(cells) > len(header) and not any(cells[len(header) :]):
            cells = cells[: len(header)]  # a trailing separator on every line
        if len(cells) != len(header):
            raise DataError(
                f"{file}:{line}: {len(cells)} cells, expected {len(header)} (the header's)"
            )
        try:
            values[k] = [float(c) for c in cells]
        except ValueError:
            bad = next(c for c in cells if not _is_number(c))
            column = header[cells.index(bad)]
            raise DataError(f"{file}:{line}: {column}={bad!r}, expected a number") from None
    if not np.isfinite(values).all():
        raise DataError(f"{file}: NaN or infinite values, expected numbers in every cell")
    channels = [h for i, h in enumerate(header) if i != t_index]
    if not channels:
        raise DataError(f"{file}: no channel columns besides the time column {header[t_index]!r}")
    keep = [i for i in range(len(header)) if i != t_index]
    times = values[:, t_index] if t_index is not None else np.empty(0)
    return channels, values[:, keep].T.copy(), times


def _is_number(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True


def _rate(file: Path, times: np.ndarray, unit: float) -> float:
    steps = np.diff(times) * unit
    if not (steps > 0).all():
        raise DataError(f"{file}: the time column does not increase on every row")
    return float(1.0 / np.median(steps))


def read_labels(file: Path) -> dict[str, dict[str, int]]:
    """A labels table: column ``object`` (or the first), then one 0/1 column per label."""
    try:
        rows = read_table(file)
    except (OSError, UnicodeDecodeError) as err:
        raise DataError(f"{file}: cannot read ({err}); expected a labels CSV") from None
    if len(rows) < 2:
        raise DataError(f"{file}: expected a header and one row per object")
    header = [h.strip() for h in rows[0][1]]
    if header[0] == "" and len(header) > 1:  # pandas' unnamed index column
        header, rows = header[1:], [(n, row[1:]) for n, row in rows]
    names = header[1:]
    if not names or not all(NAME.fullmatch(a) for a in names):
        raise DataError(
            f"{file}: label columns {names}, expected {header[0] or OBJECT_COLUMN} then label "
            "names of letters, digits, _ and -"
        )
    out: dict[str, dict[str, int]] = {}
    for line, raw in rows[1:]:
        cells = [c.strip() for c in raw]
        if len(cells) != len(header):
            raise DataError(f"{file}:{line}: {len(cells)} cells, expected {len(header)}")
        bad = [(a, c) for a, c in zip(names, cells[1:], strict=True) if c.lower() not in FLAGS]
        if bad:
            raise DataError(
                f"{file}:{line}: {cells[0]} {bad[0][0]}={bad[0][1]!r}, expected 0 or 1 "
                "(true/false, 1.0/0.0)"
            )
        out[cells[0]] = {a: FLAGS[c.lower()] for a, c in zip(names, cells[1:], strict=True)}
    return out


def declared_split_of(labels: dict[str, dict[str, int]]) -> tuple[dict[str, object], str]:
    """The split an import writes into ``dataset.yaml`` (object -> label -> 0/1): object-grouped
    folds with the largest K every label allows (`folds_for`), and the line that says so; none
    fits (a label with one object of a class): folds without K, chosen again when a job keeps
    fewer labels."""
    names = next(iter(labels.values()))
    counts = {
        a: (pos, len(labels) - pos)
        for a in names
        for pos in [sum(row[a] for row in labels.values())]
    }
    try:
        k, why = folds_for(counts)
    except DataError as err:
        return {"name": "folds"}, f"folds, K chosen by each job ({err})"
    return {"name": "folds", "folds": k}, (
        f"folds K={k} ({why}); declared in dataset.yaml, split=... overrides it"
    )


def import_csv(
    src: str | Path,
    dst: str | Path,
    *,
    labels: str | Path | None = None,
    pattern: str = DEFAULT_PATTERN,
    glob: str = "**/*.csv",
    time_column: str | None = None,
    time_unit: str = "s",
    rate: float | None = None,
    sensor: str | None = None,
) -> Imported:
    """Read every trial CSV under ``src`` and the ``labels`` table (default ``src/labels.csv``),
    check them all, then write the folder layout to ``dst`` (a new or empty folder)."""
    src, dst = Path(src).expanduser(), Path(dst).expanduser()
    if not src.is_dir():
        raise DataError(f"{src}: no such folder, expected the folder of per-trial CSV files")
    if dst.exists() and (not dst.is_dir() or any(dst.iterdir())):
        raise DataError(f"{dst}: exists and is not an empty folder; expected a new folder")
    if time_unit not in TIME_UNITS:
        raise DataError(f"--time-unit {time_unit!r}: expected one of {', '.join(TIME_UNITS)}")
    labels_file = Path(labels).expanduser() if labels is not None else src / "labels.csv"
    if not labels_file.is_file():
        raise DataError(f"{labels_file}: no such file, expected the labels table (--labels)")
    table = read_labels(labels_file)
    objects = _objects(src, pattern, glob, labels_file.resolve())
    missing = [o for o in objects if o not in table]
    if missing:
        raise DataError(
            f"{labels_file}: no row for object(s) {missing} (which have trial files); expected "
            "one row per object"
        )
    table = {o: table[o] for o in objects}  # objects without trials are not imported
    arrays: dict[str, list[np.ndarray]] = {}
    rates: list[tuple[Path, float]] = []
    channels: list[str] | None = None
    first: Path | None = None
    for name, files in objects.items():
        for file in files:
            found, values, times = read_trial(file, time_column)
            if channels is None:
                channels, first = found, file
            elif found != channels:
                raise DataError(
                    f"{file}: channels {found}, expected those of {first} ({len(channels)}: "
                    f"{channels[:3]}...)"
                )
            if times.size:
                rates.append((file, _rate(file, times, TIME_UNITS[time_unit])))
            arrays.setdefault(name, []).append(values)
    assert channels is not None and first is not None
    hz = _check_rates(rates, rate, first)
    found_sensor = Sensor(sensor or src.name, tuple(channels), hz)
    split, note = declared_split_of(table)
    write_folder(dst, found_sensor, table, arrays, split=split)
    FolderDataSet(dst)  # what data=folder will read, checked once
    samples = [a.shape[1] for trial_arrays in arrays.values() for a in trial_arrays]
    return Imported(dst, found_sensor, objects, samples, table, note)


def _check_rates(rates: list[tuple[Path, float]], rate: float | None, first: Path) -> float:
    """The sampling rate: ``rate`` when given, else the time columns' median (each file's
    within `RATE_TOLERANCE` of it)."""
    if rate is not None:
        if not rate > 0:
            raise DataError(f"--rate {rate}: expected samples per second > 0")
        return float(rate)
    if not rates:
        raise DataError(
            f"{first}: no time column ({', '.join(TIME_COLUMNS)} or --time-column) to read the "
            "sampling rate from; give it with --rate HZ"
        )
    median = float(np.median([r for _, r in rates]))
    for file, r in rates:
        if abs(r - median) > RATE_TOLERANCE * median:
            raise DataError(
                f"{file}: sampled at {r:.4g} Hz, the other files at {median:.4g} Hz; expected "
                "one rate (or give --rate HZ)"
            )
    return round(median, 3)

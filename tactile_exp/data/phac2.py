"""Reader for the PHAC-2 HDF5 file and its photographs (PHAC2_FORMAT.md §1, §3, §6).

The reader discovers its input rather than assuming it: trial groups by name pattern among the
root's children (never a recursive walk, because split groups hold hard links to the same trials),
optional channels by presence. It reads one trial group at a time so that the 470 MB file never
sits in memory, and every bad input raises a `DataError` naming the file, the HDF5 path and what
was expected.
"""

from __future__ import annotations

import hashlib
import os
import re
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

import cv2
import h5py
import numpy as np

from tactile_exp.data.dataset import PHAC2_LAYOUT, Sensor
from tactile_exp.data.deflate import read_array
from tactile_exp.data.layout import (
    ADC_MAX,
    ADJECTIVES,
    BIOTAC_CHANNELS,
    EPS,
    FINGERS,
    ROW_RATE_HZ,
    DataError,
    FingerData,
    TrialData,
    TrialName,
)

MIN_EP_ROWS = 2  # an EP needs a duration to be resampled (P3); one row is as good as none
PHOTO_SUFFIXES = (".jpg", ".jpeg")
ADJECTIVE_LINKS = {"adjectives": 1, "adjectives_neg": 0}  # group -> label its links carry
_OPTIONAL_FLOAT = {  # path inside the trial group -> per-row shape
    "gripper_aperture/joint_position": (),
    "gripper_aperture/joint_velocity": (),
    "gripper_aperture/joint_effort": (),
    "accelerometer": (3,),
    "transforms/translation": (3,),
    "transforms/rotation": (4,),
}
_ID_TOKEN = re.compile(r"(?<!\d)(\d{3})(?!\d)")
# Two BioTacs, each 19 electrodes, PAC (22 samples per row: a 2200 Hz stream), PDC, TAC, TDC;
# one row per BioTac frame (PHAC2_FORMAT.md §1). The haptic modalities know the layout in detail.
BIOTAC = Sensor(
    name="BioTac (2 fingers)",
    channels=tuple(
        f"{finger}/{channel}"
        for finger in FINGERS
        for channel in (*(f"electrode_{i:02d}" for i in range(1, 20)), "pac", "pdc", "tac", "tdc")
    ),
    rate_hz=ROW_RATE_HZ,
    layout=PHAC2_LAYOUT,
)


def default_cache_dir() -> Path:
    """Where generated data and caches live: ``$TACTILE_EXP_CACHE`` or ``~/.cache/tactile_exp``."""
    env = os.environ.get("TACTILE_EXP_CACHE")
    return Path(env).expanduser() if env else Path.home() / ".cache" / "tactile_exp"


def load_photograph(path: Path) -> np.ndarray:
    """Read one JPEG as (H, W, 3) uint8 RGB."""
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        raise DataError(f"{path}: cannot read the photograph (expected a readable JPEG)")
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)


def _decode_names(ds: h5py.Dataset) -> tuple[str, ...]:
    return tuple(
        (v.decode("ascii") if isinstance(v, bytes) else str(v)).strip() for v in ds[()].ravel()
    )


class PHAC2:
    """One PHAC-2 file (real or synthetic) plus its photograph folder: a `DataSet` whose labels
    are the 24 adjectives of METHOD D4 in the paper's order."""

    label_names: tuple[str, ...] = ADJECTIVES
    sensor: Sensor = BIOTAC
    declared_split = {"name": "published"}  # what split=declared runs (E1)

    def __init__(self, path: str | Path, photo_dir: str | Path | None = None) -> None:
        self.path = Path(path)
        default_photos = self.path.parent / "photographs"
        self.photo_dir = Path(photo_dir) if photo_dir is not None else default_photos
        if not self.path.is_file():
            raise DataError(f"{self.path}: file not found (expected the PHAC-2 HDF5 file)")
        if not h5py.is_hdf5(self.path):
            raise DataError(f"{self.path}: not an HDF5 file (expected the PHAC-2 .h5)")
        with self._open() as f:
            try:
                children = {k: isinstance(f.get(k, getlink=False), h5py.Group) for k in f}
            except (OSError, RuntimeError, KeyError) as e:
                raise DataError(f"{self.path}: cannot list the root group ({e})") from e
        parsed = [TrialName.parse(k) for k, is_group in children.items() if is_group]
        self.trials: tuple[TrialName, ...] = tuple(sorted(t for t in parsed if t is not None))
        if not self.trials:
            raise DataError(
                f"{self.path}: no trial groups at the root (expected groups named like "
                "car_sponge_101_01, i.e. <stem>_<NNN>_<TT>)"
            )
        self._by_name = {t.name: t for t in self.trials}
        self.groups = frozenset(k for k, is_group in children.items() if is_group) - set(
            self._by_name
        )
        self._labels: dict[int, dict[str, int]] | None = None

    def _open(self) -> h5py.File:
        try:
            return h5py.File(self.path, "r")
        except OSError as e:
            raise DataError(
                f"{self.path}: cannot open as HDF5 (truncated or corrupt file?): {e}"
            ) from e

    def __repr__(self) -> str:
        return f"PHAC2({str(self.path)!r}, {len(self.trials)} trials)"

    def object_ids(self) -> tuple[int, ...]:
        return tuple(sorted({t.object_id for t in self.trials}))

    def object_name(self, object_id: int) -> str:
        """The object's group stem (``car_sponge_101``): what its trial groups start with."""
        for t in self.trials:
            if t.object_id == object_id:
                return t.stem
        raise DataError(f"{self.path}: no trials of object {object_id}")

    def trial_name(self, name: str | TrialName) -> TrialName:
        """The `TrialName` of a trial group in this file; `DataError` if there is none."""
        key = name.name if isinstance(name, TrialName) else name
        try:
            return self._by_name[key]
        except KeyError:
            raise DataError(f"{self.path}: no trial group /{key}") from None

    def identity(self) -> str:
        """Short key that changes whenever the file does (for caches of derived data)."""
        return f"{self.path.stem}-{self.digest()}"

    def digest(self) -> str:
        """The file's path, size and modification time, hashed: the part of ``identity`` that
        tells two files of one name apart (MLflow's dataset digest)."""
        st = self.path.stat()
        raw = f"{self.path.resolve()}|{st.st_size}|{st.st_mtime_ns}"
        return hashlib.sha1(raw.encode()).hexdigest()[:12]

    # ---------------------------------------------------------------- labels
    def labels(self) -> dict[int, dict[str, int]]:
        """Object id -> adjective -> 0/1 (D4), checked against the adjective link groups."""
        if self._labels is None:
            with self._open() as f:
                self._labels = self._read_labels(f)
        return {k: dict(v) for k, v in self._labels.items()}

    def _read_labels(self, f: h5py.File) -> dict[int, dict[str, int]]:
        links = self._adjective_links(f)
        out: dict[int, dict[str, int]] = {}
        first: dict[int, str] = {}
        for t in self.trials:
            ds = f[t.name].get("adjectives")
            if isinstance(ds, h5py.Dataset):
                positives = set(self._check_adjectives(_decode_names(ds), f"/{t.name}/adjectives"))
                labels = {a: int(a in positives) for a in ADJECTIVES}
                for (group, adj), members in links.items():
                    want = ADJECTIVE_LINKS[group]
                    if (t.name in members) != (labels[adj] == want):
                        raise DataError(
                            f"{self.path}: /{t.name}/adjectives says {adj}={labels[adj]} but "
                            f"/{group}/{adj} {'links' if t.name in members else 'does not link'} "
                            f"{t.name} (expected the two to agree)"
                        )
            elif links:
                labels = {a: int(t.name in links.get(("adjectives", a), ())) for a in ADJECTIVES}
            else:
                raise DataError(
                    f"{self.path}: /{t.name}/adjectives missing and no /adjectives groups "
                    "(expected the positive adjective names of the object)"
                )
            if t.object_id in out and out[t.object_id] != labels:
                diff = sorted(a for a in ADJECTIVES if out[t.object_id][a] != labels[a])
                raise DataError(
                    f"{self.path}: /{first[t.object_id]} and /{t.name} disagree on {diff} "
                    "(expected object-level labels, the same for every trial)"
                )
            out.setdefault(t.object_id, labels)
            first.setdefault(t.object_id, t.name)
        return out

    def _check_adjectives(self, names: Iterable[str], where: str) -> list[str]:
        names = list(names)
        unknown = sorted(set(names) - set(ADJECTIVES))
        if unknown:
            raise DataError(
                f"{self.path}: {where} holds unknown adjective(s) {unknown} "
                f"(expected names among the 24 of METHOD D4)"
            )
        return names

    def _adjective_links(self, f: h5py.File) -> dict[tuple[str, str], set[str]]:
        """(link group, adjective) -> trial names it links; empty unknown groups are tolerated."""
        out: dict[tuple[str, str], set[str]] = {}
        for group in ADJECTIVE_LINKS:
            if group not in self.groups:
                continue
            for adj in f[group]:
                members = set(f[group][adj]) if isinstance(f[group][adj], h5py.Group) else set()
                if adj not in ADJECTIVES:
                    if members:
                        self._check_adjectives([adj], f"/{group}")
                    continue
                out[(group, adj)] = members & set(self._by_name)
        return out

    # ---------------------------------------------------------------- trials
    def read_trial(self, name: str | TrialName, optional: bool = True) -> TrialData:
        """Read and validate one trial group (D2); `DataError` on any problem."""
        trial = self.trial_name(name)
        with self._open() as f:
            return self._read_group(f, trial, optional)

    def iter_trials(
        self, names: Iterable[str | TrialName] | None = None, optional: bool = True
    ) -> Iterator[TrialData]:
        """Yield trials one group at a time (the file stays open, the data does not pile up)."""
        trials = self.trials if names is None else [self.trial_name(n) for n in names]
        with self._open() as f:
            for t in trials:
                yield self._read_group(f, t, optional)

    def check_trials(
        self, progress: Callable[[int, int], None] | None = None
    ) -> tuple[list[str], list[str]]:
        """(readable trial names, one problem line per unreadable trial), for skipping bad ones;
        ``progress(done, total)`` is called before each trial is read."""
        good: list[str] = []
        problems: list[str] = []
        with self._open() as f:
            for i, t in enumerate(self.trials):
                if progress is not None:
                    progress(i, len(self.trials))
                try:
                    self._read_group(f, t, optional=True)
                except DataError as e:
                    problems.append(str(e))
                else:
                    good.append(t.name)
        return good, problems

    def _read_group(self, f: h5py.File, trial: TrialName, optional: bool) -> TrialData:
        try:
            return _TrialReader(self.path, f, trial).read(optional)
        except (OSError, RuntimeError) as e:
            raise DataError(f"{self.path}: /{trial.name}: HDF5 read failed ({e})") from e

    # ---------------------------------------------------------------- photographs
    def photographs(self) -> dict[int, list[Path]]:
        """Object id -> sorted JPEG paths, matched by group stem, else by the 3-digit id (§3)."""
        if not self.photo_dir.is_dir():
            return {}
        stems = sorted({(t.stem, t.object_id) for t in self.trials}, key=lambda s: -len(s[0]))
        ids = set(self.object_ids())
        out: dict[int, list[Path]] = {}
        for p in sorted(self.photo_dir.iterdir()):
            if p.suffix.lower() not in PHOTO_SUFFIXES or not p.is_file():
                continue
            obj = next((oid for stem, oid in stems if stem in p.stem), None)
            if obj is None:
                found = {int(m) for m in _ID_TOKEN.findall(p.stem)} & ids
                obj = found.pop() if len(found) == 1 else None
            if obj is not None:
                out.setdefault(obj, []).append(p)
        return dict(sorted(out.items()))


class _TrialReader:
    """Reads and validates one trial group; every failure names file and HDF5 path."""

    def __init__(self, path: Path, f: h5py.File, trial: TrialName) -> None:
        self.path = path
        self.trial = trial
        self.group = f[trial.name]
        self.n = 0

    def fail(self, key: str, what: str) -> DataError:
        return DataError(f"{self.path}: /{self.trial.name}/{key}: {what}")

    def dataset(self, key: str, required: bool = True) -> h5py.Dataset | None:
        ds = self.group.get(key)
        if isinstance(ds, h5py.Dataset):
            return ds
        if required or ds is not None:
            raise self.fail(key, "missing" if ds is None else "is a group, expected a dataset")
        return None

    def array(self, key: str, tail: tuple[int, ...], integer: bool, required: bool = True):
        ds = self.dataset(key, required)
        if ds is None:
            return None
        if ds.shape != (self.n, *tail):
            raise self.fail(key, f"shape {ds.shape}, expected {(self.n, *tail)}")
        arr = read_array(ds)
        if arr.dtype.kind == "f" and np.isnan(arr).any():
            raise self.fail(key, f"{int(np.isnan(arr).sum())} NaN value(s), expected none")
        if integer and arr.dtype.kind not in "iu":
            raise self.fail(key, f"dtype {arr.dtype}, expected an integer dtype")
        if not integer and arr.dtype.kind not in "iuf":
            raise self.fail(key, f"dtype {arr.dtype}, expected a numeric dtype")
        return arr

    def states(self) -> np.ndarray:
        key = "state/controller_detail_state"
        ds = self.dataset(key)
        if ds.ndim != 1 or ds.shape[0] == 0:
            raise self.fail(key, f"shape {ds.shape}, expected (N,) with N > 0")
        arr = ds[()]
        if arr.dtype.kind == "O":
            arr = np.array([v.encode() if isinstance(v, str) else v for v in arr], dtype="S30")
        if arr.dtype.kind != "S":
            raise self.fail(key, f"dtype {arr.dtype}, expected fixed-length byte strings (S30)")
        return arr

    def finger(self, finger: str) -> FingerData:
        if not isinstance(self.group.get(f"biotacs/{finger}"), h5py.Group):
            raise self.fail(
                f"biotacs/{finger}", "missing, expected a group with " + ", ".join(BIOTAC_CHANNELS)
            )
        data = {}
        for channel, tail in BIOTAC_CHANNELS.items():
            key = f"biotacs/{finger}/{channel}"
            arr = self.array(key, tail, integer=True)
            lo, hi = int(arr.min()), int(arr.max())
            if lo < 0 or hi > ADC_MAX:
                raise self.fail(key, f"values {lo}..{hi}, expected 12-bit counts 0..{ADC_MAX}")
            data[channel] = np.asarray(arr, dtype=np.int64)
        data["pac"] = data["pac"].reshape(-1)  # row-major: 22 samples per frame -> 2200 Hz
        return FingerData(**data)

    def check_eps(self, states: np.ndarray) -> None:
        key = "state/controller_detail_state"
        for ep, state in EPS.items():
            idx = np.flatnonzero(states == state)
            if idx.size == 0:
                raise self.fail(key, f"EP {ep} ({state.decode()}) absent, expected a block of rows")
            if idx.size < MIN_EP_ROWS:
                rows = f"{idx.size} row(s), expected at least {MIN_EP_ROWS}"
                raise self.fail(key, f"EP {ep} ({state.decode()}) has {rows}")
            if idx[-1] - idx[0] + 1 != idx.size:
                raise self.fail(
                    key, f"EP {ep} ({state.decode()}) split into several blocks, expected one"
                )

    def read(self, optional: bool) -> TrialData:
        states = self.states()
        self.n = states.shape[0]
        fingers = (self.finger(FINGERS[0]), self.finger(FINGERS[1]))
        self.check_eps(states)
        adjectives: tuple[str, ...] = ()
        ds = self.dataset("adjectives", required=False)
        if ds is not None:
            adjectives = _decode_names(ds)
            unknown = sorted(set(adjectives) - set(ADJECTIVES))
            if unknown:
                raise self.fail("adjectives", f"unknown adjective(s) {unknown}, expected D4 names")
        out = TrialData(self.trial, fingers, states, adjectives=adjectives)
        if not optional:
            return out
        ctrl = self.array("state/controller_state", (), integer=True, required=False)
        out.controller_state = None if ctrl is None else np.asarray(ctrl, dtype=np.int64)
        floats = {
            k: self.array(k, tail, integer=False, required=False)
            for k, tail in _OPTIONAL_FLOAT.items()
        }
        out.gripper = {
            k.split("/")[1]: v
            for k, v in floats.items()
            if k.startswith("gripper") and v is not None
        }
        out.accelerometer = floats["accelerometer"]
        out.translation = floats["transforms/translation"]
        out.rotation = floats["transforms/rotation"]
        return out

"""Names, constants and in-memory records of the PHAC-2 layout (PHAC2_FORMAT.md).

Everything that both the reader and the synthetic generator must agree on lives here, so the
generator cannot drift from what the reader expects.
"""

from __future__ import annotations

import csv
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cache
from importlib import resources
from typing import Any

import numpy as np


class DataError(ValueError):
    """Bad input data; the message names the file, the group or key, and what was expected."""


ADJECTIVES: tuple[str, ...] = (
    "absorbent", "bumpy", "compressible", "cool", "crinkly", "fuzzy",
    "hairy", "hard", "metallic", "nice", "porous", "rough",
    "scratchy", "slippery", "smooth", "soft", "solid", "springy",
    "squishy", "sticky", "textured", "thick", "thin", "unpleasant",
)  # fmt: skip

# The four exploratory procedures: short name -> exact `controller_detail_state` string (S30).
EPS: dict[str, bytes] = {
    "squeeze": b"SQUEEZE_SET_PRESSURE_SLOW",
    "hold": b"HOLD_FOR_10_SECONDS",
    "slow_slide": b"SLIDE_5CM",
    "fast_slide": b"MOVE_DOWN_5CM",
}
BASELINE_STATE = b"MOVE_ARM_START_POSITION"  # rows used as the at-rest baseline (BASELINES.md §1.1)

FINGERS: tuple[str, ...] = ("finger_0", "finger_1")
BIOTAC_CHANNELS: dict[str, tuple[int, ...]] = {  # dataset -> per-row shape after the row axis
    "electrodes": (19,),
    "pac": (22,),
    "pdc": (),
    "tac": (),
    "tdc": (),
}
PAC_PER_ROW = 22
ROW_RATE_HZ = 100.0  # one row per BioTac frame; time = row index / 100 (never `timestamps`)
PAC_RATE_HZ = ROW_RATE_HZ * PAC_PER_ROW
ADC_MAX = 4095

TRIAL_PATTERN = re.compile(r"^(.*)_(\d{3})_(\d{2})$")
NON_TRIAL_PREFIXES = ("adjectives", "train_test", "validation")
POSITIVE_SPLIT_GROUP = "train_test_sets"
NEGATIVE_SPLIT_GROUP = "train_test_negative_sets"


@dataclass(frozen=True, order=True)
class TrialName:
    """A trial group name split into its parts, e.g. ``car_sponge_101_01``."""

    name: str
    stem: str
    object_id: int
    trial: int

    @classmethod
    def parse(cls, name: str) -> TrialName | None:
        """Parse a root child's name; ``None`` for anything that is not a trial group."""
        if name.startswith(NON_TRIAL_PREFIXES):
            return None
        m = TRIAL_PATTERN.match(name)
        if m is None:
            return None
        stem_with_id = f"{m.group(1)}_{m.group(2)}"
        return cls(name=name, stem=stem_with_id, object_id=int(m.group(2)), trial=int(m.group(3)))


@dataclass(frozen=True)
class ObjectInfo:
    """One PHAC-2 object as listed in ``resources/objects.csv``."""

    object_id: int
    group_stem: str  # e.g. ``car_sponge_101`` (trial groups are ``<group_stem>_<TT>``)
    display_name: str
    material: str
    labels: dict[str, int]  # adjective -> 0/1

    @property
    def positives(self) -> tuple[str, ...]:
        return tuple(a for a in ADJECTIVES if self.labels[a])


@cache
def objects() -> tuple[ObjectInfo, ...]:
    """The 60 real PHAC-2 objects with their 24 labels (shipped in data/resources/objects.csv)."""
    text = resources.files("tactile_exp.data").joinpath("resources/objects.csv").read_text()
    rows = list(csv.DictReader(text.splitlines()))
    return tuple(
        ObjectInfo(
            object_id=int(r["object_id"]),
            group_stem=r["group_stem"],
            display_name=r["display_name"],
            material=r["material"],
            labels={a: int(r[a]) for a in ADJECTIVES},
        )
        for r in rows
    )


@dataclass(frozen=True)
class PublishedTest:
    """One row of the published split table: a test object of one adjective."""

    adjective: str
    object_id: int
    label: int
    trials: tuple[int, ...] | None  # None = all trials of the object


@cache
def published_test_split() -> tuple[PublishedTest, ...]:
    """The published per-adjective test objects (PHAC2_FORMAT.md §2)."""
    text = resources.files("tactile_exp.data").joinpath("resources/test_split.csv").read_text()
    out = []
    for r in csv.DictReader(text.splitlines()):
        listed = r["test_trials"]
        trials = None if listed == "all" else tuple(int(t) for t in listed.split())
        out.append(PublishedTest(r["adjective"], int(r["object_id"]), int(r["label"]), trials))
    return tuple(out)


@dataclass
class FingerData:
    """Raw BioTac channels of one finger for one trial (int64 ADC counts, N rows)."""

    electrodes: np.ndarray  # (N, 19)
    pac: np.ndarray  # (N * 22,) flattened row-major: a continuous 2200 Hz stream
    pdc: np.ndarray  # (N,)
    tac: np.ndarray  # (N,)
    tdc: np.ndarray  # (N,)


@dataclass
class TrialData:
    """One trial as read from the file. Optional channels are ``None`` when the file lacks them."""

    name: TrialName
    fingers: tuple[FingerData, FingerData]
    detail_state: np.ndarray  # (N,) bytes (S30), one state string per row
    controller_state: np.ndarray | None = None  # (N,) int64 coarse code
    adjectives: tuple[str, ...] = ()  # positive adjectives stored in the trial
    gripper: dict[str, np.ndarray] = field(default_factory=dict)  # joint_position/velocity/effort
    accelerometer: np.ndarray | None = None  # (N, 3)
    translation: np.ndarray | None = None  # (N, 3) tool frame position (m)
    rotation: np.ndarray | None = None  # (N, 4)

    @property
    def n_rows(self) -> int:
        return int(self.detail_state.shape[0])

    def segment(self, state: bytes) -> slice:
        """Rows whose detail state equals ``state`` (one contiguous block), as a slice.

        Raises ``ValueError`` naming the trial when the state is absent.
        """
        idx = np.flatnonzero(self.detail_state == state)
        if idx.size == 0:
            raise ValueError(f"trial {self.name.name}: no rows with state {state.decode()}")
        return slice(int(idx[0]), int(idx[-1]) + 1)

    def ep_segments(self) -> dict[str, slice]:
        """The four EP row ranges keyed by short name (squeeze, hold, slow_slide, fast_slide)."""
        return {ep: self.segment(state) for ep, state in EPS.items()}


@dataclass(frozen=True)
class Split:
    """One adjective's train/test split, at trial level (E1).

    Objects never appear on both sides, except a single positive object split by trial.
    """

    adjective: str
    train: tuple[str, ...]  # trial group names
    test: tuple[str, ...]
    labels: dict[str, int]  # trial name -> 0/1 for this adjective (train and test)

    def objects(self, part: str) -> set[int]:
        names = self.train if part == "train" else self.test
        return {TrialName.parse(n).object_id for n in names}  # type: ignore[union-attr]

    def trials(self, part: str, dataset: Any, names: tuple[str, ...] | None = None) -> Trials:
        """One side (``train`` or ``test``) as labelled ``Trials``; ``names``: a subset of it
        (validation). An object split by trial records both sides' trial counts (``shared``)."""
        names = (self.train if part == "train" else self.test) if names is None else names
        per_side: dict[int, list[int]] = {}
        for side, side_names in enumerate((self.train, self.test)):
            for t in side_names:
                per_side.setdefault(TrialName.parse(t).object_id, [0, 0])[side] += 1  # type: ignore[union-attr]
        shared = {o: (a, b) for o, (a, b) in per_side.items() if a and b}
        labels = {t: self.labels[t] for t in names}
        return Trials(dataset, tuple(names), labels, self.adjective, part, shared)


@dataclass(frozen=True)
class Trials:
    """Some trials of one data set and, when known, one label's value for each: what a modality
    fits on and transforms (training, validation and test trials, or a new object's).

    ``side`` and ``shared`` serve photographs, which belong to objects, not trials: an object
    whose trials are on both sides of a split (``shared``: object -> (train, test) trial counts)
    has its photographs divided in that proportion, first views to ``train``.
    ``object_ids`` names objects given without trials (photographs only, as predict takes them).
    """

    dataset: Any  # a DataSet (tactile_exp.data.dataset)
    names: tuple[str, ...]
    labels: Mapping[str, int] | None = None  # trial -> 0/1; None: unlabelled (new data)
    label: str = ""  # the label's name (an adjective), for messages and caches
    side: str = "train"  # train | test: which share of a shared object's photographs
    shared: Mapping[int, tuple[int, int]] = field(default_factory=dict)
    object_ids: tuple[int, ...] | None = None

    def __len__(self) -> int:
        return len(self.names)

    @property
    def objects(self) -> tuple[int, ...]:
        """The objects, in first-seen order."""
        if self.object_ids is not None:
            return self.object_ids
        seen = (TrialName.parse(n).object_id for n in self.names)  # type: ignore[union-attr]
        return tuple(dict.fromkeys(seen))

    def y(self, names: tuple[str, ...] | None = None) -> np.ndarray:
        """Labels of ``names`` (default: all), zeros when unlabelled."""
        names = self.names if names is None else names
        if self.labels is None:
            return np.zeros(len(names), np.int64)
        return np.array([self.labels[t] for t in names], dtype=np.int64)

    def object_labels(self) -> dict[int, int]:
        """Each object's label (0 when unlabelled)."""
        out = {o: 0 for o in self.objects}
        for t, v in zip(self.names, self.y(), strict=True):
            out[TrialName.parse(t).object_id] = int(v)  # type: ignore[union-attr]
        return out


# The kinds of instance rows a modality gives and a model takes, as messages describe them.
INSTANCE_KINDS: dict[str, str] = {
    "signals": "(channels, time) signals",
    "features": "feature vectors",
    "images": "images",
}


@dataclass(frozen=True)
class InstanceSpec:
    """What each row of a modality's `Instances` is, declared when the data opens (before any
    run): its kind (`INSTANCE_KINDS`) and shape, ``None`` where only fitting will tell."""

    kind: str
    shape: tuple[int | None, ...] = ()

    def describe(self) -> str:
        """E.g. ``(channels, time) signals of shape (48, 100)``."""
        what = INSTANCE_KINDS.get(self.kind, self.kind)
        if not self.shape:
            return what
        dims = ", ".join("?" if d is None else str(d) for d in self.shape)
        return f"{what} of shape ({dims}{',' if len(self.shape) == 1 else ''})"


@dataclass
class Instances:
    """Model inputs with the bookkeeping needed to combine, split and evaluate them."""

    X: np.ndarray  # (n, ...) float32
    y: np.ndarray  # (n,) int 0/1
    trial: np.ndarray  # (n,) trial group names
    object_id: np.ndarray  # (n,) int

    def __post_init__(self) -> None:
        n = len(self.X)
        for key in ("y", "trial", "object_id"):
            if len(getattr(self, key)) != n:
                raise ValueError(f"Instances.{key} has {len(getattr(self, key))} rows, X has {n}")

    def __len__(self) -> int:
        return len(self.X)

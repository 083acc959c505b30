"""What the framework needs from a data set: the `DataSet` protocol and its `Sensor`.

PHAC-2 (the real file and its synthetic twin, ``data/phac2.py``) is one source, a lab's own
recordings in the folder layout (``data/folder.py``, docs/extending.md) another. Everything
above the data layer (splits, modalities, the job loop, the report) asks only for what is named
here, so a new sensor needs a source, not a new engine.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol, runtime_checkable

from tactile_exp.data.layout import DataError, TrialName


@dataclass(frozen=True)
class Sensor:
    """The channels a data set's trials hold: what a modality checks before it reads them.

    ``name`` is for people only; what a modality may rely on is declared: the channels, the
    rate and ``layout``, the physical record layout its trials follow, if any (PHAC-2's BioTac
    frames: `PHAC2_LAYOUT`). A modality that needs a layout checks it, never the name.
    """

    name: str
    channels: tuple[str, ...]
    rate_hz: float  # samples per second along a trial's time axis
    layout: str | None = None  # e.g. PHAC2_LAYOUT; None: plain (channels, time) arrays

    def describe(self) -> str:
        """One phrase for messages: ``sensor 'glove', 3 channels at 50 Hz, no declared layout``."""
        layout = f"layout {self.layout}" if self.layout else "no declared layout"
        channels = f"{len(self.channels)} channels at {self.rate_hz:g} Hz"
        return f"sensor {self.name!r}, {channels}, {layout}"


# PHAC-2's trials: two BioTacs' frames (electrodes, PAC, PDC, TAC, TDC) with the controller's
# states marking the four exploratory procedures (PHAC2_FORMAT.md §1), read by ``iter_trials``.
PHAC2_LAYOUT = "phac2-biotac"


@runtime_checkable
class DataSet(Protocol):
    """Objects with binary labels, each touched in one or more trials (``<stem>_<NNN>_<TT>``)."""

    path: Path
    label_names: tuple[str, ...]  # every label, in the data set's own order
    trials: tuple[TrialName, ...]  # sorted
    sensor: Sensor

    def object_ids(self) -> tuple[int, ...]:
        """Sorted ids of the objects that have trials."""
        ...

    def labels(self) -> dict[int, dict[str, int]]:
        """Object id -> label name -> 0/1 (a copy: the caller may change it)."""
        ...

    def identity(self) -> str:
        """Short readable key that changes whenever the data does (caches, skip-if-finished)."""
        ...

    def digest(self) -> str:
        """The changing part of ``identity`` (MLflow's dataset digest)."""
        ...

    def photographs(self) -> dict[int, list[Path]]:
        """Object id -> its photographs (JPEG paths); objects without any are left out."""
        ...

    def trial_name(self, name: str | TrialName) -> TrialName:
        """The `TrialName` of one of this data set's trials; `DataError` if there is none."""
        ...

    def object_name(self, object_id: int) -> str:
        """The object's name as the data set gives it (a folder, an HDF5 group stem)."""
        ...


def select_labels(dataset: DataSet, wanted: Sequence[str] | None) -> tuple[str, ...]:
    """The labels a job trains, in order: ``None`` (``adjectives: null``) is every label of the
    data set; a given list must name labels the data set has."""
    if wanted is None:
        return dataset.label_names
    unknown = [a for a in wanted if a not in dataset.label_names]
    if unknown:
        raise DataError(
            f"adjectives: unknown {unknown} for the data set {dataset.path}; its labels: "
            f"{', '.join(dataset.label_names)} (or adjectives=null for all of them)"
        )
    return tuple(wanted)

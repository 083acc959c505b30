"""A folder of one object's photographs as a data set (what predict takes for visual rows),
optionally beside another data set's trials of that object (multimodal rows)."""

from __future__ import annotations

import hashlib
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

from tactile_exp.data.layout import DataError, TrialData, TrialName

PHOTO_SUFFIXES = (".jpg", ".jpeg", ".png", ".bmp")


class PhotoFolder:
    """The photographs in ``folder`` (by file name) as object ``object_id``'s; ``trials``: the
    data set whose trials are the object's (None: photographs only)."""

    def __init__(self, folder: str | Path, *, trials: Any = None, object_id: int = 0) -> None:
        self.path = Path(folder)
        if not self.path.is_dir():
            raise DataError(f"{self.path}: no such folder of photographs")
        self.paths = sorted(p for p in self.path.iterdir() if p.suffix.lower() in PHOTO_SUFFIXES)
        if not self.paths:
            raise DataError(f"{self.path}: no photographs ({', '.join(PHOTO_SUFFIXES)} files)")
        self.base = trials
        self.object_id = object_id
        self.trials: tuple[TrialName, ...] = () if trials is None else trials.trials

    def object_ids(self) -> tuple[int, ...]:
        return (self.object_id,)

    def object_name(self, object_id: int) -> str:
        return self.path.name if self.base is None else self.base.object_name(object_id)

    def labels(self) -> dict[int, dict[str, int]]:
        return {} if self.base is None else self.base.labels()

    def photographs(self) -> dict[int, list[Path]]:
        return {self.object_id: list(self.paths)}

    def identity(self) -> str:
        stamp = [(p.name, p.stat().st_size, p.stat().st_mtime_ns) for p in self.paths]
        base = "" if self.base is None else self.base.identity()
        return hashlib.sha1(repr((str(self.path), stamp, base)).encode()).hexdigest()[:16]

    def trial_name(self, name: str | TrialName) -> TrialName:
        return self.base.trial_name(name)

    def iter_trials(
        self, names: Iterable[TrialName | str] | None = None, optional: bool = True
    ) -> Iterator[TrialData]:
        return self.base.iter_trials(names, optional=optional)

    def __repr__(self) -> str:
        return f"PhotoFolder({str(self.path)!r})"

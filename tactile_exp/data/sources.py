"""Where a job's data set comes from: the ``data`` config group, one entry per source."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from tactile_exp.data.dataset import DataSet
from tactile_exp.data.folder import FolderDataSet
from tactile_exp.data.layout import DataError
from tactile_exp.data.phac2 import PHAC2
from tactile_exp.registry import Registry

DATA_SOURCES: Registry[DataSet] = Registry("data source")
# A source's data.path and what it must name: checked before any run (`check_source_params`).
PATHS: dict[str, tuple[str, str]] = {  # source -> (file | folder, what the user should give)
    "phac2": ("file", "the PHAC-2 HDF5 file"),
    "folder": ("folder", "a folder holding dataset.yaml, labels.csv and trials/"),
}


@DATA_SOURCES.register("synthetic")
def synthetic(
    cache_dir: str | Path,
    seed: int = 0,
    trials: int = 10,
    duration_scale: float = 1.0,
    views: int = 8,
    image_width: int = 480,
    image_height: int = 320,
) -> DataSet:
    """The embedded default: generated once into ``cache_dir``, reused afterwards."""
    from tactile_exp.data.synthetic import SyntheticSpec, default_file

    spec = SyntheticSpec(
        seed=seed,
        trials=trials,
        duration_scale=duration_scale,
        views=views,
        image_width=image_width,
        image_height=image_height,
    )
    return PHAC2(default_file(Path(cache_dir).expanduser(), spec))


@DATA_SOURCES.register("phac2")
def phac2(path: str | Path, photo_dir: str | Path | None = None) -> DataSet:
    """The real release file (``phac_train_test_pos_neg_90_10_1_20.h5``)."""
    path = Path(path).expanduser()
    if not path.exists():
        raise DataError(f"{path}: no such file (data.path should name the PHAC-2 HDF5 file)")
    return PHAC2(path, photo_dir)


@DATA_SOURCES.register("folder")
def folder(path: str | Path) -> DataSet:
    """A lab's recordings of any sensor in the folder layout (`tactile_exp.data.folder`)."""
    return FolderDataSet(path)


def open_path(path: str | Path) -> DataSet:
    """The data set at ``path`` as its source reads it: a folder in the folder layout, else a
    PHAC-2-layout HDF5 file (what predict is given, or finds in a job's record)."""
    path = Path(path).expanduser()
    return FolderDataSet(path) if path.is_dir() else PHAC2(path)


def check_source_params(name: str, params: dict[str, Any]) -> None:
    """A source's ``path`` names an existing file or folder, before any data is read:
    ValueError naming the key otherwise."""
    if name not in PATHS or "path" not in params:
        return
    kind, what = PATHS[name]
    path = Path(str(params["path"])).expanduser()
    if not (path.is_file() if kind == "file" else path.is_dir()):
        raise ValueError(f"path: {path}: no such {kind}; expected {what}")

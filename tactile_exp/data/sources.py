"""Where a job's PHAC-2 file comes from: the ``data`` config group."""

from __future__ import annotations

from pathlib import Path

from tactile_exp.data.phac2 import PHAC2, DataError
from tactile_exp.registry import Registry

DATA_SOURCES: Registry[PHAC2] = Registry("data source")


@DATA_SOURCES.register("synthetic")
def synthetic(
    cache_dir: str | Path,
    seed: int = 0,
    trials: int = 10,
    duration_scale: float = 1.0,
    views: int = 8,
    image_width: int = 480,
    image_height: int = 320,
) -> PHAC2:
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
def phac2(path: str | Path, photo_dir: str | Path | None = None) -> PHAC2:
    """The real release file (``phac_train_test_pos_neg_90_10_1_20.h5``)."""
    path = Path(path).expanduser()
    if not path.exists():
        raise DataError(f"{path}: no such file (data.path should name the PHAC-2 HDF5 file)")
    return PHAC2(path, photo_dir)

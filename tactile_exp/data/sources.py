"""Where a job's data set comes from: the ``data`` config group, one entry per source.

A source that reads a file or folder takes it as its ``path`` argument and may declare which
(`opens`): the config check makes sure it exists before any run, and predict finds the source
for a path it is given (`open_path`) among every registered one, a plugin's as well.

A source may also declare the split its data is evaluated with (`declares_split`, without
opening it: PHAC-2's published split); otherwise the data set it opens declares it
(`tactile_exp.data.splits.declared_split`). `resolve_split` turns the config's ``split=declared``
into that rule, before the job's hash is taken.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, TypeVar

from tactile_exp.data.dataset import DataSet
from tactile_exp.data.folder import FolderDataSet
from tactile_exp.data.layout import DataError
from tactile_exp.data.phac2 import PHAC2
from tactile_exp.data.splits import DECLARED, declared_split
from tactile_exp.registry import Registry

DATA_SOURCES: Registry[DataSet] = Registry("data source")
F = TypeVar("F", bound=Callable[..., DataSet])


def opens(kind: str, what: str) -> Callable[[F], F]:
    """Declare what a source's ``path`` names: ``kind`` file or folder, ``what`` in words."""
    if kind not in ("file", "folder"):
        raise ValueError(f"opens: kind must be 'file' or 'folder', got {kind!r}")

    def declare(source: F) -> F:
        source.opens = (kind, what)  # type: ignore[attr-defined]
        return source

    return declare


def declares_split(rule: str) -> Callable[[F], F]:
    """Declare the split rule a source's data is evaluated with, known without opening it."""

    def declare(source: F) -> F:
        source.split = rule  # type: ignore[attr-defined]
        return source

    return declare


def path_kind(name: str) -> tuple[str, str] | None:
    """(file | folder | any, what) for a source that reads a ``path``; None for one that
    does not (``synthetic`` makes its own)."""
    source = DATA_SOURCES[name]
    if "path" not in inspect.signature(source).parameters:
        return None
    return getattr(source, "opens", ("any", "what the source reads"))


@DATA_SOURCES.register("synthetic")
@declares_split("published")
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
@opens("file", "the PHAC-2 HDF5 file")
@declares_split("published")
def phac2(path: str | Path, photo_dir: str | Path | None = None) -> DataSet:
    """The real release file (``phac_train_test_pos_neg_90_10_1_20.h5``)."""
    path = Path(path).expanduser()
    if not path.exists():
        raise DataError(f"{path}: no such file (data.path should name the PHAC-2 HDF5 file)")
    return PHAC2(path, photo_dir)


@DATA_SOURCES.register("folder")
@opens("folder", "a folder holding dataset.yaml, labels.csv and trials/")
def folder(path: str | Path) -> DataSet:
    """A lab's recordings of any sensor in the folder layout (`tactile_exp.data.folder`)."""
    return FolderDataSet(path)


def open_path(
    path: str | Path, source: str | None = None, params: Mapping[str, Any] | None = None
) -> DataSet:
    """The data set at ``path`` (what predict is given, or finds in a job's record): read by
    ``source`` (with its other ``params``) when that source reads such a path, else by the
    first registered source that reads one and opens it; DataError when none does."""
    path = Path(path).expanduser()
    if not path.exists():
        raise DataError(f"{path}: no such file or folder")
    kind = "folder" if path.is_dir() else "file"
    names = [n for n in DATA_SOURCES.names() if (path_kind(n) or ("",))[0] in (kind, "any")]
    if source in names:
        names.remove(source)
        names.insert(0, source)
    errors = []
    for name in names:
        kwargs = {**(params or {}), "path": path} if name == source else {"path": path}
        try:
            return DATA_SOURCES.build(name, **kwargs)
        except DataError as err:
            errors.append(f"data={name}: {err}")
    if not errors:
        raise DataError(f"{path}: no registered data source reads a {kind}")
    raise DataError(f"{path}: no data source reads it ({'; '.join(errors)})")


def check_source_params(name: str, params: dict[str, Any]) -> None:
    """A source's ``path`` names an existing file or folder, before any data is read:
    ValueError naming the key otherwise."""
    declared = path_kind(name) if name in DATA_SOURCES else None
    if declared is None or "path" not in params:
        return
    kind, what = declared
    path = Path(str(params["path"])).expanduser()
    exists = {"file": path.is_file, "folder": path.is_dir}.get(kind, path.exists)()
    if not exists:
        raise ValueError(
            f"path: {path}: no such {'path' if kind == 'any' else kind}; expected {what}"
        )


def resolve_split(
    name: str,
    params: Mapping[str, Any],
    node: Mapping[str, Any],
    adjectives: tuple[str, ...] | None,
    min_objects: int | None,
) -> tuple[dict[str, Any], str]:
    """The split node a job runs with, and what to print about it ("" when nothing was chosen).

    ``split=declared`` becomes the source's declared rule (`declares_split`), else the rule
    the data set declares, opened here (a folds split without K: the largest its labels allow);
    a folds split on a data set with frozen folds records their file's digest (``frozen``), so
    that a changed file is a new job."""
    out = dict(node)
    declared = getattr(DATA_SOURCES[name], "split", None)
    if declared is not None:
        return ({"name": declared}, "") if out.get("name") == DECLARED else (out, "")
    if out.get("name") not in (DECLARED, "folds"):
        return out, ""
    dataset = DATA_SOURCES.build(name, **params)
    note = ""
    if out.get("name") == DECLARED:
        out, note = declared_split(dataset, adjectives, min_objects)
    held = getattr(dataset, "frozen_folds", None)
    if out["name"] == "folds" and held is not None:
        out["frozen"] = held.digest
        note = f"{note or 'folds K=' + str(out.get('folds'))}, frozen folds {held.digest}"
    return out, note

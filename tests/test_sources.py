"""Data sources: what a source's ``path`` names is declared (`opens`), checked before any run,
and predict's `open_path` finds the source for a path among every registered one."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from phac2_fixture import write_file

from tactile_exp.data.dataset import Sensor
from tactile_exp.data.folder import FolderDataSet, write_folder
from tactile_exp.data.layout import DataError
from tactile_exp.data.phac2 import PHAC2
from tactile_exp.data.sources import DATA_SOURCES, check_source_params, open_path, opens, path_kind


def _folder(root: Path) -> Path:
    labels = {o: {"hard": int(o == "a")} for o in ("a", "b")}
    return write_folder(
        root, Sensor("s", ("x",), 10.0), labels, {o: [np.zeros((1, 3))] for o in labels}
    )


def test_built_in_sources_declare_what_their_path_names() -> None:
    assert path_kind("phac2") == ("file", "the PHAC-2 HDF5 file")
    assert path_kind("folder")[0] == "folder"
    assert path_kind("synthetic") is None  # it makes its own file


def test_open_path_reads_a_folder_or_a_phac2_file(tmp_path: Path) -> None:
    assert isinstance(open_path(_folder(tmp_path / "d")), FolderDataSet)
    assert isinstance(open_path(write_file(tmp_path / "t.h5")), PHAC2)
    with pytest.raises(DataError, match="no such file or folder"):
        open_path(tmp_path / "missing")


def test_a_plugin_source_is_found_for_its_path(tmp_path: Path) -> None:
    """A source registered outside the package (here: a folder with a marker file) is tried
    first when it is the job's own, and found among the others when it is not."""
    opened = []

    @opens("folder", "a folder with a MARK file")
    def marked(path: str | Path, scale: float = 1.0):
        if not (Path(path) / "MARK").exists():
            raise DataError(f"{path}: no MARK file")
        opened.append(scale)
        return FolderDataSet(path)

    with DATA_SOURCES.temporary(marked_folder=marked):
        data = _folder(tmp_path / "d")
        assert isinstance(open_path(data, "folder"), FolderDataSet) and opened == []
        (data / "MARK").touch()
        open_path(data, "marked_folder", {"scale": 2.0})
        assert opened == [2.0]  # the job's source, with its other params
        check_source_params("marked_folder", {"path": str(data)})
        with pytest.raises(ValueError, match="path: .*: no such folder; expected a folder with"):
            check_source_params("marked_folder", {"path": str(tmp_path / "nope")})

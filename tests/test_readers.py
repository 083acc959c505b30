"""Upstream file readers: a file that is not in its upstream's format is one line naming it."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from tactile_exp.data.layout import DataError
from tactile_exp.data.readers import READERS, bolt_hdf5, icub_text
from tactile_exp.data.recipe import RECIPES


def test_icub_text_needs_its_first_line_and_whole_slices(tmp_path: Path) -> None:
    channels = RECIPES.build("icub_grasp").channels
    file = tmp_path / "book_1.txt"
    file.write_text("1 2 3\n")
    with pytest.raises(DataError, match=r"book_1.txt:1: expected the first line -10000"):
        icub_text(file, channels)
    file.write_text("-10000\n" + "1 " * 9 + "\n")
    with pytest.raises(DataError, match=r"1 lines after the first, expected time slices of 7"):
        icub_text(file, channels)
    slice_ = ["1 " * 9, "2 " * 5, *["3 " * 12] * 5]
    file.write_text("\n".join(["-10000", *slice_, *slice_]))
    arr = icub_text(file, channels)[0]
    assert arr.shape == (69, 2) and arr[0, 0] == 1 and arr[9:, 0].tolist() == [3.0] * 60


def test_bolt_hdf5_names_the_missing_dataset(tmp_path: Path) -> None:
    channels = RECIPES.build("penn_bolt").channels
    file = tmp_path / "cork.h5"
    with h5py.File(file, "w") as f:
        f["cork_pdc100_1cm_01/finger_0/tdc"] = np.zeros(4)
    with pytest.raises(DataError, match=r"cork.h5: no dataset /cork_pdc100_1cm_01/finger_0/tac"):
        bolt_hdf5(file, channels)
    file.write_text("not hdf5")
    with pytest.raises(DataError, match="cork.h5: cannot read as HDF5"):
        bolt_hdf5(file, channels)


def test_every_reader_a_recipe_names_is_registered() -> None:
    for name in RECIPES.names():
        recipe = RECIPES.build(name)
        assert recipe.described is not None or recipe.reader in READERS

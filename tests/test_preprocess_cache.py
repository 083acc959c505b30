"""The disk cache of preprocessed arrays: content keys, atomic writes, checked reads."""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
import pytest

from tactile_exp.preprocess import cache
from tactile_exp.preprocess.cache import cache_key, load_arrays, save_arrays


def test_cache_key_is_short_order_independent_and_takes_any_value() -> None:
    key = cache_key(a=1, b=[2, 3])
    assert re.fullmatch("[0-9a-f]{16}", key)
    assert cache_key(b=[2, 3], a=1) == key
    assert cache_key(a=1, b=[2, 4]) != key
    assert cache_key(p=Path("x.h5")) == cache_key(p="x.h5")  # non-JSON values by their text


def test_save_writes_through_a_temporary_file_beside_the_entry(tmp_path, monkeypatch) -> None:
    path = tmp_path / "a" / "b" / "entry.npz"  # parent folders are made
    seen: list[list[str]] = []
    savez = np.savez

    def spy(f, **arrays):
        seen.append(os.listdir(path.parent))
        savez(f, **arrays)

    monkeypatch.setattr(cache.np, "savez", spy)
    save_arrays(path, {"x": np.arange(3)})
    (names,) = seen
    assert len(names) == 1 and re.fullmatch(r"entry\.npz\..+\.tmp", names[0])
    assert os.listdir(path.parent) == ["entry.npz"]
    np.testing.assert_array_equal(load_arrays(path, ("x",))["x"], np.arange(3))


def test_load_refuses_pickles_and_names_missing_arrays(tmp_path) -> None:
    path = tmp_path / "e.npz"
    assert load_arrays(path, ("x",)) is None
    save_arrays(path, {"x": np.arange(2), "y": np.ones(1)})
    assert list(load_arrays(path, ("y",))) == ["y"]
    message = f"^cache file {re.escape(str(path))} lacks arrays \\['z'\\]; delete it to rebuild$"
    with pytest.raises(ValueError, match=message):
        load_arrays(path, ("x", "z"))
    np.savez(path, x=np.array([{"a": 1}], dtype=object))
    with pytest.raises(ValueError, match="allow_pickle"):
        load_arrays(path, ("x",))


class _Unwritable:
    """An array-like that fails when numpy converts it: a crash in the middle of a cache write."""

    def __array__(self, dtype=None, copy=None):
        raise RuntimeError("disk gone")


class _Interrupting:
    def __array__(self, dtype=None, copy=None):
        raise KeyboardInterrupt


@pytest.mark.parametrize("error", [RuntimeError, KeyboardInterrupt])
def test_a_crash_while_writing_a_cache_entry_leaves_the_old_entry_and_no_debris(tmp_path, error):
    path = tmp_path / "entry.npz"
    save_arrays(path, {"a": np.arange(3)})
    big = np.ones((256, 1024))  # written to the file before the crash
    with pytest.raises(error):
        if error is KeyboardInterrupt:
            save_arrays(path, {"a": big, "b": _Interrupting()})
        else:
            save_arrays(path, {"a": big, "b": _Unwritable()})
    np.testing.assert_array_equal(load_arrays(path, ("a",))["a"], np.arange(3))
    assert os.listdir(tmp_path) == ["entry.npz"]
    fresh = tmp_path / "new" / "entry.npz"
    with pytest.raises(RuntimeError):
        save_arrays(fresh, {"a": big, "b": _Unwritable()})
    assert load_arrays(fresh, ("a",)) is None and os.listdir(fresh.parent) == []

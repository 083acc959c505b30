"""The kernels' scratch memory: pooled buffers, huge pages, the training set's copy."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tactile_exp.models import scratch as scratch_module
from tactile_exp.models.scratch import (
    HUGE_PAGE,
    carved,
    empty_on_huge_pages,
    mapped,
    on_huge_pages,
    scratch,
)


def _mapping(address: int) -> tuple[int, int, str]:
    """(start, end, permissions) of the mapping of this process that holds ``address``."""
    for line in Path("/proc/self/maps").read_text().splitlines():
        span, permissions = line.split()[:2]
        start, end = (int(a, 16) for a in span.split("-"))
        if start <= address < end:
            return start, end, permissions
    raise AssertionError(f"no mapping holds {address:#x}")


def test_scratch_reuses_only_buffers_nothing_holds_for_any_shape_that_fits(monkeypatch):
    monkeypatch.setattr(scratch_module, "_POOL", [])
    monkeypatch.setattr(scratch_module, "POOL_BYTES", 2 * 448 + 540)
    held = scratch(10, 10)  # a buffer of 100 + 100 // 8 = 112 floats (448 bytes)
    assert held.shape == (10, 10) and held.flags.c_contiguous
    assert not np.shares_memory(scratch(10, 10), held)  # held by this test: never twice
    view = held.reshape(-1)
    address = held.ctypes.data
    del held
    assert scratch(10, 10).ctypes.data != address  # a view still holds it
    del view
    assert scratch(10, 10).ctypes.data == address  # nothing holds it: reused
    assert scratch(7, 16).ctypes.data == address  # another shape that fits: the same buffer
    assert len(scratch_module._POOL) == 2
    big = scratch(12, 10)  # 120 floats fit in neither: a new buffer of 135 (540 bytes)
    assert len(scratch_module._POOL) == 3 and scratch_module._POOL[2].size == 135
    assert scratch(2, 50).ctypes.data == address  # the smallest free buffer that fits
    big_address = big.ctypes.data
    del big
    kept = [scratch(13, 10), scratch(13, 10)]  # 130 floats: the free 135, then a new 146
    assert kept[0].ctypes.data == big_address and not np.shares_memory(*kept)
    # the new buffer took the pool past its 1,436 bytes: both free 112s dropped, oldest first
    assert [a.size for a in scratch_module._POOL] == [135, 146]


def test_huge_page_buffers_are_private_aligned_and_never_handed_out_while_a_view_holds_them(
    monkeypatch,
):
    """Buffers from ``HUGE_PAGE`` bytes live in a private mapping of their own (a shared one
    would be shmem, never on huge pages): a view of one must still keep it from the pool."""
    monkeypatch.setattr(scratch_module, "_POOL", [])
    held = scratch(1024, 1024)  # 4 MiB
    assert held.ctypes.data % scratch_module.HUGE_PAGE == 0
    held[:] = 1.0
    address = held.ctypes.data
    maps = Path("/proc/self/maps").read_text().splitlines()
    mapping = [
        m for m in maps if int(m.split("-")[0], 16) <= address < int(m.split()[0].split("-")[1], 16)
    ]
    assert len(mapping) == 1 and mapping[0].split()[1] == "rw-p", mapping
    view = held[3:5]
    del held
    again = scratch(1024, 1024)
    assert again.ctypes.data != address  # the view holds it
    del again, view
    assert scratch(1024, 1024).ctypes.data == address


def test_a_mapped_array_starts_a_private_mapping_on_a_page_boundary_with_whole_pages_after():
    """Huge pages back only whole 2 MB pages inside a mapping: an array of 1.5 MB that started
    near the end of a 2 MB-page-plus mapping would get none."""
    page = scratch_module.HUGE_PAGE
    floats = page // 4  # a page's
    for count in (3 * floats // 4, floats + 1, 5 * floats // 2):  # 0.75, 1 (+4 bytes), 2.5 pages
        array = mapped(count)
        array[:] = 2.0
        start, end, permissions = _mapping(array.ctypes.data)
        assert array.ctypes.data % page == 0 and permissions == "rw-p"
        assert end - array.ctypes.data >= -(-4 * count // page) * page
        assert array.dtype == np.float32 and array.shape == (count,) and array.sum() == 2 * count


def test_pool_buffers_are_mapped_from_an_eighth_of_a_huge_page(monkeypatch):
    monkeypatch.setattr(scratch_module, "_POOL", [])
    page = scratch_module.HUGE_PAGE
    assert page // 8 == scratch_module.MAPPED_FROM
    # 150 steps x 10 states x 64 lanes: the LSTM's c_(t-1) for one thread (384 kB)
    assert scratch(150, 10, 64).ctypes.data % page == 0


def test_a_training_set_is_copied_onto_huge_pages_from_one_page_else_left_as_it_is():
    rng = np.random.default_rng(0)
    big = rng.standard_normal((600, 32, 60))  # float64; every other step: 2.3 MB as float32
    copy = on_huge_pages(big[:, :, ::2])  # not contiguous either
    assert copy.dtype == np.float32 and copy.flags.c_contiguous
    assert copy.ctypes.data % scratch_module.HUGE_PAGE == 0
    assert _mapping(copy.ctypes.data)[2] == "rw-p"
    np.testing.assert_array_equal(copy, big[:, :, ::2].astype(np.float32))
    small = rng.standard_normal((10, 32, 60)).astype(np.float32)  # 77 kB
    assert on_huge_pages(small) is small


def test_instances_written_on_huge_pages_are_trained_on_in_place_not_copied():
    """A modality's instances (``empty_on_huge_pages``) hold the training set once: a fit takes
    them, or a reshaped view of them, as they are; a strided view or float64 is still copied."""
    X = empty_on_huge_pages(60, 2, 5, 32, 60)  # 4.6 MB: 2.3 MB every other step
    assert X.dtype == np.float32 and X.flags.c_contiguous and X.ctypes.data % HUGE_PAGE == 0
    X[...] = np.random.default_rng(0).standard_normal(X.shape)
    rows = X.reshape(-1, 32, 60)  # as the haptic modality hands them on
    assert on_huge_pages(rows) is rows
    strided = on_huge_pages(rows[:, :, ::2])
    assert not np.shares_memory(strided, X) and strided.ctypes.data % HUGE_PAGE == 0
    np.testing.assert_array_equal(strided, rows[:, :, ::2])
    wide = on_huge_pages(rows.astype(np.float64))
    assert not np.shares_memory(wide, X)
    np.testing.assert_array_equal(wide, rows)
    small = empty_on_huge_pages(10, 32, 60)  # 77 kB: from malloc, as np.empty
    assert small.shape == (10, 32, 60) and small.dtype == np.float32


def test_carved_arrays_are_zeroed_back_to_back_from_a_huge_page_boundary():
    arrays = carved([(2, 3), (5,), (4, 1, 2)])
    assert [a.shape for a in arrays] == [(2, 3), (5,), (4, 1, 2)]
    assert all(a.dtype == np.float32 and a.flags.c_contiguous and not a.any() for a in arrays)
    assert arrays[0].ctypes.data % HUGE_PAGE == 0
    for before, after in zip(arrays, arrays[1:], strict=False):
        assert after.ctypes.data == before.ctypes.data + before.nbytes

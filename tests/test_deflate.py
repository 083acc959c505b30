"""read_array: h5py's values for every storage, through ISA-L where the chunks are deflate."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from tactile_exp.data.deflate import read_array

RNG = np.random.default_rng(0)
ARRAYS = {
    "int64 counts, chunks with edges": (RNG.integers(0, 4096, (1003, 19)), (128, 7)),
    "float32": (RNG.standard_normal((257, 22)).astype(np.float32), (100, 22)),
    "big-endian int32": (RNG.integers(-9, 9, 300).astype(">i4"), (64,)),
    "uint8 (shuffle has nothing to do)": (RNG.integers(0, 255, 77).astype(np.uint8), (10,)),
    "one chunk, as the generator writes": (RNG.integers(0, 4096, (690, 22)), (690, 22)),
}


@pytest.mark.parametrize("shuffle", [True, False])
@pytest.mark.parametrize("name", list(ARRAYS))
def test_deflate_chunks_inflate_by_isal_to_h5pys_values(tmp_path, monkeypatch, name, shuffle):
    arr, chunks = ARRAYS[name]
    with h5py.File(tmp_path / "f.h5", "w") as f:
        f.create_dataset("x", data=arr, chunks=chunks, compression="gzip", shuffle=shuffle)
    with h5py.File(tmp_path / "f.h5", "r") as f:
        expected = f["x"][()]
        # the ISA-L path reads the chunks itself: h5py's element read is never asked
        monkeypatch.setattr(h5py.Dataset, "__getitem__", _refuse)
        got = read_array(f["x"])
    assert got.dtype == expected.dtype and got.shape == expected.shape
    np.testing.assert_array_equal(got, expected)
    np.testing.assert_array_equal(got, arr)


def _refuse(self, key):
    raise AssertionError("h5py's read was called")


def _lzf(f, arr):
    f.create_dataset("x", data=arr, chunks=(50, 3), compression="lzf")


def _checksum(f, arr):
    f.create_dataset("x", data=arr, chunks=(50, 3), compression="gzip", fletcher32=True)


def _contiguous(f, arr):
    f.create_dataset("x", data=arr)


def _unwritten_chunks(f, arr):
    ds = f.create_dataset("x", shape=arr.shape, dtype=arr.dtype, chunks=(50, 3),
                          compression="gzip", shuffle=True, fillvalue=7)  # fmt: skip
    ds[:50, :3] = arr[:50, :3]  # one chunk of eight written, the rest read as the fill value


def _a_skipped_filter(f, arr):
    ds = f.create_dataset("x", shape=arr.shape, dtype=arr.dtype, chunks=arr.shape,
                          compression="gzip", shuffle=True)  # fmt: skip
    ds.id.write_direct_chunk((0, 0), arr.tobytes(), filter_mask=0b11)  # stored raw


def _empty(f, arr):
    f.create_dataset("x", shape=(0, 3), maxshape=(None, 3), dtype=np.int64, chunks=(10, 3),
                     compression="gzip")  # fmt: skip


@pytest.mark.parametrize(
    "store", [_lzf, _checksum, _contiguous, _unwritten_chunks, _a_skipped_filter, _empty]
)
def test_every_other_storage_reads_as_h5py_reads_it(tmp_path, store):
    arr = RNG.integers(0, 4096, (200, 6))
    with h5py.File(tmp_path / "f.h5", "w") as f:
        store(f, arr)
    with h5py.File(tmp_path / "f.h5", "r") as f:
        expected, got = f["x"][()], read_array(f["x"])
    assert got.dtype == expected.dtype and got.shape == expected.shape
    np.testing.assert_array_equal(got, expected)
    if store is _unwritten_chunks:
        assert (got[50:] == 7).all() and (got[:50, :3] == arr[:50, :3]).all()
    elif store is not _empty:
        np.testing.assert_array_equal(got, arr)


def test_a_chunk_that_does_not_inflate_is_an_oserror_naming_the_dataset(tmp_path):
    """As HDF5's own gzip filter fails (an OSError, which the readers report in one line)."""
    arr = RNG.integers(0, 4096, (100, 4))
    with h5py.File(tmp_path / "f.h5", "w") as f:
        ds = f.create_dataset("grp/x", data=arr, chunks=(50, 4), compression="gzip", shuffle=True)
        ds.id.write_direct_chunk((50, 0), b"not deflate at all")
    with h5py.File(tmp_path / "f.h5", "r") as f:
        with pytest.raises(OSError):
            f["grp/x"][()]
        with pytest.raises(OSError, match=r"/grp/x: the chunk at \(50, 0\) does not inflate"):
            read_array(f["grp/x"])

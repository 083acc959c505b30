"""Whole HDF5 datasets read with their deflate (gzip) chunks inflated by ISA-L.

PHAC-2's files, Penn BOLT's and the synthetic default keep every BioTac array as gzip + shuffle
chunks (PyTables' ``Filters(complevel=9)``; the generator writes the same filters). HDF5's own
gzip filter inflates them with zlib; ISA-L (``isal``, already the generator's deflate) inflates
the same bytes faster, and the shuffle is undone here in one byte transpose (OpenCV's). Reading
the default file's 6,000 BioTac arrays (3.1 GB as int64) is most of a job's first preprocessing:
bench/bench_preprocess.py times it both ways.

Any other filter pipeline (none, lzf, a checksum, a filter skipped for one chunk) and a dataset
with chunks never written are read by h5py as before: the values are the same either way
(tests/test_deflate.py).
"""

from __future__ import annotations

import cv2
import h5py
import numpy as np
from isal import isal_zlib
from isal.isal_zlib import error as IsalError

_SHUFFLE, _DEFLATE = h5py.h5z.FILTER_SHUFFLE, h5py.h5z.FILTER_DEFLATE


def _filters(ds: h5py.Dataset) -> tuple[int, ...]:
    plist = ds.id.get_create_plist()
    return tuple(plist.get_filter(i)[0] for i in range(plist.get_nfilters()))


def _chunk(raw: bytes, shuffled: bool, dtype: np.dtype, shape: tuple[int, ...]) -> np.ndarray:
    """One stored chunk's bytes as its (full, edge-padded) array."""
    data = np.frombuffer(isal_zlib.decompress(raw), np.uint8)
    if shuffled and dtype.itemsize > 1:  # byte k of every element was stored together
        data = cv2.transpose(data.reshape(dtype.itemsize, -1))  # 3x numpy's .T copy
    return data.view(dtype).reshape(shape)


def read_array(ds: h5py.Dataset) -> np.ndarray:
    """``ds[()]``: the whole dataset, inflated by ISA-L where it is stored as deflate chunks
    (after a shuffle or not), by h5py otherwise."""
    filters = _filters(ds) if ds.chunks is not None and ds.size else ()
    if filters not in ((_DEFLATE,), (_SHUFFLE, _DEFLATE)) or ds.dtype.kind not in "iuf":
        return ds[()]
    stored = ds.id.get_num_chunks()
    if stored != np.prod([-(-n // c) for n, c in zip(ds.shape, ds.chunks, strict=True)]):
        return ds[()]  # chunks never written read as the fill value: HDF5 knows it
    out = np.empty(ds.shape, ds.dtype)
    for index in range(stored):
        start = ds.id.get_chunk_info(index).chunk_offset
        mask, raw = ds.id.read_direct_chunk(start)
        if mask:  # a filter was skipped for this chunk: HDF5 knows how to read it
            return ds[()]
        try:
            chunk = _chunk(raw, filters[0] == _SHUFFLE, ds.dtype, ds.chunks)
        except (IsalError, ValueError) as err:  # as HDF5's own filter fails: an OSError
            raise OSError(f"{ds.name}: the chunk at {start} does not inflate ({err})") from err
        ends = (min(a + c, n) for a, c, n in zip(start, ds.chunks, ds.shape, strict=True))
        where = tuple(slice(a, b) for a, b in zip(start, ends, strict=True))
        out[where] = chunk[tuple(slice(0, s.stop - s.start) for s in where)]
    return out

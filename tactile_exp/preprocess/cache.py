"""Disk cache for preprocessed arrays: a content key and atomic save/load of named arrays.

Preprocessing reads the whole data file once; every later run loads the result. The key hashes
everything the arrays depend on (dataset identity, settings, code version), so a stale entry is
never reused, and the write is atomic (temp name then ``os.replace``) so a crash or two concurrent
jobs never leave a half-written file behind.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path

import numpy as np


def cache_key(**parts: object) -> str:
    """A short stable hash of ``parts`` (JSON-serialisable values, order-independent)."""
    text = json.dumps(parts, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def save_arrays(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """Write ``arrays`` to ``path`` (an uncompressed ``.npz``) atomically."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            np.savez(f, **arrays)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def load_arrays(path: Path, keys: tuple[str, ...]) -> dict[str, np.ndarray] | None:
    """The arrays saved at ``path``, or ``None`` when there is no entry.

    Raises ``ValueError`` naming the file when it exists but lacks one of ``keys``.
    """
    path = Path(path)
    if not path.exists():
        return None
    with np.load(path, allow_pickle=False) as f:
        missing = [k for k in keys if k not in f.files]
        if missing:
            raise ValueError(f"cache file {path} lacks arrays {missing}; delete it to rebuild")
        return {k: f[k] for k in keys}

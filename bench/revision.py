"""The package at another git revision, for a bench's ``--before REV``: its ``tactile_exp/`` and
``conf/`` exported once into the cache (``bench-before/<sha>``), kept so that its kernels compile
once per revision; a child process runs it with that folder as its ``PYTHONPATH``."""

from __future__ import annotations

import io
import os
import subprocess
import tarfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def package_at(rev: str) -> Path:
    """The folder holding ``tactile_exp/`` and ``conf/`` as they are at ``rev``."""
    sha = subprocess.run(["git", "-C", str(ROOT), "rev-parse", rev], check=True,
                         capture_output=True, text=True).stdout.strip()  # fmt: skip
    cache = Path(os.environ.get("TACTILE_EXP_CACHE", Path.home() / ".cache/tactile_exp"))
    folder = cache / "bench-before" / sha
    for part in ("tactile_exp", "conf"):
        if not (folder / part).exists():
            archive = subprocess.run(["git", "-C", str(ROOT), "archive", sha, part], check=True,
                                     capture_output=True).stdout  # fmt: skip
            folder.mkdir(parents=True, exist_ok=True)
            with tarfile.open(fileobj=io.BytesIO(archive)) as tar:
                tar.extractall(folder, filter="data")
    return folder

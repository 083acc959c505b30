"""numba, configured once for every compiled kernel of the project.

Compiled code is cached in the user cache folder (``$NUMBA_CACHE_DIR`` when set, else
``numba/`` under ``$TACTILE_EXP_CACHE`` or ``~/.cache/tactile_exp``), never inside the package
or the checkout, so kernels compile once per machine. numba reads these settings when it is
imported, hence this module: kernel modules import ``numba`` from here.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

from tactile_exp.data.phac2 import default_cache_dir

os.environ.setdefault("NUMBA_CACHE_DIR", str(default_cache_dir() / "numba"))
# workqueue: no spinning worker threads. With 2 cores shared by other work, numba's OpenMP layer
# spent ~50% more CPU per training step and ran ~1.8x slower in wall time (measured).
os.environ.setdefault("NUMBA_THREADING_LAYER", "workqueue")

import numba  # noqa: E402  (after the variables above: numba reads them at import)

# numba may have been imported earlier, before the variables were set (it then ran with its
# default threading layer even when $NUMBA_CACHE_DIR was given): apply them either way.
numba.config.CACHE_DIR = os.environ["NUMBA_CACHE_DIR"]
numba.config.THREADING_LAYER = os.environ["NUMBA_THREADING_LAYER"]

log = logging.getLogger(__name__)
_CHECKED: set[str] = set()


def announce_compile(module: str) -> None:
    """Log one line when ``module``'s kernels have no compiled code in the cache yet: their
    first compile takes about a minute, during which nothing else is printed. Checked once per
    process (the cache's index files, one per compiled function, name their module)."""
    if module in _CHECKED:
        return
    _CHECKED.add(module)
    stem = module.rsplit(".", 1)[-1]
    if not any(Path(numba.config.CACHE_DIR).glob(f"*/{stem}.*.nbi")):
        log.info(
            "compiling the %s kernels (numba, first use with this cache: about a minute, "
            "cached in %s after)",
            stem,
            numba.config.CACHE_DIR,
        )


__all__ = ["announce_compile", "numba"]

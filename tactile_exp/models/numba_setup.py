"""numba, configured once for every compiled kernel of the project.

Compiled code is cached in the user cache folder (``$NUMBA_CACHE_DIR`` when set, else
``numba/`` under ``$TACTILE_EXP_CACHE`` or ``~/.cache/tactile_exp``), never inside the package
or the checkout, so kernels compile once per machine. numba reads these settings when it is
imported, hence this module: kernel modules import ``numba`` from here.

The first compile takes about half a minute (the ConvNet's kernels), on one core. A job asks for
it ahead (``compile_ahead``): a background process compiles the kernels its model runs into the
cache while the job reads and preprocesses its data (one core), and the first kernel call waits
for that process, then loads the compiled code from the cache.
"""

from __future__ import annotations

import atexit
import importlib
import logging
import os
import subprocess
import sys
from collections.abc import Sequence, Sized
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
_AHEAD: dict[str, subprocess.Popen] = {}  # module -> the process compiling it


def _cached(module: str) -> bool:
    """Whether the cache holds compiled code of ``module`` (its index files name the module)."""
    stem = module.rsplit(".", 1)[-1]
    return any(Path(numba.config.CACHE_DIR).glob(f"*/{stem}.*.nbi"))


def _warm_up(modules: Sequence[str]) -> None:
    """The background process: each module's ``warm_up()`` compiles its kernels into the cache."""
    for module in modules:
        importlib.import_module(module).warm_up()


def _stop_compiles() -> None:
    """At exit: a compile ahead that nothing waited for (the job ended first) ends with it."""
    for process in _AHEAD.values():
        process.kill()


def compile_ahead(modules: Sequence[str]) -> None:
    """Start compiling the kernels of ``modules`` not yet in the cache in one background process
    (a new interpreter with this one's environment, hence its cache settings; a plain
    subprocess, so it works in any launcher's worker process)."""
    cold = [m for m in dict.fromkeys(modules) if m not in _AHEAD and not _cached(m)]
    if not cold:
        return
    code = "import sys; from tactile_exp.models.numba_setup import _warm_up; _warm_up(sys.argv[1:])"
    process = subprocess.Popen([sys.executable, "-c", code, *cold], stdout=subprocess.DEVNULL)
    log.info(
        "compiling the %s kernels ahead (numba, first use with this cache), beside the data "
        "loading; cached in %s",
        ", ".join(m.rsplit(".", 1)[-1] for m in cold),
        numba.config.CACHE_DIR,
    )
    _AHEAD.update(dict.fromkeys(cold, process))


atexit.register(_stop_compiles)


def announce_compile(module: str) -> None:
    """Before the first call of ``module``'s kernels in this process: wait for their compile
    ahead, if one runs, or log one line when the cache has no compiled code of them yet (their
    first compile takes about half a minute, during which nothing else is printed)."""
    if module in _CHECKED:
        return
    _CHECKED.add(module)
    stem = module.rsplit(".", 1)[-1]
    process = _AHEAD.pop(module, None)
    if process is not None:
        if process.poll() is None:
            log.info("waiting for the %s kernels' compile ahead to finish", stem)
        process.wait()
    if not _cached(module):  # none ahead, or it failed: compiled here, on first call
        log.info(
            "compiling the %s kernels (numba, first use with this cache: about half a minute, "
            "cached in %s after)",
            stem,
            numba.config.CACHE_DIR,
        )


def check_rows(rows: Sized, n: int, kernel: str) -> None:
    """Refuse row indices (an integer tensor or array) outside [0, ``n``): the compiled kernels
    read the rows of their input without bounds checks."""
    if len(rows) and not 0 <= int(rows.min()) <= int(rows.max()) < n:
        raise IndexError(f"{kernel}: rows must lie in [0, {n}), the rows of the input")


__all__ = ["announce_compile", "check_rows", "compile_ahead", "numba"]

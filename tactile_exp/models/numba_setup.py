"""numba, configured once for every compiled kernel of the project.

Compiled code is cached in the user cache folder (``$NUMBA_CACHE_DIR`` when set, else
``numba/`` under ``$TACTILE_EXP_CACHE`` or ``~/.cache/tactile_exp``), never inside the package
or the checkout, so kernels compile once per machine. numba reads these settings when it is
imported, hence this module: kernel modules import ``numba`` from here.

The first compile takes about half a minute (the ConvNet's kernels), on one core. A job asks for
it ahead (``compile_ahead``), before it opens its data: a background process compiles the kernels
its model runs into the cache while the job generates (on first use), reads and preprocesses its
data, and the first kernel call waits for that process, then loads the compiled code from the
cache. Without a compile ahead the first
call starts that process itself and waits (``ensure_compiled``): kernels are never compiled in the
process that runs them, because numba's code compiled in the calling process can round
differently from the same code loaded from its cache (the LSTM training step's FC and output
weight gradients differed in the last bits with numba 0.68), and a model's results would
then depend on whether its kernels had been compiled before.
"""

from __future__ import annotations

import atexit
import fcntl
import importlib
import importlib.util
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
_COMPILER = False  # whether this process is one compiling kernels for another


def _mark(module: str) -> Path:
    """The file that says ``module``'s kernels are compiled into the cache (``_warm_up`` writes
    it once their ``warm_up()`` ran), named by the module file's modification time and size, as
    numba tells its cached code stale. (The cache's own files do not tell it: compiling one
    module's kernels caches the functions they call from other modules.)"""
    stat = os.stat(importlib.util.find_spec(module).origin)
    return Path(numba.config.CACHE_DIR, "compiled", f"{module}-{stat.st_mtime_ns}-{stat.st_size}")


def _cached(module: str) -> bool:
    """Whether the cache holds ``module``'s kernels, compiled by its ``warm_up()``."""
    return _mark(module).exists()


def _warm_up(modules: Sequence[str]) -> None:
    """The background process: each module's ``warm_up()`` compiles its kernels into the cache
    (here, where ``ensure_compiled`` starts no process of its own), one such process at a time
    per module and cache (a lock file beside its mark): processes that start together (jobs side
    by side on a fresh cache, a test run's workers) wait for the first one's compile, then find
    the kernels cached, instead of compiling them again on the same cores."""
    global _COMPILER
    _COMPILER = True
    for module in modules:
        mark = _mark(module)
        mark.parent.mkdir(parents=True, exist_ok=True)
        with open(mark.with_name(f"{mark.name}.lock"), "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            if not mark.exists():
                importlib.import_module(module).warm_up()
                mark.touch()


def _stop_compiles() -> None:
    """At exit: a compile ahead that nothing waited for (the job ended first) ends with it."""
    for process in _AHEAD.values():
        process.kill()


def _compile_elsewhere(modules: Sequence[str]) -> subprocess.Popen:
    """A new interpreter compiling the kernels of ``modules`` into this process's cache (its
    environment, the cache folder as numba has it here; a plain subprocess, so it works in any
    launcher's worker process)."""
    code = "import sys; from tactile_exp.models.numba_setup import _warm_up; _warm_up(sys.argv[1:])"
    env = {**os.environ, "NUMBA_CACHE_DIR": numba.config.CACHE_DIR}
    return subprocess.Popen(
        [sys.executable, "-c", code, *modules], stdout=subprocess.DEVNULL, env=env
    )


def compile_ahead(modules: Sequence[str]) -> None:
    """Start compiling the kernels of ``modules`` not yet in the cache in one background
    process."""
    cold = [m for m in dict.fromkeys(modules) if m not in _AHEAD and not _cached(m)]
    if not cold:
        return
    process = _compile_elsewhere(cold)
    log.info(
        "compiling the %s kernels ahead (numba, first use with this cache), beside the data "
        "loading; cached in %s",
        ", ".join(m.rsplit(".", 1)[-1] for m in cold),
        numba.config.CACHE_DIR,
    )
    _AHEAD.update(dict.fromkeys(cold, process))


atexit.register(_stop_compiles)


def ensure_compiled(module: str) -> None:
    """Before the first call of ``module``'s kernels in this process: have them compiled into
    the cache by another process, so that this one runs them as loaded from it (see above):
    wait for their compile ahead, if one runs, else start one and wait when the cache has no
    compiled code of them (one line says so: their first compile takes about half a minute,
    during which nothing else is printed). Only if that process fails are they compiled here."""
    if module in _CHECKED or _COMPILER:
        return
    _CHECKED.add(module)
    stem = module.rsplit(".", 1)[-1]
    process = _AHEAD.pop(module, None)
    if process is None and not _cached(module):
        log.info(
            "compiling the %s kernels (numba, first use with this cache: about half a minute, "
            "in another process; cached in %s after)",
            stem,
            numba.config.CACHE_DIR,
        )
        process = _compile_elsewhere([module])
    elif process is not None and process.poll() is None:
        log.info("waiting for the %s kernels' compile ahead to finish", stem)
    if process is not None:
        process.wait()
    if not _cached(module):  # that process failed: compiled here, on first call
        log.warning(
            "compiling the %s kernels in this process: their compile in another process failed "
            "(its error is above); results may then differ from a run that loads them from the "
            "cache in %s in their last bits",
            stem,
            numba.config.CACHE_DIR,
        )


def check_rows(rows: Sized, n: int, kernel: str) -> None:
    """Refuse row indices (an integer tensor or array) outside [0, ``n``): the compiled kernels
    read the rows of their input without bounds checks."""
    if len(rows) and not 0 <= int(rows.min()) <= int(rows.max()) < n:
        raise IndexError(f"{kernel}: rows must lie in [0, {n}), the rows of the input")


__all__ = ["check_rows", "compile_ahead", "ensure_compiled", "numba"]

"""SIGTERM as an exception that never lands inside an MLflow write.

SLURM and `kill` send SIGTERM, and a terminated sweep forwards it to its workers. The job unwinds
it like an error, so its runs end FAILED rather than RUNNING. Raised in the middle of a sqlite
transaction, though, it left the connection unusable, so marking the run FAILED failed as well and
the run stayed RUNNING. Inside ``shielded()`` the signal is therefore held back and raised as
soon as the write is done.

A SIGTERM that lands in a ctypes callback (llvmlite's, while numba compiles) raises there, and
ctypes prints the exception and drops it: the job trained on as if never signalled. The signal is
therefore also remembered, and ``check()`` (each adjective, each epoch) raises it again.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

_state = {"depth": 0, "pending": 0, "received": 0}


class Terminated(SystemExit):
    """SIGTERM, unwound like an error so MLflow runs end FAILED, not RUNNING."""


def handle(signum: int, frame: object) -> None:
    """The SIGTERM handler: raise now, or at the end of the write in progress."""
    _state["received"] = signum
    if _state["depth"]:
        _state["pending"] = signum
        return
    raise Terminated(f"terminated by signal {signum}")


@contextmanager
def shielded() -> Iterator[None]:
    """Hold SIGTERM back while the block runs; raise it afterwards if it came."""
    _state["depth"] += 1
    try:
        yield
    finally:
        _state["depth"] -= 1
    if not _state["depth"] and _state["pending"]:
        signum, _state["pending"] = _state["pending"], 0
        raise Terminated(f"terminated by signal {signum}")


def check() -> None:
    """Raise a SIGTERM this process received, in case the handler's exception was dropped."""
    if _state["received"] and not _state["depth"]:
        raise Terminated(f"terminated by signal {_state['received']}")


def reason(err: BaseException) -> BaseException:
    """What ended the work: ``err``, or the SIGTERM this process received when ``err`` is another
    error. A signal that lands inside an import or a class body reaches the caller wrapped
    (Python re-raises it as ``RuntimeError: Error calling __set_name__ ...``); the job must stop
    and record the signal, not the wrapper."""
    if _state["received"] and not isinstance(err, Terminated):
        return Terminated(f"terminated by signal {_state['received']}")
    return err


def received() -> int:
    """The SIGTERM this process received, 0 if none."""
    return _state["received"]

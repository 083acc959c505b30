"""User errors: one line at the edges (the CLI job and the sweep callback), ``error: ...``
and exit status 2, with no traceback unless ``HYDRA_FULL_ERROR=1``.

``ConfigError`` lives here, below the config edge, so that a component (a store, a modality, the
sweep) can raise it without importing ``config``, which imports the registries of components;
``TrackingError`` likewise, so that this module sits below the tracking store."""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager

from tactile_exp.data.layout import DataError


class ConfigError(ValueError):
    """An impossible config value, reported before any work starts."""


class NotACell(ConfigError):
    """A combination that does not exist rather than a mistake: a fold beyond the folds a data
    set declares, a modality that reads channels a data set does not record. A single run is
    refused like any ConfigError; a sweep lists such a cell as absent, not invalid, and runs the
    others (a benchmark's grid of models x data sets x folds is rectangular, its data sets not)."""


class TrackingError(RuntimeError):
    """The tracking store cannot be used (e.g. the server is down): reported before any work."""


USER_ERRORS = (ConfigError, DataError, TrackingError)
EXIT_USER_ERROR = 2


@contextmanager
def reported() -> Iterator[None]:
    """Turn a bad value, bad file or unreachable store into one line and exit 2."""
    try:
        yield
    except USER_ERRORS as err:
        if os.environ.get("HYDRA_FULL_ERROR") == "1":
            raise
        print(f"error: {err}", file=sys.stderr, flush=True)
        sys.exit(EXIT_USER_ERROR)

"""The modules a job's config names under ``_module_``: what registers its components kept
outside the package (a model, a modality, a data source, at any depth of the config).

A job imports them when its config is checked (``config``); whatever reads a finished job back
(predict, deploy, the report) imports them again from the job's logged config, before it looks
a component up: ``import_modules(job_config, where)``.
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from typing import Any

KEY = "_module_"


class PluginError(ImportError):
    """A ``_module_`` that does not import; the message names the config key and the module."""


def modules(config: Any, prefix: str = "") -> dict[str, str]:
    """``{dotted config key: module}`` of every ``_module_`` in ``config``, in config order."""
    out: dict[str, str] = {}
    if isinstance(config, Mapping):
        for key, value in config.items():
            if key == KEY and value:
                out[f"{prefix}{KEY}"] = str(value)
            else:
                out |= modules(value, f"{prefix}{key}.")
    elif isinstance(config, list | tuple):
        for i, value in enumerate(config):
            out |= modules(value, f"{prefix}{i}.")
    return out


def import_modules(config: Any, where: str) -> None:
    """Import every module ``config`` names (``modules``); ``where`` (a run, a file) starts the
    one-line PluginError of a module that does not import."""
    for key, module in modules(config).items():
        try:
            importlib.import_module(module)
        except ImportError as err:
            raise PluginError(
                f"{where}: {key} {module!r} cannot be imported ({err}); run from the folder "
                "that holds it or put that folder on PYTHONPATH"
            ) from None

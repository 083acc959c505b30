"""Classifiers, registered by the names the ``model`` config group uses (`MODELS`)."""

from tactile_exp.models.base import Model
from tactile_exp.models.registry import MODELS

__all__ = ["MODELS", "Model"]

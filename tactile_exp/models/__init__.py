"""Classifiers, registered by the names the ``model`` config group uses."""

from tactile_exp.models.base import Instances, Model
from tactile_exp.registry import Registry

MODELS: Registry[Model] = Registry("model", Model)

__all__ = ["MODELS", "Instances", "Model"]

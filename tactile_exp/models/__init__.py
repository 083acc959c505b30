"""Classifiers, registered by the names the ``model`` config group uses."""

from tactile_exp.models.base import Instances, Model
from tactile_exp.registry import Registry

MODELS: Registry[Model] = Registry("model", Model)

__all__ = ["MODELS", "Instances", "Model"]

# Import the implementations so they register themselves (explicit: import errors stay visible).
from tactile_exp.baselines import svm  # noqa: E402, F401  (linear_svm, Chu et al.'s classifier)
from tactile_exp.models import googlenet, haptic_cnn, haptic_lstm, linear, random_guess  # noqa: E402, F401

"""Chu et al.'s hand-designed baselines (Table I rows A-F): static and HMM features, linear SVM.

Importing this package registers the ``linear_svm`` model in `tactile_exp.models.MODELS`.
"""

from tactile_exp.baselines.features import BaselineFeatures
from tactile_exp.baselines.svm import LinearSVMModel, ObjectCVLinearSVM

__all__ = ["BaselineFeatures", "LinearSVMModel", "ObjectCVLinearSVM"]

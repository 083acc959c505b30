"""Chu et al.'s hand-designed baselines (Table I rows A-F): static and HMM features.

Their classifier, the linear SVM, is the ``linear_svm`` model (`tactile_exp.models.linear_svm`).
"""

from tactile_exp.baselines.features import BaselineFeatures

__all__ = ["BaselineFeatures"]

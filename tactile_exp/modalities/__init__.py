"""What a model sees: the ``modality`` config group, one module per modality."""

from tactile_exp.modalities.base import MODALITIES, Modality

__all__ = ["MODALITIES", "Modality"]

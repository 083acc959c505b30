"""Haptic (P1-P6) and visual (V1-V2) preprocessing, cached on disk after one pass over the data."""

from tactile_exp.preprocess.haptic import (
    HapticArrays,
    HapticPreprocessor,
    downsample_pac,
    load_haptic_arrays,
    resample,
)
from tactile_exp.preprocess.visual import (
    VisualArrays,
    VisualFeatures,
    crop_plate,
    find_plate,
    load_visual_arrays,
)

__all__ = [
    "HapticArrays",
    "HapticPreprocessor",
    "VisualArrays",
    "VisualFeatures",
    "crop_plate",
    "downsample_pac",
    "find_plate",
    "load_haptic_arrays",
    "load_visual_arrays",
    "resample",
]

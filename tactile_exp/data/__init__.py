"""Data sets: the `DataSet` protocol, its sources (PHAC-2 and the folder layout), splits and
validation."""

from tactile_exp.data.dataset import DataSet, Sensor, select_labels
from tactile_exp.data.folder import FolderDataSet
from tactile_exp.data.layout import DataError, Instances
from tactile_exp.data.phac2 import PHAC2, default_cache_dir, load_photograph
from tactile_exp.data.splits import SPLITS, check_split, make_split
from tactile_exp.data.validate import summary, validate

__all__ = [
    "PHAC2",
    "SPLITS",
    "DataError",
    "DataSet",
    "FolderDataSet",
    "Instances",
    "Sensor",
    "check_split",
    "default_cache_dir",
    "load_photograph",
    "make_split",
    "select_labels",
    "summary",
    "validate",
]

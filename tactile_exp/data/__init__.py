"""PHAC-2 data: layout records, the HDF5 reader, splits and validation."""

from tactile_exp.data.layout import DataError, Instances
from tactile_exp.data.phac2 import PHAC2, default_cache_dir, load_photograph
from tactile_exp.data.splits import SPLITS, check_split, make_split
from tactile_exp.data.validate import summary, validate

__all__ = [
    "PHAC2",
    "SPLITS",
    "DataError",
    "Instances",
    "check_split",
    "default_cache_dir",
    "load_photograph",
    "make_split",
    "summary",
    "validate",
]

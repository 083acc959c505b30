"""PHAC-2 data: layout records, the HDF5 reader, splits and validation."""

from tactile_exp.data.phac2 import PHAC2, DataError, default_cache_dir, load_photograph
from tactile_exp.data.splits import SPLITS, check_split
from tactile_exp.data.validate import summary, validate

__all__ = [
    "PHAC2",
    "SPLITS",
    "DataError",
    "check_split",
    "default_cache_dir",
    "load_photograph",
    "summary",
    "validate",
]

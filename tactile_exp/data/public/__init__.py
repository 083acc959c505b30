"""Public touch data sets by recipe: ``python -m tactile_exp.data public list|import``.

`recipe` reads the declarative recipes (``recipes/*.yaml``, registered in ``RECIPES``) and their
frozen folds (``folds/*.yaml``); `readers` turns an upstream file into trials; `importer` checks
the upstream's files against a recipe and writes the folder layout (docs/public-data.md).
"""

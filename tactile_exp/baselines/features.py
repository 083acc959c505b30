"""Per-split baseline features, what the engine calls per adjective (Table I rows A-F).

Rows: A = static, 1 trial; B = static, 10 trials (the engine pools per object); C = dynamic,
1 trial; D = dynamic, 10 trials (engine pooling); E = A + C (features static + dynamic);
F = A + D (static + dynamic with ``dynamic_pool="object"``: each trial's static vector followed by
the mean dynamic vector of its object's trials on the same side of the split).

The data file is read once per data set and settings (one trial at a time); the reduced tables
are memoised in-process and, with ``cache_dir``, saved on disk (atomic write). With ``cache_dir``
the fitted HMM chains of each adjective are saved too, keyed by the data, the split's membership
and labels, and the chain settings and seed, so rows C, D, E and F fit each chain once (and, in
one process, load it once and score every trial once).
"""

from __future__ import annotations

import sys
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from tactile_exp.baselines.dynamic import GRIDS, DynamicFeatures, SequenceTable
from tactile_exp.baselines.static import (
    AUTHORS_F_MAX,
    GRIPPER_NAMES,
    TRANSFORM_NAMES,
    FeatureWarning,
    StaticFeatures,
    StaticTable,
    trial_static,
    warn_fills,
)
from tactile_exp.data.layout import Split, TrialName
from tactile_exp.preprocess.cache import cache_key, load_arrays, save_arrays

FEATURE_KINDS = ("static", "dynamic")
POOLS = ("trial", "object")
CODE_VERSION = 1  # bump when a feature definition changes, so old caches are not reused
OPTIONAL_NAMES = (*GRIPPER_NAMES, *TRANSFORM_NAMES)
_MEMO: dict[str, Any] = {}


def _trials(dataset: Any) -> list[str]:
    return [t.name if isinstance(t, TrialName) else str(t) for t in dataset.trials]


def _read(dataset: Any, names: list[str]):
    """Yield the trials one at a time with a progress line every 10%."""
    step = max(1, len(names) // 10)
    source = (
        dataset.iter_trials(names)
        if hasattr(dataset, "iter_trials")
        else map(dataset.read_trial, names)
    )
    for i, trial in enumerate(source, 1):
        if i % step == 0 or i == len(names):
            print(f"baseline features: read {i}/{len(names)} trials", file=sys.stderr, flush=True)
        yield trial


def build_tables(
    dataset: Any,
    static_f_max: float | None | bool = False,
    lengths: Sequence[int] = (),
    cache_dir: Path | None = None,
) -> tuple[StaticTable | None, SequenceTable | None]:
    """Static table (when ``static_f_max`` is not False) and sequence table (when ``lengths``).

    Cached in-process and under ``cache_dir``; the file is read once for whatever is missing.
    """
    identity = dataset.identity()
    keys = {
        "static": cache_key(kind="static", data=identity, f_max=static_f_max, v=CODE_VERSION),
        "dynamic": cache_key(kind="dynamic", data=identity, lengths=list(lengths), v=CODE_VERSION),
    }
    want = {"static": static_f_max is not False, "dynamic": bool(lengths)}
    out: dict[str, Any] = {}
    for kind, needed in want.items():
        if not needed:
            continue
        if keys[kind] in _MEMO:
            out[kind] = _MEMO[keys[kind]]
        elif cache_dir is not None:
            path = Path(cache_dir) / f"baseline_{kind}_{keys[kind]}.npz"
            if kind == "static":
                arrays = load_arrays(path, StaticTable.KEYS)
                out[kind] = None if arrays is None else StaticTable.from_arrays(arrays)
            else:
                arrays = load_arrays(path, SequenceTable.keys(lengths))
                out[kind] = None if arrays is None else SequenceTable.from_arrays(arrays, lengths)
    missing = [k for k, needed in want.items() if needed and out.get(k) is None]
    if missing:
        names = _trials(dataset)
        records, trials, fills = [], [], []
        for trial in _read(dataset, names):
            if "static" in missing:
                records.append(trial_static(trial, static_f_max, fills))  # type: ignore[arg-type]
            if "dynamic" in missing:
                trials.append(SequenceTable.from_trials([trial], lengths))
        if "static" in missing:
            warn_fills(fills)
            out["static"] = StaticTable.from_records(names, records)
            absent = [n for n in OPTIONAL_NAMES if n not in out["static"].names]
            if absent:
                warnings.warn(
                    f"{dataset!r}: no {absent} in every trial (gripper or transforms channel "
                    "missing); those static features are left out",
                    FeatureWarning,
                    2,
                )
        if "dynamic" in missing:
            out["dynamic"] = _concat_sequences(trials, lengths)
        for kind in missing:
            if cache_dir is not None:
                path = Path(cache_dir) / f"baseline_{kind}_{keys[kind]}.npz"
                save_arrays(path, out[kind].arrays())
    for kind in out:
        _MEMO[keys[kind]] = out[kind]
    return out.get("static"), out.get("dynamic")


def _concat_sequences(parts: list[SequenceTable], lengths: Sequence[int]) -> SequenceTable:
    n = len(parts[0].mean)
    return SequenceTable(
        [t for p in parts for t in p.trials],
        np.concatenate([p.count for p in parts]),
        [np.concatenate([p.mean[c] for p in parts]) for c in range(n)],
        [np.concatenate([p.scatter[c] for p in parts]) for c in range(n)],
        {T: [np.concatenate([p.seqs[T][c] for p in parts]) for c in range(n)] for T in lengths},
    )


@dataclass
class FittedFeatures:
    """What ``BaselineFeatures.fit`` learned for one adjective: the static base names kept and
    their PCA, and the adjective's HMM chains; applied to any trials' tables."""

    static: StaticFeatures | None
    static_names: list[str]
    dynamic: DynamicFeatures | None
    dynamic_pool: str

    def state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        settings: dict[str, Any] = {}
        arrays: dict[str, np.ndarray] = {}
        if self.static is not None:
            settings["static_names"] = list(self.static_names)
            arrays |= {f"static.{k}": v for k, v in self.static.arrays().items()}
        if self.dynamic is not None:
            arrays |= {f"dynamic.{k}": v for k, v in self.dynamic.arrays().items()}
        return settings, arrays

    @classmethod
    def from_state(
        cls, params: dict[str, Any], settings: dict[str, Any], arrays: dict[str, np.ndarray]
    ) -> FittedFeatures:
        """``state()``'s output back, with the modality's ``params`` (features, faithful, ...)."""
        static = dynamic = None
        names: list[str] = []
        if "static" in params["features"]:
            faithful = bool(params["faithful"])
            static = StaticFeatures(per_trial_pca=faithful, interleave=faithful)
            static.load_arrays({k.removeprefix("static."): v for k, v in arrays.items()})
            names = [str(n) for n in settings["static_names"]]
        if "dynamic" in params["features"]:
            dynamic = DynamicFeatures(str(params["hmm_grid"]), seed=int(params["seed"]))
            dynamic.load_arrays({k.removeprefix("dynamic."): v for k, v in arrays.items()})
        return cls(static, names, dynamic, str(params["dynamic_pool"]))


class BaselineFeatures:
    """Chu et al.'s static and/or dynamic features of a data set's trials: the per-trial tables
    (``prepare``, cached), fitted on one adjective's training trials (``fit``)."""

    def __init__(
        self,
        dataset: Any,
        features: Sequence[str] = ("static",),
        faithful: bool = True,
        dynamic_pool: str = "trial",
        hmm_grid: str = "small",
        cache_dir: Path | None = None,
        seed: int = 0,
    ) -> None:
        unknown = sorted(set(features) - set(FEATURE_KINDS))
        if unknown or not features:
            raise ValueError(
                f"features {list(features)}: expected a non-empty subset of {FEATURE_KINDS}"
            )
        if dynamic_pool not in POOLS:
            raise ValueError(f"dynamic_pool {dynamic_pool!r}: expected one of {POOLS}")
        if hmm_grid not in GRIDS:
            raise ValueError(f"hmm_grid {hmm_grid!r}: expected one of {tuple(GRIDS)}")
        self.dataset = dataset
        self.features = tuple(k for k in FEATURE_KINDS if k in features)
        self.faithful = faithful
        self.dynamic_pool = dynamic_pool
        self.hmm_grid = hmm_grid
        self.cache_dir = cache_dir
        self.seed = seed
        self.feature_names: list[str] = []

    def prepare(self) -> None:
        """Read the file once into the per-trial tables every adjective shares (cached on disk);
        bad input fails here, before any fitting."""
        self.static_table_, self.sequence_table_ = build_tables(
            self.dataset,
            static_f_max=(AUTHORS_F_MAX if self.faithful else None)
            if "static" in self.features
            else False,
            lengths=DynamicFeatures.lengths(self.hmm_grid) if "dynamic" in self.features else (),
            cache_dir=self.cache_dir,
        )

    def fit(self, split: Split) -> BaselineFeatures:
        """Fit what depends on the split on ``split.train`` only (HMMs: training positives)."""
        if not hasattr(self, "static_table_"):
            self.prepare()
        self.feature_names = []
        static = dynamic = None
        if self.static_table_ is not None:
            static = StaticFeatures(per_trial_pca=self.faithful, interleave=self.faithful)
            static.fit(self.static_table_, split.train)
            self.feature_names += static.feature_names(self.static_table_)
        if self.sequence_table_ is not None:
            dynamic = self._fit_dynamic(split)
            suffix = "@object" if self.dynamic_pool == "object" else ""
            self.feature_names += [n + suffix for n in dynamic.feature_names]
        names = list(self.static_table_.names) if self.static_table_ is not None else []
        self.fitted_ = FittedFeatures(static, names, dynamic, self.dynamic_pool)
        return self

    def fitted(self) -> FittedFeatures:
        return self.fitted_

    def _fit_dynamic(self, split: Split) -> DynamicFeatures:
        """The adjective's 16 chains: loaded from ``cache_dir`` when fitted before, else fitted
        (and saved there)."""
        dynamic = DynamicFeatures(self.hmm_grid, seed=self.seed)
        if self.cache_dir is None:
            return dynamic.fit(self.sequence_table_, split)
        key = self._chain_key(split, dynamic)
        path = Path(self.cache_dir) / f"baseline_hmm_{split.adjective}_{key}.npz"
        if str(path) in _MEMO:  # an earlier row of this process: its scores come along
            return _MEMO[str(path)]
        arrays = load_arrays(path, DynamicFeatures.KEYS)
        if arrays is not None:
            dynamic.load_arrays(arrays)
        else:
            dynamic.fit(self.sequence_table_, split)
            save_arrays(path, dynamic.arrays())
        _MEMO[str(path)] = dynamic
        return dynamic

    def _chain_key(self, split: Split, dynamic: DynamicFeatures) -> str:
        """Cache key of one adjective's fitted chains: data, training trials, settings, seed."""
        return cache_key(
            kind="hmm",
            data=self.dataset.identity(),
            adjective=split.adjective,
            train=sorted(split.train),
            labels=sorted((t, split.labels[t]) for t in split.train),
            settings=dynamic.settings(),
            v=CODE_VERSION,
        )

    def transform(self, trials: Sequence[str]) -> np.ndarray:
        """(n, D) float features of ``trials`` by this object's own fit."""
        if not hasattr(self, "fitted_"):
            raise RuntimeError("BaselineFeatures.transform called before fit")
        return self.transform_with(self.fitted_, trials)

    def transform_with(self, fitted: FittedFeatures, trials: Sequence[str]) -> np.ndarray:
        """(n, D) float features of ``trials`` (from this object's tables) by ``fitted``; never
        NaN. Object pooling (row F) averages over the trials of each object among ``trials``."""
        if not hasattr(self, "static_table_"):
            self.prepare()
        trials = list(trials)
        blocks = []
        if fitted.static is not None:
            blocks.append(fitted.static.transform(self._static_table(fitted), trials))
        if fitted.dynamic is not None:
            X = fitted.dynamic.transform(self.sequence_table_, trials)
            if fitted.dynamic_pool == "object":
                objects = np.array([TrialName.parse(t).object_id for t in trials])  # type: ignore[union-attr]
                X = np.stack([X[objects == o].mean(axis=0) for o in objects])
            blocks.append(X)
        X = np.hstack(blocks).astype(float)
        if not np.isfinite(X).all():
            raise FloatingPointError("baseline features: non-finite values (a bug, please report)")
        return X

    def _static_table(self, fitted: FittedFeatures) -> StaticTable:
        """The static table with the base features ``fitted`` kept, in its order."""
        table = self.static_table_
        if list(table.names) == fitted.static_names:
            return table
        lacking = [n for n in fitted.static_names if n not in table.names]
        if lacking:
            raise ValueError(
                f"{self.dataset!r}: trials lack static features {lacking} that the model was "
                "trained with (gripper or transforms channel missing)"
            )
        order = [table.names.index(n) for n in fitted.static_names]
        return replace(table, base=table.base[:, :, order], names=list(fitted.static_names))

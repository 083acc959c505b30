"""The ``haptic_features`` modality: Chu et al.'s hand-designed features, one row per trial."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from tactile_exp.data.layout import Instances, Split, TrialData
from tactile_exp.data.phac2 import PHAC2
from tactile_exp.modalities.base import MODALITIES, Modality, trial_rows


@MODALITIES.register("haptic_features")
class HapticFeatures(Modality):
    """Chu et al.'s hand-designed features (M5): one vector per trial."""

    def __init__(self, dataset: PHAC2, cache_dir: Path, **settings: Any) -> None:
        """``settings``: BaselineFeatures' (features, faithful, dynamic_pool, hmm_grid, ...)."""
        super().__init__(dataset, cache_dir)
        from tactile_exp.baselines.features import BaselineFeatures

        self.features = BaselineFeatures(dataset, cache_dir=cache_dir, **settings)

    def prepare(self) -> None:
        self.features.prepare()

    def instances(self, split: Split) -> tuple[Instances, Instances]:
        self.features.fit(split)
        out = []
        for trials in (split.train, split.test):
            X = self.features.transform(trials).astype(np.float32)
            out.append(Instances(X, *trial_rows(trials, split, 1)))
        return out[0], out[1]

    def state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        """The feature settings, the static base names kept, the static PCA and the adjective's
        HMM chains as fitted for the last split: what ``trial_features`` needs for new trials."""
        f = self.features
        settings: dict[str, Any] = dict(
            modality="haptic_features", features=list(f.features), faithful=f.faithful,
            dynamic_pool=f.dynamic_pool, hmm_grid=f.hmm_grid,
        )  # fmt: skip
        arrays: dict[str, np.ndarray] = {}
        if f.static_table_ is not None:
            settings["static_names"] = list(f.static_table_.names)
            arrays |= {f"static.{k}": v for k, v in f.static_.arrays().items()}
        if f.sequence_table_ is not None:
            arrays |= {f"dynamic.{k}": v for k, v in f.dynamic_.arrays().items()}
        return settings, arrays


def trial_features(
    trials: Sequence[TrialData], settings: Mapping[str, Any], arrays: Mapping[str, np.ndarray]
) -> np.ndarray:
    """(n, D) features of ``trials`` (from any file) as the modality fitted in ``state()`` gave
    them, for predict. Row F's object pooling averages the dynamic vectors of the given trials
    of each object (training pooled an object's trials on its side of the split: all of a test
    object's trials)."""
    from tactile_exp.baselines.dynamic import DynamicFeatures, SequenceTable
    from tactile_exp.baselines.static import (
        AUTHORS_F_MAX,
        StaticFeatures,
        StaticTable,
        trial_static,
    )

    names = [t.name.name for t in trials]
    blocks = []
    if "static" in settings["features"]:
        faithful = bool(settings["faithful"])
        fills: list[str] = []
        records = [trial_static(t, AUTHORS_F_MAX if faithful else None, fills) for t in trials]
        table = StaticTable.from_records(names, records)
        kept = [str(n) for n in settings["static_names"]]
        lacking = [n for n in kept if n not in table.names]
        if lacking:
            raise ValueError(
                f"trials {names} lack static features {lacking} that the model was trained with "
                "(gripper or transforms channel missing)"
            )
        table.base = table.base[:, :, [table.names.index(n) for n in kept]]
        table.names = kept
        static = StaticFeatures(per_trial_pca=faithful, interleave=faithful)
        static.load_arrays({k.removeprefix("static."): v for k, v in arrays.items()})
        blocks.append(static.transform(table, names))
    if "dynamic" in settings["features"]:
        dynamic = DynamicFeatures(str(settings["hmm_grid"]))
        dynamic.load_arrays({k.removeprefix("dynamic."): v for k, v in arrays.items()})
        lengths = sorted({T for _, T, _ in dynamic.params_})
        X = dynamic.transform(SequenceTable.from_trials(trials, lengths), names)
        if settings["dynamic_pool"] == "object":
            objects = np.array([t.name.object_id for t in trials])
            X = np.stack([X[objects == o].mean(axis=0) for o in objects])
        blocks.append(X)
    return np.hstack(blocks).astype(np.float32)

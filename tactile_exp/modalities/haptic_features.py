"""The ``haptic_features`` modality: Chu et al.'s hand-designed features, one row per trial."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any, Self

import numpy as np

from tactile_exp.data.dataset import PHAC2_LAYOUT
from tactile_exp.data.layout import Instances, Split, TrialData, TrialName, Trials
from tactile_exp.modalities.base import MODALITIES, Modality, trial_rows


class _Chosen:
    """Some trials of a data set, read with their optional channels (the static features use
    the gripper and the hand transforms): new trials, as ``build_tables`` reads a data set."""

    def __init__(self, dataset: Any, names: Iterable[str]) -> None:
        self.dataset = dataset
        self.trials = tuple(dataset.trial_name(t) for t in names)

    def iter_trials(self, names: Iterable[TrialName] | None = None) -> Iterator[TrialData]:
        return self.dataset.iter_trials(self.trials if names is None else names)

    def identity(self) -> str:
        return f"{self.dataset.identity()}:{','.join(t.name for t in self.trials)}"

    def __repr__(self) -> str:
        return repr(self.dataset)


# The checked data set's feature tables, shared by every adjective's pipeline in this process.
_CHECKED: dict[tuple[Any, ...], Any] = {}


@MODALITIES.register("haptic_features")
class HapticFeatures(Modality):
    """Chu et al.'s hand-designed features (M5): one vector per trial.

    ``check`` builds the per-trial tables every adjective shares (cached on disk); ``fit`` the
    static PCA and the adjective's HMM chains on the training trials (chains: cached too).
    ``dynamic_pool="object"`` (row F) appends to each trial the mean dynamic vector of the
    trials of its object among those transformed: one side of a split, or a new object's.
    """

    needs_layout = PHAC2_LAYOUT  # the gripper, hand transforms and EP states of each trial
    emits = "features"
    onnx_refusal = "its hand-designed features are computed by this package's code, not a network"

    def __init__(
        self,
        *,
        cache_dir: Path | None = None,
        features: tuple[str, ...] | list[str] = ("static",),
        faithful: bool = True,
        dynamic_pool: str = "trial",
        hmm_grid: str = "small",
        seed: int = 0,
    ) -> None:
        from tactile_exp.baselines.features import BaselineFeatures

        super().__init__(cache_dir=cache_dir)
        self.settings: dict[str, Any] = dict(
            features=tuple(features), faithful=faithful, dynamic_pool=dynamic_pool,
            hmm_grid=hmm_grid, seed=seed,
        )  # fmt: skip
        BaselineFeatures(None, **self.settings)  # its checks, before any run

    def _key(self, dataset: Any) -> tuple[Any, ...]:
        return dataset.identity(), repr(sorted(self.settings.items()))

    def _features(self, dataset: Any, names: tuple[str, ...] = ()) -> Any:
        """The feature tables of ``dataset``: the checked ones, else those of ``names``."""
        from tactile_exp.baselines.features import BaselineFeatures

        checked = _CHECKED.get(self._key(dataset))
        if checked is not None:
            return checked
        features = BaselineFeatures(_Chosen(dataset, names), **self.settings)
        features.prepare()
        return features

    def check(self, dataset: Any) -> None:
        from tactile_exp.baselines.features import BaselineFeatures

        features = BaselineFeatures(dataset, cache_dir=self.cache_dir, **self.settings)
        features.prepare()
        _CHECKED.clear()
        _CHECKED[self._key(dataset)] = features

    def fit(self, trials: Trials) -> Self:
        features = self._features(trials.dataset, trials.names)
        features.fit(Split(trials.label, trials.names, (), dict(trials.labels or {})))
        self.fitted_ = features.fitted()
        return self

    def transform(self, trials: Trials) -> Instances:
        features = self._features(trials.dataset, trials.names)
        X = features.transform_with(self.fitted_, trials.names).astype(np.float32)
        return Instances(X, *trial_rows(trials, 1))

    def get_state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        """The static base names kept, the static PCA and the adjective's HMM chains."""
        return self.fitted_.state()

    def set_state(self, settings: dict[str, Any], arrays: dict[str, np.ndarray]) -> Self:
        from tactile_exp.baselines.features import FittedFeatures

        self.fitted_ = FittedFeatures.from_state(self.settings, settings, arrays)
        return self

"""The ``haptic`` modality: BioTac P1-P6 signals, one instance per finger and offset of a trial."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any, Self

import numpy as np

from tactile_exp.data.dataset import PHAC2_LAYOUT
from tactile_exp.data.layout import Instances, InstanceSpec, TrialData, TrialName, Trials
from tactile_exp.modalities.base import MODALITIES, Modality, trial_rows
from tactile_exp.models.scratch import empty_on_huge_pages

if TYPE_CHECKING:
    from tactile_exp.modalities.networks import Load, Network


class _Chosen:
    """Some trials of a data set, as ``compute_haptic_arrays`` reads a data set: their BioTac
    frames and states only (the other signals, a sixth of the reading, are not read)."""

    def __init__(self, dataset: Any, names: Iterable[str]) -> None:
        self.dataset = dataset
        self.trials = tuple(dataset.trial_name(t) for t in names)

    def iter_trials(self, names: Iterable[TrialName] | None = None) -> Iterator[TrialData]:
        return self.dataset.iter_trials(self.trials if names is None else names, optional=False)

    def identity(self) -> str:
        return self.dataset.identity()


# The checked data set's arrays, shared by every adjective's pipeline in this process.
_CHECKED: dict[tuple[Any, ...], Any] = {}


@MODALITIES.register("haptic")
class Haptic(Modality):
    """P1-P6: each trial gives 2 fingers x ``offsets`` instances of (32 signals, ``steps``).

    ``check`` computes (or loads from ``cache_dir``) every trial's resampled signals and
    statistics once per data set; ``fit`` is then small algebra on the training trials'
    statistics (``preprocess.haptic.HapticPreprocessor``). Trials of a data set that was not
    checked (a new object's, in predict) are read when transformed.
    """

    needs_layout = PHAC2_LAYOUT  # reads each trial's BioTac frames and EP states
    emits = "signals"
    onnx_refusal = None  # the ConvNet or LSTM on its instances, then the layer or T4's head

    def __init__(
        self,
        *,
        cache_dir: Path | None = None,
        steps: int = 150,
        offsets: int = 5,
        pca_components: int = 4,
        pac_downsample: str = "subsample",
        per_finger: bool = True,
        fit_on: str = "train",
    ) -> None:
        super().__init__(cache_dir=cache_dir)
        from tactile_exp.preprocess.haptic import N_ELECTRODES, check_settings

        check_settings(steps, offsets, pac_downsample)  # before any run
        if not isinstance(pca_components, int) or not 1 <= pca_components <= N_ELECTRODES:
            raise ValueError(
                f"pca_components must be an integer in 1..{N_ELECTRODES} (electrodes per "
                f"BioTac), got {pca_components!r}"
            )
        if fit_on not in ("train", "all"):
            raise ValueError(f"modality.fit_on must be 'train' or 'all', got {fit_on!r}")
        self.steps, self.offsets, self.pac_downsample = steps, offsets, pac_downsample
        self.pca_components = pca_components
        self.per_finger = per_finger
        self.fit_on = fit_on

    @classmethod
    def onnx_network(
        cls, load: Load, settings: dict[str, Any], keeps: bool, combine: int
    ) -> Network:
        """Row H (instances one by one); I and J (``combine`` trials' conv3, then the head)."""
        from tactile_exp.modalities import networks as nets

        model = load("model")
        shape = list(model.input_shape_)
        if keeps:
            net = nets.DecisionNet(model.body_, *nets.layer(model))
            return nets.Network(
                net, {"instances": [None, *shape]}, {"haptic": nets.haptic_layout(settings, 1)}
            )
        count = combine * nets.FINGERS * int(settings["offsets"])
        net = nets.DecisionNet(model.body_, *nets.layer(load("head")), per_unit=True)
        layout = nets.haptic_layout(settings, combine)
        return nets.Network(net, {"instances": [None, count, *shape]}, {"haptic": layout})

    def output(self, dataset: Any) -> InstanceSpec:
        from tactile_exp.preprocess.haptic import EP_NAMES, N_SCALAR

        channels = len(EP_NAMES) * (N_SCALAR + self.pca_components)  # 32 by default (P4)
        return InstanceSpec(self.emits, (channels, self.steps))

    def _key(self, dataset: Any) -> tuple[Any, ...]:
        return dataset.identity(), self.steps, self.offsets, self.pac_downsample

    def check(self, dataset: Any) -> None:
        from tactile_exp.preprocess.haptic import load_haptic_arrays

        every = _Chosen(dataset, dataset.trials)  # BioTac frames only, none of the other signals
        arrays = load_haptic_arrays(
            every, self.steps, self.offsets, self.pac_downsample, cache_dir=self.cache_dir
        )
        _CHECKED.clear()  # one data set's arrays in memory at a time (they can be large)
        _CHECKED[self._key(dataset)] = arrays

    def arrays(self, trials: Trials) -> Any:
        """The resampled signals holding ``trials``: the checked data set's, else read now."""
        from tactile_exp.preprocess.haptic import compute_haptic_arrays

        checked = _CHECKED.get(self._key(trials.dataset))
        if checked is not None:
            return checked
        chosen = _Chosen(trials.dataset, trials.names)
        return compute_haptic_arrays(chosen, self.steps, self.offsets, self.pac_downsample)

    def fit(self, trials: Trials) -> Self:
        from tactile_exp.preprocess.haptic import HapticPreprocessor

        arrays = self.arrays(trials)
        pre = HapticPreprocessor(arrays, self.pca_components, self.per_finger)
        self.state_ = pre.fit(trials.names if self.fit_on == "train" else arrays.trials).state()
        return self

    def transform(self, trials: Trials) -> Instances:
        from tactile_exp.preprocess.haptic import EP_NAMES, N_SCALAR, HapticPreprocessor

        pre = HapticPreprocessor(self.arrays(trials), self.pca_components, self.per_finger)
        # on huge pages: a fit trains on these rows in place (``scratch.on_huge_pages``)
        out = empty_on_huge_pages(
            len(trials.names),
            2,
            self.offsets,
            len(EP_NAMES),
            N_SCALAR + self.pca_components,
            self.steps,
        )
        X = pre.restore(self.state_).transform(trials.names, out)  # (n, 2, offsets, 32, steps)
        per_trial = X.shape[1] * X.shape[2]
        return Instances(X.reshape(-1, *X.shape[3:]), *trial_rows(trials, per_trial))

    def get_state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        """P1's normaliser and P4's PCA as fitted."""
        return {}, dict(self.state_)

    def set_state(self, settings: dict[str, Any], arrays: dict[str, np.ndarray]) -> Self:
        from tactile_exp.preprocess.haptic import HapticPreprocessor

        HapticPreprocessor.check_state(arrays, self.pca_components)
        self.state_ = dict(arrays)
        return self

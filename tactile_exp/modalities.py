"""What a model sees: the ``modality`` config group.

A modality turns one adjective's split into training and test ``Instances``, fitting whatever it
must fit (normaliser, PCA, HMM chains) on the training trials only. ``prepare`` does the one pass
over the file that every adjective shares (cached on disk), before any training starts.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from tactile_exp.data.layout import Split, TrialName
from tactile_exp.data.phac2 import PHAC2
from tactile_exp.models.base import Instances
from tactile_exp.registry import Registry


class Modality(ABC):
    def __init__(self, dataset: PHAC2, cache_dir: Path) -> None:
        self.dataset = dataset
        self.cache_dir = cache_dir

    def max_combine(self) -> tuple[int, str]:
        """The largest ``combine`` (instances of one object grouped as a unit) and its unit name."""
        return int(max(np.bincount([t.object_id for t in self.dataset.trials]))), "trials"

    @abstractmethod
    def prepare(self) -> None:
        """Read and cache what all adjectives share; raises on bad input before any training."""

    @abstractmethod
    def instances(self, split: Split) -> tuple[Instances, Instances]:
        """Training and test instances of one adjective's split."""


MODALITIES: Registry[Modality] = Registry("modality", Modality)


def _bookkeeping(trials: Sequence[str], split: Split, per_trial: int) -> tuple[np.ndarray, ...]:
    names = np.repeat(np.asarray(trials, dtype=object), per_trial)
    y = np.repeat([split.labels[t] for t in trials], per_trial).astype(np.int64)
    objects = np.repeat([TrialName.parse(t).object_id for t in trials], per_trial)  # type: ignore[union-attr]
    return y, names, objects


@MODALITIES.register("haptic")
class Haptic(Modality):
    """P1-P6: each trial gives 2 fingers x ``offsets`` instances of (32 signals, ``steps``)."""

    def __init__(
        self,
        dataset: PHAC2,
        cache_dir: Path,
        steps: int = 150,
        offsets: int = 5,
        pca_components: int = 4,
        pac_downsample: str = "subsample",
        per_finger: bool = True,
        fit_on: str = "train",
    ) -> None:
        super().__init__(dataset, cache_dir)
        if fit_on not in ("train", "all"):
            raise ValueError(f"modality.fit_on must be 'train' or 'all', got {fit_on!r}")
        self.settings = dict(steps=steps, offsets=offsets, pac_downsample=pac_downsample)
        self.pca_components = pca_components
        self.per_finger = per_finger
        self.fit_on = fit_on

    def prepare(self) -> None:
        from tactile_exp.preprocess.haptic import load_haptic_arrays

        self.arrays = load_haptic_arrays(self.dataset, cache_dir=self.cache_dir, **self.settings)

    def instances(self, split: Split) -> tuple[Instances, Instances]:
        from tactile_exp.preprocess.haptic import HapticPreprocessor

        pre = HapticPreprocessor(self.arrays, self.pca_components, self.per_finger)
        pre.fit(split.train if self.fit_on == "train" else self.arrays.trials)
        return self._instances(pre, split.train, split), self._instances(pre, split.test, split)

    def _instances(self, pre, trials: Sequence[str], split: Split) -> Instances:
        X = pre.transform(trials)  # (n, fingers, offsets, 32, steps)
        per_trial = X.shape[1] * X.shape[2]
        y, names, objects = _bookkeeping(trials, split, per_trial)
        return Instances(X.reshape(-1, *X.shape[3:]), y, names, objects)


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
            out.append(Instances(X, *_bookkeeping(trials, split, 1)))
        return out[0], out[1]


@MODALITIES.register("visual")
class Visual(Modality):
    """V1-V2 and M3's frozen trunk: one instance per photograph, its pooled, L2-normalised
    inception (5a) activations (832 values), labelled with its object's label.

    The trunk runs once per data set, weights file and channel mean (``prepare``), cached on disk
    under ``cache_dir`` and shared by every adjective and job; see ``models/googlenet.py`` for why
    it lives here rather than in the model. ``layout`` picks the trunk (``torchvision`` or
    ``caffe``, the MINC release's) and its input (``googlenet.network_input``). ``mean="train"``
    fits the V2 channel mean on each split's training photographs instead of using the one the
    layout's weights expect; that costs one trunk pass per adjective.

    An object's photographs follow its trials: all on the side that holds its trials. An object
    split by trial (the only object of its class for an adjective, see ``Split``) has its
    photographs split in the same proportion (first views to train, at least one per side), so
    the adjective keeps a positive on both sides, as in the haptic split. Instances are named
    ``<group stem>_v<VV>``: the combiner's ``combine=k`` then groups ``k`` views of one object.
    Objects without photographs are left out (a warning gives their count).
    """

    def __init__(
        self,
        dataset: PHAC2,
        cache_dir: Path,
        size: int = 224,
        mean: str = "imagenet",
        weights: str | None = None,
        layout: str = "torchvision",
        seed: int = 0,
        batch_size: int = 32,
        device: str = "auto",
    ) -> None:
        from tactile_exp.train import resolve_device

        super().__init__(dataset, cache_dir)
        if mean not in ("imagenet", "train"):
            raise ValueError(f"modality.mean must be 'imagenet' or 'train', got {mean!r}")
        if layout not in ("torchvision", "caffe"):
            raise ValueError(f"modality.layout must be 'torchvision' or 'caffe', got {layout!r}")
        if weights is not None and not Path(weights).is_file():
            raise FileNotFoundError(f"modality.weights: GoogLeNet weights file {weights} not found")
        if batch_size < 1:
            raise ValueError(f"modality.batch_size must be >= 1, got {batch_size}")
        self.size = size
        self.mean = mean
        self.weights = None if weights is None else Path(weights)
        self.layout = layout
        self.seed = seed
        self.batch_size = batch_size
        self.device = resolve_device(device)

    def max_combine(self) -> tuple[int, str]:
        """The most views of one object: the largest ``combine`` that groups distinct views."""
        photos = self.dataset.photographs()
        return max((len(p) for p in photos.values()), default=0), "views"

    def prepare(self) -> None:
        import logging

        from tactile_exp.models.googlenet import LAYOUT_MEAN_RGB
        from tactile_exp.preprocess.visual import load_visual_arrays

        log = logging.getLogger(__name__)
        self.arrays = load_visual_arrays(self.dataset, self.size, self.cache_dir)
        if len(self.arrays.images) == 0:
            raise ValueError(f"{self.dataset.path}: no photographs found for any object")
        if len(self.arrays.missing):
            log.warning(
                "visual: %d of %d objects have no photographs and are left out: %s",
                len(self.arrays.missing),
                len(self.dataset.object_ids()),
                self.arrays.missing.tolist(),
            )
        if self.weights is None:
            log.warning(
                "visual: modality.weights is null: GoogLeNet has random (Xavier) weights, so its "
                "features are random projections, not transferred MINC/ImageNet features"
            )
        self._stems = {t.object_id: t.stem for t in self.dataset.trials}
        self._fixed = (
            self._features_for(LAYOUT_MEAN_RGB[self.layout]) if self.mean == "imagenet" else None
        )

    def _features_for(self, mean: Sequence[float]) -> np.ndarray:
        """The trunk's features of every photograph with channel ``mean`` subtracted, (n, 832);
        cached on disk by the images' bytes, the weights file's bytes (or seed) and the mean."""
        import hashlib

        from tactile_exp.models.googlenet import (
            build_trunk,
            file_digest,
            network_input,
            pooled_features,
        )
        from tactile_exp.preprocess.cache import cache_key, load_arrays, save_arrays

        mean = tuple(round(float(m), 4) for m in mean)
        key = cache_key(
            kind="googlenet_5a",
            images=hashlib.sha1(self.arrays.images.tobytes()).hexdigest(),
            weights=file_digest(self.weights) if self.weights else f"xavier-seed{self.seed}",
            mean=mean,
            layout=self.layout,
            version=1,
        )
        path = self.cache_dir / f"googlenet5a-{key}.npz"
        cached = load_arrays(path, ("features",))
        if cached is not None:
            return cached["features"]
        images = network_input(self.arrays.images, mean, self.layout)  # V2, in the trunk's layout
        trunk = build_trunk(self.weights, self.seed, self.layout)
        features = pooled_features(trunk, images, self.batch_size, self.device)
        save_arrays(path, {"features": features})
        return features

    def instances(self, split: Split) -> tuple[Instances, Instances]:
        train_idx, test_idx, labels = self._assign(split)
        features = self._fixed
        if features is None:
            features = self._features_for(self.arrays.channel_mean(train_idx))
        out = []
        for part, idx in (("train", train_idx), ("test", test_idx)):
            obj = self.arrays.object_id[idx]
            y = np.array([labels[o] for o in obj], dtype=np.int64)
            if len(np.unique(y)) != 2:
                raise ValueError(
                    f"visual split of {split.adjective!r}: the {part} photographs hold labels "
                    f"{np.unique(y).tolist()}, expected positives and negatives (objects without "
                    f"photographs: {self.arrays.missing.tolist()})"
                )
            views = zip(obj, self.arrays.view[idx], strict=True)
            names = np.array([f"{self._stems[o]}_v{v:02d}" for o, v in views], dtype=object)
            out.append(Instances(features[idx], y, names, obj))
        return out[0], out[1]

    def _assign(self, split: Split) -> tuple[np.ndarray, np.ndarray, dict[int, int]]:
        """Photograph indices of the training and test sides, and each object's label."""
        counts: dict[int, list[int]] = {}
        labels: dict[int, int] = {}
        for side, trials in enumerate((split.train, split.test)):
            for t in trials:
                obj = TrialName.parse(t).object_id  # type: ignore[union-attr]
                counts.setdefault(obj, [0, 0])[side] += 1
                labels[obj] = split.labels[t]
        train: list[np.ndarray] = []
        test: list[np.ndarray] = []
        for obj, (n_train, n_test) in sorted(counts.items()):
            views = np.flatnonzero(self.arrays.object_id == obj)
            if n_test == 0 or n_train == 0:
                (train if n_test == 0 else test).append(views)
                continue
            if len(views) < 2:
                raise ValueError(
                    f"visual split of {split.adjective!r}: object {obj} is split by trial "
                    f"({n_train} train, {n_test} test) but has {len(views)} photograph(s); "
                    "at least 2 are needed to put views on both sides"
                )
            k = min(len(views) - 1, max(1, round(len(views) * n_train / (n_train + n_test))))
            train.append(views[:k])
            test.append(views[k:])
        empty = np.zeros(0, dtype=np.int64)
        return np.concatenate(train or [empty]), np.concatenate(test or [empty]), labels

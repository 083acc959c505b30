"""The ``visual`` modality: one instance per photograph, through the frozen GoogLeNet trunk."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

from tactile_exp.data.layout import Instances, Split
from tactile_exp.data.phac2 import PHAC2
from tactile_exp.data.splits import split_photographs
from tactile_exp.modalities.base import MODALITIES, Modality

log = logging.getLogger(__name__)


@MODALITIES.register("visual")
class Visual(Modality):
    """V1-V2 and M3's frozen trunk: one instance per photograph, its pooled, L2-normalised
    inception (5a) activations (832 values), labelled with its object's label.

    ``VisualFeatures`` (``preprocess/visual.py``) holds the fit/transform; see
    ``models/googlenet.py`` for why the trunk lives here rather than in the model. ``mean="train"``
    fits the V2 channel mean on each split's training photographs instead of using the one the
    layout's weights expect; that costs one trunk pass per adjective. ``layout`` picks the trunk
    (``torchvision`` or ``caffe``, the MINC release's) and its input (``googlenet.network_input``).
    Photographs follow their object's trials (``data.splits.split_photographs``). Instances are
    named ``<group stem>_v<VV>``: the combiner's ``combine=k`` then groups ``k`` views of one
    object. Objects without photographs are left out (a warning gives their count).

    Units of views are never padded (``pad_units``): row L's unit is an object's first 8 views
    (by file name); further views (PHAC-2 has objects with 10) form no second unit. An object with
    fewer than ``combine`` views on one side of a split keeps one unit padded with its own views
    (a warning names it).
    """

    pad_units = False

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
            raise ValueError(
                f"modality.layout must be 'torchvision' or 'caffe' (trunk.layout for every visual "
                f"row), got {layout!r}"
            )
        if weights is not None and not Path(weights).is_file():
            # ValueError: the job's config check turns it into one `error: modality...` line.
            raise ValueError(
                f"modality.weights (trunk.weights for every visual row): GoogLeNet weights file "
                f"{weights} not found"
            )
        if batch_size < 1:
            raise ValueError(f"modality.batch_size must be >= 1, got {batch_size}")
        resolve_device(device)  # a bad device fails here, before any work
        self.size = size
        self.mean = mean
        self.weights = None if weights is None else Path(weights)
        self.layout = layout
        self.seed = seed
        self.batch_size = batch_size
        self.device = device

    def max_combine(self) -> tuple[int, str]:
        """The most views of one object: the largest ``combine`` that groups distinct views."""
        photos = self.dataset.photographs()
        return max((len(p) for p in photos.values()), default=0), "views"

    def prepare(self) -> None:
        from tactile_exp.preprocess.visual import VisualFeatures, load_visual_arrays

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
        self.features = VisualFeatures(
            self.arrays,
            cache_dir=self.cache_dir,
            mean=self.mean,
            weights=self.weights,
            layout=self.layout,
            seed=self.seed,
            batch_size=self.batch_size,
            device=self.device,
        )
        if self.mean == "imagenet":
            self.features.fit()  # one trunk pass shared by every adjective, before any training

    def state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        """V2's channel mean as fitted, and the crop and trunk settings."""
        settings = dict(
            modality="visual", size=self.size, mean=self.mean, layout=self.layout,
            weights=None if self.weights is None else str(self.weights), seed=self.seed,
        )  # fmt: skip
        return settings, {"channel_mean": np.asarray(self.features.mean_, dtype=np.float64)}

    def instances(self, split: Split) -> tuple[Instances, Instances]:
        train_idx, test_idx, labels = split_photographs(split, self.arrays.object_id)
        if self.mean == "train":
            self.features.fit(train_idx)
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
            out.append(Instances(self.features.transform(idx), y, names, obj))
        return out[0], out[1]

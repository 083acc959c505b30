"""The ``visual`` modality: one instance per photograph, through the frozen GoogLeNet trunk."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import TYPE_CHECKING, Any, Self

import numpy as np

from tactile_exp.data.layout import Instances, InstanceSpec, Trials
from tactile_exp.data.splits import divide_views
from tactile_exp.modalities.base import MODALITIES, Modality

if TYPE_CHECKING:
    from tactile_exp.modalities.networks import Load, Network

log = logging.getLogger(__name__)


def view_name(stem: str, view: int) -> str:
    """A photograph's instance name: its object's name and its rank among the object's views
    (by file name), ``<stem>_v<VV>``: ``combine=k`` then groups ``k`` views of one object."""
    return f"{stem}_v{view:02d}"


# The photographs and trunk features in use, shared by every adjective's pipeline in a process.
_TRUNKS: dict[tuple[Any, ...], Any] = {}


@MODALITIES.register("visual")
class Visual(Modality):
    """V1-V2 and M3's frozen trunk: one instance per photograph, its pooled, L2-normalised
    inception (5a) activations (832 values), labelled with its object's label.

    ``fit`` learns the V2 channel mean: the one the layout's weights expect (``mean="imagenet"``)
    or the training photographs' (``mean="train"``, one trunk pass per adjective).
    ``layout`` picks the trunk (``torchvision`` or ``caffe``, the MINC release's) and its input
    (``preprocess.trunk``). Photographs follow their object's trials; an object whose trials a
    split shares between sides has its views divided in that proportion (``Trials.shared``).
    Objects without photographs are left out (a warning gives their count).

    Units of views are never padded (``pad_units``): row L's unit is an object's first 8 views
    (by file name); further views (PHAC-2 has objects with 10) form no second unit. An object with
    fewer than ``combine`` views on one side of a split keeps one unit padded with its own views
    (a warning names it).
    """

    pad_units = False
    takes_trials = False
    takes_photographs = True
    emits = "features"
    onnx_refusal = None  # the layer (or T4's head) on the exported trunk's features

    def __init__(
        self,
        *,
        cache_dir: Path | None = None,
        size: int = 224,
        mean: str = "imagenet",
        weights: str | None = None,
        layout: str = "torchvision",
        seed: int = 0,
        batch_size: int = 32,
        device: str = "auto",
    ) -> None:
        from tactile_exp.train import resolve_device

        super().__init__(cache_dir=cache_dir)
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

    @classmethod
    def onnx_network(
        cls, load: Load, settings: dict[str, Any], keeps: bool, combine: int
    ) -> Network:
        """Rows K (one view per row) and L (``combine`` views' features, then the head)."""
        from torch import nn

        from tactile_exp.modalities import networks as nets

        if keeps:
            net = nets.DecisionNet(nn.Identity(), *nets.layer(load("model")))
            layout = {"visual": nets.visual_layout(settings, 1)}
            return nets.Network(
                net, {"features": [None, nets.FEATURES]}, layout, nets.trunk_of(settings)
            )
        net = nets.DecisionNet(nn.Identity(), *nets.layer(load("head")), per_unit=True)
        layout = {"visual": nets.visual_layout(settings, combine)}
        return nets.Network(
            net, {"views": [None, combine, nets.FEATURES]}, layout, nets.trunk_of(settings)
        )

    def output(self, dataset: Any) -> InstanceSpec:
        from tactile_exp.preprocess.trunk import INCEPTION5A_CHANNELS

        return InstanceSpec(self.emits, (INCEPTION5A_CHANNELS,))

    def max_combine(self, dataset: Any) -> tuple[int, str]:
        """The most views of one object: the largest ``combine`` that groups distinct views."""
        photos = dataset.photographs()
        return max((len(p) for p in photos.values()), default=0), "views"

    def check(self, dataset: Any) -> None:
        trunk = self.trunk(dataset)
        arrays = trunk.arrays
        if len(arrays.images) == 0:
            raise ValueError(f"{dataset.path}: no photographs found for any object")
        if len(arrays.missing):
            log.warning(
                "visual: %d of %d objects have no photographs and are left out: %s",
                len(arrays.missing),
                len(dataset.object_ids()),
                arrays.missing.tolist(),
            )
        if self.weights is None:
            log.warning(
                "visual: modality.weights is null: GoogLeNet has random (Xavier) weights, so its "
                "features are random projections, not transferred MINC/ImageNet features"
            )
        if self.mean == "imagenet":
            trunk.features(self._layout_mean())  # one trunk pass for every adjective, up front

    def trunk(self, dataset: Any) -> Any:
        """The photographs of ``dataset`` and their trunk features (cached when checked, keyed
        by the photographs' paths too: one data file can be read with another photograph folder)."""
        from tactile_exp.preprocess.visual import (
            VisualFeatures,
            compute_visual_arrays,
            load_visual_arrays,
        )

        photos = tuple((obj, tuple(paths)) for obj, paths in sorted(dataset.photographs().items()))
        key = (dataset.identity(), photos, self.size, self.weights, self.layout, self.seed,
               self.cache_dir)  # fmt: skip
        if key not in _TRUNKS:
            if self.cache_dir is None:
                arrays = compute_visual_arrays(dataset, self.size)
            else:
                arrays = load_visual_arrays(dataset, self.size, self.cache_dir)
            _TRUNKS.clear()  # one set of photographs in memory at a time
            _TRUNKS[key] = VisualFeatures(
                arrays, cache_dir=self.cache_dir, weights=self.weights, layout=self.layout,
                seed=self.seed, batch_size=self.batch_size, device=self.device,
            )  # fmt: skip
        return _TRUNKS[key]

    def _layout_mean(self) -> tuple[float, ...]:
        from tactile_exp.preprocess.trunk import LAYOUT_MEAN_RGB

        return tuple(round(float(m), 4) for m in LAYOUT_MEAN_RGB[self.layout])

    @staticmethod
    def _rows(arrays: Any, trials: Trials) -> np.ndarray:
        """The rows of ``arrays`` (``trunk(dataset).arrays``, passed in: each ``trunk`` call lists
        the photograph folder) that hold ``trials``' objects' photographs, in view order."""
        rows = []
        for obj in sorted(trials.objects):
            views = np.flatnonzero(arrays.object_id == obj)
            views = views[np.argsort(arrays.view[views], kind="stable")]
            if obj in trials.shared:
                first, rest = divide_views(
                    views, *trials.shared[obj], f"{trials.label!r}: object {obj}"
                )
                views = first if trials.side == "train" else rest
            rows.append(views)
        return np.concatenate(rows) if rows else np.zeros(0, np.int64)

    def fit(self, trials: Trials) -> Self:
        if self.mean == "imagenet":
            self.mean_ = self._layout_mean()
        else:
            arrays = self.trunk(trials.dataset).arrays
            self.mean_ = tuple(
                round(float(m), 4) for m in arrays.channel_mean(self._rows(arrays, trials))
            )
        return self

    def transform(self, trials: Trials) -> Instances:
        trunk = self.trunk(trials.dataset)
        arrays = trunk.arrays
        rows = self._rows(arrays, trials)
        obj = arrays.object_id[rows]
        labels = trials.object_labels()
        y = np.array([labels[o] for o in obj], dtype=np.int64)
        if len(np.unique(trials.y())) == 2 and len(np.unique(y)) != 2:
            raise ValueError(
                f"visual split of {trials.label!r}: the {trials.side} photographs hold labels "
                f"{np.unique(y).tolist()}, expected positives and negatives (objects without "
                f"photographs: {arrays.missing.tolist()})"
            )
        stems = {o: trials.dataset.object_name(o) for o in np.unique(obj).tolist()}
        views = zip(obj.tolist(), arrays.view[rows].tolist(), strict=True)
        names = np.array([view_name(stems[o], v) for o, v in views], dtype=object)
        return Instances(trunk.features(self.mean_)[rows], y, names, obj)

    def get_state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        """V2's channel mean as fitted."""
        return {}, {"channel_mean": np.asarray(self.mean_, dtype=np.float64)}

    def set_state(self, settings: dict[str, Any], arrays: dict[str, np.ndarray]) -> Self:
        mean = np.asarray(arrays["channel_mean"], dtype=np.float64)
        if mean.shape != (3,):
            raise ValueError(f"channel_mean has shape {mean.shape}, expected (3,)")
        self.mean_ = tuple(float(m) for m in mean)
        return self

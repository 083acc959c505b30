"""The ``multimodal`` modality (M4, rows M and N): a haptic unit beside its object's photographs.

One instance per haptic unit: the frozen haptic ConvNet's conv3 activations of ``trials`` trials
of one object (row I's unit at 1, row J's at 10, concatenated as T4 does) followed by the
L2-normalised inception (5a) features of the object's first ``views`` photographs (row L's unit,
built by the visual modality's rule: ``unit_members`` without padding). ``multimodal_units`` and
``visual_units`` build the units for training and for ``predict`` alike.
The ConvNet is the ``haptic`` part (``parts``): given fitted through ``set_parts``, found by its
training key in a model cache (the model rows H, I and J train) or trained when absent, per
adjective; the fitted pipeline keeps it.
The visual trunk is frozen and untrained (its features are cached on disk by weights file), so
it needs no lookup. The model on
top is only a classification layer (``experiment=table1_m_*``: ``linear``, hinge loss).
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import TYPE_CHECKING, Any, Self

import numpy as np

from tactile_exp.combine import COMBINERS, unit_members
from tactile_exp.data.layout import Instances, Trials
from tactile_exp.modalities.base import MODALITIES, Modality
from tactile_exp.modalities.haptic import Haptic
from tactile_exp.modalities.visual import Visual, view_name
from tactile_exp.models.base import Model
from tactile_exp.registry import Component

if TYPE_CHECKING:
    from tactile_exp.modalities.networks import Load, Network

log = logging.getLogger(__name__)


def _component(node: dict[str, Any], key: str) -> Component:
    if not isinstance(node, dict) or "name" not in node:
        raise ValueError(f"modality.{key}: expected a mapping with a 'name' key, got {node!r}")
    params = {k: v for k, v in node.items() if k not in ("name", "_module_")}
    return Component(str(node["name"]), params)


def visual_units(features: np.ndarray, object_id: np.ndarray, views: int) -> dict[int, np.ndarray]:
    """Each object's visual unit from its photographs' features (rows in view order within an
    object): row L's unit, built as the ``visual`` modality combines views (``unit_members``
    without padding): its first ``views`` views, or all of them repeated in order when fewer."""
    n = len(features)
    rank = np.zeros(n, np.int64)
    for obj in np.unique(object_id):
        rows = np.flatnonzero(object_id == obj)
        rank[rows] = np.arange(len(rows))
    names = np.array([view_name(str(o), r) for o, r in zip(object_id, rank, strict=True)])
    photos = Instances(features, np.zeros(n, np.int64), names.astype(object), object_id)
    units: dict[int, np.ndarray] = {}
    for members in unit_members(photos, views, pad=Visual.pad_units):
        units.setdefault(int(object_id[members[0]]), features[members].reshape(-1))
    return units


def multimodal_units(
    net: Model, haptic: Instances, trials: int, visual: dict[int, np.ndarray]
) -> Instances:
    """Rows M/N's instances: the ConvNet ``net``'s conv3 of ``trials`` trials of an object
    concatenated (row I/J's unit, padded as the ``haptic`` modality pads), then the object's
    visual unit (``visual``: object id -> its ``visual_units`` entry)."""
    units = COMBINERS.build("concat")(net.transform(haptic.X), haptic, trials, pad=Haptic.pad_units)
    seen = np.stack([visual[int(o)] for o in units.object_id])
    X = np.hstack([units.X, seen]).astype(np.float32)
    return Instances(X, units.y, units.trial, units.object_id)


@MODALITIES.register("multimodal")
class Multimodal(Modality):
    """Haptic units (``trials`` trials of an object) with their object's ``views`` photographs."""

    takes_photographs = True
    needs_layout = Haptic.needs_layout
    emits = "features"  # conv3 activations of a unit's trials, then the views' trunk features
    onnx_refusal = None  # the ConvNet part on the trials, the trunk's features, one layer

    def __init__(
        self,
        *,
        cache_dir: Path | None = None,
        haptic: dict[str, Any],
        visual: dict[str, Any],
        haptic_model: dict[str, Any],
        trials: int = 1,
        views: int = 8,
    ) -> None:
        super().__init__(cache_dir=cache_dir)
        if not isinstance(trials, int) or trials < 1:
            raise ValueError(f"modality.trials must be an integer >= 1, got {trials!r}")
        if not isinstance(views, int) or views < 1:
            raise ValueError(f"modality.views must be an integer >= 1, got {views!r}")
        self.haptic_part = _component(haptic, "haptic")
        self.visual_part = _component(visual, "visual")
        self.model_part = _component(haptic_model, "haptic_model")
        if self.haptic_part.name != "haptic" or self.visual_part.name != "visual":
            raise ValueError(
                "modality.haptic and modality.visual must be the haptic and visual modalities, "
                f"got {self.haptic_part.name!r} and {self.visual_part.name!r}"
            )
        self.haptic = Haptic(cache_dir=cache_dir, **self.haptic_part.params)
        self.visual = Visual(cache_dir=cache_dir, **self.visual_part.params)
        self.trials = trials
        self.views = views
        self.left_out_: set[int] = set()

    def parts(self) -> dict[str, tuple[Component, Component]]:
        return {"haptic": (self.haptic_part, self.model_part)}

    @classmethod
    def onnx_network(
        cls, load: Load, settings: dict[str, Any], keeps: bool, combine: int
    ) -> Network:
        """Rows M and N: the ConvNet part on ``trials`` trials, the object's views, one layer."""
        from tactile_exp.modalities import networks as nets

        part, model = load("parts/haptic"), load("model")
        trials, views = int(settings["trials"]), int(settings["views"])
        haptic, visual = settings["haptic"], settings["visual"]
        count = trials * nets.FINGERS * int(haptic["offsets"])
        inputs = {
            "instances": [None, count, *part.input_shape_],
            "views": [None, views, nets.FEATURES],
        }
        layouts = {
            "haptic": nets.haptic_layout(haptic, trials),
            "visual": nets.visual_layout(visual, views),
        }
        net = nets.DecisionNet(part.body_, *nets.layer(model), per_unit=True)
        return nets.Network(net, inputs, layouts, nets.trunk_of(visual))

    def max_combine(self, dataset: Any) -> tuple[int, str]:
        return 1, "multimodal units (set modality.trials for trials per unit)"

    def check(self, dataset: Any) -> None:
        self.haptic.check(dataset)
        self.visual.check(dataset)
        limit, _ = self.haptic.max_combine(dataset)
        if self.trials > limit:
            raise ValueError(
                f"modality.trials: {self.trials} trials per unit, but objects in "
                f"{dataset.path} have at most {limit}; allowed 1..{limit}"
            )

    def fit(self, trials: Trials) -> Self:
        self.haptic.fit(trials)
        self.visual.fit(trials)
        self.left_out_ = set()
        if not hasattr(self, "net_"):
            raise ValueError("multimodal: fit needs its fitted haptic ConvNet: set_parts first")
        return self

    def set_parts(self, parts: dict[str, Model]) -> None:
        if set(parts) != {"haptic"}:
            raise ValueError(f"multimodal: expected its fitted part 'haptic', got {sorted(parts)}")
        self.net_ = parts["haptic"]

    def transform(self, trials: Trials) -> Instances:
        inst = self.haptic.transform(trials)
        objects = tuple(int(o) for o in np.unique(inst.object_id))
        seen = self.visual.transform(Trials(trials.dataset, (), object_ids=objects))
        units = visual_units(seen.X, seen.object_id, self.views)
        keep = np.isin(inst.object_id, list(units))
        left_out = sorted(set(objects) - set(units))
        if left_out:
            self.left_out_ |= set(left_out)
            log.warning(
                "multimodal %s: %d %s objects without photographs left out: %s",
                trials.label, len(left_out), trials.side, left_out,
            )  # fmt: skip
        kept = Instances(inst.X[keep], inst.y[keep], inst.trial[keep], inst.object_id[keep])
        if len(np.unique(inst.y)) == 2 and len(np.unique(kept.y)) != 2:
            raise ValueError(
                f"multimodal split of {trials.label!r}: the {trials.side} units with "
                f"photographs hold labels {np.unique(kept.y).tolist()}, expected positives "
                f"and negatives (objects without photographs: {left_out})"
            )
        return multimodal_units(self.net_, kept, self.trials, units)

    def metrics(self) -> dict[str, float]:
        return {"n_objects_without_photographs": float(len(self.left_out_))}

    def get_state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        """The haptic and visual preprocessing as fitted, keys prefixed by part."""
        settings: dict[str, Any] = {}
        arrays: dict[str, np.ndarray] = {}
        for name, modality in (("haptic", self.haptic), ("visual", self.visual)):
            part_settings, part_arrays = modality.get_state()
            settings[name] = part_settings
            arrays.update({f"{name}.{k}": v for k, v in part_arrays.items()})
        return settings, arrays

    def set_state(self, settings: dict[str, Any], arrays: dict[str, np.ndarray]) -> Self:
        for name, modality in (("haptic", self.haptic), ("visual", self.visual)):
            prefix = f"{name}."
            part = {k.removeprefix(prefix): v for k, v in arrays.items() if k.startswith(prefix)}
            modality.set_state(settings.get(name, {}), part)
        return self

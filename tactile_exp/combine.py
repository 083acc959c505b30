"""Combining instances of one object before classification (T4, Table I suffixes).

An instance is what a model classifies on its own: one finger x one sub-sampled offset of a trial
for the haptic signals (10 per trial), one trial for hand-designed features. ``combine=k`` groups
the instances of ``k`` trials of one object (on one side of a split) into one unit; ``concat``
joins their features as the paper does, ``mean`` averages them. ``separate`` keeps every instance
as its own unit (rows G, H). A modality whose objects may hold fewer instances than ``combine``
chooses what happens to the remainder (``Modality.pad_units``): haptic trials pad it by repeating
the object's own trials, views (row L) drop it, so an object's unit holds its first 8 views.
"""

from __future__ import annotations

import logging
from abc import ABC, abstractmethod

import numpy as np

from tactile_exp.data.layout import Instances
from tactile_exp.registry import Registry

log = logging.getLogger(__name__)


class Combiner(ABC):
    """Turns per-instance features into per-unit features."""

    # Capability, declared: True means every instance is its own unit, so the engine scores the
    # model itself instead of retraining a head on combined features.
    keeps_instances: bool = False

    @abstractmethod
    def __call__(
        self, features: np.ndarray, instances: Instances, combine: int, *, pad: bool = True
    ) -> Instances: ...


COMBINERS: Registry[Combiner] = Registry("combine_instances", Combiner)


def unit_members(instances: Instances, combine: int, *, pad: bool = True) -> list[np.ndarray]:
    """Row indices of each unit: ``combine`` consecutive trials (by name) of one object.

    Instances keep their order within a trial. A last group with fewer trials is, with ``pad``,
    filled by repeating its own trials in order, so concatenated units always have the same
    width; without ``pad`` it is dropped (10 views at ``combine=8``: one unit, views 0-7), except
    for an object with fewer than ``combine`` trials in all (e.g. one whose views a split shares
    between train and test), which keeps one unit padded that way, and a warning names it.
    """
    if combine < 1:
        raise ValueError(f"combine must be >= 1, got {combine}")
    units: list[np.ndarray] = []
    too_few = []
    # Each trial's rows in their order, found in one sort rather than one scan per trial.
    order = np.argsort(instances.trial, kind="stable")
    names, starts = np.unique(np.asarray(instances.trial)[order], return_index=True)
    rows = dict(zip(names, np.split(order, starts[1:]), strict=True))
    for obj in np.unique(instances.object_id):
        trials = np.unique(instances.trial[instances.object_id == obj])
        short = len(trials) < combine
        if not pad and short:
            too_few.append(int(obj))
        stop = len(trials) if pad or short else len(trials) - combine + 1
        for start in range(0, stop, combine):
            available = trials[start : start + combine]
            chunk = [available[i % len(available)] for i in range(combine)]
            units.append(np.concatenate([rows[t] for t in chunk]))
    if too_few:
        log.warning("combine=%d: objects %s have fewer, one padded unit each", combine, too_few)
    return units


def _units(instances: Instances, members: list[np.ndarray], X: np.ndarray) -> Instances:
    first = np.array([m[0] for m in members])
    y = np.asarray(instances.y)
    rows = np.concatenate(members) if members else np.zeros(0, np.intp)
    if (y[rows] != np.repeat(y[first], [len(m) for m in members])).any():
        raise ValueError("instances of one unit disagree on the label")
    return Instances(X, instances.y[first], instances.trial[first], instances.object_id[first])


@COMBINERS.register("concat")
class Concat(Combiner):
    def __call__(
        self, features: np.ndarray, instances: Instances, combine: int, *, pad: bool = True
    ) -> Instances:
        members = unit_members(instances, combine, pad=pad)
        widths = {len(m) for m in members}
        if len(widths) != 1:
            raise ValueError(f"units have different numbers of instances {sorted(widths)}")
        index = np.asarray(members, dtype=np.intp).reshape(len(members), -1)
        return _units(instances, members, features[index].reshape(len(members), -1))


@COMBINERS.register("mean")
class Mean(Combiner):
    def __call__(
        self, features: np.ndarray, instances: Instances, combine: int, *, pad: bool = True
    ) -> Instances:
        members = unit_members(instances, combine, pad=pad)
        X = np.stack([features[m].mean(axis=0) for m in members])
        return _units(instances, members, X)


@COMBINERS.register("separate")
class Separate(Combiner):
    """Every instance is its own unit; the engine then scores the model directly."""

    keeps_instances = True

    def __call__(
        self, features: np.ndarray, instances: Instances, combine: int, *, pad: bool = True
    ) -> Instances:
        return Instances(features, instances.y, instances.trial, instances.object_id)

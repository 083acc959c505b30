"""Object-grouped validation inside an adjective's training objects (not in the paper).

The paper has no validation set. To tell over-fitting from a weak model in the logs, a few
training objects are held out, stratified by label, and left out of the final training: the
validation score then describes the very model that is tested, at no extra training cost. Test
objects are never held out (``validation_split`` raises if one would be).
"""

from __future__ import annotations

import numpy as np

from tactile_exp.data.layout import Instances, Split, TrialName


def _object_of(trial: str) -> int:
    return TrialName.parse(trial).object_id  # type: ignore[union-attr]


def validation_split(split: Split, *, fraction: float, seed: int) -> tuple[Split, tuple[str, ...]]:
    """``split`` with ``fraction`` of its training objects moved out of ``train``.

    Returns the reduced split (same test trials) and the held-out trials. Objects are drawn per
    class: ``round(fraction * n)`` of each class's ``n`` training-only objects, at least one when
    the class keeps at least one object for training, so both classes are held out when
    possible. Objects that also have test trials (a positive object split by trial) stay in
    training. ``fraction == 0`` holds nothing out.
    """
    if not 0 <= fraction < 1:
        raise ValueError(f"validation fraction must be in [0, 1), got {fraction!r}")
    if fraction == 0:
        return split, ()
    test_objects = split.objects("test")
    label_of: dict[int, int] = {}
    for trial in split.train:
        label_of.setdefault(_object_of(trial), split.labels[trial])
    rng = np.random.default_rng([seed, sum(map(ord, split.adjective))])
    held: set[int] = set()
    for label in (0, 1):
        pool = sorted(o for o, lab in label_of.items() if lab == label and o not in test_objects)
        n_class = sum(1 for lab in label_of.values() if lab == label)
        take = min(max(1, round(fraction * n_class)), n_class - 1, len(pool))
        if take > 0:
            held.update(int(o) for o in rng.choice(pool, size=take, replace=False))
    if held & test_objects:
        raise AssertionError("validation objects must never be test objects")
    keep = tuple(t for t in split.train if _object_of(t) not in held)
    out = tuple(t for t in split.train if _object_of(t) in held)
    return Split(split.adjective, keep, split.test, split.labels), out


def take_trials(instances: Instances, trials: tuple[str, ...]) -> tuple[Instances, Instances]:
    """``instances`` split into the rows of ``trials`` and the rest."""
    mask = np.isin(instances.trial, np.asarray(trials, dtype=instances.trial.dtype))
    parts = []
    for m in (mask, ~mask):
        parts.append(
            Instances(instances.X[m], instances.y[m], instances.trial[m], instances.object_id[m])
        )
    return parts[0], parts[1]

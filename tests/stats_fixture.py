"""Simulated held-out scores at PHAC-2's sizes, with a known population AUC per adjective.

A unit's score is ``d * label + shared object effect + configuration's object effect + unit
noise`` (variances 0.5, 0.5, 1), so the population AUC of unit pairs is ``Phi(d / 2)``: two
configurations scored on the same objects share the object effect (they find the same objects
hard), as paired comparisons assume. Protocols: the published split's ~3 positive and ~4
negative test objects per adjective, or 5 folds pooled over PHAC-2's 60 objects (each
adjective's positive count as in the release, at least 5 so 5 folds fit). 10 units per object.
"""

from __future__ import annotations

import numpy as np
from scipy.stats import norm

from tactile_exp.data.layout import ADJECTIVES
from tactile_exp.stats import Evaluation, HeldOut

# Positive objects per adjective among PHAC-2's 60 (alphabetical, as ADJECTIVES).
PHAC2_POSITIVES = (11, 3, 23, 9, 2, 7, 5, 23, 3, 1, 7, 10, 6, 9, 28, 15, 25, 7, 24, 1, 18, 11, 2, 1)
N_OBJECTS = 60
UNITS = 10
# Population AUC of configuration "a" per adjective: 0.62..0.90, as the rows of Table I spread.
POPULATION = np.linspace(0.62, 0.90, len(ADJECTIVES))


def class_sizes(protocol: str) -> list[tuple[int, int]]:
    if protocol == "published":
        return [(3, 4)] * len(ADJECTIVES)
    pos = [min(max(p, 5), N_OBJECTS - 5) for p in PHAC2_POSITIVES]
    return [(p, N_OBJECTS - p) for p in pos]


def simulate(
    rng: np.random.Generator, protocol: str, shifts: tuple[float, ...]
) -> list[Evaluation]:
    """One data set: an evaluation per configuration, whose population AUC is ``POPULATION +
    shift`` (per adjective, capped at 0.99), all on the same test objects."""
    out: list[Evaluation] = [{} for _ in shifts]
    ds = [2 * norm.ppf(np.minimum(POPULATION + shift, 0.99)) for shift in shifts]
    for j, (adj, (n_pos, n_neg)) in enumerate(zip(ADJECTIVES, class_sizes(protocol), strict=True)):
        objects = np.arange(n_pos + n_neg)
        label = (objects < n_pos).astype(int)
        shared = rng.normal(0, np.sqrt(0.5), len(objects))
        object_id = np.repeat(objects, UNITS)
        for ev, d in zip(out, (d[j] for d in ds), strict=True):
            own = rng.normal(0, np.sqrt(0.5), len(objects))
            score = np.repeat(d * label + shared + own, UNITS) + rng.normal(0, 1, len(object_id))
            ev[adj] = HeldOut(object_id, np.repeat(label, UNITS), score)
    return out


def population_mean(shift: float = 0.0) -> float:
    return float(np.mean(np.minimum(POPULATION + shift, 0.99)))

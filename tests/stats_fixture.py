"""Simulated held-out scores at PHAC-2's sizes, with a known population AUC per adjective.

A unit's score is ``d * label + shared object effect + configuration's object effect + unit
noise`` (variances 0.5, 0.5, 1), so the population AUC of unit pairs is ``Phi(d / 2)``: two
configurations scored on the same objects share the object effect (they find the same objects
hard), as paired comparisons assume. An object is the same object for every adjective that tests
it: a fraction ``rho`` of each object effect's variance is the object's own difficulty, alike in
every adjective (a hard object scores on the wrong side of each of its labels), the rest is
drawn per adjective; ``rho=0`` makes the adjectives independent.

Protocols: ``published``, PHAC-2's published split (its table: 21 test objects shared by the 24
adjectives, 1 to 3 positive and 3 to 6 negative per adjective); ``folds``, 5 folds pooled over
PHAC-2's 60 objects (every adjective tests every object; its positive count as in the release,
at least 5 so 5 folds fit, positives drawn once with a fixed seed). 10 units per object.
"""

from __future__ import annotations

import functools

import numpy as np
from scipy.stats import norm

from tactile_exp.data.layout import ADJECTIVES, published_test_split
from tactile_exp.stats import Evaluation, HeldOut

# Positive objects per adjective among PHAC-2's 60 (alphabetical, as ADJECTIVES).
PHAC2_POSITIVES = (11, 3, 23, 9, 2, 7, 5, 23, 3, 1, 7, 10, 6, 9, 28, 15, 25, 7, 24, 1, 18, 11, 2, 1)
N_OBJECTS = 60
UNITS = 10
# Population AUC of configuration "a" per adjective: 0.62..0.90, as the rows of Table I spread.
POPULATION = np.linspace(0.62, 0.90, len(ADJECTIVES))


@functools.cache
def objects_of(protocol: str) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
    """Per adjective (ADJECTIVES' order): its test objects' ids and labels."""
    if protocol == "published":
        rows = published_test_split()
        out = []
        for adjective in ADJECTIVES:
            mine = sorted((r.object_id, r.label) for r in rows if r.adjective == adjective)
            out.append((np.array([o for o, _ in mine]), np.array([lab for _, lab in mine])))
        return tuple(out)
    if protocol == "folds":
        rng = np.random.default_rng(60)
        out = []
        for p in PHAC2_POSITIVES:
            label = np.zeros(N_OBJECTS, dtype=int)
            label[rng.permutation(N_OBJECTS)[: min(max(p, 5), N_OBJECTS - 5)]] = 1
            out.append((np.arange(N_OBJECTS), label))
        return tuple(out)
    raise ValueError(f"unknown protocol {protocol!r}")


def simulate(
    rng: np.random.Generator,
    protocol: str,
    shifts: tuple[float, ...],
    rho: float = 0.0,
    n_adjectives: int = len(ADJECTIVES),
) -> list[Evaluation]:
    """One data set: an evaluation per configuration, whose population AUC is ``POPULATION +
    shift`` (per adjective, capped at 0.99), all on the same test objects; the first
    ``n_adjectives`` adjectives (a quicker check)."""
    objects = objects_of(protocol)[:n_adjectives]
    ids = np.unique(np.concatenate([o for o, _ in objects]))
    # Each object's difficulty, alike across adjectives: common, and each configuration's own.
    common = dict(zip(ids, rng.normal(0, 1, len(ids)), strict=True))
    own = [dict(zip(ids, rng.normal(0, 1, len(ids)), strict=True)) for _ in shifts]
    out: list[Evaluation] = [{} for _ in shifts]
    ds = [2 * norm.ppf(np.minimum(POPULATION + shift, 0.99)) for shift in shifts]
    for j, (adj, (object_ids, label)) in enumerate(zip(ADJECTIVES, objects, strict=False)):
        wrong = 1 - 2 * label  # a hard object leans towards the other class
        shared = _effect(rng, object_ids, common, rho) * wrong
        unit_ids = np.repeat(object_ids, UNITS)
        for ev, d, mine in zip(out, (d[j] for d in ds), own, strict=True):
            effect = shared + _effect(rng, object_ids, mine, rho) * wrong
            score = np.repeat(d * label + effect, UNITS) + rng.normal(0, 1, len(unit_ids))
            ev[adj] = HeldOut(unit_ids, np.repeat(label, UNITS), score)
    return out


def _effect(rng, object_ids: np.ndarray, difficulty: dict, rho: float) -> np.ndarray:
    """Variance 0.5: a fraction rho from the objects' difficulty, the rest this adjective's."""
    fixed = np.array([difficulty[o] for o in object_ids])
    fresh = rng.normal(0, 1, len(object_ids))
    return np.sqrt(0.5) * (np.sqrt(rho) * fixed + np.sqrt(1 - rho) * fresh)


def population_mean(shift: float = 0.0, n_adjectives: int = len(ADJECTIVES)) -> float:
    return float(np.mean(np.minimum(POPULATION[:n_adjectives] + shift, 0.99)))

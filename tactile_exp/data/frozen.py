"""Frozen folds: a data set's object-grouped, class-stratified folds written down, so that two
labs test the same objects in the same fold.

::

    folds: K                       # folds per resample
    resamples: R                   # seeds 0..R-1
    labels:
      LABEL:
        - [[OBJECT, ...], ...]     # resample 0: the objects of fold 0, 1, ..., K-1
        - ...                      # resample 1, ...

``split=folds`` on a folder data set that holds this file as ``folds.yaml`` (what ``public
import`` writes) tests the objects of fold ``split.fold`` of resample ``seed`` instead of dealing
them; the file's digest is part of the job's split node, so a changed file is a new job.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from tactile_exp.data.layout import DataError

FOLDS_FILE = "folds.yaml"
HEADER = (
    "# Frozen folds: per label, per resample (seed), the objects of each fold (object-grouped,\n"
    "# class-stratified; tactile_exp.data.frozen). Regenerating them changes the split.\n"
)


@dataclass(frozen=True)
class FrozenFolds:
    """Label -> resample -> fold -> object names, and the digest of the file they came from."""

    folds: int
    resamples: int
    labels: dict[str, list[list[list[str]]]]
    digest: str = ""

    @classmethod
    def read(cls, file: Path) -> FrozenFolds:
        """The folds of ``file``; one-line `DataError` naming it when they are not well formed."""
        expected = "expected folds: K, resamples: R, labels: {LABEL: [[[OBJECT, ...] x K] x R]}"
        try:
            raw = file.read_bytes()
            node = yaml.safe_load(raw)
        except OSError as e:
            raise DataError(f"{file}: cannot read ({e.strerror}); {expected}") from e
        except yaml.YAMLError as e:
            raise DataError(f"{file}: not valid YAML; {expected}") from e
        if not isinstance(node, dict) or set(node) != {"folds", "resamples", "labels"}:
            raise DataError(f"{file}: {expected}")
        k, r, labels = node["folds"], node["resamples"], node["labels"]
        if not (isinstance(k, int) and k >= 2 and isinstance(r, int) and r >= 1):
            raise DataError(f"{file}: folds={k!r}, resamples={r!r}; expected K >= 2, R >= 1")
        if not isinstance(labels, dict) or not labels:
            raise DataError(f"{file}: labels: {expected}")
        for label, resamples in labels.items():
            ok = (
                isinstance(resamples, list)
                and len(resamples) == r
                and all(isinstance(f, list) and len(f) == k for f in resamples)
                and all(isinstance(objs, list) for f in resamples for objs in f)
            )
            if not ok:
                raise DataError(f"{file}: label {label!r}: expected {r} resamples of {k} folds")
            for folds in resamples:
                names = [str(o) for objs in folds for o in objs]
                if len(set(names)) != len(names):
                    raise DataError(f"{file}: label {label!r}: an object in two folds of one seed")
        digest = hashlib.sha256(raw).hexdigest()[:12]
        return cls(k, r, {str(a): v for a, v in labels.items()}, digest)

    def write(self, file: Path) -> None:
        body = {"folds": self.folds, "resamples": self.resamples, "labels": self.labels}
        file.write_text(HEADER + yaml.safe_dump(body, sort_keys=False, default_flow_style=None))

    def test_objects(self, label: str, seed: int, folds: int, fold: int, where: str) -> list[str]:
        """The objects fold ``fold`` of resample ``seed`` tests; DataError when the job asks for
        folds the file does not hold."""
        if folds != self.folds:
            raise DataError(
                f"{where}: holds frozen folds with K={self.folds}, the job asks for "
                f"split.folds={folds}; set split.folds={self.folds}"
            )
        if not 0 <= seed < self.resamples:
            raise DataError(
                f"{where}: holds {self.resamples} frozen resamples (seed=0..{self.resamples - 1}),"
                f" the job asks for seed={seed}"
            )
        if label not in self.labels:
            raise DataError(f"{where}: no frozen folds for label {label!r}")
        return [str(o) for o in self.labels[label][seed][fold]]


def deal(
    labels: Mapping[str, Mapping[str, int]], folds: int, resamples: int
) -> dict[str, list[list[list[str]]]]:
    """Object-grouped, class-stratified folds of every label (``labels``: object -> label ->
    0/1), as `tactile_exp.data.splits.folds_split` deals them: each class's objects shuffled
    (seeded by the resample and the label's place) and dealt to the folds in turn, the
    negatives continuing where the positives stopped."""
    names = list(next(iter(labels.values())))
    out: dict[str, list[list[list[str]]]] = {}
    for index, label in enumerate(names):
        per_resample = []
        for seed in range(resamples):
            rng = np.random.default_rng([seed, index, 27])
            dealt: list[list[str]] = [[] for _ in range(folds)]
            start = 0
            for value in (1, 0):
                objs = sorted(o for o, row in labels.items() if row[label] == value)
                for k, i in enumerate(rng.permutation(len(objs))):
                    dealt[(start + k) % folds].append(objs[int(i)])
                start = (start + len(objs)) % folds
            per_resample.append([sorted(f) for f in dealt])
        out[label] = per_resample
    return out


def check_stratified(folds: FrozenFolds, labels: Mapping[str, Mapping[str, int]]) -> list[str]:
    """What is wrong with ``folds`` for ``labels`` (object -> label -> 0/1): a resample that
    leaves out or repeats an object, or a fold without both classes. Empty when sound."""
    problems = []
    objects = sorted(labels)
    for label, resamples in folds.labels.items():
        for seed, dealt in enumerate(resamples):
            flat: Sequence[str] = sorted(o for f in dealt for o in f)
            if list(flat) != objects:
                problems.append(f"{label} resample {seed}: objects {flat} != {objects}")
            for k, fold in enumerate(dealt):
                if {labels[o][label] for o in fold} != {0, 1}:
                    problems.append(f"{label} resample {seed} fold {k}: not both classes")
    return problems

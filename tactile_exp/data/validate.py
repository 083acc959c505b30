"""Whole-file checks and a compact summary of a PHAC-2 file (for the data CLI and for callers).

`validate` keeps going after each problem so one run lists everything wrong with a file.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from tactile_exp.data.layout import ADJECTIVES, EPS, DataError
from tactile_exp.data.phac2 import PHAC2
from tactile_exp.data.splits import make_split

Progress = Callable[[str], None]  # one line of progress: what is being checked now
EVERY = 60  # trials between two progress lines


def _quiet(line: str) -> None:
    pass


def trial_progress(say: Progress, what: str) -> Callable[[int, int], None]:
    """A ``check_trials``/``summary`` callback saying ``what: done/total trials`` every
    ``EVERY`` trials."""

    def tick(done: int, total: int) -> None:
        if done % EVERY == 0:
            say(f"{what}: {done}/{total} trials")

    return tick


def checks(photographs: bool = True) -> list[str]:
    """What ``validate`` checks, in order (the data CLI names them when the file passes)."""
    out = [
        "every trial readable: its BioTac signals and states present and finite",
        "the labels of every object",
        f"the published train/test split of each of the {len(ADJECTIVES)} adjectives",
    ]
    return out + (["a photograph of every object"] if photographs else [])


def validate(
    path: str | Path,
    photo_dir: str | Path | None = None,
    photographs: bool = True,
    progress: Progress = _quiet,
) -> list[str]:
    """Every problem found in the file (and, unless ``photographs=False``, its photographs);
    ``progress`` gets a line per stage and every ``EVERY`` trials read."""
    try:
        dataset = PHAC2(path, photo_dir)
    except DataError as e:
        return [str(e)]
    _, problems = dataset.check_trials(trial_progress(progress, f"validate {dataset.path}"))
    progress(f"validate {dataset.path}: labels and the published splits")
    try:
        dataset.labels()
    except DataError as e:
        return [*problems, str(e)]
    for adj in ADJECTIVES:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                make_split(dataset, adj, "published")
        except DataError as e:
            problems.append(str(e))
    if photographs:
        progress(f"validate {dataset.path}: photographs in {dataset.photo_dir}")
        problems += _photo_problems(dataset)
    return problems


def _photo_problems(dataset: PHAC2) -> list[str]:
    if not dataset.photo_dir.is_dir():
        return [f"{dataset.photo_dir}: photograph folder missing (expected JPEGs of the objects)"]
    found = dataset.photographs()
    stems = {t.object_id: t.stem for t in dataset.trials}
    return [
        f"{dataset.photo_dir}: object {oid} ({stems[oid]}) has no photograph (expected a JPEG "
        f"whose name holds {stems[oid]} or {oid:03d})"
        for oid in dataset.object_ids()
        if oid not in found
    ]


def summary(dataset: PHAC2, progress: Progress = _quiet) -> dict[str, Any]:
    """Objects, trials, EP lengths, label counts, split sizes and photographs of one file;
    ``progress`` gets a line every ``EVERY`` trials read."""
    ep_rows: dict[str, list[int]] = {ep: [] for ep in EPS}
    bad = 0
    tick = trial_progress(progress, f"inspect {dataset.path}")
    for i, t in enumerate(dataset.trials):
        tick(i, len(dataset.trials))
        try:
            trial = dataset.read_trial(t, optional=False)
        except DataError:
            bad += 1
            continue
        for ep, seg in trial.ep_segments().items():
            ep_rows[ep].append(seg.stop - seg.start)
    labels = dataset.labels()
    splits: dict[str, Any] = {}
    for adj in ADJECTIVES:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                s = make_split(dataset, adj, "published")
            splits[adj] = {"train": len(s.train), "test": len(s.test)}
        except DataError as e:
            splits[adj] = {"error": str(e)}
    photos = dataset.photographs()
    return {
        "path": str(dataset.path),
        "objects": len(dataset.object_ids()),
        "trials": len(dataset.trials),
        "bad_trials": bad,
        "ep_rows": {
            ep: {"min": min(v), "median": float(np.median(v)), "max": max(v)} if v else {}
            for ep, v in ep_rows.items()
        },
        "positive_objects": {a: sum(lab[a] for lab in labels.values()) for a in ADJECTIVES},
        "splits": splits,
        "photographs": sum(len(v) for v in photos.values()),
        "objects_without_photographs": [o for o in dataset.object_ids() if o not in photos],
    }

"""Held-out scores as plain files, one per configuration x data set x fold, in and out.

``--export-results DIR`` writes every configuration's test scores as
``DIR/<configuration>/<data identity>/fold<k>.csv`` (``fold<k>_seed<s>.csv`` for seeds after the
first; ``fold0`` for a split without folds), one line per test unit and label: ``label``,
``object`` (the data set's object id), ``unit``, ``truth`` (0/1) and ``score`` (higher = more
likely positive), as the time-series classification field shares its results (tsml). The
configuration's folder is its name with ``,`` between its settings (``model=haptic_cnn,
model.groups=44``); the data set's is its identity (name and digest), which is what pairs it with
the runs of this project.

``--import-results DIR`` reads such a tree, written here or by a method run elsewhere on the same
objects, as configurations of the report: they enter the leaderboards, the declared comparisons
and the table across data sets like tracked ones (a folder name that is not ``key=value``
settings is taken as ``model=<name>``).
"""

from __future__ import annotations

import csv
import re
from pathlib import Path

import numpy as np

from tactile_exp import stats
from tactile_exp.report.heldout import Evidence
from tactile_exp.report.runs import Group, Run
from tactile_exp.report.scores import ReportError, read_scores
from tactile_exp.tracking import Tracker

COLUMNS = ("label", "object", "unit", "truth", "score")
_FILE = re.compile(r"fold(?P<fold>\d+)(_seed(?P<seed>\d+))?\.csv")


def _file_name(run: Run, first_seed: int) -> str:
    fold = max(run.fold, 0)
    return f"fold{fold}.csv" if run.seed == first_seed else f"fold{fold}_seed{run.seed}.csv"


def export(tracker: Tracker, groups: list[Group], names: dict[str, str], into: Path) -> list[Path]:
    """Each group's runs' held-out scores, a file per run (fold, seed); returns the files."""
    written = []
    for g in groups:
        folder = into / names[g.key].replace(" ", ",") / (g.first_run.data or "unknown")
        folder.mkdir(parents=True, exist_ok=True)
        for run in g.sorted_runs:
            lines = []
            for label, child in sorted(tracker.children(run.run_id).items()):
                lines += [
                    (label, u.object_id, u.unit, u.label, repr(u.score))
                    for u in read_scores(tracker, child)
                ]
            path = folder / _file_name(run, min(g.seeds))
            with open(path, "w", newline="") as f:
                writer = csv.writer(f)
                writer.writerow(COLUMNS)
                writer.writerows(lines)
            written.append(path)
    return written


def _settings(name: str) -> dict[str, str]:
    words = name.split(",")
    if all(re.fullmatch(r"[\w.]+=[^=]+", w) for w in words):
        return dict(w.split("=", 1) for w in words)
    return {"model": name}


def _read(path: Path) -> dict[str, list[tuple[int, int, float]]]:
    """One file's units per label: (object, truth, score)."""
    out: dict[str, list[tuple[int, int, float]]] = {}
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        if tuple(reader.fieldnames or ()) != COLUMNS:
            raise ReportError(f"{path}: expected the columns {','.join(COLUMNS)}")
        for line, row in enumerate(reader, start=2):
            try:
                unit = (int(row["object"]), int(row["truth"]), float(row["score"]))
            except (TypeError, ValueError):
                raise ReportError(
                    f"{path}:{line}: expected an integer object, truth 0 or 1 and a number score"
                ) from None
            if unit[1] not in (0, 1) or not np.isfinite(unit[2]):
                raise ReportError(f"{path}:{line}: expected truth 0 or 1 and a finite score")
            out.setdefault(row["label"], []).append(unit)
    return out


def load(root: Path) -> list[tuple[Group, Evidence]]:
    """Every configuration x data set folder under ``root`` as a group and its evidence (each
    seed's folds pooled, as the report pools tracked runs)."""
    if not root.is_dir():
        raise ReportError(f"--import-results {root}: not a folder")
    found = []
    for folder in sorted(p for p in root.glob("*/*") if p.is_dir()):
        files = sorted(p for p in folder.iterdir() if _FILE.fullmatch(p.name))
        if not files:
            raise ReportError(f"{folder}: no fold<k>.csv files")
        name, identity = folder.parent.name, folder.name
        pooled: dict[int, dict[str, list[tuple[int, int, float]]]] = {}
        folds: set[int] = set()
        for path in files:
            match = _FILE.fullmatch(path.name)
            seed, fold = int(match["seed"] or 0), int(match["fold"])
            folds.add(fold)
            for label, units in _read(path).items():
                pooled.setdefault(seed, {}).setdefault(label, []).extend(units)
        evaluations = []
        for seed in sorted(pooled):
            evaluation = {}
            for label, units in sorted(pooled[seed].items()):
                table = np.array(units, dtype=float)
                if len(np.unique(table[:, 1])) < 2:
                    raise ReportError(f"{folder}: {label}'s test units are of one class only")
                evaluation[label] = stats.HeldOut(
                    table[:, 0].astype(int), table[:, 1].astype(int), table[:, 2]
                )
            evaluations.append(evaluation)
        found.append(_group(name, identity, sorted(pooled), len(folds), evaluations))
    if not found:
        raise ReportError(f"--import-results {root}: no <configuration>/<data set>/ folders")
    return found


def _group(
    name: str, identity: str, seeds: list[int], n_folds: int, evaluations: list[stats.Evaluation]
) -> tuple[Group, Evidence]:
    settings = _settings(name)
    labels = tuple(sorted({a for e in evaluations for a in e}))
    runs = {}
    for seed, evaluation in zip(seeds, evaluations, strict=True):
        aucs = {a: t.value for a, t in evaluation.items()}
        runs[seed, -1] = Run(
            run_id=f"imported:{name}/{identity}/seed{seed}",
            seed=seed,
            start_time=0,
            mean_auc=float(np.mean(list(aucs.values()))),
            aucs=aucs,
            data=identity,
            sweep_id="",
            labels=labels,
            layout="imported",  # never one of the paper's rows
        )
    model = settings.get("model", name)
    group = Group(
        key=f"imported:{name}@{identity}",
        row_hash=f"imported:{name}",
        method=name,
        row="",
        paper_auc=None,
        schedule="",
        schedule_epochs="",
        split=f"imported ({n_folds} fold(s) pooled)",
        modality="",
        model=model,
        n_adjectives=len(labels),
        differences=("imported results",),
        params={"choice.model": model} | {k: v for k, v in settings.items() if k != "model"},
        overrides={k: v for k, v in settings.items() if k != "model"},
        runs=runs,
    )
    return group, Evidence(evaluations)

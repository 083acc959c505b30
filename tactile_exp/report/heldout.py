"""A configuration's held-out evidence: its child runs' ``scores.csv`` as `stats.Evaluation`s,
one per seed (with ``split=folds`` the seed's folds pooled: every object scored out of fold),
and the intervals the report prints.

Runs logged before ``scores.csv`` existed still report: their group has no evidence and says why.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tactile_exp import stats
from tactile_exp.report.runs import Group
from tactile_exp.report.scores import ReportError, read_scores
from tactile_exp.tracking import Tracker

# An AUC over fewer positive (or negative) test objects than this moves in steps of at least a
# third per object: a label, not a conclusion.
FEW_OBJECTS = 3


@dataclass
class Evidence:
    """What the scores say about one group; ``missing`` says why there is nothing."""

    evaluations: list[stats.Evaluation] = field(default_factory=list)
    missing: str = ""
    folds_run: str = ""  # split=folds: "5/5" folds pooled per seed (the fewest of any seed)
    # The bootstraps, made once: Table I, Fig. 5, the per-adjective CSV and the ablation view
    # each ask for them.
    _interval: stats.Interval | None = field(default=None, init=False, repr=False, compare=False)
    _per_adjective: dict[str, stats.Interval] | None = field(
        default=None, init=False, repr=False, compare=False
    )

    @property
    def ok(self) -> bool:
        return bool(self.evaluations)

    def interval(self) -> stats.Interval:
        if self._interval is None:
            self._interval = stats.mean_interval(self.evaluations)
        return self._interval

    def per_adjective(self) -> dict[str, stats.Interval]:
        if self._per_adjective is None:
            self._per_adjective = stats.adjective_intervals(self.evaluations)
        return self._per_adjective

    def sizes(self) -> dict[str, tuple[int, int]]:
        """Adjective -> (positive, negative) test objects (the fewest over seeds)."""
        out: dict[str, tuple[int, int]] = {}
        for ev in self.evaluations:
            for a, held in ev.items():
                n = (len(held.key[0]), len(held.key[1]))
                out[a] = min(out.get(a, n), n)
        return out

    def thin(self) -> list[str]:
        """Adjectives whose AUC rests on fewer than FEW_OBJECTS positive or negative objects."""
        return sorted(a for a, (p, n) in self.sizes().items() if min(p, n) < FEW_OBJECTS)


def load(tracker: Tracker, group: Group, metric: str = "roc_auc") -> Evidence:
    """Every seed's held-out scores of ``group`` (folds pooled), or why they are missing; its
    numbers are ``metric``'s (``tactile_exp.metrics``)."""
    evaluations: list[stats.Evaluation] = []
    fewest = None
    for seed in group.seeds:
        pooled: dict[str, list[list[float]]] = {}
        runs = group.fold_runs(seed)
        for run in runs:
            found = tracker.children(run.run_id)
            missing = sorted(set(run.aucs) - set(found))
            if missing:
                return Evidence(
                    missing=f"run {run.run_id}: no scores.csv for {', '.join(missing)} (no "
                    "finished child run; logged before the report read scores?)"
                )
            for adjective, child in found.items():
                try:
                    units = read_scores(tracker, child)
                except ReportError:
                    return Evidence(
                        missing=f"run {run.run_id} has no readable scores.csv (logged before "
                        "the report read them): no intervals, no paired comparisons"
                    )
                rows = pooled.setdefault(adjective, [])
                rows += [[u.object_id, u.label, u.score] for u in units]
        evaluation = {}
        for adjective, rows in pooled.items():
            table = np.array(rows, dtype=float)
            if len(np.unique(table[:, 1])) < 2:
                return Evidence(
                    missing=f"seed {seed}: {adjective}'s test units are of one class only"
                )
            evaluation[adjective] = stats.HeldOut(
                table[:, 0].astype(int), table[:, 1].astype(int), table[:, 2], metric
            )
        evaluations.append(evaluation)
        fewest = len(runs) if fewest is None else min(fewest, len(runs))
    folds = f"{fewest}/{group.folds}" if group.folds else ""
    return Evidence(evaluations, folds_run=folds)

"""What predict returns: per-adjective decision values of each unit, and how it prints them."""

from __future__ import annotations

import csv
import io
import json
from dataclasses import dataclass, field

import numpy as np

from tactile_exp.data.layout import DataError, Instances, TrialName, Trials
from tactile_exp.metrics import THRESHOLD


@dataclass
class Prediction:
    """Per-adjective scores of each unit (a trial, a group of trials, or an object's views)."""

    run_id: str
    units: list[str]
    adjectives: list[str]
    scores: np.ndarray  # (n_units, n_adjectives) decision values
    job: str = ""  # the job as a person knows it: run name, model, combine, Table I row
    chosen: str = ""  # how the job was chosen when no run id was given
    data: str = ""  # the data file the trials were read from, and why that one
    objects: list[int | None] = field(default_factory=list)  # each unit's object, when known
    object_names: dict[int, str] = field(default_factory=dict)  # object -> e.g. car_sponge_101
    labels: dict[int, list[str]] = field(default_factory=dict)  # object -> its true adjectives

    def object_predictions(self) -> dict[int, list[str]]:
        """Per object: the adjectives whose mean decision value over its units is > 0."""
        out = {}
        for obj in dict.fromkeys(o for o in self.objects if o is not None):
            rows = [i for i, o in enumerate(self.objects) if o == obj]
            mean = self.scores[rows].mean(axis=0)
            out[obj] = [a for a, s in zip(self.adjectives, mean, strict=True) if s > THRESHOLD]
        return out

    def predicted(self) -> list[list[str]]:
        """The adjectives whose decision value is > 0, per unit."""
        return [
            [a for a, s in zip(self.adjectives, row, strict=True) if s > THRESHOLD]
            for row in self.scores
        ]

    def to_csv(self) -> str:
        out = io.StringIO()
        writer = csv.writer(out)
        writer.writerow(["unit", *self.adjectives, "predicted"])
        for unit, row, chosen in zip(self.units, self.scores, self.predicted(), strict=True):
            writer.writerow([unit, *(f"{s:.6f}" for s in row), " ".join(chosen)])
        return out.getvalue()

    def to_json(self) -> str:
        units = [
            {"unit": u, "scores": dict(zip(self.adjectives, map(float, row), strict=True)),
             "predicted": chosen}
            for u, row, chosen in zip(self.units, self.scores, self.predicted(), strict=True)
        ]  # fmt: skip
        head = {"run_id": self.run_id, "job": self.job, "data": self.data}
        return json.dumps({**head, "units": units}, indent=1)

    def header(self) -> list[str]:
        """Which job, which data file and what the numbers are: the lines above the table."""
        lines = [f"job {self.run_id}: {self.job}" if self.job else f"job {self.run_id}"]
        lines += [f"  {self.chosen}"] if self.chosen else []
        lines += [f"data {self.data}"] if self.data else []
        lines.append(
            "scores: each adjective classifier's decision value; > 0 means the adjective is "
            "predicted"
        )
        return lines

    def to_table(self) -> str:
        lines = [*self.header(), ""]
        for unit, chosen in zip(self.units, self.predicted(), strict=True):
            lines.append(f"{unit}: {', '.join(chosen) or '(none)'}")
        width = max(len(a) for a in self.adjectives)
        cell = max(10, *(len(u) for u in self.units))  # whole unit names, never cut
        lines.append("")
        lines.append(" " * width + "  " + "  ".join(f"{u:>{cell}}" for u in self.units))
        for j, adjective in enumerate(self.adjectives):
            values = "  ".join(f"{s:>{cell}.4f}" for s in self.scores[:, j])
            lines.append(f"{adjective:>{width}}  {values}")
        lines += self._object_lines()
        return "\n".join(lines) + "\n"

    def _object_lines(self) -> list[str]:
        """Each object's predicted set (mean decision value over its units > 0), against its
        true adjectives where the data file has labels (among the adjectives scored)."""
        predicted = self.object_predictions()
        if not predicted:
            return []
        lines = ["", "per object (mean decision value over its units > 0):"]
        for obj, chosen in predicted.items():
            name = f" ({self.object_names[obj]})" if obj in self.object_names else ""
            line = f"  object {obj}{name}: predicted {', '.join(chosen) or '(none)'}"
            if obj in self.labels:
                true = [a for a in self.adjectives if a in self.labels[obj]]
                agree = sum((a in chosen) == (a in true) for a in self.adjectives)
                line += (
                    f"; true {', '.join(true) or '(none)'}; "
                    f"{agree} of {len(self.adjectives)} adjectives right"
                )
            lines.append(line)
        return lines


def unit_names(units: Instances, *, by_object: bool) -> list[str]:
    """The names predict (and the deployed model) show for scored ``units``: a unit of several
    trials by its object (``car_sponge_101``, ``..#2`` for an object's second unit), a trial's
    several instances as ``<trial>#<k>``, a single trial or view by itself."""
    names = [str(t) for t in units.trial]
    if by_object:
        names = [n.stem if (n := TrialName.parse(u)) is not None else u for u in names]
    counts = {name: names.count(name) for name in names}
    seen: dict[str, int] = {}
    out = []
    for name in names:
        seen[name] = seen.get(name, 0) + 1
        if counts[name] == 1:
            out.append(name)
        else:
            out.append(f"{name}#{seen[name] - (0 if by_object else 1)}")
    return out


def object_of(unit: str) -> int | None:
    """The object of a unit named by a trial (``<object>_<id>_<trial>[#k]``), else None."""
    name = TrialName.parse(unit.split("#", 1)[0])
    return None if name is None else name.object_id


def true_labels(
    given: Trials, objects: list[int | None], adjectives: list[str]
) -> dict[int, list[str]]:
    """The true adjectives of ``objects`` where the data file has labels; {} where not."""
    try:
        labels = given.dataset.labels()
    except (DataError, OSError, KeyError, ValueError):
        return {}
    return {
        o: [a for a in adjectives if labels[o].get(a) == 1]
        for o in dict.fromkeys(objects)
        if o is not None and o in labels
    }

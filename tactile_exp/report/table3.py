"""Table III: for a few test objects, the ground-truth adjectives beside each row's predictions.

Read from the jobs' ``scores.csv`` (held-out scores only, never a model re-applied to its own
training objects). Each adjective has its own split, so an object is a test object of some
adjectives only: an object's line covers the adjectives it is tested on in every shown row.
An object's score for an adjective is the mean decision value of its test units (the trials of
row I, the object's views of row L, the trial + views units of row M); the adjective is predicted
when that mean is > ``THRESHOLD`` (0, the hinge-loss heads' boundary).
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tactile_exp.data.layout import ObjectInfo, objects
from tactile_exp.metrics import THRESHOLD
from tactile_exp.report.runs import Group, label_order, row_group
from tactile_exp.report.scores import UnitScore, read_scores
from tactile_exp.tracking import Tracker

# The paper's Table III columns: Table I row -> modality shown.
ROWS: dict[str, str] = {"I": "haptic", "L": "visual", "M": "multimodal"}
N_OBJECTS = 3
NOT_RUN = "not run"


@dataclass(frozen=True)
class RowScores:
    """One row's job: per adjective, per test object, the mean decision value and the label."""

    row: str
    method: str
    run_id: str
    scores: dict[str, dict[int, tuple[float, int]]]  # adjective -> object id -> (score, label)
    labels: tuple[str, ...] = ()  # the adjectives in the order the job logged them

    def tested(self, object_id: int) -> set[str]:
        return {a for a, by_object in self.scores.items() if object_id in by_object}


def object_scores(units: list[UnitScore]) -> dict[int, tuple[float, int]]:
    """Object id -> (mean decision value of its test units, its label)."""
    by_object: dict[int, list[UnitScore]] = {}
    for unit in units:
        by_object.setdefault(unit.object_id, []).append(unit)
    return {
        o: (float(np.mean([u.score for u in us])), max(u.label for u in us))
        for o, us in by_object.items()
    }


def read_rows(tracker: Tracker, groups: list[Group]) -> dict[str, RowScores | None]:
    """Each of ``ROWS``: its job's per-object test scores (the group's lowest seed), or None
    when the row was not run."""
    out: dict[str, RowScores | None] = {}
    for row in ROWS:
        group = row_group(groups, row)
        if group is None:
            out[row] = None
            continue
        run_id = group.first_run.run_id
        scores = {
            a: object_scores(read_scores(tracker, c)) for a, c in tracker.children(run_id).items()
        }
        out[row] = RowScores(row, group.method, run_id, scores, tuple(label_order([group])))
    return out


def choose_objects(rows: dict[str, RowScores | None], n: int | None = N_OBJECTS) -> list[int]:
    """The ``n`` (None: all) objects tested on the most adjectives in every row that ran
    (ties: the lower id first)."""
    ran = [r for r in rows.values() if r is not None]
    if not ran:
        return []
    candidates = set.intersection(*({o for s in r.scores.values() for o in s} for r in ran))
    coverage = {o: len(set.intersection(*(r.tested(o) for r in ran))) for o in candidates}
    return sorted(coverage, key=lambda o: (-coverage[o], o))[:n]


def object_name(info: ObjectInfo) -> str:
    """The object's display name, else its group stem without the id (some objects of the
    published list have no display name): ``colored_cover_book_302`` -> ``colored cover book``."""
    return info.display_name or info.group_stem.rsplit("_", 1)[0].replace("_", " ")


def table3(rows: dict[str, RowScores | None], object_ids: list[int]) -> list[dict[str, str]]:
    """One line per object and row: tested adjectives, ground truth, predicted set, agreement."""
    names = {o.object_id: object_name(o) for o in objects()}
    ran = [r for r in rows.values() if r is not None]
    lines = []
    for object_id in object_ids:
        order = [*ran[0].labels, *sorted(set(ran[0].scores) - set(ran[0].labels))] if ran else []
        tested = [a for a in order if all(a in r.tested(object_id) for r in ran)]
        truth = [a for a in tested if ran[0].scores[a][object_id][1] == 1]
        for row, modality in ROWS.items():
            scores = rows[row]
            line = {
                "object_id": str(object_id),
                "object": names.get(object_id, ""),
                "tested_adjectives": " ".join(tested),
                "ground_truth": " ".join(truth),
                "row": row,
                "modality": modality,
                "method": scores.method if scores else "",
                "run_id": scores.run_id if scores else "",
                "predicted": NOT_RUN,
                "agree": "",
            }
            if scores is not None:
                predicted = [a for a in tested if scores.scores[a][object_id][0] > THRESHOLD]
                line["predicted"] = " ".join(predicted)
                agree = sum((a in predicted) == (a in truth) for a in tested)
                line["agree"] = f"{agree}/{len(tested)}"
            lines.append(line)
    return lines


def table3_markdown(lines: list[dict[str, str]]) -> str:
    """One table line per object: ground truth, then each row's predicted set."""
    head = ["object", "tested on", "ground truth"]
    head += [f"{row} ({modality})" for row, modality in ROWS.items()]
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    by_object: dict[str, list[dict[str, str]]] = {}
    for line in lines:
        by_object.setdefault(line["object_id"], []).append(line)
    for object_id, object_lines in by_object.items():
        first = object_lines[0]
        cells = [
            f"{first['object'] or 'object'} ({object_id})",
            f"{len(first['tested_adjectives'].split())}: "
            + ", ".join(first["tested_adjectives"].split()),
            ", ".join(first["ground_truth"].split()) or "(none)",
        ]
        for line in object_lines:
            if line["predicted"] == NOT_RUN:
                cells.append(NOT_RUN)
            else:
                chosen = ", ".join(line["predicted"].split()) or "(none)"
                cells.append(f"{chosen} ({line['agree']} agree)")
        out.append("| " + " | ".join(cells) + " |")
    return "\n".join(out) + "\n"


def write_table3(lines: list[dict[str, str]], out: Path) -> list[Path]:
    """``table3.md`` and ``table3.csv`` into ``out``."""
    (out / "table3.md").write_text(table3_markdown(lines))
    with open(out / "table3.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, list(lines[0]) if lines else ["object_id"])
        writer.writeheader()
        writer.writerows(lines)
    return [out / "table3.md", out / "table3.csv"]

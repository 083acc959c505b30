"""``scores.csv``, each adjective run's test units and their scores: written once by the
recording, read by predict's and deploy's examples and by the report; one format, here."""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass

import numpy as np

from tactile_exp.metrics import THRESHOLD

NAME = "scores.csv"
HEADER = "unit,object_id,label,score"


@dataclass(frozen=True)
class UnitScore:
    unit: str  # the unit's name: its first trial (or photograph)
    object_id: int
    label: int
    score: float  # the decision value

    @property
    def predicted(self) -> bool:
        return self.score > THRESHOLD


def write(units: np.ndarray, objects: np.ndarray, y: np.ndarray, scores: np.ndarray) -> str:
    """The file's text: one line per unit, in the order given."""
    table = io.StringIO()
    np.savetxt(
        table,
        np.column_stack([units, objects, y, scores]),
        fmt="%s",
        delimiter=",",
        header=HEADER,
        comments="",
    )
    return table.getvalue()


def read(text: str) -> list[UnitScore]:
    """The units of a file ``write`` wrote; KeyError or ValueError when it is not one."""
    return [
        UnitScore(r["unit"], int(r["object_id"]), int(float(r["label"])), float(r["score"]))
        for r in csv.DictReader(io.StringIO(text))
    ]

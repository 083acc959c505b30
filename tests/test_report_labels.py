"""The report's label note: labels a job dropped (``labels.min_objects``) and labels scored on
trials of an object seen in training, read from the jobs' run tags."""

from __future__ import annotations

from pathlib import Path

import pytest
from test_new_dataset import write_lab_data

from tactile_exp.config import settings_from_config
from tactile_exp.experiment import run
from tactile_exp.report.labels import label_notes
from tactile_exp.report.runs import collect
from tactile_exp.tracking import Tracker


@pytest.mark.slow
@pytest.mark.job
def test_dropped_and_seen_object_labels_are_listed(tiny_config, tmp_path: Path) -> None:
    data = write_lab_data(tmp_path / "lab", 3, "glove", "excel")  # sticky: one positive object
    base = ["data=folder", f"data.path={data}", "modality=signals", "model=random", "split=random"]
    kept = settings_from_config(tiny_config(base, adjectives="null"))
    run(kept)
    dropped = settings_from_config(tiny_config([*base, "labels.min_objects=2"], "null"))
    assert dropped.config_hash != kept.config_hash  # a set min_objects is another job
    assert run(dropped).results.keys() == {"hard", "soft"}
    tracker = Tracker(kept.tracking.uri, kept.tracking.experiment)
    text = label_notes(collect(tracker), tracker)
    assert "## Labels left out or scored on a seen object" in text
    assert "dropped by `labels.min_objects` (+/- objects): sticky(+1/-4)" in text
    assert "scored on trials of an object seen in training: sticky" in text
    assert label_notes([], tracker) == ""

"""``python -m tactile_exp.data import-csv``: per-trial CSV files -> the folder layout, what it
prints, its one-line refusals, and a round trip through a job and predict."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tactile_exp.data.__main__ import main as data_main
from tactile_exp.data.folder import FolderDataSet

CHANNELS = ("pdc", "tac", "e1", "e2", "e3")
LABELS = {  # object -> (hard, rough): hard +2/-3, rough +3/-2
    "cork": (1, 1),
    "foam": (0, 1),
    "felt": (0, 1),
    "steel": (1, 0),
    "satin": (0, 0),
}


def write_csvs(root: Path, trials: int = 4, rate: float = 50.0) -> Path:
    """One CSV per trial under ``root/<object>/``, a time column in seconds and a trailing
    separator on every row (as loggers write), plus a pandas-written labels table."""
    import pandas as pd

    rng = np.random.default_rng(39)
    for name, (hard, rough) in LABELS.items():
        (root / name).mkdir(parents=True)
        for t in range(1, trials + 1):
            n = int(rng.integers(70, 90))
            values = rng.normal(size=(n, len(CHANNELS))) + [hard, rough, 0, 0, 0]
            lines = ["time," + ",".join(CHANNELS)]
            lines += [
                f"{100 + k / rate:.6f}," + ",".join(f"{v:.5f}" for v in row) + ","
                for k, row in enumerate(values)
            ]
            (root / name / f"{name}_{t}.csv").write_text("\n".join(lines) + "\n")
    frame = pd.DataFrame(
        {"object": list(LABELS), "hard": [float(h) for h, _ in LABELS.values()],
         "rough": [r == 1 for _, r in LABELS.values()]}
    )  # fmt: skip
    frame.to_csv(root / "labels.csv")  # pandas' index column, 1.0/0.0 and True/False
    return root


def test_import_writes_the_folder_layout_and_prints_what_it_found(tmp_path: Path, capsys) -> None:
    src = write_csvs(tmp_path / "export", trials=12)
    assert data_main(["import-csv", str(src), str(tmp_path / "ds"), "--sensor", "skin"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == f"wrote {tmp_path / 'ds'} (data=folder data.path={tmp_path / 'ds'})"
    assert out[1] == "  objects   5: cork, felt, foam, satin, steel"
    assert out[2].startswith("  trials    60 (12-12 per object), ")
    assert out[3] == "  channels  5: pdc, tac, e1, e2, e3"
    assert out[4] == "  rate      50 Hz"
    assert out[6:8] == ["  hard                2         3", "  rough               3         2"]
    # the split dataset.yaml declares: folds with the largest K every label allows
    assert out[8] == (
        "  split     folds K=2 (label hard has 2 positive objects); declared in dataset.yaml, "
        "split=... overrides it"
    )
    ds = FolderDataSet(tmp_path / "ds")
    assert ds.declared_split == {"name": "folds", "folds": 2}
    assert ds.sensor.channels == CHANNELS and ds.sensor.rate_hz == 50.0
    assert ds.label_names == ("hard", "rough")
    assert {ds.object_name(i): (v["hard"], v["rough"]) for i, v in ds.labels().items()} == LABELS
    # trial order is natural: cork_10.csv is the 10th trial, not the 2nd
    raw = np.loadtxt(src / "cork" / "cork_10.csv", delimiter=",", skiprows=1, usecols=range(1, 6))
    np.testing.assert_allclose(ds.signals("cork_001_10"), raw.T)


@pytest.mark.parametrize(
    "case,expected",
    [
        ("cells", "{src}/foam/foam_2.csv:3: e2='x', expected a number"),
        ("channels", "{src}/steel/steel_1.csv: channels ['pdc', 'tac', 'e1', 'e2'], expected"),
        ("label", "{src}/labels.csv: no row for object(s) ['satin'] (which have trial files)"),
        ("norate", "{src}/cork/cork_1.csv: no time column (time, timestamp, t, time_s, seconds"),
        ("pattern", "{src}/cork/cork_1.csv: --object-pattern 'nomatch_(.*)' does not match"),
    ],
)
def test_bad_input_is_one_line_naming_the_file(tmp_path: Path, capsys, case, expected) -> None:
    src = write_csvs(tmp_path / "export", trials=2)
    args = ["import-csv", str(src), str(tmp_path / "ds")]
    if case == "cells":
        lines = (src / "foam" / "foam_2.csv").read_text().splitlines()
        cells = lines[2].split(",")
        cells[4] = "x"
        lines[2] = ",".join(cells)
        (src / "foam" / "foam_2.csv").write_text("\n".join(lines))
    elif case == "channels":
        file = src / "steel" / "steel_1.csv"
        file.write_text("\n".join(",".join(r.split(",")[:5]) for r in file.read_text().split()))
    elif case == "label":
        text = (src / "labels.csv").read_text().splitlines()
        (src / "labels.csv").write_text("\n".join(line for line in text if "satin" not in line))
    elif case == "norate":
        for file in src.glob("*/*.csv"):
            rows = file.read_text().split()
            file.write_text("\n".join(",".join(r.split(",")[1:]) for r in rows))
    else:
        args += ["--object-pattern", "nomatch_(.*)"]
    assert data_main(args) == 1
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("error: " + expected.format(src=src))
    assert not (tmp_path / "ds").exists()  # nothing written


@pytest.mark.slow
@pytest.mark.job
@pytest.mark.parametrize(
    "model", [["model=linear"], ["model=haptic_cnn", "model.groups=5"]], ids=["linear", "cnn"]
)
def test_csv_export_to_job_to_predict_round_trip(
    tiny_config, mlflow_uri: str, tmp_path: Path, capsys, model: list[str]
) -> None:
    """CSVs written here -> import-csv -> a job -> predict gives the job's own test scores."""
    from tactile_exp.config import settings_from_config
    from tactile_exp.experiment import run
    from tactile_exp.predict.__main__ import main as predict_main
    from tactile_exp.report.scores import read_scores
    from tactile_exp.tracking import Tracker

    src = write_csvs(tmp_path / "export", trials=4)
    data = tmp_path / "ds"
    assert data_main(["import-csv", str(src), str(data)]) == 0
    overrides = ["data=folder", f"data.path={data}", "modality=signals", "split=random", *model]
    settings = settings_from_config(tiny_config(overrides, adjectives="null"))
    result = run(settings)
    capsys.readouterr()
    tracker = Tracker(mlflow_uri, settings.tracking.experiment)
    children = tracker.children(result.run_id)
    assert sorted(children) == ["hard", "rough"]
    for label, child in children.items():
        logged = read_scores(tracker, child)
        for obj in sorted({u.object_id for u in logged}):
            code = predict_main([
                result.run_id, "--tracking-uri", mlflow_uri, "--data", str(data),
                "--object", str(obj), "--adjective", label, "--format", "json",
            ])  # fmt: skip
            assert code == 0
            units = json.loads(capsys.readouterr().out)["units"]
            predicted = {row["unit"]: row["scores"][label] for row in units}
            for unit in (u for u in logged if u.object_id == obj):
                assert predicted[unit.unit] == pytest.approx(unit.score, abs=1e-5)

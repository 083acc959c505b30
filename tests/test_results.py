"""Held-out scores out as files per configuration x data set x fold, and back in as
configurations of the report, paired with tracked ones."""

import csv
import shutil

import numpy as np
import pytest
import report_fixture

from tactile_exp.report import cli, configurations, heldout, results, runs
from tactile_exp.report.scores import ReportError
from tactile_exp.tracking import Tracker


@pytest.fixture(scope="module")
def tracked(mlflow_template, tmp_path_factory):
    path = tmp_path_factory.mktemp("results") / "mlflow.db"
    shutil.copy(mlflow_template, path)
    uri = f"sqlite:///{path}"
    tracker = Tracker(uri, "results_test")
    for model, quality in (("linear", 0.6), ("haptic_cnn", 1.5)):
        for fold in (0, 1):
            report_fixture.log_job(
                tracker, dataset="slide", model=model, quality=quality, fold=fold
            )
    return uri, tracker


def test_exported_files_read_back_as_the_same_evidence(tracked, tmp_path):
    _, tracker = tracked
    groups = runs.collect(tracker)
    names = configurations.names(groups)
    written = results.export(tracker, groups, names, tmp_path / "res")
    identity = "slide-0123456789ab"
    assert sorted(p.relative_to(tmp_path / "res").as_posix() for p in written) == [
        f"model={m}/{identity}/fold{k}.csv" for m in ("haptic_cnn", "linear") for k in (0, 1)
    ]
    with open(written[0], newline="") as f:
        rows = list(csv.DictReader(f))
    assert tuple(rows[0]) == results.COLUMNS
    assert len(rows) == len(report_fixture.LABELS) * 8 * report_fixture.UNITS  # 8 objects a fold
    back = {g.method: e for g, e in results.load(tmp_path / "res")}
    for g in groups:
        theirs = heldout.load(tracker, g).evaluations[0]
        mine = back[names[g.key]].evaluations[0]
        assert sorted(mine) == sorted(theirs)
        for label, held in theirs.items():
            order, other = np.lexsort((held.score, held.object_id)), mine[label]
            again = np.lexsort((other.score, other.object_id))
            assert np.array_equal(held.object_id[order], other.object_id[again])
            assert np.array_equal(held.score[order], other.score[again])
            assert held.auc == pytest.approx(other.auc)


def test_a_method_run_elsewhere_is_ranked_and_compared_paired(tracked, tmp_path):
    uri, _ = tracked
    folder = tmp_path / "elsewhere" / "minirocket" / "slide-0123456789ab"
    folder.mkdir(parents=True)
    rng = np.random.default_rng(3)
    for fold in (0, 1):
        with open(folder / f"fold{fold}.csv", "w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(results.COLUMNS)
            for j, label in enumerate(report_fixture.LABELS):
                for o in range(fold, report_fixture.N_OBJECTS, 2):
                    y = report_fixture.label_of(o, j)
                    writer.writerow([label, o, f"u{o}", y, 3.0 * y + rng.normal(0, 0.5)])
    out = tmp_path / "out"
    args = ["--tracking-uri", uri, "--experiment", "results_test", "--out", str(out)]
    cli.main([*args, "--import-results", str(tmp_path / "elsewhere")])
    board = list(csv.DictReader((out / "leaderboard.csv").read_text().splitlines()))
    assert [r["configuration"] for r in board][0] == "model=minirocket"
    assert board[1]["verdict"].startswith("model=minirocket beats")  # paired on the same objects
    assert board[0]["run_ids"] == "imported:minirocket/slide-0123456789ab/seed0"


@pytest.mark.parametrize(
    ("content", "says"),
    [
        ("label,object,score\nhard,1,0.5\n", "expected the columns label,object,unit,truth,score"),
        ("label,object,unit,truth,score\nhard,1,u,2,0.5\n", "fold0.csv:2: expected truth 0 or 1"),
        ("label,object,unit,truth,score\nhard,x,u,1,0.5\n", "fold0.csv:2: expected an integer"),
    ],
)
def test_a_bad_results_file_is_one_line(tmp_path, content, says):
    folder = tmp_path / "m" / "d"
    folder.mkdir(parents=True)
    (folder / "fold0.csv").write_text(content)
    with pytest.raises(ReportError, match=says):
        results.load(tmp_path)
    with pytest.raises(ReportError, match="no <configuration>/<data set>/ folders"):
        results.load(folder)

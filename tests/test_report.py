"""The report from runs logged as jobs log them: grouping, labels, numbers, files, CLI errors,
Table III from held-out scores, Fig. 6 from a stored ConvNet."""

import csv
import shutil

import numpy as np
import pytest
import report_fixture
from mlflow.tracking import MlflowClient
from PIL import Image
from sklearn.metrics import f1_score, roc_auc_score

from tactile_exp import experiment, stats, store
from tactile_exp.app import sweep
from tactile_exp.config import settings_from_config
from tactile_exp.data.layout import ADJECTIVES
from tactile_exp.report import activations, cli, configurations, figures, heldout, runs, table1
from tactile_exp.report import table3 as t3
from tactile_exp.tracking import Tracker

ROW_A = {"choice.experiment": "table1_a_haptic_static_1trial", "paper.row": "A"}
ROW_A |= {"paper.auc": "77.3", "modality.name": "haptic_features", "model.name": "linear_svm"}
ROW_K = {"choice.experiment": "table1_k_image_googlenet_1view", "paper.row": "K"}
ROW_K |= {"paper.auc": "71.5", "modality.name": "visual", "model.name": "visual_googlenet"}
ROW_I = {"choice.experiment": "table1_i_haptic_cnn_1trial", "paper.row": "I"}
ROW_I |= {"paper.auc": "83.2", "modality.name": "haptic", "model.name": "haptic_cnn"}
# (row_hash, params, seed, overrides, fail?, AUC of each adjective: base + 0.01 * index)
RUNS = [
    ("a", ROW_A, 0, "experiment=table1_a_haptic_static_1trial", False, 0.60),
    ("a", ROW_A, 1, "", False, 0.50),  # superseded by the rerun of seed 1 below
    ("a", ROW_A, 1, "", False, 0.70),
    ("a", ROW_A, 2, "", True, 0.10),  # failed: never counted
    ("k", ROW_K, 0, "split=random data=phac2 trunk.weights=w.pth trunk.layout=caffe", False, 0.55),
    ("i-quick", {**ROW_I, "choice.schedule": "quick"}, 0, "", False, 0.65),
    ("i-c10", ROW_I, 0, "combine=10", False, 0.75),  # a stronger variant, not row I
    ("i", ROW_I, 0, "", False, 0.68),
]


def _hash(key: str) -> str:
    """A group's row hash without the experiment file that keeps a Table I row apart and the
    data identity."""
    return key.split("@")[0].split(":")[0]


def _log(
    tracker: Tracker, key, row, seed, overrides, fail, base, adjectives=ADJECTIVES, search=None
):
    params = {"choice.schedule": "paper", "schedule.epochs": "200", "split.name": "published"}
    params |= {"schedule.finetune_epochs": "100", "seed": str(seed)} | row
    tags = {"run_level": "parent", "row_hash": key, "config_hash": f"{key}{seed}"}
    tags |= search or {}
    tags |= {"overrides": overrides, "data.identity": "synthetic-abc", "sweep_id": "s1"}
    aucs = {f"auc.{a}": base + 0.01 * i for i, a in enumerate(adjectives)}
    try:
        with tracker.run(f"{params['choice.experiment']}-s{seed}", params, tags) as rid:
            tracker.log_metrics(rid, {"mean_auc": float(np.mean(list(aucs.values()))), **aucs})
            if fail:
                raise RuntimeError("a failed run must not count")
    except RuntimeError:
        pass


@pytest.fixture(scope="module")
def mlflow_uri(mlflow_template, tmp_path_factory):
    """One store for the module: logging the runs is most of these tests' time."""
    path = tmp_path_factory.mktemp("report") / "mlflow.db"
    shutil.copy(mlflow_template, path)
    return f"sqlite:///{path}"


@pytest.fixture(scope="module")
def tracker(mlflow_uri):
    tracker = Tracker(mlflow_uri, "report_test")
    for run in RUNS:
        _log(tracker, *run)
    _log(tracker, "a-1adj", ROW_A, 0, "", False, 0.9, adjectives=["hard"])
    return tracker


def test_groups_count_each_seed_once_and_label_variants(tracker):
    groups = {_hash(g.key): g for g in runs.collect(tracker)}
    assert set(groups) == {"a", "a-1adj", "k", "i-quick", "i-c10", "i"}
    a = groups["a"]
    assert a.seeds == [0, 1] and sorted(a.runs) == [(0, -1), (1, -1)] and a.at_paper_settings
    mean_a = np.mean(0.01 * np.arange(24))
    assert a.aucs == pytest.approx([0.60 + mean_a, 0.70 + mean_a])  # the rerun of seed 1
    assert groups["k"].at_paper_settings  # split, data, weights overrides keep the paper's method
    assert groups["i-quick"].differences == ("schedule=quick",)
    assert groups["i-c10"].differences == ("combine=10",)
    assert groups["a-1adj"].differences == ("1 adjectives",)
    assert [g.row for g in runs.collect(tracker, sweep_id="s1")][:2] == ["A", "A"]


def test_search_trials_are_left_out_and_the_final_evaluation_says_it_was_tuned(mlflow_uri):
    tracker = Tracker(mlflow_uri, "report_search_test")
    study = {"search.study": "haptic_cnn"}
    _log(tracker, "t0", ROW_A, 0, "", False, 0.6, search=study | {"search.role": "trial"})
    _log(tracker, "t1", ROW_A, 0, "", False, 0.9, search=study | {"search.role": "trial"})
    _log(tracker, "final", ROW_A, 0, "", False, 0.7, search=study | {"search.role": "final"})
    (group,) = runs.collect(tracker)
    assert _hash(group.key) == "final"
    assert group.differences == ("tuned on validation (study haptic_cnn)",)


def test_table_numbers_and_labels(tracker):
    rows = table1.table1(runs.collect(tracker))
    a = next(r for r in rows if r["seeds"] == "0 1")
    mean_a = 0.65 + np.mean(0.01 * np.arange(24))
    assert float(a["mean_auc"]) == pytest.approx(mean_a, abs=1e-6)
    assert float(a["std_auc"]) == pytest.approx(np.std([0.6, 0.7], ddof=1), abs=1e-6)
    assert (a["row"], a["paper_auc"], a["adjectives"], a["data"]) == (
        "A",
        "0.773",
        "24",
        "synthetic-abc",
    )
    assert len(a["run_ids"].split()) == 2
    md = table1.table1_markdown(rows)
    quick = next(line for line in md.splitlines() if "schedule=quick" in line)
    assert quick.startswith("| (I) |") and "83.2" in quick
    assert md.count("| I | `table1_i_haptic_cnn_1trial` | paper |") == 1


def test_written_files_read_back(tracker, tmp_path):
    groups = runs.collect(tracker)
    paths = cli.write(
        groups=groups, out=tmp_path / "out", source="test", tracker=tracker, choices=cli.Choices()
    )
    assert [p.name for p in paths] == [
        "table1.md",
        "table1_summary.md",
        "table1.csv",
        "per_adjective.csv",
        "per_adjective_intervals.csv",
        "leaderboard.md",
        "leaderboard.csv",
        "fig5_per_adjective.png",
        "claims.md",
        "claims.csv",
        "table3.md",
        "table3.csv",
        "index.md",
    ]
    with open(tmp_path / "out" / "table1.csv") as f:
        evidence = {g.key: heldout.load(tracker, g) for g in groups}
        names = configurations.names(groups)
        assert list(csv.DictReader(f)) == table1.table1(groups, evidence, names=names)
    with open(tmp_path / "out" / "per_adjective.csv") as f:
        lines = {r["row_hash"]: r for r in csv.DictReader(f)}
    assert float(lines["a"]["metallic"]) == pytest.approx(
        0.65 + 0.01 * ADJECTIVES.index("metallic")
    )
    assert lines["a-1adj"]["thin"] == ""
    one = next(g for g in groups if g.n_adjectives == 1)
    assert figures.fig5_adjectives([one]) == ["hard"]  # not run: not drawn, rather than 0
    with Image.open(tmp_path / "out" / "fig5_per_adjective.png") as image:
        assert image.size == (1200, 450)
        assert np.asarray(image.convert("L")).std() > 10  # drawn, not blank
    # Fig. 5 takes row I at the paper's settings, not its stronger combine=10 variant.
    assert runs.best(groups, runs.HAPTIC).key == "i:table1_i_haptic_cnn_1trial@synthetic-abc"
    assert runs.best(groups, ("visual",)).key == "k:table1_k_image_googlenet_1view@synthetic-abc"
    index = (tmp_path / "out" / "index.md").read_text()
    assert "![Fig. 5](fig5_per_adjective.png)" in index and "`table1_i_haptic_cnn_1trial`" in index
    # Runs without scores.csv (logged before it existed) still report, without intervals.
    assert "No interval for 6 configuration(s)" in index and "no scores.csv for" in index
    assert "I > A | deep (ConvNet) beats hand-designed features | **not compared**" in index
    assert "I > G | the ConvNet beats the LSTM | **not run** | row G not run" in index
    # Row I's runs here hold no models: Fig. 6 says why it is missing, the rest stands.
    assert "Not drawn: run " in index and "config.yaml unreadable" in index


def test_cli_logs_a_report_run(tracker, mlflow_uri, tmp_path, capsys):
    cell = {"num": 3, "cell": "model=haptic_cnn modality=visual", "reason": "modality: no"}
    sweep.track_invalid(tracker, "s1", {"on_invalid": "skip", "jobs": 9, "invalid": [cell]})
    sweep.track_invalid(tracker, "s2", {"on_invalid": "skip", "jobs": 2, "invalid": [cell]})
    cli.main(["--tracking-uri", mlflow_uri, "--experiment", "report_test"] + [
        "--sweep-id", "s1", "--out", str(tmp_path / "r")])  # fmt: skip
    index = (tmp_path / "r" / "index.md").read_text()  # the sweep's skipped cell, once
    assert index.endswith("\n- #3 model=haptic_cnn modality=visual: modality: no\n")
    assert index.count("modality: no") == 1
    client = MlflowClient(mlflow_uri)
    runs = client.search_runs([tracker.experiment_id], "tags.run_level = 'report'")
    assert [r.info.run_name for r in runs] == ["report"]
    listed = {a.path for a in client.list_artifacts(runs[0].info.run_id, "report")}
    assert "report/table1.csv" in listed and "report/index.md" in listed
    assert runs[0].data.tags["mlflow.source.name"] == "python -m tactile_exp.report"
    assert "table1_a_haptic_static_1trial" in capsys.readouterr().out


def test_cli_names_what_is_missing(tracker, mlflow_uri, tmp_path):
    out = ["--tracking-uri", mlflow_uri, "--out", str(tmp_path / "r")]
    with pytest.raises(SystemExit, match="no MLflow experiment 'nope'.*report_test"):
        cli.main([*out, "--experiment", "nope"])
    with pytest.raises(SystemExit, match="no FINISHED job runs .* sweep_id 'zzz'"):
        cli.main([*out, "--experiment", "report_test", "--sweep-id", "zzz"])
    assert not (tmp_path / "r").exists()


# Table III: (row, adjective) -> [(object id, label, scores of its test units)].
SCORES = {
    ("I", "hard"): [(509, 1, [0.5, -0.1]), (120, 0, [-1.0])],
    ("I", "soft"): [(509, 1, [-0.3]), (119, 0, [0.2])],
    ("L", "hard"): [(509, 1, [-0.2]), (120, 0, [0.4])],
    ("L", "soft"): [(509, 1, [0.1])],
}


@pytest.fixture(scope="module")
def table3_tracker(mlflow_uri):
    """Rows I and L (not M) as jobs with per-adjective child runs holding scores.csv."""
    tracker = Tracker(mlflow_uri, "table3_test")
    for row, params in (("I", ROW_I), ("L", {**ROW_K, "paper.row": "L"})):
        _log(tracker, row, params, 0, "", False, 0.6, adjectives=["hard", "soft"])
        job = tracker.client.search_runs([tracker.experiment_id], f"tags.row_hash = '{row}'")[
            0
        ].info.run_id
        for adjective in ("hard", "soft"):
            lines = ["unit,object_id,label,score"]
            for object_id, label, values in SCORES[(row, adjective)]:
                lines += [f"t{object_id}_{i},{object_id},{label},{s}" for i, s in enumerate(values)]
            tags = {"run_level": "child", "adjective": adjective}
            with tracker.run(f"adj={adjective}", {}, tags, job) as child:
                tracker.log_text(child, "\n".join(lines) + "\n", "scores.csv")
    return tracker


def test_table3_predicted_sets_from_held_out_scores(table3_tracker, tmp_path):
    rows = t3.read_rows(table3_tracker, runs.collect(table3_tracker))
    assert rows["M"] is None and rows["I"].scores["hard"][509] == pytest.approx((0.2, 1))
    # 509 is tested on both adjectives in both rows, 120 on one; 119 only in row I.
    assert t3.choose_objects(rows) == [509, 120]
    lines = t3.table3(rows, [509, 120])
    got = {(r["object_id"], r["row"]): r for r in lines}
    assert got["509", "I"]["tested_adjectives"] == "hard soft"
    assert got["509", "I"]["ground_truth"] == "hard soft"
    assert (got["509", "I"]["predicted"], got["509", "I"]["agree"]) == ("hard", "1/2")
    assert (got["509", "L"]["predicted"], got["509", "L"]["agree"]) == ("soft", "1/2")
    assert (got["120", "L"]["predicted"], got["120", "L"]["agree"]) == ("hard", "0/1")
    assert got["120", "M"]["predicted"] == "not run" and got["120", "I"]["ground_truth"] == ""
    paths = t3.write_table3(lines, tmp_path)
    with open(paths[1]) as f:
        assert list(csv.DictReader(f)) == lines
    md = paths[0].read_text()
    assert "| hard (1/2 agree) | soft (1/2 agree) | not run |" in md
    assert "| 2: hard, soft |" in md  # the adjectives tested on, by name


def test_table3_objects_chosen_on_the_command_line(table3_tracker, mlflow_uri, tmp_path):
    out = tmp_path / "r"
    args = ["--tracking-uri", mlflow_uri, "--experiment", "table3_test", "--out", str(out)]
    cli.main([*args, "--table3-object", "120"])
    with open(out / "table3.csv") as f:
        assert {r["object_id"] for r in csv.DictReader(f)} == {"120"}
    with pytest.raises(SystemExit, match=r"objects \[119\] .* those are \[120, 509\]"):
        cli.main([*args, "--table3-object", "119"])


def test_signal_names_follow_the_preprocessing_channel_order():
    names = activations.signal_names(4)
    assert len(names) == 32 and names[:5] == [
        "squeeze PAC", "squeeze PDC", "squeeze TAC", "squeeze TDC", "squeeze PC1"]  # fmt: skip
    assert names[8] == "hold PAC" and names[-1] == "fast_slide PC4"


def test_fig6_maps_are_the_stored_convnet_on_the_job_test_trials(tiny_config, tmp_path):
    settings = settings_from_config(tiny_config([], "[metallic,hard]"))
    job = experiment.run(settings)
    tracker = Tracker(settings.tracking.uri, settings.tracking.experiment)
    data = activations.conv3_maps(
        tracker=tracker, job_id=job.run_id, adjectives=["metallic", "compressible"]
    )
    assert data.missing == ["compressible"] and len(data.signals) == 32
    assert [m.adjective for m in data.maps] == ["metallic", "metallic"]
    assert data.maps[0].unit.score >= data.maps[1].unit.score  # best, then worst positive
    # The parent run carries the interval of its mean AUC, as the report computes it.
    metrics = tracker.client.get_run(job.run_id).data.metrics
    evidence = heldout.load(tracker, runs.collect(tracker)[0])
    assert (metrics["mean_auc_ci_low"], metrics["mean_auc_ci_high"]) == pytest.approx(
        (evidence.interval().low, evidence.interval().high)
    )
    assert metrics["mean_auc_ci_low"] <= metrics["mean_auc"] <= metrics["mean_auc_ci_high"]

    # The same trials through the job's own path: its modality fits the preprocessing on the
    # training trials; the stored ConvNet's conv3 of each trial's first instance must match.
    result = job.results["metallic"]
    dataset, modality, splits = experiment.load(settings)
    train = splits["metallic"].trials("train", dataset)
    test = modality.fit(train).transform(splits["metallic"].trials("test", dataset))
    child = tracker.children(job.run_id)["metallic"]
    net = store.load_model(tracker, child, "model")
    for m in data.maps:
        assert m.unit.label == 1 and m.unit.unit in set(result.test.units)
        first = int(np.flatnonzero(test.trial == m.unit.unit)[0])
        expected = net.transform(test.X[first : first + 1]).reshape(net.conv3_shape_)
        assert m.activations == pytest.approx(expected, abs=1e-5)
        assert m.activations.min() >= 0 and m.activations.max() > 0  # ReLU'd, not all zero

    # Asked for by name, what the job cannot show is one short error line (exit status 1).
    args = ["--tracking-uri", settings.tracking.uri, "--experiment", settings.tracking.experiment]
    args += ["--out", str(tmp_path / "r"), "--fig6-run", job.run_id]
    with pytest.raises(SystemExit, match=r"^error: --fig6-adjective nosuch: no finished model"):
        cli.main([*args, "--fig6-adjective", "nosuch"])
    with pytest.raises(SystemExit) as err:
        cli.main([*args, "--fig6-adjective", "metallic", "--fig6-trial", "nosuch_999_01"])
    line = str(err.value.code)
    assert "nosuch_999_01: not a test trial of metallic" in line
    assert "\n" not in line and len(line) < 250

    path = tmp_path / "fig6.png"
    figures.fig6(data.maps, data.signals, "test", path)
    with Image.open(path) as image:
        assert image.size == figures.fig6_size(2) == (900, 800)
        assert np.asarray(image.convert("L")).std() > 10


def test_runs_table_lists_a_job_and_its_children(table3_tracker, mlflow_uri, capsys):
    job = runs.row_group(runs.collect(table3_tracker), "I").first_run
    cli.main(["--tracking-uri", mlflow_uri, "--experiment", "table3_test", "--runs-table"] + [
        job.run_id])  # fmt: skip
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("| Run Name |") and len(lines) == 2 + 1 + 2
    parent = lines[2].split(" | ")
    assert parent[0] == "| table1_i_haptic_cnn_1trial-s0"
    assert parent[-2] == f"{job.mean_auc:.3f}" and parent[3].startswith("python -m tactile_exp")
    assert [line.split(" | ")[0] for line in lines[3:]] == ["| └ adj=hard", "| └ adj=soft"]


# Held-out scores of 2-fold jobs (rows I, A; an ablation sweep) and one job of
# row G on other objects. 8 adjectives (Wilcoxon over 6 cannot pass Holm over 2 tests),
# 16 objects (6 positive), 2 units each.
FOLD_ADJ = ["absorbent", "compressible", "hard", "rough", "smooth", "soft", "squishy", "thick"]
N_OBJ, N_POS = 16, 6


def _fold_job(
    tracker, key, fold, overrides, quality, objects=range(N_OBJ), folds=2, row=None, sweep="f"
):
    """A parent run of one fold and a child per adjective holding its scores.csv."""
    rng = np.random.default_rng([fold, int(quality * 100), len(key)])
    params = {"choice.schedule": "quick", "schedule.epochs": "2", "schedule.finetune_epochs": "20"}
    params |= {"seed": "0", "split.name": "folds", "split.fold": str(fold)}
    params |= {"split.folds": str(folds), **(row or ROWS_BY_KEY.get(key, SWEPT))}
    tags = {"run_level": "parent", "row_hash": key, "config_hash": f"{key}{fold}"}
    tags |= {"overrides": overrides, "data.identity": "synthetic-abc", "sweep_id": sweep}
    tested = [o for o in objects if o % folds == fold]
    aucs, f1s = {}, {}
    name = (
        params["choice.experiment"]
        if params["choice.experiment"] != "None"
        else "haptic_cnn-concat"
    )
    with tracker.run(f"{name}-s0", params, tags) as job:  # the sweep's names alike
        for adjective in FOLD_ADJ:
            lines = ["unit,object_id,label,score"]
            ys, ss = [], []
            for o in tested:
                y = int(o < N_POS)
                for u in range(2):
                    score = quality * y + rng.normal(0, 0.3)
                    lines.append(f"t{o}_{u},{o},{y},{score}")
                    ys.append(y)
                    ss.append(score)
            aucs[f"auc.{adjective}"] = roc_auc_score(ys, ss)
            f1s[f"f1.{adjective}"] = f1_score(ys, np.array(ss) > 0)
            ctags = {"run_level": "child", "adjective": adjective}
            with tracker.run(f"adj={adjective}", {}, ctags, job) as child:
                tracker.log_text(child, "\n".join(lines) + "\n", "scores.csv")
        tracker.log_metrics(job, {"mean_auc": float(np.mean(list(aucs.values()))), **aucs})
        tracker.log_metrics(job, {"mean_f1": float(np.mean(list(f1s.values()))), **f1s})


ROW_G = {**ROW_I, "paper.row": "G", "choice.experiment": "table1_g_haptic_lstm"}
ROWS_BY_KEY = {"I": ROW_I, "A": ROW_A, "G": ROW_G}
SWEPT = {"choice.experiment": "None", "model.name": "haptic_cnn", "modality.name": "haptic"}


ABLATION = {  # (loss, combine) -> quality: combine matters, loss does not
    ("hinge", "1"): 0.3,
    ("logistic", "1"): 0.3,
    ("hinge", "10"): 1.2,
    ("logistic", "10"): 1.2,
}


@pytest.fixture(scope="module")
def folds_tracker(mlflow_uri):
    tracker = Tracker(mlflow_uri, "folds_test")
    for fold in (0, 1):
        _fold_job(tracker, "I", fold, "experiment=table1_i_haptic_cnn_1trial", 1.5)
        _fold_job(tracker, "A", fold, "experiment=table1_a_haptic_static_1trial", 0.2)
        for (loss, combine), quality in ABLATION.items():
            key = f"abl-{loss}-{combine}"
            _fold_job(tracker, key, fold, f"loss={loss} combine={combine} seed=0", quality)
    # A sweep job with row I's config (experiment files change no hashed value): its own line.
    _fold_job(tracker, "I", 0, "model=haptic_cnn seed=0", 1.5, row=SWEPT, sweep="other")
    # Row G tested on half the objects only (another split): not comparable paired with I.
    _fold_job(tracker, "G", 0, "experiment=table1_g_haptic_lstm", 1.0, range(0, N_OBJ, 2), 1)
    return tracker


def test_folds_pool_out_of_fold_scores_with_intervals_and_object_counts(folds_tracker, tmp_path):
    groups = runs.collect(folds_tracker)
    i = next(g for g in groups if g.row == "I")
    assert i.seeds == [0] and i.folds == 2 and sorted(i.runs) == [(0, 0), (0, 1)]
    assert i.method == "table1_i_haptic_cnn_1trial" and i.row == "I"
    twin = next(g for g in groups if _hash(g.key) == "I" and not g.row)
    assert sorted(twin.runs) == [(0, 0)]  # the sweep's job of row I's config, kept apart
    evidence = heldout.load(folds_tracker, i)
    pooled = evidence.evaluations[0]["hard"]
    assert sorted(set(pooled.object_id.tolist())) == list(range(N_OBJ))  # every object once
    assert pooled.auc == pytest.approx(roc_auc_score(pooled.label, pooled.score))
    row = next(r for r in table1.table1([i], {i.key: evidence}))
    assert float(row["mean_auc_ci_low"]) <= float(row["mean_auc"]) <= float(row["mean_auc_ci_high"])
    assert float(row["per_fold_mean_auc"]) == pytest.approx(i.aucs.mean())
    assert (row["n_seeds"], row["seeds"], row["test_objects"]) == ("1", "0", "6/10")
    assert row["split"] == "folds (2/2 folds pooled)"


def test_report_states_claims_friedman_and_the_ablation_view(folds_tracker, tmp_path):
    out = tmp_path / "out"
    paths = cli.write(
        groups=runs.collect(folds_tracker),
        out=out,
        source="test",
        tracker=folds_tracker,
        choices=cli.Choices(),
    )
    names = [p.name for p in paths]
    assert {"claims.md", "cd_diagram.png", "ablation.md", "ablation_combine.png"} <= set(names)
    index = (out / "index.md").read_text()
    assert "## Table I: mean AUC over the 8 adjectives run (absorbent, compressible, hard," in index
    claims = {r["claim"]: r for r in csv.DictReader((out / "claims.csv").read_text().splitlines())}
    assert (
        claims["I > A"]["result"] == "supported"
    )  # row I kept apart from the sweep's jobs  # 1.5 vs 0.2 score separation
    assert claims["I > G"]["result"] == "not compared"
    assert "different test objects" in claims["I > G"]["detail"]
    assert claims["M > I"]["result"] == "not run" and claims["thick: better by sight"][
        "result"
    ] == ("not run")
    ablation = (out / "ablation.md").read_text()
    assert "| combine=1 loss=hinge |" in ablation and "| combine=10 loss=logistic |" in ablation
    effect = {line.split(" | ")[1]: line for line in ablation.splitlines() if line.startswith("| ")}
    assert "combine=10 beats combine=1" in effect["combine=10 vs combine=1"]
    assert "not distinguishable" in effect["loss=logistic vs loss=hinge"]
    assert "Friedman chi2" in index and "![critical-difference diagram](cd_diagram.png)" in index
    per_adjective = list(csv.DictReader((out / "per_adjective.csv").read_text().splitlines()))
    configurations = [r["configuration"] for r in per_adjective]
    assert len(set(configurations)) == len(configurations)  # no two lines named alike
    assert "Per-adjective AUC of the best haptic configuration (no visual row was run)" in index
    with Image.open(out / "fig5_per_adjective.png") as image:
        assert np.asarray(image.convert("L")).std() > 10


def test_an_auc_on_few_test_objects_is_flagged(folds_tracker):
    i = next(g for g in runs.collect(folds_tracker) if g.row == "I")
    obj = np.repeat(np.arange(6), 3)
    label = (obj < 2).astype(int)  # 2 positive objects: an AUC in steps of 1/2 per object
    held = stats.HeldOut(obj, label, label + np.linspace(0, 1, len(obj)))
    evidence = heldout.Evidence([{"hard": held, "soft": held}])
    assert evidence.sizes() == {"hard": (2, 4), "soft": (2, 4)} and evidence.thin() == [
        "hard",
        "soft",
    ]
    md = table1.table1_markdown(table1.table1([i], {i.key: evidence}))
    assert "| 2/4 (< 3 on: hard soft) |" in md


def test_report_of_another_metric_recomputes_it_from_the_pooled_scores(folds_tracker, tmp_path):
    """--metric f1: the runs' f1.<adjective>, the pooled out-of-fold F1 of the
    scores with object-bootstrap intervals, and the claims compared on F1."""
    groups = runs.collect(folds_tracker, metric="f1")
    i = next(g for g in groups if g.row == "I")
    assert [g.key for g in groups] == [g.key for g in runs.collect(folds_tracker)]
    assert i.aucs.mean() == pytest.approx(np.mean([r.mean_auc for r in i.sorted_runs]))
    evidence = heldout.load(folds_tracker, i, "f1")
    pooled = evidence.evaluations[0]["hard"]
    iv = evidence.per_adjective()["hard"]
    assert iv.estimate == pytest.approx(f1_score(pooled.label, pooled.score > 0), abs=1e-12)
    auc = heldout.load(folds_tracker, i).per_adjective()["hard"]
    assert iv.low <= iv.estimate <= iv.high and (iv.low, iv.high) != (auc.low, auc.high)

    out = tmp_path / "f1"
    cli.write(groups=groups, out=out, source="test", tracker=folds_tracker, choices=cli.Choices(),
              metric="f1")  # fmt: skip
    row = next(r for r in csv.DictReader((out / "table1.csv").read_text().splitlines())
               if r["row"] == "I")  # fmt: skip
    assert float(row["mean_f1"]) == pytest.approx(evidence.interval().estimate, abs=1e-6)
    assert "mean_auc" not in row and row["paper_auc"] == ""
    claims = {r["claim"]: r for r in csv.DictReader((out / "claims.csv").read_text().splitlines())}
    a = heldout.load(folds_tracker, next(g for g in groups if g.row == "A"), "f1")
    difference = np.mean([
        f1_score(x.label, x.score > 0) - f1_score(y.label, y.score > 0)
        for x, y in zip(evidence.evaluations[0].values(), a.evaluations[0].values(), strict=True)
    ])  # fmt: skip
    assert f"I - A = {difference:+.3f} [" in claims["I > A"]["detail"]
    index = (out / "index.md").read_text()
    assert "**Metric: F1** (`--metric f1`, logged as `f1`)" in index
    assert "## Table I: mean F1 over the 8 adjectives run" in index
    assert "Per-adjective F1 of the best haptic configuration" in index


def test_label_names_and_their_order_come_from_the_runs(mlflow_uri):
    """A data set's own labels, in the order its jobs logged them (tag data.labels); a job
    that trained fewer than the data set has is a variant."""
    tracker = Tracker(mlflow_uri, "report_labels_test")
    own = {"data.labels": "warm grippy loud"}
    _log(tracker, "two", ROW_A, 0, "", False, 0.6, adjectives=["loud", "warm"], search=own)
    _log(
        tracker, "all", ROW_I, 0, "", False, 0.7, adjectives=["loud", "grippy", "warm"], search=own
    )
    groups = {_hash(g.key): g for g in runs.collect(tracker)}
    assert list(groups["two"].per_adjective()) == ["warm", "loud"]
    assert (groups["two"].differences, groups["all"].differences) == (("2 adjectives",), ())
    assert groups["two"].n_labels == 3
    assert figures.fig5_adjectives(list(groups.values())) == ["warm", "grippy", "loud"]


def test_an_axis_that_changed_no_score_is_flagged_not_compared(mlflow_uri, tmp_path):
    """loss=hinge and loss=logistic scoring alike (the T4 head's hinge stage does not move on
    separable units): the ablation view says the axis changed no score instead of testing it."""
    tracker = Tracker(mlflow_uri, "identical_test")
    for fold in (0, 1):
        for loss in ("hinge", "logistic"):
            for combine, quality in (("1", 0.3), ("10", 1.2)):
                key = f"x-{loss[0]}-{combine}"  # equal lengths: the same scores for both losses
                _fold_job(tracker, key, fold, f"loss={loss} combine={combine} seed=0", quality)
    out = tmp_path / "out"
    cli.write(
        groups=runs.collect(tracker), out=out, source="t", tracker=tracker, choices=cli.Choices()
    )
    ablation = (out / "ablation.md").read_text()
    effect = {line.split(" | ")[1]: line for line in ablation.splitlines() if line.startswith("| ")}
    assert cli.IDENTICAL in effect["loss=logistic vs loss=hinge"]
    assert cli.IDENTICAL not in effect["combine=10 vs combine=1"]
    assert "**`loss` changed no score here**" in ablation and "FinetuneWarning" in ablation
    assert "**`combine` changed no score here**" not in ablation


def test_figures_never_assume_the_point_lies_inside_its_interval(tracker, tmp_path):
    """A percentile bootstrap interval can leave out its point estimate (F1 on 2 positive
    objects): Fig. 5 and the ablation plot draw it from its ends (matplotlib refuses a negative
    error bar)."""
    g = runs.collect(tracker)[0]
    outside = {a: stats.Interval(0.57, 0.38, 0.56) for a in g.per_adjective()}
    figures.fig5([("best haptic", g, outside)], "t", tmp_path / "fig5.png", "f1")
    lines = {
        "loss=hinge": [(1.0, stats.Interval(0.6, 0.2, 0.5)), (10.0, stats.Interval(0.1, 0.2, 0.4))]
    }
    figures.numeric_axis("combine", lines, tmp_path / "axis.png", "f1")
    for name in ("fig5.png", "axis.png"):
        with Image.open(tmp_path / name) as image:
            assert np.asarray(image.convert("L")).std() > 10


def test_coinciding_ablation_lines_are_labelled_identical():
    same = [(1.0, stats.Interval(0.6, 0.5, 0.7)), (10.0, stats.Interval(0.7, 0.6, 0.8))]
    other = [(1.0, stats.Interval(0.6, 0.5, 0.7)), (10.0, stats.Interval(0.65, 0.6, 0.8))]
    labels = figures.line_labels({"loss=hinge": same, "loss=logistic": same, "loss=x": other})
    assert labels == {
        "loss=hinge": "loss=hinge",
        "loss=logistic": "loss=logistic (identical to loss=hinge)",
        "loss=x": "loss=x",
    }


def test_cd_diagram_labels_are_short_with_a_legend(tmp_path):
    names = ["A", "(I)", "combine=1 loss=hinge", "combine=10 loss=hinge"]
    assert figures.cd_labels(names) == ["A", "(I)", "c1", "c2"]
    aucs = np.array([[0.7, 0.8, 0.6, 0.9], [0.6, 0.7, 0.5, 0.8], [0.5, 0.6, 0.7, 0.6]]).T
    figures.cd_diagram(stats.friedman(names, aucs), tmp_path / "cd.png")
    with Image.open(tmp_path / "cd.png") as image:
        assert np.asarray(image.convert("L")).std() > 10


def test_table3_names_an_object_without_a_display_name():
    info = next(o for o in t3.objects() if o.object_id == 302)
    assert info.display_name == "" and t3.object_name(info) == "colored cover book"


def test_table1_summary_has_the_four_columns_a_reader_compares(tracker):
    rows = table1.table1(runs.collect(tracker))
    summary = table1.table1_summary(rows).splitlines()
    assert summary[0] == "| row | method | mean AUC % [95% CI] | paper (real PHAC-2) |"
    assert len(summary) == len(rows) + 2
    assert all(line.count(" | ") == 3 for line in summary[2:])
    assert any(line.startswith("| A | `table1_a_haptic_static_1trial` | ") for line in summary)


def test_the_margin_option_decides_an_as_good_as_claim(mlflow_uri, tmp_path, capsys):
    """Row J a shade better than row I on every fold: ``I >= J`` is supported only when the
    margin (``--margin``, default ``stats.MARGIN``) covers the loss the interval allows."""
    tracker = Tracker(mlflow_uri, "margin_test")
    row_j = {**ROW_I, "paper.row": "J", "choice.experiment": "table1_j_haptic_cnn_10trials"}
    for fold in (0, 1):
        _fold_job(tracker, "I", fold, "experiment=table1_i_haptic_cnn_1trial", 0.6)
        _fold_job(tracker, "J", fold, "experiment=table1_j_haptic_cnn_10trials", 0.7, row=row_j)
    verdicts = {}
    for margin in ([], ["--margin", "0.3"]):
        out = tmp_path / f"r{len(margin)}"
        args = ["--tracking-uri", mlflow_uri, "--experiment", "margin_test", "--out", str(out)]
        cli.main([*args, *margin])
        claims = {r["claim"]: r for r in csv.DictReader((out / "claims.csv").open())}
        verdicts[len(margin)] = claims["I >= J"]["result"]
        shown = margin[1] if margin else str(stats.MARGIN)
        assert f"rules out a loss of {shown} or" in (out / "claims.md").read_text()
    assert verdicts == {
        0: "not distinguishable (the interval allows a loss beyond 0.020)",
        2: "supported (not worse by 0.300 or more)",
    }
    runs = MlflowClient(mlflow_uri).search_runs(
        [tracker.experiment_id], "tags.run_level = 'report'", order_by=["start_time ASC"]
    )
    assert [r.data.params["margin"] for r in runs] == [str(stats.MARGIN), "0.3"]
    with pytest.raises(SystemExit):
        cli.main([*args, "--margin", "0"])
    assert "--margin: an AUC difference in (0, 1), got 0.0" in capsys.readouterr().err


# Three folder data sets, three models, 2 folds each: the ConvNet planted better on slide,
# identical in effect to the linear model on flat (the same scores), worse on slip.
FOLDER_QUALITY = {
    "slide": {"linear": (0.6, ""), "haptic_cnn": (2.0, ""), "haptic_lstm": (0.6, "")},
    "flat": {"linear": (0.8, "same"), "haptic_cnn": (0.8, "same"), "haptic_lstm": (0.5, "")},
    "slip": {"linear": (1.2, ""), "haptic_cnn": (0.5, ""), "haptic_lstm": (0.8, "")},
}


@pytest.fixture(scope="module")
def folder_tracker(mlflow_uri):
    tracker = Tracker(mlflow_uri, "folder_report_test")
    for dataset, models in FOLDER_QUALITY.items():
        for model, (quality, noise) in models.items():
            for fold in (0, 1):
                report_fixture.log_job(
                    tracker, dataset=dataset, model=model, quality=quality, fold=fold, noise=noise
                )
    return tracker


def test_a_report_on_folder_data_sets_compares_configurations_not_the_paper(
    folder_tracker, mlflow_uri, tmp_path, capsys
):
    out = tmp_path / "out"
    args = ["--tracking-uri", mlflow_uri, "--experiment", "folder_report_test", "--out", str(out)]
    cli.main([*args, "--compare", "model=haptic_cnn > model=linear"])
    index = (out / "index.md").read_text()
    assert index.startswith("# 3 configurations on 3 data sets\n")
    for paper in ("Gao et al.", "Table I", "claims", "Fig. 5", "Fig. 6", "Table III", "not run"):
        assert paper not in index
    assert not {"claims.md", "fig5_per_adjective.png", "table3.md"} & {
        p.name for p in out.iterdir()
    }
    board = list(csv.DictReader((out / "leaderboard.csv").read_text().splitlines()))
    slide = [r for r in board if r["dataset"] == "slide"]
    assert [r["configuration"] for r in slide][0] == "model=haptic_cnn"
    assert all("fold" not in r["configuration"] for r in board)
    assert {r["configuration"] for r in board} == {
        "model=haptic_cnn",
        "model=haptic_lstm",
        "model=linear",
    }
    assert all(r["test_objects"] == "6/10" for r in board)  # every object once, pooled
    compared = {
        r["dataset"]: r
        for r in csv.DictReader((out / "comparisons.csv").read_text().splitlines())
        if not r["label"]
    }
    assert compared["slide"]["result"] == "supported"
    assert compared["flat"]["result"] == "not distinguishable"
    assert compared["slip"]["result"] in ("contradicted", "not distinguishable")
    bench = list(csv.DictReader((out / "benchmark.csv").read_text().splitlines()))
    assert [r["missing_on"] for r in bench] == ["", "", ""] and all(r["mean_rank"] for r in bench)
    assert "Friedman over 3 data sets and 3 configurations" in index
    with Image.open(out / "benchmark_cd.png") as image:
        assert np.asarray(image.convert("L")).std() > 10
    printed = capsys.readouterr().out
    assert "Leaderboard (every column:" in printed and "Table I" not in printed
    client = MlflowClient(mlflow_uri)
    experiment = client.get_experiment_by_name("folder_report_test")
    (report,) = client.search_runs([experiment.experiment_id], "tags.run_level = 'report'")
    tables = {a.path for a in client.list_artifacts(report.info.run_id, "tables")}
    assert tables == {f"tables/{t}.json" for t in ("leaderboard", "comparisons", "benchmark")}
    assert report.data.params["compare"] == "model=haptic_cnn > model=linear"


def test_a_bad_comparison_is_one_line(folder_tracker, mlflow_uri, tmp_path, capsys):
    args = ["--tracking-uri", mlflow_uri, "--experiment", "folder_report_test"]
    args += ["--out", str(tmp_path / "out")]
    with pytest.raises(SystemExit) as err:
        cli.main([*args, "--compare", "model=nosuch > model=linear"])
    line = str(err.value.code)
    assert line.startswith("error: --compare 'model=nosuch > model=linear': 'model=nosuch' names")
    assert "\n" not in line
    with pytest.raises(SystemExit) as err:
        cli.main([*args, "--compare", "model=haptic_cnn, model=linear"])
    assert err.value.code == 2 and "expected 'A > B' or 'A >= B'" in capsys.readouterr().err


def _folder_data(root, signal: float):
    """16 objects x 2 trials of 8 channels; label k (positive for 6 objects) raises channel k by
    ``signal`` standard deviations: learnable with signal > 0, noise alone with 0."""
    from tactile_exp.data.dataset import Sensor
    from tactile_exp.data.folder import write_folder

    rng = np.random.default_rng([7, int(signal * 10)])
    sensor = Sensor("test sensor", tuple(f"c{k}" for k in range(8)), 50.0)
    labels, trials = {}, {}
    for o in range(report_fixture.N_OBJECTS):
        name = f"obj{o:02d}"
        labels[name] = {
            a: report_fixture.label_of(o, k) for k, a in enumerate(report_fixture.LABELS)
        }
        level = signal * np.array(list(labels[name].values()), dtype=float)
        trials[name] = [level[:, None] + rng.normal(size=(8, 60)) for _ in range(2)]
    return write_folder(root, sensor, labels, trials)


@pytest.mark.slow
@pytest.mark.job
def test_jobs_on_two_folder_data_sets_then_the_comparison_report(tiny_config, mlflow_uri, tmp_path):
    """Real jobs (three models, two folds) on two folder data sets, one with a planted signal,
    then the report: the planted data set's leaderboard and declared comparison find it, the
    other's do not, and the across-data-sets table ranks every configuration."""
    from tactile_exp.config import settings_from_config

    models = (["model=linear"], ["model=haptic_cnn", "model.groups=8"], ["model=random"])
    for name, signal in (("planted", 3.0), ("noise", 0.0)):
        data = _folder_data(tmp_path / name, signal)
        for model in models:
            for fold in (0, 1):
                overrides = ["data=folder", f"data.path={data}", "modality=signals"]
                overrides += ["split=folds", "split.folds=2", f"split.fold={fold}", *model]
                # The linear model's T4 head gets 3 SGD steps on the tiny schedule: too few.
                overrides += ["schedule.head.epochs=100", "schedule.head.batch_size=8"]
                experiment.run(settings_from_config(tiny_config(overrides, adjectives="null")))
    out = tmp_path / "report"
    args = ["--tracking-uri", mlflow_uri, "--out", str(out)]
    cli.main([*args, "--compare", "model=linear > model=random"])
    board = list(csv.DictReader((out / "leaderboard.csv").read_text().splitlines()))
    planted = [r["configuration"] for r in board if r["dataset"] == "planted"]
    assert planted[-1] == "model=random" and len(planted) == 3
    compared = {
        r["dataset"]: r["result"]
        for r in csv.DictReader((out / "comparisons.csv").read_text().splitlines())
        if not r["label"]
    }
    assert compared == {"planted": "supported", "noise": "not distinguishable"}
    index = (out / "index.md").read_text()
    assert index.startswith("# 3 configurations on 2 data sets\n") and "Table I" not in index
    assert "Friedman over 2 data sets and 3 configurations" in index
    assert (out / "benchmark_cd.png").exists()


def test_the_preset_option_turns_the_paper_sections_on_and_off(
    folds_tracker, folder_tracker, mlflow_uri, tmp_path
):
    args = ["--tracking-uri", mlflow_uri, "--out"]
    cli.main([*args, str(tmp_path / "auto"), "--experiment", "folds_test"])
    auto = (tmp_path / "auto" / "index.md").read_text()
    assert auto.startswith("# Gao et al. (ICRA 2016)") and "## Table I" in auto
    cli.main([*args, str(tmp_path / "none"), "--experiment", "folds_test", "--preset", "none"])
    none = (tmp_path / "none" / "index.md").read_text()
    assert "## Table I" not in none and "claims" not in none and "## Leaderboard" in none
    assert none.startswith("# 8 configurations on synthetic-abc\n")
    cli.main(
        [*args, str(tmp_path / "on"), "--experiment", "folder_report_test"]
        + ["--preset", "gao2016"]
    )
    assert "## Table I" in (tmp_path / "on" / "index.md").read_text()


def test_a_named_baseline_is_each_leaderboard_s_reference(folder_tracker, mlflow_uri, tmp_path):
    out = tmp_path / "out"
    cli.main(
        ["--tracking-uri", mlflow_uri, "--experiment", "folder_report_test", "--out", str(out)]
        + ["--baseline", "model=haptic_lstm"]
    )
    board = list(csv.DictReader((out / "leaderboard.csv").read_text().splitlines()))
    assert {r["baseline"] for r in board} == {"model=haptic_lstm"}
    slide = {r["configuration"]: r for r in board if r["dataset"] == "slide"}
    assert slide["model=haptic_cnn"]["verdict"].startswith(
        "model=haptic_cnn beats model=haptic_lstm"
    )
    assert slide["model=haptic_lstm"]["difference"] == ""


def test_a_model_without_epochs_has_no_schedule_in_table1(mlflow_uri):
    tracker = Tracker(mlflow_uri, "no_epochs_test")
    params = {"choice.model": "estimator", "model.name": "estimator", "seed": "0"}
    tags = {"run_level": "parent", "row_hash": "est", "config_hash": "est0", "overrides": ""}
    with tracker.run("estimator-concat-c1-s0", params, tags) as rid:
        tracker.log_metrics(rid, {"mean_auc": 0.7, "auc.hard": 0.7})
    (g,) = runs.collect(tracker)
    assert (g.schedule, g.schedule_epochs) == ("", "")
    assert not any("schedule" in d for d in g.differences)
    (row,) = table1.table1([g])
    assert row["schedule"] == "no epochs"

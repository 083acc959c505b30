"""The benchmark across data sets: cells, ranks over complete blocks, Friedman, the missing."""

import numpy as np
import pytest
from report_fixture import group
from scipy import stats as sps

from tactile_exp.report import benchmark, configurations, leaderboard

QUALITY = {  # data set -> model -> score separation
    "slip": {"linear": 1.2, "haptic_cnn": 0.4, "lstm": 0.8},
    "slide": {"linear": 0.5, "haptic_cnn": 2.0, "lstm": 0.9},
    "grasp": {"linear": 1.5, "haptic_cnn": 0.3, "lstm": 0.7, "random": 0.0},
}


def _bench(made):
    """The benchmark of (group, evidence) pairs, a leaderboard per data set."""
    groups = [g for g, _ in made]
    evidence = {g.key: e for g, e in made}
    names = configurations.names(groups)
    boards = [
        leaderboard.board(d, gs, evidence, names)
        for d, gs in configurations.by_dataset(groups).items()
    ]
    return benchmark.benchmark(boards)


def _quality_bench():
    return _bench([group(d, m, q) for d, models in QUALITY.items() for m, q in models.items()])


def test_ranks_and_friedman_are_over_the_configurations_on_every_data_set():
    bench = _quality_bench()
    assert bench.datasets == ("grasp", "slide", "slip")
    assert bench.missing == {"model=random": ("slide", "slip")}
    assert bench.configurations[-1] == "model=random" and "model=random" not in bench.mean_ranks
    complete = ["model=haptic_cnn", "model=linear", "model=lstm"]
    values = np.array([[bench.cells[n, d].estimate for d in bench.datasets] for n in complete])
    expected = sps.rankdata(-values, axis=0).mean(axis=1)
    assert [bench.mean_ranks[n] for n in complete] == pytest.approx(expected)
    f = bench.friedman
    assert f.n_adjectives == 3 and sorted(f.names) == complete
    assert f.statistic == pytest.approx(sps.friedmanchisquare(*values).statistic)
    assert list(bench.configurations[:3]) == sorted(complete, key=lambda n: bench.mean_ranks[n])


def test_the_tables_list_the_missing_and_never_rank_them():
    bench = _quality_bench()
    rows = benchmark.rows(bench, "roc_auc")
    random = next(r for r in rows if r["configuration"] == "model=random")
    assert random["mean_rank"] == "" and random["slide"] == "" and random["grasp"]
    assert random["missing_on"] == "slide slip"
    md = benchmark.markdown(bench, "roc_auc")
    assert "| `model=random` |" in md and "not ranked" in md and "not run" in md
    assert "Not ranked (missing on a data set): `model=random` (not on slide, slip)" in md
    assert "Friedman over 3 data sets and 3 configurations" in md


def test_two_complete_configurations_get_ranks_and_no_friedman():
    bench = _bench(
        [group(d, m, q) for d in ("a", "b") for m, q in (("linear", 1.0), ("lstm", 0.5))]
    )
    assert bench.friedman is None and "Friedman's test needs 3" in bench.why_not
    assert bench.mean_ranks == {"model=linear": 1.0, "model=lstm": 2.0}


@pytest.mark.slow  # ~3 min: 20 jobs of five models, MiniRocket's and MultiRocket's kernels compiled
@pytest.mark.job
def test_the_benchmark_sweep_on_imported_recipes_runs_every_cell_once(
    tmp_path, cache_dir, mlflow_uri
):
    """``-m sweep=benchmark data.path=A,B`` on two public recipes imported from tiny copies of
    their upstreams: every model x data set x declared fold is one FINISHED job, the folds past
    a data set's K and the static features on non-PHAC-2 data are absent (not run, not failed);
    the report ranks the models across the two data sets and draws the CD diagram; the same
    command again trains nothing."""
    import csv
    import subprocess
    import sys

    from mlflow import MlflowClient
    from public_fixture import pinned_recipe, write_bolt, write_icub

    from tactile_exp.data.__main__ import main as data_main
    from tactile_exp.report import cli

    data = []
    for name, write in (("icub_grasp", write_icub), ("penn_bolt", write_bolt)):
        src = write(tmp_path / f"{name}_clone")
        recipe = pinned_recipe(name, src, tmp_path / f"{name}.yaml")
        assert (
            data_main(["public", "import", str(recipe), "--from", str(src), str(tmp_path / name)])
            == 0
        )
        data.append(str(tmp_path / name))
    command = [
        sys.executable, "-m", "tactile_exp", "-m", "sweep=benchmark", f"data.path={','.join(data)}",
        "schedule=tiny", f"cache_dir={cache_dir}", f"tracking.uri={mlflow_uri}",
        f"hydra.sweep.dir={tmp_path / 'multirun'}",
    ]  # fmt: skip
    run = dict(stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, timeout=900)
    first = subprocess.run(command, **run)
    assert first.returncode == 0, first.stdout[-3000:]
    # 6 models x 2 data sets x 5 folds: 5 models x 2 folds x 2 data sets run; the rest absent
    # (folds 2..4 of K=2, and the static features, which read PHAC-2's layout only)
    assert "20 FINISHED, 0 skipped (invalid), 0 FAILED, 40 absent (not cells)" in first.stdout
    client = MlflowClient(mlflow_uri)
    experiment = client.get_experiment_by_name("tactile_exp_benchmark").experiment_id
    jobs = client.search_runs([experiment], "tags.run_level = 'parent'")
    assert len(jobs) == 20 and {j.info.status for j in jobs} == {"FINISHED"}
    assert {j.data.params["choice.model"] for j in jobs} == {
        "linear", "haptic_lstm", "haptic_cnn", "minirocket", "multirocket",
    }  # fmt: skip
    for job in jobs:  # every label of every cell scored
        children = client.search_runs(
            [experiment], f"tags.mlflow.parentRunId = '{job.info.run_id}'"
        )
        assert children and all(0.0 <= c.data.metrics["auc"] <= 1.0 for c in children)

    out = tmp_path / "report"
    cli.main(
        ["--tracking-uri", mlflow_uri, "--experiment", "tactile_exp_benchmark", "--out", str(out)]
    )
    rows = list(csv.DictReader((out / "benchmark.csv").read_text().splitlines()))
    assert len(rows) == 5 and all(r["mean_rank"] for r in rows)
    index = (out / "index.md").read_text()
    assert index.startswith("# 5 configurations on 2 data sets\n")
    assert "Friedman over 2 data sets and 5 configurations" in index
    assert (out / "benchmark_cd.png").exists()

    again = subprocess.run(command, **run)
    assert again.returncode == 0, again.stdout[-3000:]
    assert again.stdout.count("already FINISHED with this config") == 20
    assert len(client.search_runs([experiment], "tags.run_level = 'parent'")) == 20

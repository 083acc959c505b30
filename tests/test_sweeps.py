"""The named grids: `sweep=table1` is every table1_* file and takes seed/split lists; `sweep=smoke`
runs every row end to end, and the report built from it matches the runs."""

import csv
import subprocess
import sys

import numpy as np
import pytest
from conftest import CONF
from hydra import compose, initialize_config_dir
from hydra._internal.config_loader_impl import ConfigLoaderImpl
from hydra._internal.core_plugins.basic_sweeper import BasicSweeper
from hydra._internal.utils import create_config_search_path
from hydra.core.override_parser.overrides_parser import OverridesParser
from mlflow.tracking import MlflowClient
from PIL import Image
from test_extending import table1_rows

from tactile_exp.report import cli, figures, table3


def _jobs(sweep: str, *arguments: str) -> list[list[str]]:
    """The jobs `python -m tactile_exp -m sweep=<sweep> <arguments>` launches, as Hydra's basic
    sweeper expands them (the sweep file's params, then the command line's)."""
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose("config", overrides=[f"sweep={sweep}"], return_hydra_config=True)
    params = [f"{k}={v}" for k, v in cfg.hydra.sweeper.params.items()]
    loader = ConfigLoaderImpl(config_search_path=create_config_search_path(str(CONF)))
    overrides = OverridesParser.create(config_loader=loader).parse_overrides([*params, *arguments])
    return [job for batch in BasicSweeper.split_arguments(overrides, None) for job in batch]


def test_table1_grid_over_three_random_splits():
    jobs = _jobs("table1", "seed=0,1,2", "split=random")
    rows = table1_rows(CONF)
    assert len(jobs) == 3 * len(rows)
    assert {(j[0], j[1]) for j in jobs} == {
        (f"experiment={r}", f"seed={s}") for r in rows for s in (0, 1, 2)
    }
    assert all(j[2] == "split=random" for j in jobs)


def test_smoke_grid_is_every_row_on_tiny_data():
    assert [j[0] for j in _jobs("smoke")] == [f"experiment={r}" for r in table1_rows(CONF)]
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose(
            "config", overrides=["sweep=smoke", "experiment=table1_j_haptic_cnn_10trials"]
        )
    assert cfg.schedule.epochs == 2 and cfg.tracking.experiment == "tactile_exp_smoke"
    assert cfg.combine == cfg.data.trials == 2  # row J combines all of an object's trials


@pytest.mark.slow
def test_smoke_sweep_and_report(cache_dir, mlflow_uri, tmp_path):
    args = [f"cache_dir={cache_dir}", f"tracking.uri={mlflow_uri}"]
    args += [f"hydra.sweep.dir={tmp_path}/multirun"]
    subprocess.run(
        [sys.executable, "-m", "tactile_exp", "-m", "sweep=smoke", *args], check=True, timeout=900
    )
    out = tmp_path / "report"
    cli.main(
        ["--tracking-uri", mlflow_uri, "--experiment", "tactile_exp_smoke"] + ["--out", str(out)]
    )  # fmt: skip (defaults: Fig. 6 of metallic and compressible)

    client = MlflowClient(mlflow_uri)
    experiment = client.get_experiment_by_name("tactile_exp_smoke")
    parents = {
        r.info.run_id: r
        for r in client.search_runs([experiment.experiment_id], "tags.run_level = 'parent'")
    }
    assert all(r.info.status == "FINISHED" for r in parents.values())
    with open(out / "table1.csv") as f:
        table = list(csv.DictReader(f))
    letters = [r.split("_")[1].upper() for r in table1_rows(CONF)]
    assert [r["row"] for r in table] == letters  # every row, once, in order
    for line in table:
        runs = [parents[i] for i in line["run_ids"].split()]
        assert len(runs) == 1 and line["at_paper_settings"] == "False"
        assert float(line["mean_auc"]) == pytest.approx(runs[0].data.metrics["mean_auc"], abs=1e-6)
        assert line["data"] == runs[0].data.tags["data.identity"]
        assert line["differences"] == "schedule=tiny; 2 adjectives"
    with open(out / "per_adjective.csv") as f:
        for line in csv.DictReader(f):
            run = next(r for r in parents.values() if r.data.tags["row_hash"] == line["row_hash"])
            for adjective in ("hard", "metallic"):
                assert float(line[adjective]) == pytest.approx(
                    run.data.metrics[f"auc.{adjective}"], abs=1e-6
                )
    sizes = {"fig5_per_adjective.png": (1200, 450), "fig6_metallic.png": figures.fig6_size(2)}
    for name, size in sizes.items():
        with Image.open(out / name) as image:
            assert image.size == size
            assert np.asarray(image.convert("L")).std() > 10
    index = (out / "index.md").read_text()
    for name in ("table1.csv", "per_adjective.csv", "table3.csv", *sizes):
        assert f"]({name})" in index
    # The smoke grid trains hard and metallic only: Fig. 6 says compressible is not there.
    assert "Not drawn for compressible: the job did not run them." in index
    assert not (out / "fig6_compressible.png").exists()
    with open(out / "table3.csv") as f:
        lines = list(csv.DictReader(f))
    assert [line["row"] for line in lines] == ["I", "L", "M"] * 3  # three objects, three rows
    for line in lines:
        job = parents[line["run_id"]]
        assert job.data.params["paper.row"] == line["row"]
        assert line["predicted"] != table3.NOT_RUN and line["agree"].endswith("/2")
    assert {line["tested_adjectives"] for line in lines} == {"hard metallic"}
    assert (out / "table3.md").read_text().count("\n") == 2 + 3
    reports = client.search_runs([experiment.experiment_id], "tags.run_level = 'report'")
    listed = {a.path for a in client.list_artifacts(reports[0].info.run_id, "report")}
    assert listed == {f"report/{p.name}" for p in out.iterdir()}
    # Table I (md, csv), per-adjective (2 csv), Fig. 5, claims (md, csv), the CD diagram,
    # Fig. 6 of metallic, Table III (md, csv), index.md
    assert len(listed) == 12

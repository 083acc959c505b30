"""The named grids: `sweep=table1` is every table1_* file and takes seed/split lists; `sweep=smoke`
runs every row end to end, and the report built from it matches the runs. A sweep survives its
invalid cells and failed jobs (``tactile_exp.app.sweep``): every job's config is
checked before the first starts, invalid cells are listed and skipped (or nothing runs), a job
that fails while training leaves its runs FAILED and the jobs after it run, and one line sums it
up; SIGTERM to the launcher stops its workers and closes the runs killed ones left RUNNING."""

import csv
import logging
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import CONF, TINY_DATA
from hydra import compose, initialize_config_dir
from hydra._internal.config_loader_impl import ConfigLoaderImpl
from hydra._internal.core_plugins.basic_sweeper import BasicSweeper
from hydra._internal.utils import create_config_search_path
from hydra.core.global_hydra import GlobalHydra
from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.types import RunMode
from mlflow.tracking import MlflowClient
from omegaconf import OmegaConf
from PIL import Image
from test_extending import table1_rows

from tactile_exp.app import sweep
from tactile_exp.errors import ConfigError
from tactile_exp.report import cli, figures, table3
from tactile_exp.runtime import processes
from tactile_exp.runtime.termination import Terminated


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
        # rows A-F and O train no epochs (linear SVMs, chance): no schedule is theirs
        epochs = line["row"] not in "ABCDEFO"
        assert line["schedule"] == ("tiny (2+1 epochs)" if epochs else "no epochs")
        assert line["differences"] == ("schedule=tiny; " if epochs else "") + "2 adjectives"
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
    # Table I (md, csv, the four-column summary md), per-adjective (2 csv), the leaderboard (md,
    # csv), Fig. 5, claims (md, csv), the CD diagram, Fig. 6 of metallic, Table III (md, csv),
    # index.md
    assert len(listed) == 15
    assert "report/table1_summary.md" in listed


# The grid: model=haptic_cnn takes the haptic modality only, so its first cell is invalid.
GRID = ["model=haptic_cnn,linear", "modality=visual,haptic", "schedule=tiny", "adjectives=[hard]"]
INVALID_REASON = (
    "modality: model=haptic_cnn takes (channels, time) signals, modality=visual gives feature "
    "vectors; modality=haptic or signals would fit"
)
# A model that trains like `random` but raises while training for one seed: a job failing mid-sweep.
FAILING_MODULE = '''
"""Random scores, or an error while training for one seed: a job that fails mid-sweep."""

from tactile_exp.models.random_guess import RandomGuess
from tactile_exp.models.registry import MODELS


@MODELS.register("fails_for_seed")
class FailsForSeed(RandomGuess):
    def __init__(self, *, seed: int = 0, fail_seed: int = -1) -> None:
        super().__init__(seed=seed)
        self.fail_seed = fail_seed

    def fit(self, train, on_epoch=None):
        if self.seed == self.fail_seed:
            raise RuntimeError(f"planned failure while training with seed {self.seed}")
        return super().fit(train, on_epoch)
'''


@pytest.fixture
def multirun(cache_dir, mlflow_uri, tmp_path):
    """The config Hydra hands the sweep callback for `python -m tactile_exp -m <overrides>` on
    tiny data, composed in multirun mode, with GlobalHydra up as in a real sweep."""

    def _compose(*overrides: str):
        args = [*overrides, *TINY_DATA, f"cache_dir={cache_dir}", f"tracking.uri={mlflow_uri}"]
        args.append(f"hydra.sweep.dir={tmp_path / 'multirun'}")
        return GlobalHydra.instance().hydra.compose_config(  # type: ignore[union-attr]
            "config", args, run_mode=RunMode.MULTIRUN, with_log_configuration=False
        )

    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        yield _compose


def test_every_cell_is_checked_before_the_first_job(multirun):
    config = multirun(*GRID)
    jobs = sweep.sweep_jobs(config)
    assert [job[:2] for job in jobs] == [
        ("model=haptic_cnn", "modality=visual"),
        ("model=haptic_cnn", "modality=haptic"),
        ("model=linear", "modality=visual"),
        ("model=linear", "modality=haptic"),
    ]
    assert all(job[2:4] == ("schedule=tiny", "adjectives=[hard]") for job in jobs)
    valid, invalid, absent = sweep.check_jobs(config, jobs)
    assert absent == []
    assert [(e["num"], e["cell"], e["reason"]) for e in invalid] == [
        (0, "model=haptic_cnn modality=visual", INVALID_REASON)
    ]
    assert invalid[0]["overrides"] == list(jobs[0])
    assert [(s.model.name, s.modality.name) for s in valid] == [
        ("haptic_cnn", "haptic"),
        ("linear", "visual"),
        ("linear", "haptic"),
    ]
    assert {s.sweep_id for s in valid} == {str(config.hydra.sweep.dir)}


def test_a_fold_beyond_the_declared_split_is_absent_not_invalid(multirun):
    """PHAC-2's declared split has one test side: split.fold=1 is no cell of a grid over data
    sets, listed apart from the invalid ones; a negative fold is a mistake."""
    config = multirun("model=linear", "split=declared", "split.fold=0,1,-1")
    jobs = sweep.sweep_jobs(config)
    valid, invalid, absent = sweep.check_jobs(config, jobs)
    assert [s.split for s in valid] == ["published"]
    assert [(e["cell"], e["reason"]) for e in absent] == [
        (
            "split.fold=1",
            "split.fold=1: the data set declares split=published, one test side (split.fold=0)",
        )
    ]
    assert [(e["cell"], e["reason"]) for e in invalid] == [
        ("split.fold=-1", "split.fold: expected a whole number >= 0, got -1")
    ]


def test_an_absent_job_is_recorded_absent_and_counted_apart(tmp_path, caplog):
    folder = tmp_path / "m"
    reason = "split.fold=3: the data set declares 2 folds (0..1)"
    sweep._write(
        folder / sweep.INVALID_FILE,
        {"invalid": [], "absent": [{"num": 1, "overrides": ["split.fold=3"], "reason": reason}]},
    )
    assert sweep.SweepJob(folder, 1, ("split.fold=3",)).skipped()
    outcome = yaml.safe_load((folder / "outcomes" / "1.yaml").read_text())
    assert (outcome["status"], outcome["reason"]) == ("absent", reason)
    sweep.SweepJob(folder, 0, ("split.fold=0",)).record("FINISHED")
    callback = sweep.PrepareSweep()
    callback.jobs = [("split.fold=0",), ("split.fold=3",)]
    config = OmegaConf.create({"hydra": {"runtime": {"cwd": str(tmp_path)}, "sweep": {"dir": "m"}}})
    caplog.set_level(logging.INFO, logger="tactile_exp.app.sweep")
    callback.on_multirun_end(config)  # an absent cell is no failure: no exit
    assert caplog.records[-1].getMessage() == (
        "1 FINISHED, 0 skipped (invalid), 0 FAILED, 1 absent (not cells)"
    )


def test_a_sweep_file_s_params_come_first_and_another_sweeper_is_not_enumerated(multirun):
    jobs = sweep.sweep_jobs(multirun("sweep=table1", "seed=0,1"))
    assert len(jobs) == 2 * len(table1_rows(CONF))
    first = "experiment=table1_a_haptic_static_1trial"
    assert [job[:3] for job in jobs[:2]] == [(first, "sweep=table1", f"seed={s}") for s in (0, 1)]
    config = multirun("seed=0,1")
    config.hydra.sweeper._target_ = "hydra_plugins.hydra_optuna_sweeper.OptunaSweeper"
    assert sweep.sweep_jobs(config) is None


def _restore_sigterm():
    handler = signal.getsignal(signal.SIGTERM)
    return lambda: signal.signal(signal.SIGTERM, handler)


@pytest.mark.parametrize("full_error", ["0", "1"])
def test_on_invalid_fail_runs_nothing(
    full_error, multirun, mlflow_uri, tmp_path, capsys, monkeypatch
):
    """Also with HYDRA_FULL_ERROR=1 (a traceback): Hydra only warns about a callback's exception
    and launches the jobs all the same, so the callback exits itself."""
    monkeypatch.setenv("HYDRA_FULL_ERROR", full_error)
    config = multirun(*GRID, "sweep.on_invalid=fail")
    with pytest.raises(SystemExit) as stop:
        sweep.PrepareSweep().on_multirun_start(config)
    assert stop.value.code == 2
    error = "sweep.on_invalid=fail: 1 of 4 jobs have an invalid config (listed above); none run"
    last = capsys.readouterr().err.splitlines()[-1]
    assert last == (
        f"error: {error}" if full_error == "0" else f"tactile_exp.errors.ConfigError: {error}"
    )
    listed = yaml.safe_load((tmp_path / "multirun" / "invalid.yaml").read_text())
    assert listed["on_invalid"] == "fail" and listed["jobs"] == 4
    assert [e["reason"] for e in listed["invalid"]] == [INVALID_REASON]
    # Nothing tracked: not even the experiment is created.
    assert [e.name for e in MlflowClient(mlflow_uri).search_experiments()] == ["Default"]


def test_on_invalid_check_composes_every_job_and_runs_none(multirun, mlflow_uri, capsys):
    """What --cfg job is to one job: exit 0 when every cell is valid, 2 naming the invalid."""
    valid = multirun("model=linear", "modality=visual,haptic", "schedule=tiny", "adjectives=[hard]")
    valid.sweep.on_invalid = "check"
    with pytest.raises(SystemExit) as stop:
        sweep.PrepareSweep().on_multirun_start(valid)
    assert stop.value.code == 0
    with pytest.raises(SystemExit) as stop:
        sweep.PrepareSweep().on_multirun_start(multirun(*GRID, "sweep.on_invalid=check"))
    assert stop.value.code == 2
    assert capsys.readouterr().err.splitlines()[-1].startswith("error: sweep.on_invalid=check: 1")
    assert [e.name for e in MlflowClient(mlflow_uri).search_experiments()] == ["Default"]


def test_one_mistake_in_every_job_is_one_line(multirun, capsys):
    """Every cell fails for one reason (an impossible value they share, data.path left out of
    sweep=benchmark): the sweep says it once, not once per cell."""
    config = multirun("model=linear,haptic_lstm", "combine=0")
    with pytest.raises(SystemExit) as stop:
        sweep.PrepareSweep().on_multirun_start(config)
    assert stop.value.code == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith("error: every one of the 2 jobs: combine: ")


def test_a_cell_without_a_config_file_is_left_to_hydra_s_own_error(multirun, tmp_path):
    """`model=nope`: the sweeper names the missing file before it launches anything."""
    sweep.PrepareSweep().on_multirun_start(multirun("model=linear,nope", "adjectives=[hard]"))
    assert not (tmp_path / "multirun" / "invalid.yaml").exists()


def test_skipped_cells_are_listed_for_the_report_before_any_job(
    multirun, mlflow_uri, tmp_path, caplog
):
    restore = _restore_sigterm()
    try:
        with caplog.at_level(logging.WARNING, logger="tactile_exp.app.sweep"):
            sweep.PrepareSweep().on_multirun_start(multirun(*GRID))
    finally:
        restore()
    block = caplog.records[-1].getMessage().splitlines()
    assert block == [
        "1 of 4 jobs have an invalid config, skipped (sweep.on_invalid=skip); in "
        f"{tmp_path / 'multirun' / 'invalid.yaml'}:",
        f"  #0 model=haptic_cnn modality=visual: {INVALID_REASON}",
    ]
    client = MlflowClient(mlflow_uri)
    experiment = client.get_experiment_by_name("tactile_exp")
    (record,) = client.search_runs([experiment.experiment_id], "tags.run_level = 'sweep'")
    assert record.info.status == "FINISHED"
    assert record.data.tags["sweep_id"] == str(tmp_path / "multirun")
    assert record.data.tags["n_jobs"] == "4" and record.data.tags["n_invalid"] == "1"
    assert record.data.tags["invalid"] == f"#0 model=haptic_cnn modality=visual: {INVALID_REASON}"
    stored = client.download_artifacts(record.info.run_id, "invalid.yaml", str(tmp_path))
    assert yaml.safe_load(Path(stored).read_text()) == yaml.safe_load(
        (tmp_path / "multirun" / "invalid.yaml").read_text()
    )


def test_a_listed_job_is_skipped_and_a_failed_one_is_kept_from_hydra(tmp_path, capsys):
    folder = tmp_path / "multirun"
    listing = {"invalid": [{"num": 1, "overrides": ["seed=2"], "reason": "seed: no"}]}
    sweep._write(folder / sweep.INVALID_FILE, listing)
    outcome = lambda num: yaml.safe_load((folder / "outcomes" / f"{num}.yaml").read_text())  # noqa: E731

    assert not sweep.SweepJob(folder, 0, ("seed=1",)).skipped()
    assert sweep.SweepJob(folder, 1, ("seed=2",)).skipped()
    assert outcome(1) == {
        "num": 1,
        "status": "skipped",
        "overrides": ["seed=2"],
        "reason": "seed: no",
    }

    with sweep.SweepJob(folder, 0, ("seed=1",)).recorded():
        raise RuntimeError("boom")  # logged with its traceback, not raised
    assert outcome(0)["status"] == "FAILED" and outcome(0)["reason"] == "RuntimeError: boom"
    # Drop what the traceback's logging wrote (under xdist a handler an earlier test left may
    # hold a closed stream): only the user error's own output is asserted below.
    capsys.readouterr()
    with sweep.SweepJob(folder, 2, ("seed=3",)).recorded():
        raise ConfigError("combine: found only now")
    assert capsys.readouterr().err == "error: combine: found only now\n"
    assert outcome(2)["reason"] == "combine: found only now"
    with sweep.SweepJob(folder, 3, ("seed=4",)).recorded():
        pass
    assert outcome(3)["status"] == "FINISHED"
    with pytest.raises(RuntimeError), sweep.SweepJob(folder, 5, (), raises=True).recorded():
        raise RuntimeError("boom")  # another sweeper (the study's) handles it: it gets it
    assert outcome(5)["status"] == "FAILED"
    with pytest.raises(Terminated), sweep.SweepJob(folder, 4, ("seed=5",)).recorded():
        raise Terminated("terminated by signal 15")  # the job exits: nothing recorded
    assert not (folder / "outcomes" / "4.yaml").exists()


def test_a_signal_wrapped_in_another_error_stops_the_sweep_job(tmp_path, sigterm_raises):
    """A SIGTERM that Python re-raised inside another error (a class built during an import)
    is the signal: the job exits instead of being recorded FAILED and taking the next job."""

    class Descriptor:
        def __set_name__(self, owner: type, name: str) -> None:
            os.kill(os.getpid(), signal.SIGTERM)

    folder = tmp_path / "m"
    with pytest.raises(Terminated), sweep.SweepJob(folder, 0, ("seed=1",)).recorded():
        type("Owner", (), {"field": Descriptor()})
    assert not (folder / "outcomes" / "0.yaml").exists()


def test_the_summary_line_counts_every_job(tmp_path, caplog):
    config = OmegaConf.create({"hydra": {"runtime": {"cwd": str(tmp_path)}, "sweep": {"dir": "m"}}})
    callback = sweep.PrepareSweep()
    callback.jobs = [
        (f"model={m}", f"seed={s}", "schedule=tiny") for m in ("a", "b") for s in (1, 2)
    ]
    folder = tmp_path / "m"
    for num, status in enumerate(["FINISHED", "skipped", "FINISHED"]):  # job #3 never recorded
        sweep.SweepJob(folder, num, callback.jobs[num]).record(status)
    caplog.set_level(logging.INFO, logger="tactile_exp.app.sweep")
    with pytest.raises(SystemExit) as stop:
        callback.on_multirun_end(config)
    assert stop.value.code == 1
    assert caplog.records[-1].getMessage() == (
        "2 FINISHED, 1 skipped (invalid), 1 FAILED: model=b seed=2"
    )
    sweep.SweepJob(folder, 3, callback.jobs[3]).record("FINISHED")
    callback.on_multirun_end(config)  # nothing FAILED: no exit
    assert caplog.records[-1].getMessage() == "3 FINISHED, 1 skipped (invalid), 0 FAILED"


def _sweep(tmp_path, mlflow_uri, cache_dir, *overrides, env=None):
    args = [*overrides, *TINY_DATA, f"cache_dir={cache_dir}", f"tracking.uri={mlflow_uri}"]
    args.append(f"hydra.sweep.dir={tmp_path / 'multirun'}")
    return subprocess.run(
        [sys.executable, "-m", "tactile_exp", "-m", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        timeout=600,
        env={**os.environ, **(env or {})},
    )


def _parents(mlflow_uri):
    client = MlflowClient(mlflow_uri)
    experiment = client.get_experiment_by_name("tactile_exp")
    return client.search_runs([experiment.experiment_id], "tags.run_level = 'parent'")


@pytest.mark.slow
@pytest.mark.job
def test_the_issue_s_sweep_runs_its_valid_cells_and_skips_the_invalid_one(
    tmp_path, mlflow_uri, cache_dir
):
    done = _sweep(tmp_path, mlflow_uri, cache_dir, *GRID)
    assert done.returncode == 0, done.stdout[-3000:]
    out = done.stdout
    listed = f"#0 model=haptic_cnn modality=visual: {INVALID_REASON}"
    assert out.index(listed) < out.index("Launching 4 jobs") < out.index("MLflow run")
    assert "skipped: invalid config" in out and "error:" not in out
    assert out.rstrip().endswith("3 FINISHED, 1 skipped (invalid), 0 FAILED")
    parents = _parents(mlflow_uri)
    assert sorted(
        (r.data.params["choice.model"], r.data.params["choice.modality"]) for r in parents
    ) == [
        ("haptic_cnn", "haptic"),
        ("linear", "haptic"),
        ("linear", "visual"),
    ]
    assert all(r.info.status == "FINISHED" for r in parents)
    folder = tmp_path / "multirun"
    (invalid,) = yaml.safe_load((folder / "invalid.yaml").read_text())["invalid"]
    assert (invalid["num"], invalid["reason"]) == (0, INVALID_REASON)
    # The skipped cell keeps its number and folder (its config, no run): #1..#3 are the others.
    assert (
        yaml.safe_load((folder / "0" / ".hydra" / "overrides.yaml").read_text())
        == invalid["overrides"]
    )
    status = {
        n: yaml.safe_load((folder / "outcomes" / f"{n}.yaml").read_text())["status"]
        for n in range(4)
    }
    assert status == {0: "skipped", 1: "FINISHED", 2: "FINISHED", 3: "FINISHED"}


@pytest.mark.slow
@pytest.mark.job
@pytest.mark.parametrize(
    "launcher", [[], ["hydra/launcher=joblib", "hydra.launcher.n_jobs=2"]], ids=["basic", "joblib"]
)
def test_a_job_failing_in_training_leaves_its_runs_failed_and_the_rest_run(
    launcher, tmp_path, mlflow_uri, cache_dir
):
    (tmp_path / "fails_for_seed.py").write_text(FAILING_MODULE)
    path = os.pathsep.join([str(tmp_path), os.environ.get("PYTHONPATH", "")])
    overrides = [
        "model=random",
        "model.name=fails_for_seed",
        "+model._module_=fails_for_seed",
        "+model.fail_seed=1",
        "combine_instances=separate",
        "adjectives=[hard]",
        "seed=1,2,3",
        *launcher,
    ]
    done = _sweep(tmp_path, mlflow_uri, cache_dir, *overrides, env={"PYTHONPATH": path})
    assert done.returncode == 1, done.stdout[-3000:]
    assert done.stdout.rstrip().endswith("2 FINISHED, 0 skipped (invalid), 1 FAILED: seed=1")
    assert "Error executing job" not in done.stdout  # Hydra never saw the failure
    client = MlflowClient(mlflow_uri)
    runs = client.search_runs([client.get_experiment_by_name("tactile_exp").experiment_id])
    assert sorted(
        (r.data.tags["run_level"], r.data.params["seed"], r.info.status) for r in runs
    ) == [
        ("child", "1", "FAILED"),
        ("child", "2", "FINISHED"),
        ("child", "3", "FINISHED"),
        ("parent", "1", "FAILED"),
        ("parent", "2", "FINISHED"),
        ("parent", "3", "FINISHED"),
    ]
    failed = [r for r in runs if r.info.status == "FAILED"]
    assert all("planned failure while training with seed 1" in r.data.tags["error"] for r in failed)


def test_a_terminated_sweep_closes_the_runs_its_killed_workers_left_running(
    mlflow_uri, monkeypatch
):
    """Once one loky worker exits, loky SIGKILLs the others, some before they closed their runs
    (seen in CI); workers that ignore SIGTERM are killed after the grace period. Either way the
    launcher marks their runs FAILED, and only theirs."""
    import socket

    from tactile_exp.tracking import Tracker

    stubborn = "import signal, time; signal.signal(signal.SIGTERM, signal.SIG_IGN); print(); "
    workers = [
        subprocess.Popen(
            [sys.executable, "-c", stubborn + "time.sleep(60)"], stdout=subprocess.PIPE
        )
        for _ in range(2)
    ]
    for w in workers:
        w.stdout.readline()  # SIGTERM ignored from here on
    monkeypatch.setattr(processes, "children", lambda pid: [w.pid for w in workers])
    monkeypatch.setattr(sweep, "WORKER_GRACE_S", 0.5)
    tracker = Tracker(mlflow_uri, "tactile_exp")
    host = socket.gethostname()

    def make(name, pid):
        tags = {"host": host, "pid": str(pid), "pid_start": ""}
        return tracker.client.create_run(tracker.experiment_id, run_name=name, tags=tags)

    orphans = [make("job", workers[0].pid), make("adj=hard", workers[0].pid)]
    orphans.append(make("job", workers[1].pid))
    live = make("elsewhere", os.getpid())  # another job of this experiment, still running
    done = make("done", workers[1].pid)
    tracker.client.set_terminated(done.info.run_id, status="FINISHED")

    with pytest.raises(SystemExit) as exit_:
        sweep.terminate_workers(signal.SIGTERM, None, tracker=tracker)
    assert exit_.value.code == 128 + signal.SIGTERM
    assert not any(processes.process_alive(w.pid) for w in workers)
    client = MlflowClient(mlflow_uri)
    for r in orphans:
        closed = client.get_run(r.info.run_id)
        assert closed.info.status == "FAILED" and closed.info.end_time is not None
        assert "terminated by signal 15" in closed.data.tags["error"]
    assert client.get_run(live.info.run_id).info.status == "RUNNING"
    assert client.get_run(done.info.run_id).info.status == "FINISHED"


TERMINATE = """
import os, subprocess, sys
from multiprocessing import resource_tracker
from tactile_exp.app import sweep
from tactile_exp.runtime import processes

class NoRuns:
    def end_runs_of(self, pids, *, error):
        return []

sweep.WORKER_GRACE_S = 5.0
resource_tracker.ensure_running()  # a child that ignores SIGTERM, as loky's does
worker = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"])
before = processes.children(os.getpid())
trackers = sorted(p for p in before if processes.is_resource_tracker(p))
try:
    sweep.terminate_workers(15, None, tracker=NoRuns())
except SystemExit as stop:
    print("exit", stop.code)
print("before", *sorted(before))
print("alive", *sorted(p for p in before if processes.process_alive(p)))
print("worker", worker.pid)
print("trackers", *trackers)
"""


def test_a_terminated_sweep_stops_its_workers_and_leaves_resource_trackers_alone():
    """Resource trackers ignore SIGTERM and end with the launcher: waiting for them cost a
    terminated sweep the whole grace period, then SIGKILLed them."""
    done = subprocess.run(
        [sys.executable, "-c", TERMINATE], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr[-2000:]
    lines = {key: value for key, _, value in (s.partition(" ") for s in done.stdout.splitlines())}
    assert lines["exit"] == "143"
    before, alive = lines["before"].split(), lines["alive"].split()
    assert lines["worker"] in before and len(before) == 2
    assert len(lines["trackers"].split()) == 1
    assert alive == lines["trackers"].split()  # the tracker neither killed nor waited for

"""MLflow tracking: one parent run per job, one child run per adjective.

Uses ``MlflowClient`` explicitly (no global active run) so every run is terminated exactly once:
FINISHED on success, FAILED (with the error as a tag) on any exception. Jobs are idempotent: a
job whose ``config_hash`` already has a FINISHED parent run on the same data file (its
``data.identity``) is skipped, so re-running a crashed sweep's command resumes it.

What ``mlflow ui`` needs to show these runs as training runs: every run carries source tags
(entry point, git commit of the checkout) and its job's data file as a dataset input (name +
digest = the file identity). MLflow 3.x opens an experiment on its GenAI Overview whatever the
experiment says: its UI reads the ``workflowType`` URL parameter, else the browser's remembered
choice (the "GenAI | Model training" switch), default GenAI; the ``mlflow.experimentKind`` tag
only counts where that switch is off. No tag or server option selects the runs, so each job
ends its log with ``Tracker.runs_view``: a link to the runs table with ``workflowType`` set and
the job's columns, filter and order as an MLflow shared view (an experiment tag the UI reads).
"""

from __future__ import annotations

import functools
import hashlib
import json
import logging
import os
import random
import re
import socket
import subprocess
import time
import urllib.error
import urllib.request
from collections.abc import Callable, Collection, Iterator, Mapping, Sequence
from contextlib import contextmanager, nullcontext
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

from tactile_exp.errors import TrackingError
from tactile_exp.runtime.processes import process_alive, process_tags
from tactile_exp.runtime.termination import reason, shielded

if TYPE_CHECKING:
    from mlflow.entities import Run

os.environ.setdefault("MLFLOW_DISABLE_TELEMETRY", "true")  # no calls home; the network is closed
# Where tqdm is installed, MLflow draws a progress bar for every artifact download: one per stored
# model a job reuses or ``predict`` loads, in the job's log and ahead of predict's errors.
os.environ.setdefault("MLFLOW_ENABLE_ARTIFACTS_PROGRESS_BAR", "false")

log = logging.getLogger(__name__)
T = TypeVar("T")

MAX_PARAM_LENGTH = 6000  # MLflow's limit on a param value
MAX_BATCH = 1000  # MLflow's limit on metrics per log_batch call
# The UI's switch between its traditional-ML run views and its GenAI (traces) views, read where
# MLflow's workflow switch is off; MLflow 3.17 reads ``WORKFLOW`` instead (see the docstring).
EXPERIMENT_TAGS = {"mlflow.experimentKind": "custom_model_development"}
WORKFLOW = "workflowType=machine_learning"  # URL parameter: the UI's "Model training" views
SHARED_VIEW_TAG = "mlflow.sharedViewState."  # + key: a runs-table state the UI's URL can name
UI_DEFAULT = "http://127.0.0.1:5000"  # where ``mlflow ui`` serves by default
MAX_RESULTS = 50000  # the most runs MLflow returns for one search
# Conditions of MLflow's filter syntax that the run queries below combine.
_JOB = "tags.run_level = 'parent'"
_FINISHED = "attributes.status = 'FINISHED'"
_RUNNING = "attributes.status = 'RUNNING'"
_NEWEST_FIRST = "attributes.start_time DESC"
# A write that another job's same write can collide with (a shared store: PostgreSQL does not
# serialise writers as sqlite does) is read back and retried, with backoff, for this long.
CONFLICT_WAIT_S = 60.0
# (sqlite's "database is locked": a writer that waited its busy timeout for another's).
_CONFLICT = re.compile(
    r"unique constraint|duplicate key|UniqueViolation|already exists|database is locked", re.I
)
# How MLflow's client reports a server that stopped answering once its own retries (with
# backoff: ``MLFLOW_HTTP_REQUEST_MAX_RETRIES``, default 7, about 4 minutes) are spent.
_UNREACHABLE = re.compile(
    r"Max retries exceeded|Connection (refused|reset|aborted)|ConnectionError|"
    r"RemoteDisconnected|timeout exception|too many (500|502|503|504) error",
    re.I,
)


def project_root() -> Path:
    """The source checkout (where pyproject.toml is) for an editable install, else the cwd."""
    root = Path(__file__).resolve().parents[1]
    return root if (root / "pyproject.toml").exists() else Path.cwd()


def resolve_uri(uri: str | None) -> str:
    """Config value, else $MLFLOW_TRACKING_URI, else sqlite:///<project>/mlflow.db."""
    if uri:
        return uri
    if os.environ.get("MLFLOW_TRACKING_URI"):
        return os.environ["MLFLOW_TRACKING_URI"]
    return f"sqlite:///{project_root() / 'mlflow.db'}"


@functools.cache
def git_commit(root: Path) -> str | None:
    """The commit of the source checkout at ``root``, once per process; None outside one (an
    installed wheel, no git) rather than the commit of whatever repository the cwd is in."""
    if not (root / "pyproject.toml").exists():
        return None
    try:
        out = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            timeout=10,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    commit = out.stdout.strip()
    return commit if out.returncode == 0 and commit else None


def source_tags(entry_point: str) -> dict[str, str]:
    """The run tags that make the UI's Source column say which code produced a run."""
    tags = {"mlflow.source.name": entry_point, "mlflow.source.type": "LOCAL"}
    commit = git_commit(Path(__file__).resolve().parents[1])
    if commit is not None:
        tags["mlflow.source.git.commit"] = commit
    return tags


def _artifact_root(uri: str) -> str | None:
    """Artifacts beside a local sqlite store; a server decides its own location."""
    if uri.startswith("sqlite:///"):
        return (Path(uri.removeprefix("sqlite:///")).parent / "mlartifacts").as_uri()
    return None


def ui_base(uri: str) -> str:
    """The address of the MLflow UI for store ``uri``: the server itself, else ``mlflow ui``."""
    return uri.rstrip("/") if uri.startswith(("http://", "https://")) else UI_DEFAULT


def canonical_column(kind: str, key: str) -> str:
    """A runs-table column as the UI names it, e.g. ``metrics.`mean_auc```."""
    return f"{kind}.`{key}`"


def check_server(uri: str, timeout: float = 5.0) -> None:
    """One short request to an HTTP tracking server's ``/health`` instead of MLflow's retries."""
    try:
        with urllib.request.urlopen(f"{uri.rstrip('/')}/health", timeout=timeout) as response:
            response.read()
    except (urllib.error.URLError, OSError, ValueError) as err:
        reason = getattr(err, "reason", err)
        raise TrackingError(
            f"tracking.uri: no MLflow server answers at {uri} ({reason}); start one "
            "(`mlflow server`) or use tracking=local"
        ) from err


def _first_line(err: BaseException) -> str:
    lines = str(err).strip().splitlines()
    return (lines[0] if lines else type(err).__name__)[:300]


def conflicting(err: BaseException) -> bool:
    """Whether ``err`` is a write that lost a race to (or waited out) another job's write."""
    return _CONFLICT.search(str(err)) is not None


def unreachable(err: BaseException) -> bool:
    """Whether ``err`` is a tracking server that stopped answering (MLflow's retries spent)."""
    return _UNREACHABLE.search(str(err)) is not None


def retried(
    write: Callable[[], T], *, done: Callable[[], bool] = lambda: False, what: str
) -> T | None:
    """Compare-and-retry for a write that other jobs may make at the same moment: on a conflict,
    ``done()`` reads the store back (someone else's identical write counts: then None) and else
    the write is tried again, with jittered backoff, for up to ``CONFLICT_WAIT_S`` seconds.
    Each try is ``shielded``: a SIGTERM ends the job between tries, never inside one."""
    delay, deadline = 0.05, time.monotonic() + CONFLICT_WAIT_S
    while True:
        try:
            with shielded():
                return write()
        except Exception as err:
            if not conflicting(err) or time.monotonic() > deadline:
                raise
            log.debug("%s: lost a race (%s); reading it back", what, err)
        if done():
            return None
        time.sleep(delay * (1 + random.random()))
        delay = min(2 * delay, 2.0)


@contextmanager
def fail_fast() -> Iterator[None]:
    """MLflow's client tries each request once inside the block: for the last writes of a job
    whose server already failed to answer through a whole retry period."""
    name = "MLFLOW_HTTP_REQUEST_MAX_RETRIES"
    before = os.environ.get(name)
    os.environ[name] = "0"
    try:
        yield
    finally:
        if before is None:
            os.environ.pop(name, None)
        else:
            os.environ[name] = before


def flatten(config: Mapping[str, Any], prefix: str = "") -> dict[str, str]:
    """Nested config -> {"model.params.lr": "0.01", ...} as MLflow params."""
    out: dict[str, str] = {}
    for key, value in config.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            out.update(flatten(value, f"{name}."))
        else:
            out[name] = str(value)[:MAX_PARAM_LENGTH]
    return out


class ExperimentNotFound(LookupError):
    """Reading an experiment that the tracking store does not hold."""


class Tracker:
    """Thin wrapper over ``MlflowClient`` with the run tree this project uses.

    Every query of the store is a method here, named after what it returns, so the MLflow filter
    syntax (and the tags it filters on) is written in this module only."""

    def __init__(
        self, uri: str | None, experiment: str, *, entry_point: str = "python -m tactile_exp"
    ) -> None:
        """The tracker a job logs with: ``experiment`` is created when the store lacks it."""
        self._connect(uri, entry_point)
        self.experiment_id = self._experiment(experiment)

    @classmethod
    def open(
        cls, uri: str | None, experiment: str, *, entry_point: str = "python -m tactile_exp"
    ) -> Tracker:
        """The tracker of an experiment the store already holds, for what only reads it
        (predict, the report): a misspelt name raises ``ExperimentNotFound`` naming the
        experiments there instead of creating an empty one."""
        tracker = cls.__new__(cls)
        tracker._connect(uri, entry_point)
        found = tracker.client.get_experiment_by_name(experiment)
        if found is None:
            names = sorted(e.name for e in tracker.client.search_experiments())
            raise ExperimentNotFound(
                f"no MLflow experiment {experiment!r} in {tracker.uri}; "
                f"experiments there: {', '.join(names) or 'none'}"
            )
        tracker.experiment_id = found.experiment_id
        return tracker

    def _connect(self, uri: str | None, entry_point: str) -> None:
        from mlflow.tracking import MlflowClient

        self.uri = resolve_uri(uri)
        if self.uri.startswith(("http://", "https://")):
            check_server(self.uri)
        self.client = MlflowClient(tracking_uri=self.uri)
        self.source_tags = source_tags(entry_point)

    def _experiment(self, name: str) -> str:
        """Create-or-get: jobs that start together all create ``name``; one wins, the others
        find the winner's experiment."""
        get = self.client.get_experiment_by_name
        if get(name) is None:
            retried(
                lambda: self.client.create_experiment(
                    name, artifact_location=_artifact_root(self.uri), tags=EXPERIMENT_TAGS
                ),
                done=lambda: get(name) is not None,
                what=f"experiment {name}",
            )
        found = get(name)
        for key, value in EXPERIMENT_TAGS.items():  # made before the tag existed
            if found.tags.get(key) != value:
                self.set_experiment_tag(found.experiment_id, key, value)
        return found.experiment_id

    def set_experiment_tag(self, experiment_id: str, key: str, value: str) -> None:
        """An experiment tag that other jobs may write at the same moment (with the same value:
        the runs-table view, the experiment kind): compare-and-retry."""

        def done() -> bool:
            return self.client.get_experiment(experiment_id).tags.get(key) == value

        retried(
            lambda: self.client.set_experiment_tag(experiment_id, key, value),
            done=done,
            what=f"experiment tag {key}",
        )

    def runs_view(self, columns: Sequence[str], *, order_by: str, where: str = "") -> str:
        """A link that opens the UI on this experiment's runs table (not its GenAI Overview)
        showing the jobs (parent runs; those meeting ``where`` too, an MLflow filter) with
        ``columns``, sorted by ``order_by``, best first. The state is a shared view: an
        experiment tag named by its content, so the jobs of one sweep write the same tag once
        each and print the same link."""
        state = {
            "selectedColumns": list(columns),
            "searchFilter": f"{_JOB} and {where}" if where else _JOB,
            "orderByKey": order_by,
            "orderByAsc": False,
        }
        text = json.dumps(state, sort_keys=True)
        key = hashlib.sha256(text.encode()).hexdigest()[:12]
        try:  # a view is a convenience: failing to store it never fails a job
            self.set_experiment_tag(self.experiment_id, f"{SHARED_VIEW_TAG}{key}", text)
        except Exception as err:
            log.warning("the runs-table view was not stored (%s); the link shows no columns", err)
        page = f"{ui_base(self.uri)}/#/experiments/{self.experiment_id}/runs"
        return f"{page}?{WORKFLOW}&viewStateShareKey={key}"

    def _search(
        self, *where: str, order_by: str | None = None, limit: int = MAX_RESULTS
    ) -> list[Run]:
        """This experiment's runs meeting every condition in ``where`` (MLflow filter syntax)."""
        found = self.client.search_runs(
            [self.experiment_id],
            filter_string=" and ".join(where),
            order_by=[order_by] if order_by else None,
            max_results=limit,
        )
        return list(found)

    def finished_run(self, config_hash: str, *, data_identity: str) -> str | None:
        """A FINISHED job of ``config_hash`` on the data file ``data_identity`` (its
        ``data.identity`` tag): the same config on another file (a new generator version, a
        replaced or real file) has not been run, so it is not skipped."""
        runs = self._search(
            f"tags.config_hash = '{config_hash}'",
            _JOB,
            f"tags.`data.identity` = '{data_identity}'",
            _FINISHED,
            limit=1,
        )
        return runs[0].info.run_id if runs else None

    def jobs(
        self, *, sweep_id: str | None = None, finished_only: bool = True, limit: int = MAX_RESULTS
    ) -> list[Run]:
        """The experiment's jobs (parent runs), newest first: the FINISHED ones unless
        ``finished_only`` is false, those of sweep ``sweep_id`` when it is given."""
        where = [_JOB, *([_FINISHED] if finished_only else [])]
        if sweep_id is not None:
            where.append(f"tags.sweep_id = '{sweep_id}'")
        return self._search(*where, order_by=_NEWEST_FIRST, limit=limit)

    def child_runs(
        self, parent_id: str, *, level: str | None = "child", finished_only: bool = False
    ) -> list[Run]:
        """The runs under job ``parent_id``, oldest first: its adjectives' (``level`` child),
        its trained parts' (``part``) or all of them (None); the FINISHED ones when
        ``finished_only``."""
        where = [f"tags.mlflow.parentRunId = '{parent_id}'"]
        if level is not None:
            where.append(f"tags.run_level = '{level}'")
        if finished_only:
            where.append(_FINISHED)
        runs = self._search(*where)
        return sorted(runs, key=lambda r: (r.info.start_time, r.info.run_id))

    def children(self, parent_id: str) -> dict[str, str]:
        """Adjective -> the FINISHED child run of job ``parent_id`` that scored it (what predict
        applies and the report reads)."""
        runs = self.child_runs(parent_id, finished_only=True)
        return {r.data.tags["adjective"]: r.info.run_id for r in runs}

    def child_metrics(self, parent_id: str, key: str) -> dict[str, float]:
        """Adjective -> metric ``key`` of each child run of job ``parent_id`` that logged it
        (a skipped job's validation AUCs, read back for its objective)."""
        return {
            r.data.tags["adjective"]: r.data.metrics[key]
            for r in self.child_runs(parent_id)
            if key in r.data.metrics
        }

    def trained_run(self, key: str) -> Run | None:
        """The newest FINISHED run tagged with training key ``key``: it trained that model, or
        loaded it (then its ``reused_from`` tag names the run that trained it)."""
        runs = self._search(
            f"tags.training_key = '{key}'", _FINISHED, order_by=_NEWEST_FIRST, limit=1
        )
        return runs[0] if runs else None

    def claims(self, key: str) -> list[Run]:
        """The RUNNING runs tagged with training key ``key``, oldest first: each is a job's claim
        to train that model (``store.await_trained`` decides which claim trains it)."""
        runs = self._search(f"tags.training_key = '{key}'", _RUNNING)
        return sorted(runs, key=lambda r: (r.info.start_time, r.info.run_id))

    def sweep_runs(self, sweep_id: str) -> list[Run]:
        """The runs a sweep keeps about itself (``run_level`` sweep: the cells it listed
        invalid) for sweep ``sweep_id``."""
        return self._search("tags.run_level = 'sweep'", f"tags.sweep_id = '{sweep_id}'")

    def end_stale_runs(self, config_hash: str) -> list[str]:
        """Mark KILLED the RUNNING runs of ``config_hash`` whose process on this host is gone
        (``kill -9``, a crash of the machine's jobs): they would otherwise stay RUNNING forever.
        Runs of other hosts are left alone (their liveness cannot be checked from here)."""
        ended = self._end_orphans(
            f"tags.config_hash = '{config_hash}'",
            status="KILLED",
            error=lambda pid, host: (
                f"stale: process {pid} on {host} ended without closing this run"
            ),
        )
        if ended:
            log.warning("marked %d stale RUNNING run(s) of this config KILLED", len(ended))
        return ended

    def end_runs_of(self, pids: Collection[int], *, error: str) -> list[str]:
        """Mark FAILED, with ``error``, the RUNNING runs of processes ``pids`` on this host that
        have ended: a terminated sweep's workers that were killed before they closed their runs."""
        wanted = {str(pid) for pid in pids}
        return self._end_orphans(status="FAILED", error=lambda _pid, _host: error, pids=wanted)

    def _end_orphans(
        self,
        *where: str,
        status: str,
        error: Callable[[str, str], str],
        pids: Collection[str] | None = None,
    ) -> list[str]:
        """End the RUNNING runs meeting ``where`` whose process on this host is gone
        (and is one of ``pids`` when given); ``error(pid, host)`` is their ``error`` tag."""
        from mlflow.entities import RunTag

        host = socket.gethostname()
        runs = self._search(*where, _RUNNING)
        ended = []
        for r in runs:
            tags = r.data.tags
            pid = tags.get("pid", "")
            if (
                tags.get("host") != host
                or not pid.isdigit()
                or (pids is not None and pid not in pids)
            ):
                continue
            if process_alive(int(pid), tags.get("pid_start", "")):
                continue
            self.client.log_batch(r.info.run_id, tags=[RunTag("error", error(pid, host))])
            self.client.set_terminated(r.info.run_id, status=status)
            ended.append(r.info.run_id)
        return ended

    @contextmanager
    def run(
        self,
        name: str,
        params: Mapping[str, str],
        tags: Mapping[str, str],
        parent_id: str | None = None,
    ) -> Iterator[str]:
        """A run that ends FINISHED, or FAILED with the error recorded, whatever happens inside."""
        from mlflow.entities import Param, RunTag

        all_tags = {"mlflow.runName": name, **process_tags(), **self.source_tags, **tags}
        if parent_id is not None:
            all_tags["mlflow.parentRunId"] = parent_id
        run_id = None
        try:
            with shielded():  # a SIGTERM now is raised once the run exists, so it ends FAILED
                run = self.client.create_run(self.experiment_id, run_name=name, tags=all_tags)
                run_id = run.info.run_id
                items = [Param(k, v) for k, v in params.items()]
                for i in range(0, len(items), 100):  # MLflow takes at most 100 params per batch
                    self.client.log_batch(run_id, params=items[i : i + 100])
            try:
                yield run_id
            except BaseException as caught:  # a SIGTERM wrapped in another error is the signal
                signalled = reason(caught)
                if signalled is caught:
                    raise
                raise signalled from caught
        except BaseException as err:
            if run_id is None:
                raise
            message = f"{type(err).__name__}: {err}"[:5000]
            status = "KILLED" if isinstance(err, KeyboardInterrupt) else "FAILED"
            down = unreachable(err)
            try:  # a server that has not answered through MLflow's retries gets one more try
                with shielded(), fail_fast() if down else nullcontext():
                    self.client.log_batch(run_id, tags=[RunTag("error", message)])
                    self.client.set_terminated(run_id, status=status)
            except Exception as end_err:
                if not unreachable(end_err):
                    raise
                log.warning(
                    "run %s stays RUNNING: the tracking server does not answer; a rerun of "
                    "this config on this host marks it KILLED",
                    run_id,
                )
            if down and not isinstance(err, TrackingError):
                raise TrackingError(
                    f"tracking.uri: the MLflow server at {self.uri} stopped answering "
                    f"({_first_line(err)}); rerun the same command once it is back"
                ) from err
            raise
        with shielded():
            self.client.set_terminated(run_id, status="FINISHED")

    def set_tags(self, run_id: str, tags: Mapping[str, str]) -> None:
        from mlflow.entities import RunTag

        with shielded():
            self.client.log_batch(run_id, tags=[RunTag(k, v) for k, v in tags.items()])

    def log_dataset(self, run_id: str, *, name: str, digest: str, source: str) -> None:
        """A data file as the run's dataset input: the UI's Dataset column (name + digest).

        Parallel jobs race to insert the experiment's one row for the file: the loser's retry
        finds the winner's row and links its run to it."""
        from mlflow.entities import Dataset, DatasetInput

        dataset = Dataset(name=name, digest=digest, source_type="local", source=source)
        retried(
            lambda: self.client.log_inputs(run_id, datasets=[DatasetInput(dataset)]),
            what=f"dataset {name}",
        )

    def log_metrics(self, run_id: str, values: Mapping[str, float], step: int = 0) -> None:
        self.log_curves(run_id, {k: [v] for k, v in values.items()}, start=step)

    def log_curves(self, run_id: str, curves: Mapping[str, list[float]], start: int = 0) -> None:
        """Per-epoch curves in as few calls as MLflow allows (batched: ~4x faster on sqlite)."""
        from mlflow.entities import Metric

        now = int(time.time() * 1000)
        metrics = [
            Metric(key, float(v), now, start + step)
            for key, values in curves.items()
            for step, v in enumerate(values)
        ]
        for i in range(0, len(metrics), MAX_BATCH):
            with shielded():
                self.client.log_batch(run_id, metrics=metrics[i : i + MAX_BATCH])

    def log_text(self, run_id: str, text: str, path: str) -> None:
        with shielded():
            self.client.log_text(run_id, text, path)

    def log_figure(self, run_id: str, figure: Any, path: str) -> None:
        with shielded():
            self.client.log_figure(run_id, figure, path)

    def log_table(self, run_id: str, rows: list[dict[str, str]], path: str) -> None:
        """Rows (one dict per row, the same keys) as an MLflow table artifact (a JSON file)."""
        columns = list(rows[0]) if rows else []
        self.client.log_table(run_id, {c: [r[c] for r in rows] for c in columns}, path)

    def log_file(self, run_id: str, file: Path, path: str) -> None:
        self.client.log_artifact(run_id, str(file), path)

    def log_dir(self, run_id: str, folder: Path, path: str) -> None:
        with shielded():
            self.client.log_artifacts(run_id, str(folder), path)

    def download(self, run_id: str, path: str, into: Path | None = None) -> Path:
        """Artifact ``path`` of run ``run_id`` ("" for all of them) as a local file or folder
        (in folder ``into`` when given, else a temporary one)."""
        dst = None if into is None else str(into)
        return Path(self.client.download_artifacts(run_id, path, dst))

    def artifacts(self, run_id: str) -> set[str]:
        """The top-level artifact paths of run ``run_id``."""
        return {a.path for a in self.client.list_artifacts(run_id)}

    def get_run(self, run_id: str) -> Run:
        """Run ``run_id`` (MlflowException when the store has none)."""
        return self.client.get_run(run_id)

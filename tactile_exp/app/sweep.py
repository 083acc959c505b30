"""The Hydra sweep callback (``hydra.callbacks.prepare_sweep`` in ``conf/config.yaml``) and
what each job of a sweep records for it.

A sweep survives its bad cells. Before the first job starts, every job's config is composed and
checked as a single run checks it; invalid cells are listed in ``<sweep folder>/invalid.yaml``
and skipped (``sweep.on_invalid=skip``) or nothing runs (``fail``). Cells that do not exist (a fold
beyond a data set's declared folds, a modality a data set cannot give: `NotACell`) are listed
there as absent and never run, whatever ``on_invalid`` says. A job that fails while running
records it and returns instead of raising: Hydra 1.3's basic sweeper re-raises a failed job's
exception once its batch is done, which skips ``on_multirun_end`` and every later batch. Each job
writes how it ended to ``<sweep folder>/outcomes/<hydra.job.num>.yaml`` (a file, so that it works
under the joblib launcher's worker processes too) and the sweep ends with one summary line.

Kept apart from ``tracking.py`` so that the MLflow layer imports neither Hydra nor the engine.
"""

from __future__ import annotations

import functools
import logging
import os
import signal
import sys
import time
import traceback
from collections import Counter
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import yaml
from hydra.errors import HydraException
from hydra.experimental.callback import Callback
from hydra.types import RunMode
from omegaconf import DictConfig

from tactile_exp.runtime import processes, termination

if TYPE_CHECKING:
    from tactile_exp.config import Settings
    from tactile_exp.recording import Tracker

log = logging.getLogger(__name__)

WORKER_GRACE_S = 60.0  # how long a terminated sweep waits for its workers to mark runs FAILED
ON_INVALID = ("skip", "fail", "check")  # sweep.on_invalid; check: list, then run nothing
INVALID_FILE = "invalid.yaml"  # in the sweep folder: the cells not run (invalid, absent), and why
OUTCOMES = "outcomes"  # in the sweep folder: <hydra.job.num>.yaml, how each job ended
EXIT_FAILED = 1  # a sweep with a FAILED job (a failed Hydra job exits 1 too)


def terminate_workers(signum: int, frame: object, *, tracker: Tracker) -> None:
    """SIGTERM to a sweep's launcher: pass it on to the worker processes (each unwinds its job,
    marks its runs FAILED and exits), wait for them, then exit. Without this the launcher died
    alone and its joblib workers went on with parent PID 1.

    A worker can die with its runs still RUNNING: once one worker exits, loky SIGKILLs the others
    (a "broken" pool), maybe mid-unwind or before its next SIGTERM check (``termination.check``);
    and workers past the grace period are killed (``processes.stop``). Their runs are closed
    here instead."""
    workers = [
        pid for pid in processes.children(os.getpid()) if not processes.is_resource_tracker(pid)
    ]
    log.warning("terminated: stopping %d worker process(es)", len(workers))
    processes.stop(workers, WORKER_GRACE_S)
    error = f"Terminated: terminated by signal {signum}; killed before it ended this run"
    closed = tracker.end_runs_of(workers, error=error)
    if closed:
        log.warning("marked FAILED %d run(s) that killed worker(s) left RUNNING", len(closed))
    raise SystemExit(128 + signum)


def sweep_folder(hydra_cfg: DictConfig) -> Path:
    """``hydra.sweep.dir`` from where the sweep started (a job may change directory)."""
    return Path(str(hydra_cfg.runtime.cwd)) / str(hydra_cfg.sweep.dir)


def sweep_jobs(config: DictConfig) -> list[tuple[str, ...]] | None:
    """Each job's overrides, as Hydra's basic sweeper launches them: its ``params``, then the
    command line's, expanded by the sweeper's own ``split_arguments`` (job i is
    ``hydra.job.num`` i). None under another sweeper, which picks its jobs as it goes (Optuna):
    those jobs are checked as they start, an invalid one FAILED."""
    from hydra._internal.core_plugins.basic_sweeper import BasicSweeper
    from hydra.core.global_hydra import GlobalHydra
    from hydra.core.override_parser.overrides_parser import OverridesParser

    sweeper = config.hydra.sweeper
    if not _basic(sweeper):
        return None
    params = [f"{k}={v}" for k, v in (sweeper.get("params") or {}).items()]
    parser = OverridesParser.create(config_loader=GlobalHydra.instance().config_loader())
    overrides = parser.parse_overrides([*params, *config.hydra.overrides.task])
    batches = BasicSweeper.split_arguments(overrides, sweeper.get("max_batch_size"))
    return [tuple(job) for batch in batches for job in batch]


def _basic(sweeper: DictConfig) -> bool:
    """Whether ``hydra.sweeper`` is Hydra's basic sweeper (the default)."""
    from hydra._internal.core_plugins.basic_sweeper import BasicSweeper

    return bool(sweeper.get("_target_") == f"{BasicSweeper.__module__}.{BasicSweeper.__name__}")


def axes(jobs: Sequence[Sequence[str]]) -> list[int]:
    """Where the jobs' overrides differ (the sweeper lists every job's keys in one order): what
    names a cell, rather than the overrides all jobs share."""
    if len(jobs) < 2:
        return list(range(len(jobs[0]))) if jobs else []
    return [i for i in range(len(jobs[0])) if len({job[i] for job in jobs}) > 1]


def cell(overrides: Sequence[str], where: Sequence[int]) -> str:
    """A job named by its grid coordinates, e.g. ``model=haptic_cnn modality=visual``."""
    return " ".join(overrides[i] for i in where if i < len(overrides)) or "(no overrides)"


def job_settings(job: DictConfig) -> Settings:
    """One job's settings, checked as a single run checks them before it creates a run
    (``core.open_data``: no data is preprocessed)."""
    from tactile_exp.config import settings_from_config
    from tactile_exp.core import open_data

    sweep_id = str(Path(job.hydra.sweep.dir))  # as the job tags its runs
    settings = settings_from_config(
        job, sweep_id=sweep_id, overrides=tuple(job.hydra.overrides.task)
    )
    open_data(settings)
    return settings


def _reason(err: Exception) -> str:
    from tactile_exp.errors import USER_ERRORS

    return str(err) if isinstance(err, USER_ERRORS) else f"{type(err).__name__}: {err}"


def _write(path: Path, content: dict[str, Any]) -> None:
    """Whole or not at all: a reader never sees half a file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    part = path.with_name(f".{path.name}.{os.getpid()}")
    part.write_text(yaml.safe_dump(content, sort_keys=False, width=1000))
    os.replace(part, path)


@dataclass(frozen=True)
class SweepJob:
    """One job of a sweep, from inside it: whether it was listed invalid, and how it ended."""

    folder: Path  # the sweep's folder
    num: int  # hydra.job.num: its place in the grid
    overrides: tuple[str, ...]
    # Whether a failure goes on to Hydra: not to the basic sweeper, which would re-raise it and
    # stop; to another one, which handles it (the study sweeper marks its trial failed).
    raises: bool = False

    @classmethod
    def of(cls, hydra_cfg: DictConfig) -> SweepJob | None:
        """The running job's, from ``HydraConfig.get()``; None for a single run."""
        if hydra_cfg.mode != RunMode.MULTIRUN:
            return None
        overrides = tuple(str(o) for o in hydra_cfg.overrides.task)
        raises = not _basic(hydra_cfg.sweeper)
        return cls(sweep_folder(hydra_cfg), int(hydra_cfg.job.num), overrides, raises)

    def skipped(self) -> bool:
        """Whether the sweep listed this job invalid before it started: then it is recorded as
        skipped, with its reason, and creates no run."""
        path = self.folder / INVALID_FILE
        if not path.is_file():  # another sweeper: nothing was checked in advance
            return False
        listed = yaml.safe_load(path.read_text()) or {}
        for entry in listed.get("invalid") or []:
            if tuple(entry["overrides"]) == self.overrides:
                log.warning("skipped: invalid config (%s): %s", path, entry["reason"])
                self.record("skipped", entry["reason"])
                return True
        for entry in listed.get("absent") or []:
            if tuple(entry["overrides"]) == self.overrides:
                log.info("absent: not a cell of this grid: %s", entry["reason"])
                self.record("absent", entry["reason"])
                return True
        return False

    def record(self, status: str, reason: str = "") -> None:
        content = {"num": self.num, "status": status, "overrides": list(self.overrides)}
        _write(
            self.folder / OUTCOMES / f"{self.num}.yaml",
            content | ({"reason": reason} if reason else {}),
        )

    @contextmanager
    def recorded(self) -> Iterator[None]:
        """Record the job FINISHED, or FAILED with its error (its runs are FAILED by then), and
        keep a failure from the basic sweeper so the sweep goes on: a bad value or file found
        only now is one ``error:`` line, anything else its traceback in the job's log."""
        from tactile_exp.errors import USER_ERRORS

        try:
            yield
        except Exception as err:
            signalled = termination.reason(err)
            if signalled is not err:  # a SIGTERM wrapped on its way here: stop, do not go on
                raise signalled from err
            if isinstance(err, USER_ERRORS):
                print(f"error: {err}", file=sys.stderr, flush=True)
            else:
                log.exception("job #%d FAILED (the sweep goes on)", self.num)
            self.record("FAILED", _reason(err))
            if self.raises:
                raise
        else:
            self.record("FINISHED")


class PrepareSweep(Callback):
    """Before a multirun launches its jobs: check every job's config and list the invalid
    cells (skipped, or nothing runs); create the MLflow experiment, the data and the shared
    preprocessed arrays once, so jobs neither race on the sqlite schema nor repeat work; make
    SIGTERM to the launcher stop its workers. After the last job: one summary line, and exit 1
    if a job FAILED."""

    def __init__(self) -> None:
        self.jobs: list[tuple[str, ...]] = []  # as the basic sweeper launches them

    def on_multirun_start(self, config: DictConfig, **kwargs: Any) -> None:
        from tactile_exp.errors import EXIT_USER_ERROR, USER_ERRORS, reported

        # Hydra turns an exception raised here into a warning and launches the jobs all the
        # same, so a user error must exit: one line, or with HYDRA_FULL_ERROR=1 its traceback.
        try:
            with reported():
                self._prepare(config)
        except USER_ERRORS:
            traceback.print_exc()
            sys.exit(EXIT_USER_ERROR)

    def _prepare(self, config: DictConfig) -> None:
        """What ``on_multirun_start`` does; a user error raised here stops the sweep."""
        from tactile_exp import recording
        from tactile_exp.config import settings_from_config
        from tactile_exp.core import load
        from tactile_exp.errors import ConfigError

        folder = sweep_folder(config.hydra)
        on_invalid = config.get("sweep", {}).get("on_invalid", "skip")
        if on_invalid not in ON_INVALID:
            raise ConfigError(f"sweep.on_invalid: must be skip, fail or check, got {on_invalid!r}")
        for old in [folder / INVALID_FILE, *(folder / OUTCOMES).glob("*.yaml")]:
            old.unlink(missing_ok=True)  # an earlier sweep's, in the same folder
        jobs = sweep_jobs(config)
        if jobs is None:
            valid, invalid, absent = [settings_from_config(config)], [], []
        else:
            start = time.perf_counter()
            log.info("checking the configs of %d jobs before the first starts", len(jobs))
            try:
                valid, invalid, absent = check_jobs(config, jobs)
            except HydraException:  # a cell with no config file (model=nope): the sweeper
                return  # says so in its own words before it launches anything
            self.jobs = jobs
            log.info(
                "%d valid, %d invalid%s (checked in %.1f s)",
                len(valid),
                len(invalid),
                f", {len(absent)} absent" if absent else "",
                time.perf_counter() - start,
            )
            _flag_loss_axis(jobs, valid)
            listing = {"on_invalid": on_invalid, "jobs": len(jobs), "invalid": invalid}
            _write(folder / INVALID_FILE, listing | ({"absent": absent} if absent else {}))
            if absent:
                _show_absent(absent, folder / INVALID_FILE)
        reasons = {e["reason"] for e in invalid}
        if not valid and len(reasons) == 1:  # one mistake (data.path=... left out): one line
            raise ConfigError(f"every one of the {len(self.jobs)} jobs: {reasons.pop()}")
        if invalid:
            _show_invalid(listing, folder / INVALID_FILE)
            if on_invalid in ("fail", "check"):
                raise ConfigError(
                    f"sweep.on_invalid={on_invalid}: {len(invalid)} of {len(self.jobs)} jobs have "
                    "an invalid config (listed above); none run"
                )
        if not valid:
            raise ConfigError(f"all {len(self.jobs)} jobs are invalid or absent; none run")
        if on_invalid == "check":  # composed and checked, as each job would be; nothing runs
            log.info("sweep.on_invalid=check: all %d jobs valid; none run", len(valid))
            sys.exit(0)
        tracker = recording.open_tracker(valid[0])
        if invalid:
            track_invalid(tracker, valid[0].sweep_id, listing)
        signal.signal(signal.SIGTERM, functools.partial(terminate_workers, tracker=tracker))
        load(valid[0])

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        ended = {}
        for path in (sweep_folder(config.hydra) / OUTCOMES).glob("*.yaml"):
            outcome = yaml.safe_load(path.read_text())
            ended[int(outcome["num"])] = outcome
        for num, overrides in enumerate(self.jobs):  # a job whose process died records nothing
            died = "ended without recording how (its process died?)"
            ended.setdefault(num, {"status": "FAILED", "overrides": overrides, "reason": died})
        line = ", ".join(
            f"{sum(o['status'] == status for o in ended.values())} {status}{shown}"
            for status, shown in (("FINISHED", ""), ("skipped", " (invalid)"), ("FAILED", ""))
        )
        absent = sum(o["status"] == "absent" for o in ended.values())
        line += f", {absent} absent (not cells)" if absent else ""
        failed = [o["overrides"] for _, o in sorted(ended.items()) if o["status"] == "FAILED"]
        if failed:
            where = axes(self.jobs or [o["overrides"] for o in ended.values()])
            log.error("%s: %s", line, "; ".join(cell(o, where) for o in failed))
            sys.exit(EXIT_FAILED)
        log.info(line)


def _flag_loss_axis(jobs: Sequence[Sequence[str]], valid: Sequence[Settings]) -> None:
    """A ``loss`` axis over combined-instance jobs may change no score: say so before they run."""
    swept = {jobs[0][i].split("=")[0].lstrip("+~") for i in axes(jobs) if i < len(jobs[0])}
    if "loss" in swept and any(v.combiner == "concat" for v in valid):
        log.warning(
            "loss is swept over combine_instances=concat jobs: their scores come from the "
            "classification layer retrained on combined units (T4), whose hinge stage moves "
            "nothing once the logistic stage has separated them (the haptic ConvNet's on the "
            "quick and paper schedules: FinetuneWarning); loss=hinge then scores exactly as "
            "loss=logistic (conf/loss/hinge.yaml), and the report marks the axis as changing no "
            "score"
        )


def check_jobs(
    config: DictConfig, jobs: Sequence[Sequence[str]]
) -> tuple[list[Settings], list[dict[str, Any]], list[dict[str, Any]]]:
    """The valid jobs' settings, the invalid ones and the absent ones (`NotACell`), each of
    those as ``num``, ``cell``, ``reason``, ``overrides``."""
    from hydra.core.global_hydra import GlobalHydra

    from tactile_exp.errors import NotACell

    loader = GlobalHydra.instance().config_loader()
    valid, invalid, absent = [], [], []
    where = axes(jobs)
    for num, overrides in enumerate(jobs):
        job = loader.load_sweep_config(config, list(overrides))  # as its launcher composes it
        try:
            valid.append(job_settings(job))
        except Exception as err:  # whatever would stop the job before its first run
            entry = {
                "num": num,
                "cell": cell(overrides, where),
                "reason": _reason(err),
                "overrides": list(overrides),
            }
            (absent if isinstance(err, NotACell) else invalid).append(entry)
    return valid, invalid, absent


def _show_invalid(listing: dict[str, Any], path: Path) -> None:
    """The invalid cells in one block, before any job starts."""
    invalid = listing["invalid"]
    what = "skipped (sweep.on_invalid=skip)" if listing["on_invalid"] == "skip" else "none run"
    lines = [f"{len(invalid)} of {listing['jobs']} jobs have an invalid config, {what}; in {path}:"]
    lines += [f"  #{e['num']} {e['cell']}: {e['reason']}" for e in invalid]
    log.warning("\n".join(lines))


def _show_absent(absent: Sequence[dict[str, Any]], path: Path) -> None:
    """The cells that do not exist, one line per reason (expected in a grid over data sets:
    a benchmark lists dozens); each cell is in ``path``."""
    reasons = Counter(e["reason"] for e in absent)
    lines = [f"{len(absent)} cells do not exist (a fold or modality their data lacks), not run"]
    lines[0] += f"; in {path}:"
    lines += [f"  {n} x {reason}" for reason, n in reasons.items()]
    log.info("\n".join(lines))


def track_invalid(tracker: Tracker, sweep_id: str, content: dict[str, Any]) -> None:
    """The skipped cells as a small sweep-level run (``run_level=sweep``, tagged with the
    sweep's ``sweep_id``): ``invalid.yaml`` as its artifact, one line per cell as its
    ``invalid`` tag, for the report."""
    lines = [f"#{e['num']} {e['cell']}: {e['reason']}" for e in content["invalid"]]
    tags = {
        "run_level": "sweep",
        "sweep_id": sweep_id,
        "n_jobs": str(content["jobs"]),
        "n_invalid": str(len(content["invalid"])),
        "invalid": "\n".join(lines)[:5000],
    }
    with tracker.run("sweep", {"on_invalid": content["on_invalid"]}, tags) as run_id:
        tracker.log_text(run_id, yaml.safe_dump(content, sort_keys=False, width=1000), INVALID_FILE)

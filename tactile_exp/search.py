"""Hyperparameter search on validation objects: the Optuna study behind the
``study`` sweeper (``hydra_plugins/tactile_exp_study``), its summary run, and
``python -m tactile_exp.search best STUDY``.

Hydra's own Optuna sweeper pins optuna<3, whose sqlite storage fails with the SQLAlchemy 2 that
MLflow brings; so the sweeper is ours, on current Optuna, while Hydra's launchers run the trials.
Each trial is an ordinary job (tagged ``search.study`` and ``search.trial``) that returns its
validation objective (``tactile_exp.objective``); the test objects are scored once, by the final
evaluation that ``best`` prints.
"""

from __future__ import annotations

import argparse
import io
import logging
import math
import os
import shlex
import socket
import sys
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from tactile_exp import marks
from tactile_exp.errors import ConfigError
from tactile_exp.runtime.processes import process_alive
from tactile_exp.tracking import Tracker, resolve_uri, retried

if TYPE_CHECKING:
    import optuna
    from optuna.distributions import BaseDistribution

log = logging.getLogger(__name__)

STORAGE_FILE = "optuna.db"  # the default study storage, beside the MLflow sqlite store
# Keys (and config groups) a search may not sample, with why; the search's own override
# prefixes, left out of the final evaluation's command: both marked in tactile_exp/marks.py.
FIXED_KEYS = marks.fixed()
SEARCH_ONLY = marks.search_only()
INTERRUPTED = "interrupted"  # a trial's user attribute: stopped by a signal, to be run again


def default_storage(tracking_uri: str | None) -> str:
    """``sqlite:///<folder of the MLflow sqlite store>/optuna.db``; beside the project's default
    store when MLflow is a server (a cluster gives ``hydra.sweeper.storage`` a database URL)."""
    uri = resolve_uri(tracking_uri)
    if uri.startswith("sqlite:///"):
        folder = Path(uri.removeprefix("sqlite:///")).parent
    else:
        folder = Path(resolve_uri(None).removeprefix("sqlite:///")).parent
    return f"sqlite:///{folder / STORAGE_FILE}"


def as_override(value: Any) -> str:
    """A sampled value as Hydra override text (lists as ``[a,b]``)."""
    if isinstance(value, list | tuple):
        return "[" + ",".join(as_override(v) for v in value) + "]"
    return str(value)


def fixed_reason(key: str) -> str:
    """Why a search may not sample ``key`` ("" when it may): the key, or a group's override
    (``+data=...``, ``split@x=...``), is in ``FIXED_KEYS`` or under one of them."""
    name = key.lstrip("+~").split("@")[0]
    for fixed, why in FIXED_KEYS.items():
        if name == fixed or name.startswith(f"{fixed}."):
            return why
    return ""


def check_objective(objective: str, metrics: Sequence[str]) -> None:
    """A search's objective reads a validation metric the jobs compute (one listed in
    ``metrics``), else every trial would return NaN."""
    from tactile_exp.metrics import METRICS
    from tactile_exp.objective import metric_key

    key = metric_key(objective)
    if key not in [METRICS.build(n).key for n in metrics]:
        raise ConfigError(
            f"objective: {objective} reads the validation {key}, which metrics={list(metrics)} "
            "does not compute; list its metric in metrics"
        )


def search_space(params: Mapping[str, Any]) -> dict[str, BaseDistribution]:
    """Optuna distributions of Hydra sweep expressions: ``choice(a,b)`` (lists allowed),
    ``range(lo,hi[,step])`` (whole numbers, hi excluded), ``interval(lo,hi)`` and
    ``tag(log,interval(lo,hi))``."""
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.core.override_parser.types import ChoiceSweep, IntervalSweep, RangeSweep
    from optuna.distributions import (
        CategoricalDistribution,
        FloatDistribution,
        IntDistribution,
    )

    parser = OverridesParser.create()
    space: dict[str, BaseDistribution] = {}
    for key, expression in params.items():
        where = f"hydra.sweeper.params.{key}"
        why = fixed_reason(str(key))
        if why:
            raise ConfigError(f"{where}: {key} is fixed in a search, not sampled: {why}")
        try:
            override = parser.parse_override(f"{key}={expression}")
        except Exception as err:
            raise ConfigError(f"{where}: cannot parse {expression!r} ({err})") from err
        sweep = override.value()
        if isinstance(sweep, ChoiceSweep):
            space[key] = CategoricalDistribution([as_override(v) for v in sweep.list])
        elif isinstance(sweep, RangeSweep):
            values = [sweep.start, sweep.stop, sweep.step]
            if not all(isinstance(v, int) for v in values) or sweep.stop <= sweep.start:
                raise ConfigError(f"{where}: range(lo, hi, step) takes whole numbers, lo < hi")
            last = sweep.stop - 1 - (sweep.stop - 1 - sweep.start) % sweep.step
            space[key] = IntDistribution(int(sweep.start), int(last), step=int(sweep.step))
        elif isinstance(sweep, IntervalSweep):
            log_scale = "log" in sweep.tags
            if log_scale and sweep.start <= 0:
                raise ConfigError(f"{where}: a log interval needs a positive lower end")
            space[key] = FloatDistribution(float(sweep.start), float(sweep.end), log=log_scale)
        else:
            raise ConfigError(
                f"{where}: expected choice(...), range(...), interval(...) or "
                f"tag(log, interval(...)), got {expression!r}"
            )
    if not space:
        raise ConfigError("hydra.sweeper.params: a search needs at least one parameter to sample")
    return space


def open_study(
    name: str, storage: str, *, direction: str, sampler: optuna.samplers.BaseSampler
) -> optuna.Study:
    """The study ``name`` in ``storage``, made on first use, else continued."""
    import optuna

    try:  # sweeps starting together on one database race to make its tables and the study
        study = retried(
            lambda: optuna.create_study(
                study_name=name,
                storage=storage,
                direction=direction,
                sampler=sampler,
                load_if_exists=True,
            ),
            what=f"study {name}",
        )
    except ValueError as err:
        raise ConfigError(f"hydra.sweeper.direction: {err}") from err
    if study.direction.name.lower() != direction:
        raise ConfigError(
            f"hydra.sweeper.direction: study {name!r} in {storage} was made to "
            f"{study.direction.name.lower()}, got {direction}"
        )
    return study


def trials_made(name: str, storage: str) -> int:
    """How many trials study ``name`` holds (0 before it exists)."""
    import optuna

    if name not in optuna.study.get_all_study_names(storage):
        return 0
    return len(optuna.load_study(study_name=name, storage=storage).trials)


def check_same_search(study: optuna.Study, fixed: Sequence[str], objective: str) -> None:
    """A continued study must be the same search: same fixed overrides, same objective."""
    recorded = study.user_attrs.get("fixed_overrides")
    if recorded is None:
        study.set_user_attr("fixed_overrides", list(fixed))
        study.set_user_attr("objective", objective)
        return
    if list(recorded) != list(fixed) or study.user_attrs.get("objective") != objective:
        raise ConfigError(
            f"hydra.sweeper.study_name: study {study.study_name!r} was run with "
            f"{' '.join(recorded)} (objective {study.user_attrs.get('objective')}); this command "
            f"has {' '.join(fixed)} (objective {objective}): name another study"
        )


def claim(trial: optuna.Trial) -> None:
    """Mark ``trial`` as this process's, so a later start can tell when it was abandoned."""
    trial.set_user_attr("host", socket.gethostname())
    trial.set_user_attr("pid", os.getpid())


def interrupted(study: optuna.Study, trial: optuna.Trial) -> None:
    """A trial stopped by a signal or by its launcher: no result (no ``error``), run again later."""
    import optuna

    trial.set_user_attr(INTERRUPTED, True)
    study.tell(trial, state=optuna.trial.TrialState.FAIL)


def failed(study: optuna.Study, trial: optuna.Trial, error: str) -> None:
    """A trial whose job failed or gave no objective: a result of its values, counted."""
    import optuna

    trial.set_user_attr("error", error[:2000])
    study.tell(trial, state=optuna.trial.TrialState.FAIL)


def resume(study: optuna.Study) -> int:
    """Queue again the trials that did not end (interrupted, or RUNNING in a process on this
    host that is gone): their values run first, and a job that had finished is skipped by its
    config (the job-level skip), its objective read back from MLflow. Returns how many."""
    import optuna

    State = optuna.trial.TrialState
    host = socket.gethostname()
    trials = study.trials
    requeued = {t.user_attrs.get("requeue_of") for t in trials}
    queued = 0
    for t in trials:
        mine = t.user_attrs.get("host") == host  # claimed on this host: its pid is recorded
        orphan = t.state == State.RUNNING and mine and not process_alive(t.user_attrs["pid"])
        if orphan:
            study.tell(t.number, state=State.FAIL)
        stopped = orphan or (t.state == State.FAIL and "error" not in t.user_attrs)
        if stopped and t.number not in requeued:
            study.enqueue_trial(t.params, user_attrs={"requeue_of": t.number})
            queued += 1
    return queued


def counted(study: optuna.Study) -> int:
    """Trials that count towards ``n_trials``: finished ones and real failures (a failing
    configuration is a result), not interrupted ones (they are queued again)."""
    import optuna

    State = optuna.trial.TrialState
    return sum(
        1
        for t in study.trials
        if t.state in (State.COMPLETE, State.PRUNED)
        or (t.state == State.FAIL and "error" in t.user_attrs)
    )


def trials_csv(study: optuna.Study) -> str:
    """Every trial: number, state, objective, sampled values, error."""
    import csv

    keys = sorted({k for t in study.trials for k in t.params})
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(["number", "state", "value", *keys, "error"])
    for t in study.trials:
        value = "" if t.value is None else f"{t.value:.6f}"
        params = [as_override(t.params[k]) if k in t.params else "" for k in keys]
        writer.writerow([t.number, t.state.name, value, *params, t.user_attrs.get("error")])
    return out.getvalue()


def log_summary(study: optuna.Study, tracker: Tracker) -> str:
    """The study's summary run (run_level=study): best values as params, best objective, trial
    counts, ``trials.csv`` and Optuna's optimisation-history and parameter-importance plots."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import optuna
    from optuna.visualization import matplotlib as plots

    complete = [t for t in study.trials if t.state == optuna.trial.TrialState.COMPLETE]
    tags = {  # the sweeper records the objective and fixed overrides (check_same_search) first
        "run_level": "study",
        "search.study": study.study_name,
        "search.objective": study.user_attrs["objective"],
        "search.fixed_overrides": " ".join(study.user_attrs["fixed_overrides"])[:5000],
    }
    params: dict[str, str] = {}
    metrics = {"n_trials": float(len(study.trials)), "n_complete": float(len(complete))}
    if complete:
        best = study.best_trial
        params = {k: as_override(v) for k, v in best.params.items()}
        metrics.update(best_value=float(best.value), best_trial=float(best.number))
        tags["search.best_trial"] = str(best.number)
    with tracker.run(f"study={study.study_name}", params, tags) as run_id:
        tracker.log_metrics(run_id, metrics)
        tracker.log_text(run_id, trials_csv(study), "trials.csv")
        figures = {"optimization_history.png": plots.plot_optimization_history}
        if len(complete) >= 2 and len(study.best_trial.params) >= 1:
            figures["param_importances.png"] = plots.plot_param_importances
        for path, plot in figures.items():
            try:
                with warnings.catch_warnings():  # "experimental" since Optuna 2.2
                    warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
                    axes = plot(study)
            except (ValueError, RuntimeError) as err:  # e.g. every trial had the same values
                log.warning("study %s: no %s (%s)", study.study_name, path, err)
                continue
            legend = axes.get_legend()
            if legend is not None:  # Optuna anchors it outside the axes, where it is cut off
                legend.set_bbox_to_anchor(None)
                legend.set_loc("best")  # inside, where it covers the fewest points
            figure = axes.figure
            figure.tight_layout()
            tracker.log_figure(run_id, figure, path)
            plt.close(figure)
    return run_id


def final_command(study: optuna.Study) -> list[str]:
    """The one test evaluation of the best values: every training object (validation.fraction=0,
    as the paper trains), tagged as the study's final evaluation (study.role=final)."""
    best = study.best_trial
    fixed = [
        o for o in study.user_attrs.get("fixed_overrides", []) if not o.startswith(SEARCH_ONLY)
    ]
    sampled = [f"{k}={as_override(v)}" for k, v in best.params.items()]
    search = [
        "validation.fraction=0",
        f"study.name={study.study_name}",
        "study.role=final",
        f"study.trial={best.number}",
    ]
    return ["python", "-m", "tactile_exp", *fixed, *sampled, *search]


def best_report(study: optuna.Study) -> str:
    """What ``best`` prints: the best trial, its values as overrides, the final command."""
    import optuna

    complete = [t for t in study.trials if t.state == optuna.trial.TrialState.COMPLETE]
    if not complete:
        raise ConfigError(f"study {study.study_name!r}: no finished trial yet")
    best = study.best_trial
    objective = study.user_attrs.get("objective", "objective")
    lines = [
        f"study {study.study_name}: {len(complete)} of {len(study.trials)} trials finished; "
        f"best trial {best.number}: {objective} {best.value:.4f} (validation objects)",
        "best values:",
        *(f"  {k}={as_override(v)}" for k, v in best.params.items()),
        "the one test evaluation (retrained on every training object, tagged search.role=final):",
        "  " + shlex.join(final_command(study)),
    ]
    return "\n".join(lines)


def load_study(name: str, storage: str) -> optuna.Study:
    import optuna

    try:
        return optuna.load_study(study_name=name, storage=storage)
    except KeyError as err:
        names = ", ".join(optuna.get_all_study_names(storage)) or "none"
        raise ConfigError(f"study {name!r}: not in {storage}; studies there: {names}") from err


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m tactile_exp.search best STUDY``."""
    from tactile_exp.errors import reported

    parser = argparse.ArgumentParser(prog="python -m tactile_exp.search", description=__doc__)
    commands = parser.add_subparsers(required=True)
    best = commands.add_parser("best", help="print a study's best values and its final command")
    best.add_argument("study")
    best.add_argument("--storage", help="study storage URL (default: beside the MLflow store)")
    best.add_argument("--tracking-uri", help="MLflow store whose folder holds optuna.db")
    args = parser.parse_args(argv)
    logging.getLogger("optuna").setLevel(logging.WARNING)
    with reported():
        storage = args.storage or default_storage(args.tracking_uri)
        print(best_report(load_study(args.study, storage)))
    return 0


def objective_or_nan(value: Any) -> float:
    """A job's return value as a finite float, else NaN (a failed objective)."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        return math.nan
    return number if math.isfinite(number) else math.nan


if __name__ == "__main__":
    sys.exit(main())

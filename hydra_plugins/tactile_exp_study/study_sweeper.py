"""The ``study`` sweeper (``hydra/sweeper: study``, selected by ``conf/search/*.yaml``): asks an
Optuna study for values, has the configured Hydra launcher run them as jobs (basic, joblib,
submitit), and tells the study each job's validation objective (issue 28).

Hydra finds sweepers only in the ``hydra_plugins`` package; the logic is in ``tactile_exp.search``.
"""

from __future__ import annotations

import logging
from typing import Any

from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.core.plugins import Plugins
from hydra.core.utils import JobStatus
from hydra.plugins.sweeper import Sweeper
from hydra.types import HydraContext, TaskFunction
from omegaconf import DictConfig, OmegaConf, open_dict

log = logging.getLogger("tactile_exp.search")


class StudySweeper(Sweeper):
    """Runs ``n_trials`` trials of the study ``study_name``, ``n_jobs`` at a time; the same
    command continues an existing study up to ``n_trials`` (interrupted trials run again)."""

    def __init__(
        self,
        study_name: str,
        n_trials: int,
        n_jobs: int,
        direction: str,
        sampler: Any,
        params: Any,
        storage: str | None = None,
    ) -> None:
        self.study_name = study_name
        self.n_trials = n_trials
        self.n_jobs = n_jobs
        self.direction = direction
        self.sampler = sampler
        self.params = dict(params or {})
        self.storage = storage
        self.job_idx = 0

    def setup(
        self, *, hydra_context: HydraContext, task_function: TaskFunction, config: DictConfig
    ) -> None:
        self.config = config
        self.hydra_context = hydra_context
        self.launcher = Plugins.instance().instantiate_launcher(
            hydra_context=hydra_context, task_function=task_function, config=config
        )

    def sweep(self, arguments: list[str]) -> None:
        from tactile_exp.errors import reported

        with reported():
            self._sweep(arguments)

    def _sweep(self, arguments: list[str]) -> None:
        from hydra.utils import instantiate

        from tactile_exp import search
        from tactile_exp.config import ConfigError, settings_from_config
        from tactile_exp.tracking import Tracker

        for key, value, lowest in (("n_trials", self.n_trials, 1), ("n_jobs", self.n_jobs, 1)):
            if not isinstance(value, int) or isinstance(value, bool) or value < lowest:
                raise ConfigError(
                    f"hydra.sweeper.{key}: must be a whole number >= 1, got {value!r}"
                )
        if not self.study_name:
            raise ConfigError("hydra.sweeper.study_name: missing; set study.name=...")
        # Every job of the study is a trial: refused here (validation.fraction=0, a test
        # objective) before the study or any run exists.
        checked = OmegaConf.masked_copy(self.config, [k for k in self.config if k != "hydra"])
        with open_dict(checked):
            checked.study.name = self.study_name
            checked.study.role = "trial"
        settings = settings_from_config(checked)
        search.check_objective(settings.objective, settings.metrics)

        parser = OverridesParser.create(config_loader=self.hydra_context.config_loader)
        parsed = parser.parse_overrides(arguments)
        fixed = [o.input_line for o in parsed if not o.is_sweep_override()]
        # Sweep expressions on the command line join (or replace) the search file's.
        swept = {
            o.key_or_group: o.input_line.split("=", 1)[1] for o in parsed if o.is_sweep_override()
        }
        space = search.search_space({**self.params, **swept})

        import optuna

        optuna.logging.set_verbosity(optuna.logging.WARNING)
        storage = self.storage or search.default_storage(settings.tracking.uri)
        # Seeded by the trials already made: a continued study does not repeat its first draws.
        seed = int(self.sampler.get("seed", 0) or 0) + search.trials_made(self.study_name, storage)
        sampler = instantiate(OmegaConf.merge(self.sampler, {"seed": seed}))
        study = search.open_study(
            self.study_name, storage, direction=self.direction, sampler=sampler
        )
        search.check_same_search(study, fixed, settings.objective)
        queued = search.resume(study)
        done = search.counted(study)
        log.info(
            "study %s in %s: %d of %d trials done%s; objective %s on validation objects",
            self.study_name,
            storage,
            done,
            self.n_trials,
            f", {queued} interrupted trial(s) queued again" if queued else "",
            settings.objective,
        )
        tracker = Tracker(settings.tracking.uri, settings.tracking.experiment)
        while done < self.n_trials:
            trials = [study.ask(space) for _ in range(min(self.n_jobs, self.n_trials - done))]
            batch = []
            for trial in trials:
                search.claim(trial)
                sampled = [f"{k}={search.as_override(v)}" for k, v in trial.params.items()]
                study_keys = [
                    f"study.name={self.study_name}",
                    "study.role=trial",
                    f"study.trial={trial.number}",
                ]
                batch.append([*fixed, *sampled, *study_keys])
            self.validate_batch_is_legal(batch)
            try:
                returns = self.launcher.launch(batch, initial_job_idx=self.job_idx)
            except BaseException:
                for trial in trials:
                    search.interrupted(study, trial)
                raise
            self.job_idx += len(returns)
            for trial, ret in zip(trials, returns, strict=True):
                if ret.status != JobStatus.COMPLETED:
                    search.failed(study, trial, f"{type(ret._return_value).__name__}: job failed")
                    log.warning("trial %d failed: %s", trial.number, ret._return_value)
                    continue
                value = search.objective_or_nan(ret.return_value)
                if value != value:
                    search.failed(study, trial, f"{settings.objective} is NaN (no validation AUC)")
                    log.warning("trial %d: %s is NaN", trial.number, settings.objective)
                    continue
                study.tell(trial, value)
            done = search.counted(study)
            complete = [t for t in study.trials if t.value is not None]
            best = study.best_trial if complete else None
            log.info(
                "study %s: %d/%d trials; best %s",
                self.study_name,
                done,
                self.n_trials,
                f"trial {best.number}: {best.value:.4f}" if best else "none yet",
            )
        run_id = search.log_summary(study, tracker)
        log.info("study %s summary: MLflow run %s", self.study_name, run_id)
        if any(t.value is not None for t in study.trials):
            print(search.best_report(study), flush=True)

"""The MLflow model cache: trained models kept as artifacts of runs, found again by training key.

``MlflowCache`` is ``cache.ModelCache`` over an MLflow experiment, for one adjective's run: the
adjective's own model is trained in that run (kept with its pipeline when the run finishes), a
modality's part (row M's ConvNet) in a run of its own (``run_level=part``), so any later job
finds either. The files are ``artifacts``' folders.

Jobs side by side (Hydra's joblib or submitit launcher) train each model once: the RUNNING run
that trains a key is its claim, and a job that needs the key while an older live run claims it
waits for that run's model (``await_trained``) instead of training it again; a job puts such an
adjective off until its others are done (``training_elsewhere``), and so trains the models that
no job has started yet in the meantime.
"""

from __future__ import annotations

import logging
import socket
import tempfile
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from tactile_exp import artifacts
from tactile_exp.artifacts import MODEL_FILES, ArtifactError
from tactile_exp.cache import Train, Trained
from tactile_exp.runtime import termination
from tactile_exp.runtime.processes import process_alive
from tactile_exp.tracking import Tracker

log = logging.getLogger(__name__)

POLL_SECONDS = 2.0  # how often a job waiting for another job's model looks again


class MlflowCache:
    """``get_or_train`` in ``tracker``'s experiment for the adjective run ``run_id`` (a child of
    ``parent_id``). The run is created tagged with the training key of its own model (its
    claim); ``reuse`` False trains every model (a part is still kept for later jobs);
    ``lease``: seconds before another host's claim counts as abandoned."""

    def __init__(
        self,
        tracker: Tracker,
        *,
        run_id: str,
        parent_id: str,
        adjective: str,
        reuse: bool,
        lease: float,
        tags: Mapping[str, str] | None = None,
    ) -> None:
        self.tracker = tracker
        self.run_id = run_id
        self.parent_id = parent_id
        self.adjective = adjective
        self.reuse = reuse
        self.lease = lease
        self.tags = dict(tags or {})  # added to a part's run (the job's config_hash)

    def get_or_train(
        self,
        key: str,
        train: Train,
        *,
        part: str | None = None,
        overrides: Mapping[str, Any] | None = None,
    ) -> Trained:
        if part is None:
            return self._own(key, train, overrides)
        return self._part(key, train, part, overrides)

    def _own(self, key: str, train: Train, overrides: Mapping[str, Any] | None) -> Trained:
        """The adjective's model: this run is the key's claim, and its pipeline keeps the model."""
        if self.reuse:
            found = reusable(self.tracker, key, self.run_id, lease=self.lease, overrides=overrides)
            if found is not None:
                log.info("  %s: reusing the model trained in run %s", self.adjective, found[1])
                self.tracker.set_tags(self.run_id, {"reused_from": found[1]})
                return Trained(found[0], source=found[1])
        return Trained(*train())

    def _part(
        self, key: str, train: Train, part: str, overrides: Mapping[str, Any] | None
    ) -> Trained:
        """A part: found by key, else trained in a run of its own (run_level=part, tagged with
        the key), which waits while an older live job trains it."""
        name = f"{self.adjective}/{part}"
        source = find_trained(self.tracker, key) if self.reuse else None
        trained = None
        if source is None:
            tags = {
                **self.tags,
                "run_level": "part",
                "adjective": self.adjective,
                "part": part,
                "training_key": key,
            }
            params = {"adjective": self.adjective}
            with self.tracker.run(f"adj={name}", params, tags, self.parent_id) as rid:
                found = None
                if self.reuse:  # this run is the key's claim
                    found = reusable(self.tracker, key, rid, lease=self.lease, overrides=overrides)
                if found is None:
                    model, history = train()
                    self.tracker.log_curves(rid, history)
                    write = lambda f: artifacts.write_model(f, artifacts.model_name(model), model)  # noqa: E731
                    log_folder(self.tracker, rid, "model", write)
                    trained, source = Trained(model, history), rid
                else:
                    trained, source = Trained(found[0], source=found[1]), found[1]
                    self.tracker.set_tags(rid, {"reused_from": source})
        if trained is None or trained.source is not None:
            log.info("  %s: reusing the model trained in run %s", name, source)
            self.tracker.set_tags(self.run_id, {f"reused_from.{part}": source})
            if trained is None:
                trained = Trained(
                    load_model(self.tracker, source, "model", overrides), source=source
                )
        self.tracker.set_tags(self.run_id, {f"part.{part}": source})
        return trained


def find_trained(tracker: Tracker, key: str) -> str | None:
    """The run that trained the model with training key ``key`` in this experiment: the newest
    FINISHED run with the key, or, when that run reused it, the run it names in ``reused_from``
    (every copy holds the same weights; provenance points at the training)."""
    run = tracker.trained_run(key)
    return None if run is None else run.data.tags.get("reused_from", run.info.run_id)


def await_trained(
    tracker: Tracker, key: str, run_id: str, *, lease: float, poll: float = POLL_SECONDS
) -> str | None:
    """The run that trained the model of ``key`` (as ``find_trained``), waiting while another
    live run claims the key; None when run ``run_id`` (RUNNING, tagged with ``key``) is to train
    it: no run has finished training it and ``run_id`` is the oldest live claim.

    A claim is a RUNNING run tagged with the key; the oldest live one trains, so two jobs that
    start together agree on one. A claim whose process on this host has ended, or another
    host's claim older than ``lease`` seconds (``tracking.claim_lease``), is passed over (taken
    over by the next oldest)."""
    holder, passed = None, set()
    while True:
        # Claims first, then finished runs: a claimant that finishes between the two queries is
        # then seen FINISHED, never missed by both (which would train its model a second time).
        claim, abandoned = _oldest_live_claim(tracker, key, lease)
        source = find_trained(tracker, key)
        if source is not None:
            if holder is not None:
                log.info("  training key %s: trained in run %s, loading it", key, source)
            return source
        for stale in set(abandoned) - passed:
            log.info("  training key %s: run %s's claim is abandoned, passed over", key, stale)
        passed.update(abandoned)
        if claim is None or claim.info.run_id == run_id:
            return None
        if holder != claim.info.run_id:
            holder = claim.info.run_id
            tags = claim.data.tags
            log.info(
                "  training key %s: waiting for run %s (process %s on %s), which trains it",
                key,
                holder,
                tags.get("pid", "?"),
                tags.get("host", "?"),
            )
        termination.check()
        time.sleep(poll)


def training_elsewhere(tracker: Tracker, key: str, *, lease: float) -> str | None:
    """The live run that is training the model of ``key`` right now: the oldest live claim while
    no run has finished it (None when it is trained or unclaimed). A job whose next adjective's
    model is being trained elsewhere takes its other adjectives first (``experiment``), so two
    jobs that need the same models share their training instead of one waiting."""
    claim, _ = _oldest_live_claim(tracker, key, lease)  # claims first: see await_trained
    if claim is None or find_trained(tracker, key) is not None:
        return None
    return claim.info.run_id


def reusable(
    tracker: Tracker,
    key: str,
    claim: str,
    *,
    lease: float,
    overrides: Mapping[str, Any] | None = None,
) -> tuple[Any, str] | None:
    """The trained model of ``key`` and the run that trained it, waiting while an older live
    job trains it (``await_trained``); None when run ``claim`` (tagged with the key) is to train
    it. The one find-or-train rule for every stored model: an adjective's and a part's."""
    source = await_trained(tracker, key, claim, lease=lease)
    if source is None:
        return None
    return load_model(tracker, source, "model", overrides), source


def _oldest_live_claim(tracker: Tracker, key: str, lease: float) -> tuple[Any, list[str]]:
    """The oldest RUNNING run tagged ``training_key = key`` whose process may still run it
    (None when there is none), and the ids of the older abandoned ones passed over."""
    host, now = socket.gethostname(), time.time() * 1000
    abandoned = []
    for run in tracker.claims(key):
        tags = run.data.tags
        pid = tags.get("pid", "")
        if tags.get("host") == host and pid.isdigit():
            alive = process_alive(int(pid), tags.get("pid_start", ""))
        else:
            alive = now - run.info.start_time < lease * 1000
        if alive:
            return run, abandoned
        abandoned.append(run.info.run_id)
    return None, abandoned


def log_folder(tracker: Tracker, run_id: str, path: str, write: Callable[[Path], None]) -> None:
    """``write`` fills a temporary folder, which is then logged whole as artifact ``path``."""
    with tempfile.TemporaryDirectory(prefix="tactile_exp-artifact-") as tmp:
        write(Path(tmp))
        tracker.log_dir(run_id, Path(tmp), path)


def download(tracker: Tracker, run_id: str, path: str, files: tuple[str, ...]) -> Path:
    """Artifact folder ``path`` of ``run_id`` as a local folder holding every one of ``files``."""
    try:
        local = tracker.download(run_id, path)
    except Exception as err:
        raise ArtifactError(f"run {run_id}: artifact {path}/ cannot be read ({err})") from None
    artifacts.check_files(local, files, f"run {run_id}: artifact {path}")
    return local


def load_model(
    tracker: Tracker, run_id: str, path: str, overrides: Mapping[str, Any] | None = None
) -> Any:
    """The model kept as artifact ``path`` of run ``run_id`` (see ``read_model``)."""
    folder = download(tracker, run_id, path, MODEL_FILES)
    return artifacts.read_model(folder, f"run {run_id}: artifact {path}", overrides)

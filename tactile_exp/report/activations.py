"""Fig. 6's data: conv3 activation maps of a job's stored haptic ConvNet on its test trials.

Nothing is retrained: each adjective's ConvNet is loaded from its child run (``model/``, via
``tactile_exp.store``), and the test trials are rebuilt from the job's own data file with the
preprocessing the child run stored (``preprocess/``), by the code path ``tactile_exp.predict``
scores new trials with. The maps are the network's ``transform`` (conv3, ReLU'd) reshaped to
(conv3 channels, time); channel ``g * width + j`` is filter ``j`` of group ``g``, the group of
input signal ``g``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from tactile_exp.data.layout import EPS
from tactile_exp.preprocess.haptic import N_SCALAR, SIGNALS
from tactile_exp.report.scores import ReportError, UnitScore, read_scores
from tactile_exp.tracking import Tracker

N_TRIALS = 2  # panels per adjective: its best- and worst-scored positive test trial


@dataclass(frozen=True)
class Conv3Map:
    """One test trial's conv3 map (its first instance: finger_0, offset 0) for one adjective."""

    adjective: str
    unit: UnitScore  # the trial's test unit as the job scored it
    activations: np.ndarray  # (conv3 channels, time)


def signal_names(pca_components: int) -> list[str]:
    """The haptic ConvNet's input channels (P5), EP-major: for each EP, PAC, PDC, TAC, TDC and
    the electrode PCs, as ``HapticPreprocessor`` orders them."""
    per_ep = [s.upper() for s in SIGNALS[:N_SCALAR]] + [f"PC{i + 1}" for i in range(pca_components)]
    return [f"{ep} {signal}" for ep in EPS for signal in per_ep]


def first_per_unit(units: list[UnitScore]) -> dict[str, UnitScore]:
    """Unit name -> its first line: row H scores each instance of a trial under the trial's
    name, and the first is finger_0, offset 0, the instance Fig. 6 shows."""
    out: dict[str, UnitScore] = {}
    for unit in units:
        out.setdefault(unit.unit, unit)
    return out


def pick_units(units: list[UnitScore], n: int) -> list[UnitScore]:
    """``n`` test trials spread over the positive ones by score, best first (so both correct and
    wrong decisions show when there are any); all test trials when none is positive."""
    unique = list(first_per_unit(units).values())
    pool = [u for u in unique if u.label == 1] or unique
    pool.sort(key=lambda u: -u.score)
    index = np.unique(np.linspace(0, len(pool) - 1, min(n, len(pool))).round().astype(int))
    return [pool[i] for i in index]


@dataclass(frozen=True)
class Fig6Data:
    job_id: str
    maps: list[Conv3Map]
    signals: list[str]  # conv3's input signals, in channel-group order
    missing: list[str]  # asked-for adjectives the job has no finished model for


def conv3_maps(
    *,
    tracker: Tracker,
    job_id: str,
    adjectives: Sequence[str],
    trials: Sequence[str] = (),
    n_trials: int = N_TRIALS,
) -> Fig6Data:
    """The conv3 maps of job ``job_id`` (a ``haptic_cnn`` job) for ``trials`` (test trials of
    every adjective), or ``n_trials`` picked per adjective."""
    from tactile_exp.artifacts import ArtifactError
    from tactile_exp.data.layout import Trials
    from tactile_exp.jobs import PredictError, StoredJob
    from tactile_exp.pipeline import AdjectivePipeline

    try:
        job = StoredJob.read(tracker, job_id)
    except (ArtifactError, PredictError) as err:
        raise ReportError(str(err)) from None
    modality, model = job.spec.modality.name, job.spec.model.name
    if (modality, model) != ("haptic", "haptic_cnn"):
        raise ReportError(f"run {job_id}: a {modality}/{model} job, not a haptic ConvNet's")
    found = tracker.children(job_id)
    dataset = job.spec.data_source()
    logged = job.data_identity
    if logged and dataset.identity() != logged:
        raise ReportError(
            f"run {job_id} ran on data {logged}; {dataset.path} is now {dataset.identity()}"
        )
    maps, signals = [], []
    for adjective in (a for a in adjectives if a in found):
        child = found[adjective]
        units = first_per_unit(read_scores(tracker, child))
        if trials:
            absent = [t for t in trials if t not in units]
            if absent:
                some = ", ".join(sorted(units)[:3])
                raise ReportError(
                    f"{', '.join(absent)}: not a test trial of {adjective} in run {job_id} "
                    f"(its {len(units)} test trials include {some})"
                )
            chosen = [units[t] for t in trials]
        else:
            chosen = pick_units(list(units.values()), n_trials)
        names = [u.unit for u in chosen]
        pipeline = AdjectivePipeline.load(job.folder(child), f"run {child}")
        instances = pipeline.preprocess.transform(Trials(dataset, tuple(names)))
        net = pipeline.model_
        first = [int(np.flatnonzero(instances.trial == name)[0]) for name in names]
        conv3 = net.transform(instances.X[first]).reshape(len(first), *net.conv3_shape_)
        maps += [Conv3Map(adjective, u, a) for u, a in zip(chosen, conv3, strict=True)]
        signals = signal_names(int(pipeline.modality.params["pca_components"]))
    missing = [a for a in adjectives if a not in found]
    return Fig6Data(job_id, maps, signals, missing)

"""The tracked runs the report reads: FINISHED job (parent) runs grouped into Table I's lines.

Runs are grouped by ``row_hash``, the resolved config up to the seed (and fold): runs in a group
differ only in seed (and, with ``split=random``, in the split the seed draws; with
``split=folds``, in the fold). Each (seed, fold) counts once (its latest run).

A run's numbers are those of the report's metric (``--metric``, ``tactile_exp.metrics``): its
``mean_<key>`` and ``<key>.<adjective>``, ROC AUC (``mean_auc``, ``auc.<adjective>``) by default;
the fields keep AUC's names.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

from tactile_exp.metrics import METRICS
from tactile_exp.tracking import Tracker

# Command-line overrides that leave a row's method as the paper has it: which data, which split,
# where results go, which GoogLeNet weights file. Anything else makes the group a variant.
NEUTRAL_OVERRIDES = (
    "experiment",
    "seed",
    "split",
    "data",
    "tracking",
    "device",
    "cache_dir",
    "modality.weights",
    "modality.layout",
    "modality.visual.weights",
    "modality.visual.layout",
    "trunk",
    "sweep",
    "hydra",
)
HAPTIC = ("haptic", "haptic_features")
# Runs logged before jobs tagged their data set's labels (``data.labels``) ran on
# PHAC-2, whose 24 adjectives are in alphabetical order: the order and count assumed for them.
UNTAGGED_LABELS = 24


@dataclass(frozen=True)
class Run:
    run_id: str
    seed: int
    start_time: int
    mean_auc: float  # mean_<key> of the report's metric
    aucs: dict[str, float]  # <key>.<adjective> of the report's metric
    data: str  # the data file's identity
    sweep_id: str
    fold: int = -1  # split=folds: the tested fold; -1 for the other split rules
    folds: int = 0  # split=folds: K; 0 otherwise
    labels: tuple[str, ...] = ()  # every label of its data set, in order (tag data.labels)
    layout: str | None = None  # its data set's record layout (tag data.layout; "none": plain)


@dataclass
class Group:
    """Runs of one config up to the seed: one line of Table I."""

    key: str  # the row hash, and the experiment file when one named the row
    row_hash: str
    method: str
    row: str  # the paper's Table I row the experiment file names, or ""
    paper_auc: float | None
    schedule: str
    schedule_epochs: str
    split: str
    modality: str
    model: str
    n_adjectives: int
    differences: tuple[str, ...]  # what differs from the paper's settings of the row
    params: dict[str, str] = field(default_factory=dict)  # the first run's params
    overrides: dict[str, str] = field(default_factory=dict)  # its command line, key -> value
    runs: dict[tuple[int, int], Run] = field(default_factory=dict)  # (seed, fold) -> latest run

    @property
    def at_paper_settings(self) -> bool:
        return bool(self.row) and not self.differences

    @property
    def seeds(self) -> list[int]:
        return sorted({seed for seed, _ in self.runs})

    @property
    def folds(self) -> int:
        """K of ``split=folds`` (0 for the other rules)."""
        return max(r.folds for r in self.runs.values())

    def fold_runs(self, seed: int) -> list[Run]:
        """One seed's runs, by fold (a single run unless ``split=folds``)."""
        return [self.runs[k] for k in sorted(self.runs) if k[0] == seed]

    @property
    def aucs(self) -> np.ndarray:
        """Each seed's mean AUC over adjectives (with folds: the mean over its folds' runs, the
        per-fold mean; the pooled out-of-fold AUC needs the scores, see ``report.heldout``)."""
        return np.array([np.mean([r.mean_auc for r in self.fold_runs(s)]) for s in self.seeds])

    @property
    def n_labels(self) -> int:
        """How many labels the group's data set has (its runs may have trained fewer)."""
        return len(self.first_run.labels) or UNTAGGED_LABELS

    @property
    def layout(self) -> str | None:
        """Its data set's record layout as the jobs tagged it (None: logged before the tag)."""
        return self.first_run.layout

    @property
    def first_run(self) -> Run:
        """The run of the lowest seed (and fold): the one a per-run view (Fig. 6, Table III)
        shows."""
        return self.runs[min(self.runs)]

    @property
    def sorted_runs(self) -> list[Run]:
        return [self.runs[s] for s in sorted(self.runs)]

    def per_adjective(self) -> dict[str, float]:
        runs = self.sorted_runs
        return {
            a: float(np.mean([r.aucs[a] for r in runs if a in r.aucs])) for a in label_order([self])
        }


def label_order(groups: list[Group]) -> list[str]:
    """The labels the groups' runs were trained on, in their data sets' order (the order the
    jobs logged; alphabetical for runs logged without it, which is PHAC-2's paper order)."""
    order: dict[str, int] = {}
    for g in groups:
        for r in g.sorted_runs:
            for a in r.labels:
                order.setdefault(a, len(order))
    ran = {a for g in groups for r in g.runs.values() for a in r.aucs}
    return sorted(ran, key=lambda a: (order.get(a, len(order)), a))


def _differences(
    params: dict[str, str], overrides: str, n_adjectives: int, n_labels: int
) -> tuple[str, ...]:
    out = []
    if params.get("choice.schedule", "paper") != "paper":
        out.append(f"schedule={params['choice.schedule']}")
    if n_adjectives != n_labels:
        out.append(f"{n_adjectives} adjectives")
    for item in overrides.split():
        key = item.lstrip("+~").split("=", 1)[0]
        neutral = any(key == k or key.startswith(f"{k}.") for k in NEUTRAL_OVERRIDES)
        if not neutral and key not in ("adjectives", "schedule"):
            out.append(item)
    return tuple(out)


def _tuned(tags: dict[str, str]) -> tuple[str, ...]:
    """A study's final evaluation says its values were chosen on validation objects."""
    if tags.get("search.role") != "final":
        return ()
    return (f"tuned on validation (study {tags.get('search.study', '?')})",)


def collect(tracker: Tracker, sweep_id: str | None = None, metric: str = "roc_auc") -> list[Group]:
    """Every group of FINISHED parent runs (of one sweep, if given) that logged ``metric``,
    sorted by Table I row."""
    metric_key = METRICS.build(metric).key
    found = tracker.jobs(sweep_id=sweep_id or None)
    groups: dict[str, Group] = {}
    for run in found:
        params, tags, metrics = run.data.params, run.data.tags, run.data.metrics
        # A search trial's job selects on validation objects; its test AUC is no result of its
        # own (the study's one final evaluation, tagged "final", is the tuned row's line).
        if f"mean_{metric_key}" not in metrics or tags.get("search.role") == "trial":
            continue
        prefix = f"{metric_key}."
        aucs = {k.removeprefix(prefix): v for k, v in metrics.items() if k.startswith(prefix)}
        labels = tuple(tags.get("data.labels", "").split())
        key = tags.get("row_hash") or tags["config_hash"]  # runs logged before row_hash existed
        row_hash = key
        experiment = params.get("choice.experiment", "None")
        if experiment != "None":  # a Table I row stays one even if a sweep ran its config
            key = f"{key}:{experiment}"
        if tags.get("data.identity"):  # the same config on changed data is another line
            key = f"{key}@{tags['data.identity']}"
        if key not in groups:
            paper = params.get("paper.auc", "None")
            groups[key] = Group(
                key=key,
                row_hash=row_hash,
                method=experiment
                if experiment != "None"
                else re.sub(r"-s\d+$", "", re.sub(r"-fold=\d+(?=-)", "", run.info.run_name)),
                row=params.get("paper.row", ""),
                paper_auc=None if paper == "None" else float(paper),
                schedule=params.get("choice.schedule", ""),
                schedule_epochs=f"{params['schedule.epochs']}+"
                f"{params['schedule.finetune_epochs']} epochs"
                if "schedule.epochs" in params
                else "",  # a model without epochs logs no schedule
                split=params.get("split.name", ""),
                modality=params.get("modality.name", ""),
                model=params.get("model.name", ""),
                n_adjectives=len(aucs),
                differences=_differences(
                    params, tags.get("overrides", ""), len(aucs), len(labels) or UNTAGGED_LABELS
                )
                + _tuned(tags),
                params=dict(params),
                overrides=dict(
                    item.lstrip("+~").split("=", 1)
                    for item in tags.get("overrides", "").split()
                    if "=" in item
                ),
            )
        entry = Run(
            run_id=run.info.run_id,
            seed=int(params["seed"]),
            start_time=run.info.start_time,
            mean_auc=metrics[f"mean_{metric_key}"],
            aucs=aucs,
            data=tags.get("data.identity", ""),
            sweep_id=tags.get("sweep_id", ""),
            fold=int(params.get("split.fold", -1)),
            folds=int(params.get("split.folds", 0)),
            labels=labels,
            layout=tags.get("data.layout"),
        )
        kept = groups[key].runs.get((entry.seed, entry.fold))
        if kept is None or entry.start_time > kept.start_time:
            groups[key].runs[entry.seed, entry.fold] = entry
    return sorted(
        groups.values(),
        key=lambda g: (g.row or "~", g.method, sorted(g.overrides.items()), g.key),
    )


def skipped_cells(tracker: Tracker, sweep_id: str) -> list[str]:
    """The cells sweep ``sweep_id`` listed invalid and skipped, one line each (``#num cell:
    reason``): the ``invalid`` tag of its ``run_level=sweep`` run (``app.sweep``)."""
    found = tracker.sweep_runs(sweep_id)
    return [line for run in found for line in run.data.tags.get("invalid", "").splitlines()]


def best(groups: list[Group], modalities: tuple[str, ...]) -> Group | None:
    """The group of these modalities with the highest mean AUC, preferring the paper's settings
    (a 2-epoch preset must not stand for a modality when the full row exists)."""
    candidates = [g for g in groups if g.modality in modalities and g.model != "random"]
    preferred = [g for g in candidates if g.at_paper_settings] or candidates
    return max(preferred, key=lambda g: g.aucs.mean(), default=None)


def row_group(groups: list[Group], row: str) -> Group | None:
    """The group that stands for Table I row ``row``: the paper's settings when run, else the
    variant with the most adjectives, then the most recent run."""
    candidates = [g for g in groups if g.row == row]
    return max(
        candidates,
        key=lambda g: (
            g.at_paper_settings,
            g.n_adjectives,
            max(r.start_time for r in g.runs.values()),
        ),
        default=None,
    )

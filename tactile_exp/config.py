"""The edge between Hydra and the core: a resolved config becomes plain, validated settings once.

Everything a job needs is checked here, before any data is read or any model trained, and each
error names the config key and the allowed values.
"""

from __future__ import annotations

import hashlib
import json
import re
from collections.abc import Collection
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

from tactile_exp import docs_test, marks, plugins
from tactile_exp.errors import ConfigError, NotACell
from tactile_exp.registry import Component

DEVICE = re.compile(r"auto|cpu|cuda(:\d+)?")  # what train.resolve_device accepts
# Derived from the settings' marks (tactile_exp/marks.py), where each key says why.
UNHASHED = marks.unhashed()  # left out of the config hash
UNNAMED = marks.unnamed()  # left out of run names and axes
ADDED_AT_DEFAULT = marks.added_at_default()  # left out of the hash at these values
STUDY_ROLES = ("trial", "final")  # study.role: a search trial, or its best values' test run
ADJECTIVES_SPELLED_OUT = 3  # a run name lists at most this many adjectives, else counts them


@dataclass(frozen=True)
class Tracking:
    """Where runs go and how a job uses the runs already there (``conf/tracking/*.yaml``)."""

    uri: str | None
    experiment: str
    skip_finished: bool  # a job already FINISHED on this data file is skipped
    reuse: bool = True  # load a FINISHED run's model of the same training key instead of training
    claim_lease: float = 3600.0  # seconds before another host's training claim counts as abandoned


@dataclass(frozen=True)
class Settings:
    data: Component
    modality: Component
    model: Component
    combiner: str
    combine: int
    split: str
    adjectives: tuple[str, ...] | None  # None: every label of the data set (`select_labels`)
    seed: int
    device: str
    cache_dir: Path
    tracking: Tracking
    choices: dict[str, str]  # config-group choices, e.g. {"model": "haptic_cnn", ...}
    resolved: dict[str, Any]  # the whole resolved config: only logged (params, config.yaml)
    config_hash: str
    row_hash: str  # config_hash with the seed blanked: what the report groups by
    run_name: str
    sweep_id: str = ""
    output_dir: Path | None = None  # Hydra's job folder (holds .hydra/)
    validation_fraction: float = (
        0.0  # training objects held out for val_auc (tactile_exp.validation)
    )
    overrides: tuple[str, ...] = ()  # the job's command-line overrides (Hydra's task overrides)
    workers: int = 1  # processes that train adjectives side by side (tactile_exp.runtime.workers)
    objective: str = "mean_val_auc"  # what the job returns to Hydra (tactile_exp.objective)
    study_tags: dict[str, str] = field(default_factory=dict)  # search.study, search.role, ...
    axes: dict[str, str] = field(default_factory=dict)  # the job's overrides: see ``axes``
    split_params: dict[str, Any] = field(default_factory=dict)  # e.g. folds=5, fold=0
    modules: tuple[str, ...] = ()  # the components' ``_module_``s: see ``component_modules``
    metrics: tuple[str, ...] = ("roc_auc",)  # logged per adjective (tactile_exp.metrics)
    min_objects: int | None = None  # labels.min_objects: see `data.splits.label_splits`
    split_note: str = ""  # split=declared's choice, frozen folds: printed once (`_resolve_split`)

    @property
    def is_trial(self) -> bool:
        """A search trial's job: it logs and shows no test metric (the study's final run does)."""
        return self.study_tags.get("search.role") == "trial"

    @property
    def split_key(self) -> str:
        """The split rule with its parameters: what a stored model's training key records."""
        params = ",".join(f"{k}={v}" for k, v in sorted(self.split_params.items()))
        return f"{self.split}({params})" if params else self.split


def config_hash(resolved: dict[str, Any]) -> str:
    """What makes two jobs the same job: the resolved config without its unhashed keys."""
    kept = {
        k: v
        for k, v in resolved.items()
        if k not in UNHASHED and not (k in ADDED_AT_DEFAULT and v == ADDED_AT_DEFAULT[k])
    }
    return hashlib.sha256(json.dumps(kept, sort_keys=True, default=str).encode()).hexdigest()[:16]


def axes(overrides: tuple[str, ...]) -> dict[str, str]:
    """What this job sets apart from the defaults: ``{"model": "haptic_lstm", "combine": "10",
    "schedule.lr": "0.01"}`` from its command-line overrides (a sweep's swept values are among
    them), without those marked unnamed (``UNNAMED``)."""
    out = {}
    for item in overrides:
        key, _, value = item.partition("=")
        deleted = key.startswith("~")
        key = key.lstrip("+~")
        if re.split(r"[./]", key)[0] not in UNNAMED:
            out[key] = "(deleted)" if deleted else value
    return out


def _group(key: str) -> str:
    """The top-level key or config group an override key sets (``schedule.lr`` -> schedule)."""
    return re.split(r"[./]", key.lstrip("+~"))[0]


def _short(key: str, value: str, groups: Collection[str]) -> str:
    """One axis in a run name: a group's option alone (``logistic``), ``c10`` for combine, the
    adjectives (or their count), else ``leaf=value`` with a file path as its stem."""
    if key == "combine":
        return f"c{value}"
    if key == "adjectives":
        names = [a.strip(" '\"") for a in value.strip("[]").split(",") if a.strip()]
        if len(names) <= ADJECTIVES_SPELLED_OUT:
            return "+".join(names)
        return f"{len(names)}adj-{hashlib.sha256(value.encode()).hexdigest()[:4]}"
    if "/" in value:
        value = Path(value).stem
    return value if key in groups else f"{key.rsplit('.', 1)[-1]}={value}"


def run_name(
    choices: dict[str, str], combiner: str, combine: int, seed: int, job_axes: dict[str, str]
) -> str:
    """The Table I row (or model, combiner and combine), then every other axis the job sets,
    then the seed: the jobs of one sweep differ in some axis, so their names differ too."""
    experiment = choices.get("experiment")
    if experiment and experiment != "None":
        parts, named = [experiment], {"experiment", "seed"}
    else:
        parts = [choices["model"], combiner, f"c{combine}"]
        named = {"model", "combine_instances", "combine", "seed"}
    parts += [_short(k, v, choices) for k, v in job_axes.items() if k not in named]
    return "-".join([*parts, f"s{seed}"])


def _component(node: Any, group: str) -> Component:
    """``name`` picks the registry entry; ``_module_`` (optional) names a module to import first
    that registers it, so a component outside the package needs only its module and its YAML."""
    if not isinstance(node, dict) or "name" not in node:
        raise ConfigError(f"{group}: expected a mapping with a 'name' key, got {node!r}")
    try:
        plugins.import_modules({group: {"_module_": node.get("_module_")}}, "config")
    except plugins.PluginError as err:
        raise ConfigError(str(err).removeprefix("config: ")) from None
    params = {k: v for k, v in node.items() if k not in ("name", "_module_")}
    return Component(str(node["name"]), params)


def component_modules(resolved: dict[str, Any]) -> tuple[str, ...]:
    """Every ``_module_`` of the config (``plugins.modules``): a spawned worker process
    (``tactile_exp.runtime.workers``) imports them again, as the config check did here."""
    return tuple(dict.fromkeys(plugins.modules(resolved).values()))


def unread_groups(model: Component) -> tuple[str, ...]:
    """The groups among ``marks.MODEL_GROUPS`` (schedule, loss) that ``model`` does not read
    (``Model.reads``): a job leaves them out of its hash, run name and logged config."""
    from tactile_exp.models.registry import MODELS

    if model.name not in MODELS:
        return ()  # check_components says the name is unknown
    reads = MODELS[model.name].reads
    return tuple(g for g in marks.MODEL_GROUPS if g not in reads)


def _check_tracking(tracking: Any) -> Tracking:
    """The tracking group, checked before any run: a value a running job would only read
    later (``reuse`` per adjective, ``claim_lease`` while waiting) fails here, not there."""
    if not isinstance(tracking, dict):
        raise ConfigError(f"tracking: expected a mapping (conf/tracking/*.yaml), got {tracking!r}")
    experiment = tracking.get("experiment")
    if isinstance(experiment, bool) or not isinstance(experiment, str | int) or experiment == "":
        raise ConfigError(
            f"tracking.experiment: must name an MLflow experiment, got {experiment!r}"
        )
    for key in ("skip_finished", "reuse"):
        if not isinstance(tracking.get(key, True), bool):
            raise ConfigError(f"tracking.{key}: must be true or false, got {tracking[key]!r}")
    lease = tracking.get("claim_lease", Tracking.claim_lease)
    if isinstance(lease, bool) or not isinstance(lease, int | float) or not lease > 0:
        raise ConfigError(f"tracking.claim_lease: must be a number of seconds > 0, got {lease!r}")
    uri = tracking.get("uri")
    return Tracking(
        uri=None if uri is None else str(uri),
        experiment=str(experiment),
        skip_finished=tracking.get("skip_finished", True),
        reuse=tracking.get("reuse", True),
        claim_lease=float(lease),
    )


def _check_missing(node: Any, prefix: str = "") -> None:
    """A mandatory value left at ``???`` (e.g. ``data=phac2`` without ``data.path``)."""
    if isinstance(node, dict):
        for key, value in node.items():
            _check_missing(value, f"{prefix}{key}.")
    elif node == "???":
        key = prefix.rstrip(".")
        raise ConfigError(f"{key}: missing; set it on the command line, e.g. {key}=...")


def _check_schedule(node: Any) -> None:
    """The ``schedule`` node the SGD-trained models take whole (``schedule: ${schedule}``),
    checked where the user sets it: ``schedule.lr``, not the model's copy."""
    from tactile_exp.models.schedule import Schedule, ScheduleError

    try:
        Schedule.of(node)
    except ScheduleError as err:
        raise ConfigError(str(err)) from err


def _check_data(data: Any) -> None:
    """The data's file or folder must exist before a run is created for it."""
    from tactile_exp.data.sources import check_source_params

    if isinstance(data, dict):
        try:
            check_source_params(str(data.get("name")), data)
        except ValueError as err:
            raise ConfigError(f"data.{err}") from err


def param_error(group: str, params: dict[str, Any], err: Exception) -> ConfigError:
    """A component's ValueError as ``group.key: ...`` when it names one of its parameters."""
    message = str(err)
    words = message.replace("=", " ").replace(":", " ").split()
    first = words[0] if words else ""
    if first == "device" or message.startswith("device="):
        return ConfigError(f"device: {message}")
    if first in params:
        return ConfigError(f"{group}.{first}: {message}")
    return ConfigError(f"{group}: {message}")


def settings_from_config(
    cfg: DictConfig,
    choices: dict[str, str] | None = None,
    sweep_id: str = "",
    output_dir: Path | None = None,
    overrides: tuple[str, ...] = (),
) -> Settings:
    """Resolve ``cfg`` and validate every value a job depends on."""
    cfg = docs_test.shorten(cfg)  # a no-op outside the documentation's command test
    ours = OmegaConf.masked_copy(cfg, [k for k in cfg if k != "hydra"])  # hydra.* is Hydra's
    resolved: dict[str, Any] = OmegaConf.to_container(ours, resolve=True)  # type: ignore[assignment]
    # A Table I row is its config up to the seed (and every value interpolating it): runs that
    # differ only in seed, or with split=random in the split it draws, repeat one row.
    unseeded = OmegaConf.masked_copy(ours, list(ours))
    unseeded.seed = None
    if "fold" in unseeded.split:  # split=folds: a seed's folds together are one repeat
        unseeded.split.fold = None
    row_config: dict[str, Any] = OmegaConf.to_container(unseeded, resolve=True)  # type: ignore[assignment]
    check_marked(resolved)
    choices = dict(choices or {})
    for group in ("data", "modality", "model", "combine_instances", "split"):
        choices.setdefault(group, str(resolved[group]["name"]))

    adjectives = _check_adjectives(resolved.get("adjectives"))

    combine = resolved.get("combine")
    if not isinstance(combine, int) or isinstance(combine, bool) or combine < 1:
        raise ConfigError(f"combine: must be a whole number of trials >= 1, got {combine!r}")
    combiner = str(resolved["combine_instances"]["name"])
    if combiner == "separate" and combine != 1:
        raise ConfigError(
            "combine: combine_instances=separate scores every instance on its own; "
            f"it takes combine=1, got {combine}"
        )
    device = resolved.get("device")
    if not isinstance(device, str) or not DEVICE.fullmatch(device):
        raise ConfigError(f"device: must be auto, cpu, cuda or cuda:N, got {device!r}")
    seed = resolved.get("seed")
    if not isinstance(seed, int) or isinstance(seed, bool) or not 0 <= seed < 2**32:
        raise ConfigError(f"seed: must be a whole number in 0..2**32-1, got {seed!r}")
    workers = resolved.get("workers", 1)
    if not isinstance(workers, int) or isinstance(workers, bool) or workers < 1:
        raise ConfigError(f"workers: must be a whole number of processes >= 1, got {workers!r}")
    _check_missing(resolved)
    _check_data(resolved["data"])
    _check_schedule(resolved.get("schedule"))

    fraction = (resolved.get("validation") or {}).get("fraction", 0.0)
    if isinstance(fraction, bool) or not isinstance(fraction, int | float) or not 0 <= fraction < 1:
        raise ConfigError(f"validation.fraction: must be a number in [0, 1), got {fraction!r}")

    min_objects = (resolved.get("labels") or {}).get("min_objects")
    if min_objects is not None and (
        isinstance(min_objects, bool) or not isinstance(min_objects, int) or min_objects < 1
    ):
        raise ConfigError(
            f"labels.min_objects: must be null (refuse labels the split cannot evaluate) or a "
            f"whole number of objects >= 1 per class, got {min_objects!r}"
        )
    split_note = _resolve_split(resolved, row_config, adjectives, min_objects)
    if resolved["split"]["name"] != choices["split"]:
        choices["split"] = str(resolved["split"]["name"])
    objective = _check_objective(resolved.get("objective", "mean_val_auc"))
    metrics = _check_metrics(resolved.get("metrics", ["roc_auc"]))
    study_tags = _check_study(resolved.get("study") or {}, float(fraction))

    tracking = _check_tracking(resolved.get("tracking"))
    data = _component(resolved["data"], "data")
    modality = _component(resolved["modality"], "modality")
    model = _component(resolved["model"], "model")
    unread = unread_groups(model)
    for group in unread:  # no value of it reaches the model: it is not part of the job
        resolved.pop(group, None)
        row_config.pop(group, None)
        choices.pop(group, None)
    job_axes = {k: v for k, v in axes(overrides).items() if _group(k) not in unread}
    overrides = tuple(o for o in overrides if _group(o.partition("=")[0]) not in unread)
    if split_note and "split" not in job_axes:  # named as with the chosen split given
        job_axes["split"] = choices["split"]
        if "folds" in resolved["split"]:
            job_axes["split.folds"] = str(resolved["split"]["folds"])
    settings = Settings(
        data=data,
        modality=modality,
        model=model,
        combiner=combiner,
        combine=combine,
        split=str(resolved["split"]["name"]),
        adjectives=adjectives,
        seed=seed,
        device=device,
        cache_dir=Path(str(resolved["cache_dir"])).expanduser(),
        tracking=tracking,
        choices=choices,
        resolved=resolved,
        config_hash=config_hash(resolved),
        row_hash=config_hash(row_config),
        run_name=run_name(choices, combiner, combine, seed, job_axes),
        sweep_id=sweep_id,
        output_dir=output_dir,
        validation_fraction=float(fraction),
        overrides=overrides,
        workers=workers,
        objective=objective,
        study_tags=study_tags,
        axes=job_axes,
        split_params={k: v for k, v in resolved["split"].items() if k != "name"},
        modules=component_modules(resolved),
        metrics=metrics,
        min_objects=min_objects,
        split_note=split_note,
    )
    check_components(settings)
    return settings


def _resolve_split(
    resolved: dict[str, Any],
    row_config: dict[str, Any],
    adjectives: tuple[str, ...] | None,
    min_objects: int | None,
) -> str:
    """``split=declared`` (and a folds split's frozen folds) resolved by the data source
    (`tactile_exp.data.sources.resolve_split`) in the config and its row, before either is
    hashed: the job is hashed and named by the split it runs. Returns what to print once."""
    from tactile_exp.data.sources import DATA_SOURCES, resolve_split
    from tactile_exp.data.splits import DECLARED

    node = resolved.get("split")
    if not isinstance(node, dict) or not isinstance(resolved.get("data"), dict):
        return ""
    data = _component(resolved["data"], "data")  # imports a plugin source's module
    if data.name not in DATA_SOURCES:
        return ""  # check_components names the unknown source
    declared = node.get("name") == DECLARED
    fold = node.get("fold", 0) if declared else None
    try:
        new, note = resolve_split(data.name, data.params, node, adjectives, min_objects)
    except TypeError as err:
        raise param_error("data", data.params, err) from err
    if declared:
        new = _declared_fold(new, fold)
    resolved["split"] = new
    row_config["split"] = {**new, "fold": None} if "fold" in new else dict(new)
    return note


def _declared_fold(node: dict[str, Any], fold: Any) -> dict[str, Any]:
    """``split=declared``'s ``split.fold`` on the split the data set declares: a fold of its
    folds, or 0 where it declares one test side (PHAC-2's published split). A fold beyond them
    is no cell of a sweep over data sets (`NotACell`), not a mistake."""
    if not isinstance(fold, int) or isinstance(fold, bool) or fold < 0:
        raise ConfigError(f"split.fold: expected a whole number >= 0, got {fold!r}")
    if node["name"] != "folds":
        if fold:
            raise NotACell(
                f"split.fold={fold}: the data set declares split={node['name']}, one test side "
                "(split.fold=0)"
            )
        return node
    if fold >= int(node["folds"]):
        raise NotACell(
            f"split.fold={fold}: the data set declares {node['folds']} folds "
            f"(0..{node['folds'] - 1})"
        )
    return {**node, "fold": fold}


def check_marked(resolved: dict[str, Any]) -> None:
    """Every top-level key has a mark (``tactile_exp/marks.py``): an unmarked key would change
    the config hash, run names and a search's space without anyone deciding whether it should."""
    unmarked = [k for k in resolved if k not in marks.MARKS]
    if unmarked:
        raise ConfigError(
            f"{unmarked[0]}: not a setting of tactile_exp; a new top-level key is declared in "
            "conf/config.yaml and marked in tactile_exp/marks.py (docs/configuration.md)"
        )


def _check_adjectives(value: Any) -> tuple[str, ...] | None:
    """``null`` (every label of the data set) or a list of label names, each once; which names
    exist is the data set's to say (`tactile_exp.data.dataset.select_labels`, when it opens)."""
    if value is None:
        return None
    if not isinstance(value, list) or not value:
        raise ConfigError(
            f"adjectives: must list at least one label, or be null for all of them, got {value!r}"
        )
    names = [str(a) for a in value]
    if len(set(names)) != len(names):
        raise ConfigError(f"adjectives: listed twice in {names}")
    return tuple(names)


def _check_objective(name: Any) -> str:
    """A validation metric: the value Hydra gets never depends on a test object's score."""
    from tactile_exp.objective import OBJECTIVES, TEST_METRICS

    if name in OBJECTIVES:
        return str(name)
    known = ", ".join(OBJECTIVES.names())
    if isinstance(name, str) and name.split(".")[0] in TEST_METRICS:
        raise ConfigError(
            f"objective: {name} is scored on the test objects; what a job returns to Hydra (and "
            f"a search selects on) must be a validation metric: {known}"
        )
    raise ConfigError(f"objective: unknown {name!r}; allowed: {known}")


def _check_metrics(names: Any) -> tuple[str, ...]:
    """Registered metrics, each once, roc_auc among them (mean_auc and the report rest on it)."""
    from tactile_exp.metrics import METRICS

    known = ", ".join(METRICS.names())
    if not isinstance(names, list) or not names:
        raise ConfigError(f"metrics: must be a list of metric names from {known}, got {names!r}")
    unknown = [n for n in names if not isinstance(n, str) or n not in METRICS]
    if unknown:
        raise ConfigError(f"metrics: unknown {unknown}; known metrics: {known}")
    if len(set(names)) != len(names):
        raise ConfigError(f"metrics: listed twice in {names}")
    if "roc_auc" not in names:
        raise ConfigError(
            f"metrics: {names} leaves out roc_auc, the paper's E2 (mean_auc, its interval and "
            "the report's default rest on it); list it, e.g. [roc_auc, f1]"
        )
    return tuple(names)


def _check_study(study: dict[str, Any], fraction: float) -> dict[str, str]:
    """The search tags of a job; a search trial needs validation objects to be scored on."""
    name, role, trial = study.get("name"), study.get("role"), study.get("trial")
    if role is not None and role not in STUDY_ROLES:
        raise ConfigError(f"study.role: must be one of {', '.join(STUDY_ROLES)}, got {role!r}")
    if role is not None and not name:
        raise ConfigError(f"study.name: missing; a job with study.role={role} names its study")
    if role == "trial" and fraction == 0:
        raise ConfigError(
            f"validation.fraction: 0 holds out no validation objects, but study {name!r} selects "
            "on them (its objective is a validation metric, never the test AUC); "
            "set validation.fraction in (0, 1), e.g. 0.15"
        )
    if name is None:
        return {}
    tags = {"search.study": str(name), "search.role": str(role or "")}
    if trial is not None:
        tags["search.trial"] = str(trial)
    return tags


def check_components(settings: Settings) -> None:
    """Every named component exists and accepts its parameters (models built once, untrained)."""
    from tactile_exp.combine import COMBINERS
    from tactile_exp.data.sources import DATA_SOURCES
    from tactile_exp.data.splits import SPLITS, check_split_params
    from tactile_exp.modalities import MODALITIES
    from tactile_exp.models.registry import MODELS
    from tactile_exp.models.schedule import STEPS, ScheduleError

    if settings.device.startswith("cuda"):
        from tactile_exp.train import resolve_device

        try:
            resolve_device(settings.device)
        except ValueError as err:
            raise ConfigError(f"device: {err}") from err
    for key, registry, name in (
        ("data", DATA_SOURCES, settings.data.name),
        ("modality", MODALITIES, settings.modality.name),
        ("model", MODELS, settings.model.name),
        ("combine_instances", COMBINERS, settings.combiner),
        ("split", SPLITS, settings.split),
    ):
        if name not in registry:
            known = ", ".join(registry.names())
            raise ConfigError(f"{key}: unknown option {name!r}; known: {known}")
    try:
        check_split_params(settings.split, settings.split_params)
    except ValueError as err:
        raise ConfigError(f"split.{err}") from err
    schedule = settings.model.params.get("schedule")
    if isinstance(schedule, dict) and not set(STEPS) <= set(schedule):
        missing = ", ".join(k for k in STEPS if k not in schedule)
        raise ConfigError(  # e.g. ++model.schedule.lr=0.5 replaced the whole ${schedule} node
            f"model.schedule: missing {missing}; the model takes the schedule node whole: set "
            "schedule.<key> (e.g. schedule.lr=0.05), not model.schedule.<key>"
        )
    try:
        model = MODELS.build(settings.model.name, **settings.model.params)
    except ScheduleError as err:  # a model's own schedule (visual_googlenet's step)
        raise ConfigError(f"model.{err}") from err
    except (TypeError, ValueError) as err:
        raise param_error("model", settings.model.params, err) from err
    if not COMBINERS[settings.combiner].keeps_instances:
        _check_head(settings.model.name, model)
    steps = settings.modality.params.get("steps")
    if isinstance(steps, int) and steps >= 1:
        try:
            model.check_steps(steps)
        except ValueError as err:
            message = f"modality.steps: {steps} with model={settings.model.name}: {err}"
            raise ConfigError(message) from err
    emits = MODALITIES[settings.modality.name].emits
    if model.accepts and emits and emits not in model.accepts:
        raise ConfigError(_kind_mismatch(settings, model.accepts, emits))


def _check_head(name: str, model: Any) -> None:
    """A storable head (combined instances) must be a registered model: the stored pipeline
    names it by its registry name, and loading builds it from that name."""
    from tactile_exp import artifacts

    try:
        head = model.head()
    except NotImplementedError as err:
        raise ConfigError(f"combine_instances: model={name} has no head: {err}") from None
    if not head.storable:
        return
    try:
        artifacts.model_name(head)
    except KeyError:
        cls = type(head)
        raise ConfigError(
            f"model: model={name}'s head() gives a {cls.__module__}.{cls.__qualname__}, which is "
            "not a registered model, so a stored pipeline could not name it; register it "
            "(@MODELS.register) or return a registered model from head()"
        ) from None


def _kind_mismatch(settings: Settings, accepts: tuple[str, ...], emits: str) -> str:
    """One line: the model takes other rows than the modality gives; modalities that fit."""
    from tactile_exp.data.layout import INSTANCE_KINDS
    from tactile_exp.modalities import MODALITIES

    fits = [n for n in MODALITIES.names() if MODALITIES[n].emits in accepts]
    takes = " or ".join(INSTANCE_KINDS.get(k, k) for k in accepts)
    return (
        f"modality: model={settings.model.name} takes {takes}, modality="
        f"{settings.modality.name} gives {INSTANCE_KINDS.get(emits, emits)}; "
        f"modality={' or '.join(fits)} would fit"
    )


def check_data_chain(settings: Settings, dataset: Any, modality: Any) -> None:
    """Data set -> modality -> model, once the data opens and before any run: the modality
    gets what it needs from the data set (declared: `Modality.lacks`) and the model takes
    what the modality gives on it (`Model.accepts`, `Model.check_input`); else one
    ConfigError naming the key and a value that would work."""
    from tactile_exp.modalities import MODALITIES
    from tactile_exp.models.registry import MODELS

    model_cls = MODELS[settings.model.name]
    lacking = modality.lacks(dataset)
    if lacking is not None:
        fits = [
            n
            for n in MODALITIES.names()
            if MODALITIES[n].lacks(dataset) is None
            and (not model_cls.accepts or MODALITIES[n].emits in model_cls.accepts)
        ]
        advice = (
            f"modality={' or '.join(fits)} would fit"
            if fits
            else (f"no modality fits it with model={settings.model.name}")
        )
        raise NotACell(
            f"modality: modality={settings.modality.name} needs {lacking}, which {dataset.path} "
            f"({dataset.sensor.describe()}) does not give; {advice}"
        )
    spec = modality.output(dataset)
    if model_cls.accepts and spec.kind not in model_cls.accepts:
        raise ConfigError(_kind_mismatch(settings, model_cls.accepts, spec.kind))
    model = MODELS.build(settings.model.name, **settings.model.params)
    try:
        model.check_input(spec)
    except ValueError as err:
        where = f" (modality={settings.modality.name} on {dataset.path})"
        raise param_error("model", settings.model.params, ValueError(f"{err}{where}")) from err

"""Every YAML composes and builds; option names are registry names; bad values fail early."""

import inspect
import os
import re
import subprocess
import sys
from fnmatch import fnmatch
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import TINY_DATA
from hydra import compose, initialize_config_dir
from hydra.errors import MissingConfigException
from mlflow.tracking import MlflowClient
from omegaconf import OmegaConf

from tactile_exp.combine import COMBINERS
from tactile_exp.config import settings_from_config
from tactile_exp.data.dataset import Sensor
from tactile_exp.data.folder import write_folder
from tactile_exp.data.layout import DataError
from tactile_exp.data.sources import DATA_SOURCES
from tactile_exp.data.splits import SPLITS
from tactile_exp.errors import ConfigError
from tactile_exp.modalities import MODALITIES
from tactile_exp.models import MODELS
from tactile_exp.models.losses import LOSSES

CONF = Path(__file__).resolve().parents[1] / "conf"

REGISTRIES = {
    "data": DATA_SOURCES,
    "modality": MODALITIES,
    "model": MODELS,
    "loss": LOSSES,
    "combine_instances": COMBINERS,
    "split": SPLITS,
}


def _options(group: str) -> list[str]:
    return sorted(p.stem for p in (CONF / group).glob("*.yaml"))


def _model_for(modality: str) -> str:
    """The default model if it takes ``modality``, else the first registered one that does."""
    emits = MODALITIES[modality].emits
    takes = [n for n in MODELS.names() if emits in MODELS[n].accepts]
    takes_any = [n for n in MODELS.names() if not MODELS[n].accepts]
    return "haptic_cnn" if "haptic_cnn" in takes else (takes or takes_any)[0]


def _name(group: str, option: str) -> str:
    """The registered component an option builds: its YAML's ``name``."""
    return yaml.safe_load((CONF / group / f"{option}.yaml").read_text())["name"]


@pytest.mark.parametrize("group", sorted(REGISTRIES))
def test_option_names_equal_registry_names(group):
    """Each registered component has the option of its name; any other option configures a
    registered one (model=minirocket is model=estimator with aeon's MiniRocket)."""
    named = {o: _name(group, o) for o in _options(group)}
    assert sorted(o for o, n in named.items() if o == n) == REGISTRIES[group].names()
    assert set(named.values()) <= set(REGISTRIES[group].names())


def _cases() -> list:
    cases = [(g, o) for g in sorted(REGISTRIES) for o in _options(g)]
    cases += [("experiment", o) for o in _options("experiment")]
    cases += [("sweep", o) for o in _options("sweep")]
    return cases


def _folder(root: Path) -> Path:
    """A data set in the folder layout: 4 objects, two labels of 2 positive objects each."""
    labels = {f"o{i}": {"a": i % 2, "b": i // 2} for i in range(4)}
    trials = {o: [np.zeros((2, 5))] * 2 for o in labels}
    return write_folder(root / "ds", Sensor("s", ("c0", "c1"), 10.0), labels, trials)


@pytest.mark.parametrize("group,option", _cases())
def test_every_option_composes_and_builds(compose_config, group, option, tmp_path):
    overrides = [f"{group}={option}"]
    if group == "data" and option == "phac2":
        (tmp_path / "phac.h5").touch()  # only its existence is checked before a job
        overrides.append(f"data.path={tmp_path / 'phac.h5'}")
    folder = (group, option) in (("data", "folder"), ("sweep", "benchmark"))
    if folder:  # opened before a job: split=declared asks it
        overrides.append(f"data.path={_folder(tmp_path)}")
    if group == "modality":
        overrides.append(f"model={_model_for(option)}")
    if group == "model" and MODELS[_name(group, option)].accepts:
        accepts = MODELS[_name(group, option)].accepts
        fits = [m for m in MODALITIES.names() if MODALITIES[m].emits in accepts]
        overrides.append(f"modality={fits[-1]}")
    cfg = compose_config(overrides)
    settings = settings_from_config(cfg)  # builds the model through its registry
    if group in REGISTRIES:
        assert cfg[group].name == _name(group, option)
    if group == "experiment":
        _assert_experiment_applied(compose_config, cfg, option)
    for component, registry in (
        (settings.data, DATA_SOURCES),
        (settings.modality, MODALITIES),
    ):
        extra = {"cache_dir": None} if registry is MODALITIES else {}
        inspect.signature(registry[component.name]).bind(**extra, **component.params)
    assert cfg.loss.name in LOSSES


def _leaves(node: dict, prefix: str = "") -> dict[str, object]:
    out: dict[str, object] = {}
    for key, value in node.items():
        if isinstance(value, dict):
            out |= _leaves(value, f"{prefix}{key}.")
        else:
            out[f"{prefix}{key}"] = value
    return out


def _assert_experiment_applied(compose_config, cfg, option: str) -> None:
    """Every group the experiment file overrides, and every value it sets, is in the config."""
    text = yaml.safe_load((CONF / "experiment" / f"{option}.yaml").read_text())
    for entry in text.pop("defaults", []):
        [(key, chosen)] = entry.items()
        group = key.removeprefix("override /")
        alone = compose_config([f"{group}={chosen}"])[group]
        if "name" in alone:
            assert cfg[group].name == alone.name, (option, group)
        else:
            assert cfg[group] == alone, (option, group)
    for key, value in _leaves(text).items():
        if isinstance(value, str) and value.startswith("${"):
            continue  # an interpolation: its target is checked where it is set
        assert OmegaConf.select(cfg, key) == value, (option, key)


def test_table1_sweep_runs_every_row_and_nothing_else():
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose("config", overrides=["sweep=table1"], return_hydra_config=True)
    pattern = cfg.hydra.sweeper.params.experiment
    assert pattern.startswith("glob(") and pattern.endswith(")")
    matched = {o for o in _options("experiment") if fnmatch(o, pattern[5:-1])}
    assert matched == {o for o in _options("experiment") if re.fullmatch(r"table1_[a-z]_.+", o)}
    assert len(matched) >= 13 and "quick_table1_i" not in matched


def test_tracking_options(compose_config, monkeypatch):
    assert _options("tracking") == ["local", "server"]
    monkeypatch.delenv("MLFLOW_TRACKING_URI", raising=False)
    local = settings_from_config(compose_config(["tracking=local"])).tracking
    assert local.uri is None and local.skip_finished  # resolve_uri: env, else the checkout
    server = settings_from_config(compose_config(["tracking=server"])).tracking
    assert server.uri == "http://127.0.0.1:5000" and server.experiment == "tactile_exp"
    monkeypatch.setenv("MLFLOW_TRACKING_URI", "http://tracking.example:5000")
    server = settings_from_config(compose_config(["tracking=server"])).tracking
    assert server.uri == "http://tracking.example:5000"


def test_tracking_switches_are_typed_settings(compose_config):
    """What a job reads of ``tracking`` is in ``Settings.tracking``, the YAML's values or, for a
    tracking YAML of one's own that lacks them, the defaults."""
    tracking = settings_from_config(compose_config()).tracking
    assert (tracking.reuse, tracking.claim_lease, tracking.skip_finished) == (True, 3600.0, True)
    changed = ["tracking.reuse=false", "tracking.claim_lease=60", "tracking.skip_finished=false"]
    tracking = settings_from_config(compose_config(changed)).tracking
    assert (tracking.reuse, tracking.claim_lease, tracking.skip_finished) == (False, 60.0, False)
    assert isinstance(tracking.claim_lease, float)
    lacking = ["~tracking.reuse", "~tracking.claim_lease", "~tracking.skip_finished"]
    tracking = settings_from_config(compose_config(lacking)).tracking
    assert (tracking.reuse, tracking.claim_lease, tracking.skip_finished) == (True, 3600.0, True)


@pytest.mark.parametrize(
    ("override", "line"),
    [
        ("tracking.reuse=maybe", "tracking.reuse: must be true or false, got 'maybe'"),
        ("tracking.reuse=1", "tracking.reuse: must be true or false, got 1"),
        ("tracking.skip_finished=no", "tracking.skip_finished: must be true or false, got 'no'"),
        ("tracking.claim_lease=0", "tracking.claim_lease: must be a number of seconds > 0, got 0"),
        (
            "tracking.claim_lease=-5",
            "tracking.claim_lease: must be a number of seconds > 0, got -5",
        ),
        (
            "tracking.claim_lease=long",
            "tracking.claim_lease: must be a number of seconds > 0, got 'long'",
        ),
        (
            "tracking.claim_lease=true",
            "tracking.claim_lease: must be a number of seconds > 0, got True",
        ),
        ("tracking.experiment=''", "tracking.experiment: must name an MLflow experiment, got ''"),
    ],
)
def test_tracking_values_fail_at_the_config_edge(compose_config, override, line):
    with pytest.raises(ConfigError) as err:
        settings_from_config(compose_config([override]))
    assert str(err.value).startswith(line) and "\n" not in str(err.value)


@pytest.mark.slow  # a `python -m tactile_exp` process: Hydra's start, ~5 s
def test_a_bad_reuse_value_is_refused_before_any_run(tmp_path, mlflow_uri):
    """``tracking.reuse`` is read per adjective inside a job: a typo must stop the command with
    one error line before any run exists, not fail the job's runs one by one."""
    env = {**os.environ, "HYDRA_FULL_ERROR": "0"}
    args = [*TINY_DATA, "model=random", "combine_instances=separate", "adjectives=[hard]"]
    args += [f"tracking.uri={mlflow_uri}", f"hydra.run.dir={tmp_path / 'run'}"]
    done = subprocess.run(
        [sys.executable, "-m", "tactile_exp", *args, "tracking.reuse=maybe"],
        capture_output=True,
        text=True,
        timeout=180,
        env=env,
    )
    assert done.returncode == 2
    errors = [line for line in done.stderr.splitlines() if "Warning" not in line]
    assert errors == ["error: tracking.reuse: must be true or false, got 'maybe'"]
    client = MlflowClient(mlflow_uri)
    assert [e.name for e in client.search_experiments()] == ["Default"]  # no experiment, no run
    assert not client.search_runs(["0"])


def test_component_modules_are_settings(compose_config):
    """A component's ``_module_`` (imported again by each worker process) is a setting."""
    settings = settings_from_config(compose_config(["+model._module_=tactile_exp.models.sgd"]))
    assert settings.modules == ("tactile_exp.models.sgd",)
    assert "_module_" not in settings.model.params
    assert settings_from_config(compose_config()).modules == ()


def test_experiments_read_like_table1(compose_config):
    rows = {p.stem.split("_")[1] for p in (CONF / "experiment").glob("table1_*.yaml")}
    assert rows == set("abcdefghijklmno")
    m = settings_from_config(compose_config(["experiment=table1_m_multimodal_i_l"]))
    n = settings_from_config(compose_config(["experiment=table1_n_multimodal_j_l"]))
    for row, trials in ((m, 1), (n, 10)):
        assert (row.modality.name, row.model.name, row.combiner) == (
            "multimodal",
            "linear",
            "separate",
        )
        assert row.modality.params["trials"] == trials and row.model.params["pretrain_loss"] is None
    j = settings_from_config(compose_config(["experiment=table1_j_haptic_cnn_10trials"]))
    assert (j.model.name, j.combiner, j.combine) == ("haptic_cnn", "concat", 10)
    a = settings_from_config(compose_config(["experiment=table1_a_haptic_static_1trial"]))
    assert (a.model.name, a.modality.params["features"]) == ("linear_svm", ["static"])


def test_defaults_are_the_paper_settings(compose_config):
    s = settings_from_config(compose_config())
    p = s.model.params
    step = p["schedule"]
    assert (step["epochs"], step["batch_size"], step["lr"], step["momentum"]) == (
        200,
        1000,
        0.01,
        0.9,
    )
    assert (p["loss"], p["pretrain_loss"]) == ("hinge", "logistic")
    assert s.adjectives is None  # every label of the data set: PHAC-2's 24 adjectives
    assert s.run_name == "haptic_cnn-concat-c1-s0"


def test_config_hash_ignores_tracking_only(compose_config):
    base = settings_from_config(compose_config()).config_hash
    assert settings_from_config(compose_config(["tracking.uri=sqlite:///x.db"])).config_hash == base
    assert settings_from_config(compose_config(["seed=1"])).config_hash != base


@pytest.mark.parametrize(
    "override,message",
    [
        ("combine=0", "combine: must be a whole number of trials >= 1"),
        ("combine=1.5", "combine: must be a whole number"),
        ("adjectives=[]", "adjectives: must list at least one label, or be null"),
        ("adjectives=hard", "adjectives: must list at least one label, or be null"),
        ("adjectives=[hard,soft,hard]", "adjectives: listed twice"),
        ("device=tpu", "device: must be auto, cpu, cuda or cuda:N"),
        ("schedule.lr=0", "schedule.lr: lr must be > 0 and finite, got 0"),
        ("schedule.lr=-1", "schedule.lr: lr must be > 0 and finite, got -1"),
        ("schedule.epochs=0", "schedule.epochs: epochs must be an int >= 1, got 0"),
        ("schedule.head.lr=0", "schedule.head.lr: lr must be > 0"),
        (
            "modality=visual",
            "modality: model=haptic_cnn takes (channels, time) signals, modality=visual gives "
            "feature vectors; modality=haptic or signals would fit",
        ),
        ("seed=-1", "seed: must be a whole number in 0..2**32-1, got -1"),
        ("model.kernel_sizes=[5,0,5]", "model.kernel_sizes: kernel_sizes must be >= 1"),
        ("data=phac2", "data.path: missing; set it on the command line"),
        ("data=phac2 data.path=/no/such.h5", "data.path: /no/such.h5: no such file"),
        ("schedule.head.batch_size=0", "schedule.head.batch_size: batch_size must be an int >= 1"),
        ("+schedule.epoch=2", "schedule.epoch: unknown key; allowed: epochs, finetune_epochs,"),
        (  # Hydra's ++ replaces the interpolated node: refused, not trained for 200 epochs
            "++model.schedule.lr=0.5",
            "model.schedule: missing epochs, finetune_epochs, batch_size, momentum; the model",
        ),
        (
            "model=visual_googlenet modality=visual model.schedule.lr=0",
            "model.schedule.lr: lr must be > 0 and finite, got 0",
        ),
    ],
)
def test_impossible_values_fail_naming_the_key(compose_config, override, message):
    """A ConfigError of one line that starts with the key, not any error mentioning it."""
    with pytest.raises(ConfigError) as err:
        settings_from_config(compose_config(override.split()))
    assert str(err.value).startswith(message) and "\n" not in str(err.value)


def test_an_unknown_group_option_is_hydras_own_error(compose_config):
    with pytest.raises(MissingConfigException, match="Could not find 'model/nope'"):
        compose_config(["model=nope"])


def test_separate_takes_one_trial(compose_config):
    with pytest.raises(ConfigError, match="combine_instances=separate"):
        settings_from_config(
            compose_config(["experiment=table1_h_haptic_cnn_separate", "combine=10"])
        )


def test_one_trunk_override_reaches_every_visual_row(compose_config):
    """-m sweep=table1 trunk.weights=FILE trunk.layout=caffe: K, L, M and N all get the file."""
    trunk = ["trunk.weights=/weights/material.pth", "trunk.layout=caffe"]
    for row, node in (
        ("table1_k_image_googlenet_1view", "modality"),
        ("table1_l_image_googlenet_8views", "modality"),
        ("table1_m_multimodal_i_l", "modality.visual"),
        ("table1_n_multimodal_j_l", "modality.visual"),
    ):
        visual = OmegaConf.select(compose_config([f"experiment={row}", *trunk]), node)
        assert (visual.weights, visual.layout) == ("/weights/material.pth", "caffe"), row
    one_job = compose_config(["experiment=table1_l_image_googlenet_8views", "modality.weights=w"])
    assert one_job.modality.weights == "w"
    for row, changes in (
        ("table1_a_haptic_static_1trial", False),
        ("table1_m_multimodal_i_l", True),
    ):
        plain = settings_from_config(compose_config([f"experiment={row}"]))
        given = settings_from_config(compose_config([f"experiment={row}", *trunk]))
        assert (given.config_hash != plain.config_hash) is changes, row  # resume skips A
        assert (given.row_hash != plain.row_hash) is changes, row


SWEEP_16 = [  # the ablation: -m model=... loss=... combine_instances=... combine=1,10
    [f"model={m}", f"loss={lo}", f"combine_instances={ci}", f"combine={c}"]
    for m in ("haptic_cnn", "haptic_lstm")
    for lo in ("hinge", "logistic")
    for ci in ("concat", "mean")
    for c in (1, 10)
]


def _job(overrides: list[str]):
    """Settings as ``python -m tactile_exp`` builds them: Hydra's choices and task overrides."""
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose("config", overrides=overrides, return_hydra_config=True)
    hc = cfg.hydra
    choices = {k: str(v) for k, v in hc.runtime.choices.items() if not k.startswith("hydra")}
    return settings_from_config(cfg, choices, overrides=tuple(hc.overrides.task))


def test_the_jobs_of_a_sweep_have_distinct_names_from_their_overrides(compose_config):
    """Each job of the 16-job ablation gets its own name from what it sets (the loss too) and
    its own axis values; its config hash is that of the same config without names or axes."""
    common = ["schedule=tiny", "adjectives=[hard,soft]", "tracking.uri=sqlite:///x.db"]
    jobs = [(overrides, _job([*overrides, *common])) for overrides in SWEEP_16]
    names = [s.run_name for _, s in jobs]
    assert len(set(names)) == 16
    assert "haptic_lstm-mean-c10-logistic-tiny-hard+soft-s0" in names
    for overrides, s in jobs:
        assert s.axes == dict(o.split("=") for o in [*overrides, *common[:2]])  # no tracking
    for overrides, s in jobs[::5]:
        plain = settings_from_config(compose_config([*overrides, *common]))
        assert plain.config_hash == s.config_hash
        assert plain.run_name == "-".join(s.run_name.split("-")[:3] + [f"s{s.seed}"])


def test_run_name_short_forms():
    s = _job(
        [
            "experiment=table1_i_haptic_cnn_1trial",
            "schedule.lr=0.001",
            "seed=3",
            "adjectives=[hard,soft,smooth,thick]",
            "cache_dir=/tmp/c",
            "data=phac2",
            "data.path=" + __file__,  # a file that exists: data=phac2 checks it
        ]
    )
    # the Table I row, then each axis short; the seed once, last; cache_dir says nothing
    assert s.run_name.startswith("table1_i_haptic_cnn_1trial-lr=0.001-4adj-")
    assert s.run_name.endswith("-phac2-path=test_config-s3")
    assert s.axes["schedule.lr"] == "0.001" and "cache_dir" not in s.axes


def test_seed_is_checked_the_same_for_every_row(compose_config):
    for row in ("table1_i_haptic_cnn_1trial", "table1_o_random", "table1_a_haptic_static_1trial"):
        with pytest.raises(ConfigError, match="^seed: "):
            settings_from_config(compose_config([f"experiment={row}", "seed=-1"]))


@pytest.mark.parametrize(
    "override,message",
    [
        (
            "metrics=[roc_auc,accuracy]",
            "metrics: unknown ['accuracy']; known metrics: average_precision, f1, roc_auc",
        ),
        ("metrics=[]", "metrics: must be a list of metric names from average_precision, f1, "),
        ("metrics=roc_auc", "metrics: must be a list of metric names from "),
        ("metrics=[roc_auc,f1,roc_auc]", "metrics: listed twice in ['roc_auc', 'f1', 'roc_auc']"),
        ("metrics=[f1,average_precision]", "metrics: ['f1', 'average_precision'] leaves out roc"),
    ],
)
def test_metrics_refuse_unknown_names_in_one_line(compose_config, override, message):
    with pytest.raises(ConfigError) as err:
        settings_from_config(compose_config([override]))
    assert str(err.value).startswith(message) and "\n" not in str(err.value)


def test_metrics_are_listed_in_order_and_change_no_hash_name_or_axis(compose_config):
    """What is logged is not what is trained: a finished job is not rerun for a new metric."""
    default = _job(["adjectives=[hard,soft]"])
    assert default.metrics == ("roc_auc", "average_precision", "f1")
    chosen = _job(["adjectives=[hard,soft]", "metrics=[f1,roc_auc]"])
    assert chosen.metrics == ("f1", "roc_auc")
    assert (chosen.config_hash, chosen.row_hash) == (default.config_hash, default.row_hash)
    assert (chosen.run_name, chosen.axes) == (default.run_name, default.axes)


def test_a_metric_registered_after_import_is_accepted(compose_config):
    """The registry is read when the config is checked: a test module (or a component's
    ``_module_``) may add a metric."""
    from tactile_exp.metrics import METRICS, register

    with METRICS.temporary():
        register("hits", needs_both_classes=False)(lambda y, s: float((s > 0).sum()))
        got = settings_from_config(compose_config(["metrics=[roc_auc,hits]"]))
    assert got.metrics == ("roc_auc", "hits")


def test_labels_min_objects_left_out_of_the_hash_while_null(compose_config) -> None:
    from tactile_exp.config import config_hash

    settings = settings_from_config(compose_config([]))
    without = {k: v for k, v in settings.resolved.items() if k != "labels"}
    assert settings.config_hash == config_hash(without)  # jobs stored before the key existed
    assert settings.min_objects is None
    set_ = settings_from_config(compose_config(["labels.min_objects=2"]))
    assert set_.min_objects == 2 and set_.config_hash != settings.config_hash


@pytest.mark.parametrize("value", ["0", "-1", "1.5", "true", "two"])
def test_labels_min_objects_must_be_a_count(compose_config, value) -> None:
    with pytest.raises(ConfigError, match="labels.min_objects: must be null .* or a whole number"):
        settings_from_config(compose_config([f"labels.min_objects={value}"]))


def _lab(root, channels: int, sensor: str):
    import numpy as np

    from tactile_exp.data.dataset import Sensor
    from tactile_exp.data.folder import write_folder

    names = [f"o{i}" for i in range(4)]
    labels = {o: {"hard": int(i < 2)} for i, o in enumerate(names)}
    chans = tuple(f"c{k}" for k in range(channels))
    arrays = {o: [np.zeros((channels, 30))] * 2 for o in names}
    return write_folder(root, Sensor(sensor, chans, 100.0), labels, arrays)


@pytest.mark.parametrize(
    "overrides,line",
    [
        (  # the sensor named as PHAC-2's: its layout is what counts
            [],
            "modality: modality=haptic needs trials in the phac2-biotac layout, which {path} "
            "(sensor 'BioTac (2 fingers)', 48 channels at 100 Hz, no declared layout) does not "
            "give; modality=signals would fit",
        ),
        (
            ["modality=signals"],
            "model.groups: groups=32 does not divide the 48 channels of each instance; "
            "model.groups=channels (one group per channel, as M1 has one per signal; ours) or a "
            "divisor of 48 (modality=signals on {path})",
        ),
    ],
    ids=["biotac-name", "cnn-48-channels"],
)
def test_data_modality_model_checked_when_the_data_opens(
    compose_config, tmp_path, overrides, line
) -> None:
    """The issue's failures, now one line when the data opens (no run, no traceback)."""
    from tactile_exp.experiment import open_data

    path = _lab(tmp_path / "bt", 48, "BioTac (2 fingers)")
    cfg = compose_config(["data=folder", f"data.path={path}", "split=random", *overrides])
    settings = settings_from_config(cfg)
    with pytest.raises(ConfigError) as err:
        open_data(settings)
    assert str(err.value).startswith(line.format(path=path))
    base = ["data=folder", f"data.path={path}", "split=random"]
    fits = settings_from_config(compose_config([*base, "modality=signals", "model.groups=48"]))
    open_data(fits)  # the value the message names works


def test_the_default_split_of_a_folder_data_set_is_folds_with_the_k_its_labels_allow(
    compose_config, tmp_path
):
    """split=declared (the default) on a folder data set that declares nothing: folds with the
    largest K every label allows, hashed and named as the same split given on the command line."""
    data = _folder(tmp_path)  # labels a and b: 2 positive and 2 negative objects each
    base = ["data=folder", f"data.path={data}", "modality=signals", "model=linear"]
    default = settings_from_config(compose_config(base), overrides=tuple(base))
    given = [*base, "split=folds", "split.folds=2"]
    explicit = settings_from_config(compose_config(given), overrides=tuple(given))
    assert (default.split, default.split_params) == ("folds", {"folds": 2, "fold": 0})
    assert default.split_note == "folds K=2 (label a has 2 positive objects)"
    assert explicit.split_note == ""
    assert default.config_hash == explicit.config_hash
    assert default.row_hash == explicit.row_hash
    assert (
        default.run_name
        == explicit.run_name
        == ("linear-concat-c1-folder-path=ds-signals-folds-folds=2-s0")
    )
    assert default.choices["split"] == "folds"
    # the command line still wins
    random = [*base, "split=random"]
    assert settings_from_config(compose_config(random)).split == "random"


def test_a_declared_split_in_dataset_yaml_is_what_the_default_runs(compose_config, tmp_path):
    data = _folder(tmp_path)
    node = yaml.safe_load((data / "dataset.yaml").read_text())
    overrides = ["data=folder", f"data.path={data}", "modality=signals", "model=linear"]
    for declared, want in (
        ({"name": "random"}, ("random", {}, "random (declared by the data set)")),
        ({"name": "folds", "folds": 2}, ("folds", {"folds": 2, "fold": 0}, "folds K=2 (declared")),
    ):
        (data / "dataset.yaml").write_text(yaml.safe_dump({**node, "split": declared}))
        s = settings_from_config(compose_config(overrides))
        assert (s.split, s.split_params) == want[:2] and s.split_note.startswith(want[2])


def test_the_default_split_on_phac2_is_the_published_one_with_nothing_printed(compose_config):
    settings = settings_from_config(compose_config(TINY_DATA))
    assert (settings.split, settings.split_params, settings.split_note) == ("published", {}, "")
    assert settings.resolved["split"] == {"name": "published"}


def test_no_fold_count_fits_is_one_error_naming_the_label(compose_config, tmp_path):
    data = _folder(tmp_path)
    text = (data / "labels.csv").read_text().replace("o3,1,1", "o3,0,1")  # a: one positive object
    (data / "labels.csv").write_text(text)
    cfg = compose_config(["data=folder", f"data.path={data}", "modality=signals", "model=linear"])
    with pytest.raises(DataError, match=r"split=declared: no folds split fits: label a has 1 "):
        settings_from_config(cfg)
    cfg = compose_config(
        ["data=folder", f"data.path={data}", "modality=signals", "model=linear", "adjectives=[b]"]
    )
    assert settings_from_config(cfg).split_params == {"folds": 2, "fold": 0}

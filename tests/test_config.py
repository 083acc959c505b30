"""Every YAML composes and builds; option names are registry names; bad values fail early."""

import inspect
import re
from fnmatch import fnmatch
from pathlib import Path

import pytest
import yaml
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from tactile_exp.combine import COMBINERS
from tactile_exp.config import ConfigError, settings_from_config
from tactile_exp.data.sources import DATA_SOURCES
from tactile_exp.data.splits import SPLITS
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
    takes = [n for n in MODELS.names() if modality in MODELS[n].modalities]
    takes_any = [n for n in MODELS.names() if not MODELS[n].modalities]
    return "haptic_cnn" if "haptic_cnn" in takes else (takes or takes_any)[0]


@pytest.mark.parametrize("group", sorted(REGISTRIES))
def test_option_names_equal_registry_names(group):
    assert _options(group) == REGISTRIES[group].names()


@pytest.mark.parametrize(
    "group,option",
    [(g, o) for g in sorted(REGISTRIES) for o in _options(g)]
    + [("experiment", o) for o in _options("experiment")]
    + [("sweep", o) for o in _options("sweep")],
)
def test_every_option_composes_and_builds(compose_config, group, option, tmp_path):
    overrides = [f"{group}={option}"]
    if group == "data" and option == "phac2":
        (tmp_path / "phac.h5").touch()  # only its existence is checked before a job
        overrides.append(f"data.path={tmp_path / 'phac.h5'}")
    if group == "modality":
        overrides.append(f"model={_model_for(option)}")
    if group == "model" and MODELS[option].modalities:
        overrides.append(f"modality={MODELS[option].modalities[0]}")
    cfg = compose_config(overrides)
    settings = settings_from_config(cfg)  # builds the model through its registry
    if group in REGISTRIES:
        assert cfg[group].name == option
    if group == "experiment":
        _assert_experiment_applied(compose_config, cfg, option)
    for component, registry in (
        (settings.data, DATA_SOURCES),
        (settings.modality, MODALITIES),
    ):
        extra = {"dataset": None, "cache_dir": None} if registry is MODALITIES else {}
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
            assert cfg[group].name == chosen, (option, group)
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
    assert len(s.adjectives) == 24
    assert s.run_name == "haptic_cnn-concat-c1-s0"


def test_config_hash_ignores_tracking_only(compose_config):
    base = settings_from_config(compose_config()).config_hash
    assert settings_from_config(compose_config(["tracking.uri=sqlite:///x.db"])).config_hash == base
    assert settings_from_config(compose_config(["seed=1"])).config_hash != base


@pytest.mark.parametrize(
    "override,message",
    [
        ("model=nope", "Could not find 'model/nope'"),
        ("combine=0", "combine: must be a whole number of trials >= 1"),
        ("combine=1.5", "combine: must be a whole number"),
        ("adjectives=[]", "adjectives: must list at least one"),
        ("adjectives=[hard,fluffy]", "adjectives: unknown ['fluffy']"),
        ("device=tpu", "device: must be auto, cpu, cuda or cuda:N"),
        ("schedule.lr=0", "schedule.lr: lr must be > 0"),
        ("schedule.lr=-1", "schedule.lr: "),
        ("schedule.epochs=0", "schedule.epochs: epochs must be an int >= 1, got 0"),
        ("schedule.head.lr=0", "schedule.head.lr: lr must be > 0"),
        ("modality=visual", "modality: model=haptic_cnn takes modality haptic, got 'visual'"),
    ],
)
def test_impossible_values_fail_naming_the_key(compose_config, override, message):
    with pytest.raises(Exception) as err:
        settings_from_config(compose_config([override]))
    assert message in str(err.value)


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

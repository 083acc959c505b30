# Cross-cutting, so not tests/test_<module>.py: the extension contract spans the
# registries, conf/, the engine and the Table I sweep; proved through all of them at once.
"""The extension contract: a new model is one module + one YAML, a new Table I row is one
experiment file, and the Table I sweep picks the row up; proved in a temporary config dir."""

import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import CONF, TINY_DATA, doc_block
from hydra import compose, initialize_config_dir
from hydra.core.override_parser.overrides_parser import OverridesParser
from sklearn.metrics import roc_auc_score

from tactile_exp.config import settings_from_config
from tactile_exp.experiment import run
from tactile_exp.models import MODELS
from tactile_exp.testing import check_model

# The page's own example: its module and its YAML, run here as the page shows them.
MODULE = doc_block("extending.md", '"""A nearest-centroid classifier')
YAML = doc_block("extending.md", "name: nearest_centroid")


def table1_rows(conf: Path) -> list[str]:
    """The experiments `-m sweep=table1` runs: its glob, filtered by Hydra over the files."""
    sweep = yaml.safe_load((conf / "sweep" / "table1.yaml").read_text())
    value = sweep["hydra"]["sweeper"]["params"]["experiment"]
    glob = OverridesParser.create().parse_override(f"experiment={value}").value()
    return glob.filter(sorted(p.stem for p in (conf / "experiment").glob("*.yaml")))


def test_table1_sweep_is_every_table1_file_and_nothing_else():
    rows = table1_rows(CONF)
    assert [r.split("_")[1] for r in rows] == list("abcdefghijklmno")
    assert "quick_table1_i" not in rows


@pytest.fixture
def models():
    """MODELS as it is, restored after the test: a model registered in the test stays in it."""
    with MODELS.temporary():
        yield MODELS


def test_new_model_and_new_row_in_a_temporary_config_dir(tmp_path, monkeypatch, cache_dir, models):
    conf = tmp_path / "conf"
    shutil.copytree(CONF, conf)
    (tmp_path / "my_models").mkdir()
    (tmp_path / "my_models" / "centroid.py").write_text(MODULE)
    monkeypatch.syspath_prepend(str(tmp_path))
    (conf / "model" / "nearest_centroid.yaml").write_text(YAML)
    (conf / "experiment" / "table1_z_nearest_centroid.yaml").write_text(
        "# @package _global_\n"
        "defaults:\n"
        "  - override /model: nearest_centroid\n"
        "  - override /combine_instances: separate\n"
        "paper:\n  row: Z\n  auc: 61.5\n"
    )
    assert "table1_z_nearest_centroid" in table1_rows(conf)
    overrides = [
        *TINY_DATA,
        f"cache_dir={cache_dir}",
        f"tracking.uri=sqlite:///{tmp_path / 'mlflow.db'}",
        "adjectives=[hard,soft]",
        "experiment=table1_z_nearest_centroid",
    ]
    with initialize_config_dir(config_dir=str(conf), version_base="1.3"):
        cfg = compose("config", overrides=overrides)
    settings = settings_from_config(cfg)
    assert "nearest_centroid" in MODELS.names()
    assert settings.model.params == {"shrink": 0.0}
    assert "schedule" not in settings.resolved  # it reads none (Model.reads)
    check_model("nearest_centroid", config_dir=conf)
    result = run(settings)
    assert set(result.results) == {"hard", "soft"}
    for r in result.results.values():  # the AUC of the new model's scores, both classes there
        assert set(r.test.y) == {0, 1} and np.isfinite(r.test.scores).all()
        assert r.metrics["auc"] == roc_auc_score(r.test.y, r.test.scores)
        assert len(np.unique(r.test.scores)) > 1  # the new model's scores, not a constant

# Cross-cutting, so not tests/test_<module>.py: every experiment file through config,
# data, modality, model, store and tracking at once; the per-module files test each part alone.
"""Slow: every Table I experiment file runs end to end on tiny data."""

from pathlib import Path

import numpy as np
import pytest
from mlflow.tracking import MlflowClient
from sklearn.metrics import roc_auc_score

from tactile_exp.config import settings_from_config
from tactile_exp.experiment import run

# The Table I rows on PHAC-2's layout; the benchmark's (benchmark_*, raw channels of a folder
# data set) run end to end in tests/test_benchmark.py.
CONF = Path(__file__).parents[1] / "conf"
EXPERIMENTS = sorted(
    p.stem for p in (CONF / "experiment").glob("*.yaml") if not p.stem.startswith("benchmark_")
)
# Tiny data has 2 trials and 2 views per object: shrink the rows that combine more.
SHRINK = {"table1_j_haptic_cnn_10trials": ["combine=2"], "table1_b_haptic_static_10trials": [
    "combine=2"], "table1_d_haptic_dynamic_10trials": ["combine=2"],
    "table1_l_image_googlenet_8views": ["combine=2"],
    "table1_m_multimodal_i_l": ["modality.visual.size=32"],
    "table1_n_multimodal_j_l": ["modality.trials=2", "modality.visual.size=32"]}  # fmt: skip


@pytest.mark.slow
@pytest.mark.parametrize("experiment", EXPERIMENTS)
def test_experiment_runs_end_to_end(tiny_config, mlflow_uri, experiment):
    overrides = [f"experiment={experiment}", "data.views=2"]
    overrides += SHRINK.get(experiment, [])
    result = run(settings_from_config(tiny_config(overrides, adjectives="[hard,thick]")))
    assert set(result.results) == {"hard", "thick"}
    for r in result.results.values():  # both classes scored, the AUC that of these scores
        assert (
            set(r.test.y) == {0, 1}
            and len(r.test.scores) == len(r.test.y)
            and np.all(np.isfinite(r.test.scores))
        )
        assert r.metrics["auc"] == pytest.approx(roc_auc_score(r.test.y, r.test.scores), abs=1e-12)
    parent = MlflowClient(mlflow_uri).get_run(result.run_id)
    assert parent.info.status == "FINISHED"
    mean = np.mean([r.metrics["auc"] for r in result.results.values()])
    assert parent.data.metrics["mean_auc"] == pytest.approx(mean, abs=1e-12)

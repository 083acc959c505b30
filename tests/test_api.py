"""The notebook API: a row fitted and scored in a few lines, with no MLflow store at all."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from conftest import TINY_DATA

SCRIPT = """
import json, sys
from sklearn.metrics import roc_auc_score
from tactile_exp import api

settings = api.compose(*sys.argv[1:])
results = api.fit(settings)
again = api.fit(settings, cache=None)
print(json.dumps({
    "auc": {a: r.metrics["auc"] for a, r in results.items()},
    "recomputed": {a: roc_auc_score(r.test.y, r.test.scores) for a, r in results.items()},
    "sides": {a: sorted(r.sides) for a, r in results.items()},
    "again": {a: r.metrics["auc"] for a, r in again.items()},
    "loaded": sorted(m for m in sys.modules if m.startswith("mlflow") or m in (
        "tactile_exp.tracking", "tactile_exp.recording", "tactile_exp.store")),
}))
"""


def test_fit_a_row_with_no_tracking_store(cache_dir, numba_cache, tmp_path):
    store = tmp_path / "never" / "mlflow.db"
    overrides = [
        *TINY_DATA,
        f"cache_dir={cache_dir}",
        f"tracking.uri=sqlite:///{store}",
        "schedule=tiny",
        "adjectives=[hard,soft]",
        "experiment=table1_i_haptic_cnn_1trial",
    ]
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    done = subprocess.run(
        [sys.executable, "-c", SCRIPT, *overrides], capture_output=True, text=True, env=env
    )
    assert done.returncode == 0, done.stderr[-3000:]
    out = json.loads(done.stdout.strip().splitlines()[-1])
    assert list(out["auc"]) == ["hard", "soft"] and out["auc"] == out["recomputed"]
    assert out["sides"] == {"hard": ["test", "train"], "soft": ["test", "train"]}
    assert out["again"] == out["auc"]  # a fresh cache trains the same models (seeded)
    assert out["loaded"] == [] and not store.parent.exists()  # MLflow never imported nor written

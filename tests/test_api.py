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


class JsonLines:
    """A tracker back-end other than MLflow, written outside the engine: one JSON line per
    adjective as it is scored, then one for the job."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def _write(self, record: dict) -> None:
        with self.path.open("a") as f:
            f.write(json.dumps(record) + "\n")

    def adjective(self, settings, result) -> None:
        self._write({"job": settings.run_name, "adjective": result.adjective, **result.metrics})

    def job(self, settings, results) -> None:
        aucs = [r.metrics["auc"] for r in results.values()]
        self._write({"job": settings.run_name, "mean_auc": sum(aucs) / len(aucs)})


def test_a_new_tracker_back_end_records_what_fit_returns(tiny_config, tmp_path):
    from tactile_exp import api
    from tactile_exp.config import settings_from_config

    overrides = ["model=random", "combine_instances=separate", "seed=5"]
    settings = settings_from_config(tiny_config(overrides, "[hard,soft]"))
    path = tmp_path / "results.jsonl"
    results = api.fit(settings, recorder=JsonLines(path))
    lines = [json.loads(line) for line in path.read_text().splitlines()]
    assert [line.get("adjective") for line in lines] == ["hard", "soft", None]
    for line in lines[:2]:
        assert {k: v for k, v in line.items() if k not in ("job", "adjective")} == (
            results[line["adjective"]].metrics
        )
    assert (
        lines[2]["mean_auc"]
        == (results["hard"].metrics["auc"] + results["soft"].metrics["auc"]) / 2
    )
    assert {line["job"] for line in lines} == {settings.run_name}

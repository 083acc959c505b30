"""Bench: what each benchmark model (``conf/experiment/benchmark_*.yaml``) costs per adjective
beside the others, on one folder data set, side by side in one run.

Each model runs fold 0 of the data set's declared split (``split=declared``) on its first
``--labels`` labels, into a fresh MLflow store, on the paper's schedule. A first one-label job
of each model compiles its kernels (ours and aeon's) and reads the data, so no model pays for
that in the figures; then ``--rounds`` rounds run every model, in alternating order. Prints each
model's median seconds per adjective (``sizes.seconds``: preprocessing, fit and scoring) and its
mean test AUC over the labels. A model whose modality the data set cannot give (the static
features off PHAC-2's layout) is listed as not run.

    python bench/bench_benchmark_models.py --data DIR --labels 3 --rounds 1 [--json OUT]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
from pathlib import Path

from hydra import compose, initialize_config_dir

from tactile_exp.config import settings_from_config
from tactile_exp.cores import cores
from tactile_exp.data.folder import FolderDataSet
from tactile_exp.errors import NotACell
from tactile_exp.experiment import JobResult, run

CONF = Path(__file__).resolve().parents[1] / "conf"
MODELS = sorted(p.stem for p in (CONF / "experiment").glob("benchmark_*.yaml"))


def job(experiment: str, data: Path, labels: list[str], store: Path) -> JobResult:
    overrides = [
        f"experiment={experiment}",
        "data=folder",
        f"data.path={data}",
        f"adjectives=[{','.join(labels)}]",
        f"tracking.uri=sqlite:///{store / 'mlflow.db'}",
        "tracking.skip_finished=false",
        "tracking.reuse=false",
    ]
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        settings = settings_from_config(compose("config", overrides=overrides))
    return run(settings)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, required=True, help="a folder data set")
    parser.add_argument("--labels", type=int, default=3, help="labels per job")
    parser.add_argument("--rounds", type=int, default=1)
    parser.add_argument("--json", type=Path, default=None, help="also write the figures here")
    args = parser.parse_args()
    labels = list(FolderDataSet(args.data).label_names[: args.labels])
    print(f"{cores()} cores; {args.data}: labels {', '.join(labels)}, fold 0, paper schedule")
    seconds: dict[str, list[float]] = {}
    aucs: dict[str, list[float]] = {}
    absent: dict[str, str] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for model in MODELS:
            try:
                job(model, args.data, labels[:1], Path(tmp) / f"warm-{model}")
            except NotACell as err:
                absent[model] = str(err).split(";")[0]
                print(f"{model}: not run ({absent[model]})")
                continue
            seconds[model], aucs[model] = [], []
        for r in range(args.rounds):
            order = list(seconds) if r % 2 == 0 else list(reversed(list(seconds)))
            for model in order:
                result = job(model, args.data, labels, Path(tmp) / f"{r}-{model}")
                for res in result.results.values():
                    seconds[model].append(res.sizes["seconds"])
                    aucs[model].append(res.metrics["auc"])
    figures: dict[str, object] = {}
    for model in seconds:
        per = statistics.median(seconds[model])
        auc = statistics.mean(aucs[model])
        print(f"{model}: {per:.1f} s per adjective (median), mean AUC {auc:.3f}")
        figures[f"{model}, s per adjective"] = round(per, 1)
        figures[f"{model}, mean AUC"] = round(auc, 3)
    for model, why in absent.items():
        figures[f"{model}, s per adjective"] = f"not run: {why}"
    if args.json:
        from record import write

        notes = f"{args.data.name}: {len(labels)} labels, fold 0, {args.rounds} rounds"
        write(args.json, "bench_benchmark_models", figures, notes)


if __name__ == "__main__":
    main()

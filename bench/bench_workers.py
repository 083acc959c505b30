"""Bench: one ConvNet job with its adjectives in one process (workers=1) vs two worker processes
(workers=2), side by side.

The job is row I (``experiment=table1_i_haptic_cnn_1trial``) on the embedded data, cut to
``--adjectives`` adjectives and ``--epochs`` network epochs (fine-tuning and the T4 head keep
the paper's schedule), each into a fresh MLflow store. A first one-adjective, one-epoch job
compiles the kernels, so neither side pays for it; then ``--rounds`` rounds run both settings,
in alternating order. Prints each job's seconds, the median per setting, their ratio (target
of the worker processes: workers=2 at least 15% faster on 2 cores), and each setting's
mean AUC (equal up to float rounding: per-thread gradient partials add up in another order).
Each worker pays ~9 s to start (spawn, imports, data, kernels from the cache): a job of a few
short adjectives gains nothing (4 adjectives x 40 epochs: 0.98x), a long one does.

    .venv/bin/python bench/bench_workers.py --adjectives 6 --epochs 120
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from hydra import compose, initialize_config_dir

from tactile_exp.config import settings_from_config
from tactile_exp.cores import cores
from tactile_exp.data.layout import ADJECTIVES
from tactile_exp.data.phac2 import default_cache_dir
from tactile_exp.experiment import JobResult, run

CONF = Path(__file__).resolve().parents[1] / "conf"


def job(adjectives: list[str], epochs: int, workers: int, store: Path) -> tuple[float, JobResult]:
    """Seconds and result of one row I job, start (data opened) to finish."""
    overrides = [
        "experiment=table1_i_haptic_cnn_1trial",
        f"adjectives=[{','.join(adjectives)}]",
        f"schedule.epochs={epochs}",
        f"workers={workers}",
        f"cache_dir={default_cache_dir()}",
        f"tracking.uri=sqlite:///{store / 'mlflow.db'}",
        "tracking.skip_finished=false",
    ]
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        settings = settings_from_config(compose("config", overrides=overrides))
    start = time.perf_counter()
    result = run(settings)
    return time.perf_counter() - start, result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--adjectives", type=int, default=6, help="adjectives per job (<= 24)")
    parser.add_argument("--epochs", type=int, default=120, help="network epochs (paper: 200)")
    parser.add_argument("--rounds", type=int, default=2)
    args = parser.parse_args()
    adjectives = list(ADJECTIVES[: args.adjectives])
    print(f"{cores()} cores; row I, {len(adjectives)} adjectives, {args.epochs} epochs")
    with tempfile.TemporaryDirectory() as tmp:
        seconds, _ = job(adjectives[:1], 1, 1, Path(tmp) / "warm")
        print(f"warm-up (compile on first use, data): {seconds:.1f} s")
        times: dict[int, list[float]] = {1: [], 2: []}
        aucs: dict[int, float] = {}
        for r in range(args.rounds):
            for workers in (1, 2) if r % 2 == 0 else (2, 1):
                seconds, result = job(
                    adjectives, args.epochs, workers, Path(tmp) / f"{r}-{workers}"
                )
                times[workers].append(seconds)
                aucs[workers] = result.means["mean_auc"]
                print(f"  round {r + 1}, workers={workers}: {seconds:.1f} s")
    one, two = statistics.median(times[1]), statistics.median(times[2])
    print(
        f"median job: workers=1 {one:.1f} s, workers=2 {two:.1f} s; workers=2 takes {two / one:.3f}"
    )
    print(f"  of the time ({one / two:.2f}x the throughput)")
    print(f"mean AUC: workers=1 {aucs[1]:.4f}, workers=2 {aucs[2]:.4f}")


if __name__ == "__main__":
    main()

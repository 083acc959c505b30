"""Bench: a YAML-only MiniRocket model (aeon's MiniRocket + scikit-learn's RidgeClassifierCV,
``model=estimator``) per adjective under ``combine_instances=concat``, fitting the model's own
classifier too (as before ``fit_representation``: nothing scores with it, the head does) vs
fitting only its transformer, side by side.

Both run the same job on the default data (the embedded file, ``modality=haptic``, the
published splits), cut to ``--adjectives`` adjectives, each into a fresh MLflow store, with
MiniRocket's default 10,000 kernels (``--kernels``). A first one-adjective job compiles aeon's
kernels, so neither side pays for it; then ``--rounds`` rounds run both, in alternating order.
Prints each adjective's seconds (``sizes.seconds``: preprocessing, fit and scoring), the
median per adjective of each side, their ratio, and each adjective's test AUC on both sides,
which must be equal: the head is the only classifier that scores.

    .venv/bin/python bench/bench_estimator.py --adjectives 3 --rounds 2 [--json OUT]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from hydra import compose, initialize_config_dir

from tactile_exp.config import settings_from_config
from tactile_exp.cores import cores
from tactile_exp.data.layout import ADJECTIVES
from tactile_exp.data.phac2 import default_cache_dir
from tactile_exp.experiment import JobResult, run
from tactile_exp.models.base import Model
from tactile_exp.models.estimator import EstimatorModel

CONF = Path(__file__).resolve().parents[1] / "conf"
MINIROCKET = "aeon.transformations.collection.convolution_based.MiniRocket"


@contextmanager
def whole_model_fitted() -> Iterator[None]:
    """The estimator fits its classifier under concat too (``fit_representation`` is ``fit``)."""
    own = EstimatorModel.fit_representation
    EstimatorModel.fit_representation = Model.fit_representation  # type: ignore[method-assign]
    try:
        yield
    finally:
        EstimatorModel.fit_representation = own  # type: ignore[method-assign]


def job(adjectives: list[str], kernels: int, store: Path) -> tuple[float, JobResult]:
    overrides = [
        "model=estimator",
        f"model.transformer={{_target_:{MINIROCKET},n_kernels:{kernels}}}",
        "model.layout=series",
        f"adjectives=[{','.join(adjectives)}]",
        f"cache_dir={default_cache_dir()}",
        f"tracking.uri=sqlite:///{store / 'mlflow.db'}",
        "tracking.skip_finished=false",
        "tracking.reuse=false",
    ]
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        settings = settings_from_config(compose("config", overrides=overrides))
    start = time.perf_counter()
    result = run(settings)
    return time.perf_counter() - start, result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--adjectives", type=int, default=3, help="adjectives per job (<= 24)")
    parser.add_argument("--kernels", type=int, default=10_000, help="MiniRocket's n_kernels")
    parser.add_argument("--rounds", type=int, default=1)
    parser.add_argument("--json", type=Path, default=None, help="also write the figures here")
    args = parser.parse_args()
    adjectives = list(ADJECTIVES[: args.adjectives])
    print(f"{cores()} cores; MiniRocket ({args.kernels} kernels) + RidgeClassifierCV, concat, c1")
    sides = {"classifier fitted too": whole_model_fitted, "transformer only": contextmanager(
        lambda: iter([None])
    )}  # fmt: skip
    seconds: dict[str, dict[str, list[float]]] = {s: {a: [] for a in adjectives} for s in sides}
    aucs: dict[str, dict[str, float]] = {s: {} for s in sides}
    with tempfile.TemporaryDirectory() as tmp:
        warm, _ = job(adjectives[:1], 84, Path(tmp) / "warm")
        print(f"warm-up (aeon's kernels compiled, data): {warm:.1f} s")
        for r in range(args.rounds):
            for i, side in enumerate(sides if r % 2 == 0 else reversed(list(sides))):
                with sides[side]():
                    total, result = job(adjectives, args.kernels, Path(tmp) / f"{r}-{i}")
                for adjective, res in result.results.items():
                    seconds[side][adjective].append(res.sizes["seconds"])
                    aucs[side][adjective] = res.metrics["auc"]
                print(f"  round {r + 1}, {side}: job {total:.1f} s")
    before, after = sides
    for adjective in adjectives:
        b = statistics.median(seconds[before][adjective])
        a = statistics.median(seconds[after][adjective])
        auc_b, auc_a = aucs[before][adjective], aucs[after][adjective]
        same = "equal" if auc_b == auc_a else "DIFFER"
        print(
            f"{adjective}: {before} {b:.1f} s, {after} {a:.1f} s ({a / b:.2f} of the time); "
            f"AUC {auc_b:.4f} / {auc_a:.4f} ({same})"
        )
    b = statistics.median(s for v in seconds[before].values() for s in v)
    a = statistics.median(s for v in seconds[after].values() for s in v)
    print(f"median per adjective: {before} {b:.1f} s, {after} {a:.1f} s; ratio {a / b:.2f}")
    if args.json:
        from record import write

        figures: dict[str, object] = {
            f"median s per adjective, {before}": round(b, 1),
            f"median s per adjective, {after}": round(a, 1),
            "ratio": round(a / b, 2),
        }
        for adjective in adjectives:
            figures[f"{adjective} AUC, {before} / {after}"] = (
                f"{aucs[before][adjective]:.4f} / {aucs[after][adjective]:.4f}"
            )
        notes = f"{len(adjectives)} adjectives, {args.rounds} rounds, {args.kernels} kernels"
        write(args.json, "bench_estimator", figures, notes)


if __name__ == "__main__":
    main()

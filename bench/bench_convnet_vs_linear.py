"""The haptic ConvNet against linear models on the same inputs, splits and validation.

For each split (published, and seeded random ones) and adjective, the training objects lose the
job's validation objects (``tactile_exp.validation``, the same draw as the experiment), and every
model below is trained on what is left and scored by ROC AUC on training, validation and test
units:

- ``cnn``: the ConvNet's own classifier on each instance (2 fingers x 5 offsets per trial);
- ``I-old``/``I-new``, ``J-old``/``J-new``: the classification layer retrained on conv3 of 1 trial
  or 10 trials (T4), with the network's schedule (``old``: the earlier schedule) or the
  ``--head-*`` schedule (``new``: ``conf/schedule/paper.yaml``'s ``head``); one ConvNet serves
  all four;
- ``flat``: logistic regression on the flattened preprocessed trial (10 instances x 32 x 150);
- ``meanstd``: logistic regression on each instance's per-channel means and stds (640 per trial);
- ``A``, ``F`` (``--baselines``): Table I rows A and F (Chu et al.'s features, linear SVM).

The logistic regressions are StandardScaler + LogisticRegression(C=0.1), as in bench_dynamics.py.
Runs without Hydra or MLflow, so it also runs where only torch and scikit-learn are installed:

    PYTHONPATH=$PWD .venv/bin/python bench/bench_convnet_vs_linear.py --epochs 20 --finetune 10 \\
        --splits published:0 random:1 random:2 --adjectives hard nice thick metallic
"""

from __future__ import annotations

import argparse
import csv
import time
import warnings
from pathlib import Path

import numpy as np
from sklearn.linear_model import LogisticRegression
from sklearn.metrics import roc_auc_score
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from tactile_exp.combine import COMBINERS
from tactile_exp.data.layout import ADJECTIVES, Instances, Split
from tactile_exp.data.phac2 import default_cache_dir
from tactile_exp.data.sources import DATA_SOURCES
from tactile_exp.data.splits import make_split
from tactile_exp.modalities import MODALITIES
from tactile_exp.models.registry import MODELS
from tactile_exp.models.schedule import Schedule
from tactile_exp.validation import take_trials, validation_split


def _auc(y: np.ndarray, s: np.ndarray) -> float:
    return float(roc_auc_score(y, s)) if len(np.unique(y)) == 2 else float("nan")


def _aucs(score, sets: dict[str, Instances]) -> dict[str, float]:
    return {f"{name}_auc": _auc(units.y, score(units.X)) for name, units in sets.items()}


def _logistic(train: Instances, sets: dict[str, Instances]) -> dict[str, float]:
    model = make_pipeline(StandardScaler(), LogisticRegression(C=0.1, max_iter=3000))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # convergence notes on the 48,000-d flat input
        model.fit(train.X.reshape(len(train), -1), train.y)
    return _aucs(lambda X: model.decision_function(X.reshape(len(X), -1)), sets)


def _per_trial(sets: dict[str, Instances], transform) -> dict[str, Instances]:
    concat = COMBINERS.build("concat")
    return {k: concat(transform(s.X), s, 1) for k, s in sets.items()}


def _mean_std(X: np.ndarray) -> np.ndarray:
    return np.concatenate([X.mean(-1), X.std(-1)], -1).reshape(len(X), -1)


def baseline_rows(dataset, cache: Path, seed: int) -> dict:
    """Rows A and F's modalities (conf/experiment/table1_{a,f}_*.yaml), HMM seeded like a job."""
    rows = {
        "A": {"features": ["static"]},
        "F": {"features": ["static", "dynamic"], "dynamic_pool": "object"},
    }
    out = {}
    for row, settings in rows.items():
        out[row] = MODALITIES.build(
            "haptic_features",
            dataset=dataset,
            cache_dir=cache / "preprocessed",
            seed=seed,
            **settings,
        )
        out[row].prepare()
    return out


def run_split(args, dataset, haptic, rule: str, seed: int, out) -> None:
    writer = csv.writer(out)
    features = baseline_rows(dataset, args.cache, seed) if args.baselines else {}
    for adjective in args.adjectives:
        start = time.perf_counter()
        split = make_split(dataset, adjective, rule, seed)
        reduced, held = validation_split(split, fraction=args.val_fraction, seed=seed)
        joint = Split(adjective, reduced.train, split.test + held, split.labels)
        train, rest = haptic.instances(joint)
        val, test = take_trials(rest, held)
        sets = {"train": train, "val": val, "test": test}
        rows: dict[str, dict[str, float]] = {}

        trials = _per_trial(sets, lambda X: X.reshape(len(X), -1))
        rows["flat"] = _logistic(trials["train"], trials)
        stats = _per_trial(sets, _mean_std)
        rows["meanstd"] = _logistic(stats["train"], stats)

        cnn = MODELS.build(
            "haptic_cnn",
            schedule=Schedule(epochs=args.epochs, finetune_epochs=args.finetune),
            seed=seed,
            device=args.device,
        )
        history = cnn.fit(train)
        rows["cnn"] = _aucs(cnn.decision_function, sets)
        rows["cnn"]["loss"] = history["train_loss"][-1]
        conv3 = {k: cnn.transform(s.X) for k, s in sets.items()}
        new = Schedule(
            epochs=args.head_epochs,
            finetune_epochs=args.head_finetune,
            batch_size=args.head_batch,
            lr=args.head_lr,
            momentum=0.9,
        )
        old = Schedule(
            epochs=args.epochs,
            finetune_epochs=args.finetune,
            batch_size=1000,
            lr=0.01,
            momentum=0.9,
        )
        concat = COMBINERS.build("concat")
        for row, combine in (("I", 1), ("J", 10)):
            units = {k: concat(conv3[k], s, combine) for k, s in sets.items()}
            for tag, schedule in (("old", old), ("new", new)):
                head = MODELS.build("linear", schedule=schedule, seed=seed, device=args.device)
                curves = head.fit(units["train"])
                rows[f"{row}-{tag}"] = _aucs(head.decision_function, units)
                rows[f"{row}-{tag}"]["loss"] = curves["train_loss"][-1]

        if args.baselines:
            for row, model in features.items():
                ftrain, frest = model.instances(joint)
                fval, ftest = take_trials(frest, held)
                svm = MODELS.build("linear_svm", seed=seed)
                svm.fit(ftrain)
                fsets = {"train": ftrain, "val": fval, "test": ftest}
                rows[row] = _aucs(svm.decision_function, fsets)

        for model, r in rows.items():
            writer.writerow(
                [f"{rule}:{seed}", adjective, model]
                + [f"{r.get(k, float('nan')):.4f}" for k in ("train_auc", "val_auc", "test_auc")]
                + [f"{r.get('loss', float('nan')):.4f}"]
            )
        print(
            f"{rule}:{seed} {adjective:<12} "
            + " ".join(f"{m}={r['test_auc']:.3f}" for m, r in rows.items())
            + f" ({time.perf_counter() - start:.0f} s)",
            flush=True,
        )
        out.flush()


def summarise(path: Path) -> None:
    """Mean over adjectives of train / val / test AUC per split and model (NaN-skipping)."""
    with open(path) as f:
        rows = list(csv.DictReader(f))
    keys = sorted({(r["split"], r["model"]) for r in rows}, key=lambda k: (k[1], k[0]))
    print(f"{'model':<8}{'split':<11}{'train':>7}{'val':>7}{'test':>7}{'loss':>8}  n_val")
    for split, model in keys:
        sel = [r for r in rows if r["split"] == split and r["model"] == model]
        cols = [np.nanmean([float(r[c]) for r in sel]) for c in ("train", "val", "test", "loss")]
        n_val = sum(np.isfinite(float(r["val"])) for r in sel)
        print(f"{model:<8}{split:<11}" + "".join(f"{v:7.3f}" for v in cols[:3]), end="")
        print(f"{cols[3]:8.4f}  {n_val}/{len(sel)}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache-dir", type=Path, default=None, help="default: $TACTILE_EXP_CACHE")
    ap.add_argument("--splits", nargs="+", default=["published:0", "random:1", "random:2"])
    ap.add_argument("--adjectives", nargs="+", default=list(ADJECTIVES))
    ap.add_argument("--epochs", type=int, default=20, help="ConvNet logistic epochs (paper: 200)")
    ap.add_argument("--finetune", type=int, default=10, help="hinge epochs (ours: 100)")
    ap.add_argument("--head-epochs", type=int, default=200)
    ap.add_argument("--head-finetune", type=int, default=100)
    ap.add_argument("--head-batch", type=int, default=32)
    ap.add_argument("--head-lr", type=float, default=0.001)
    ap.add_argument("--val-fraction", type=float, default=0.15)
    ap.add_argument("--baselines", action="store_true", help="also rows A and F (HMM chains)")
    ap.add_argument("--device", default="auto")
    ap.add_argument("--out", type=Path, default=Path("convnet_vs_linear.csv"))
    args = ap.parse_args()
    cache = args.cache_dir or default_cache_dir()
    start = time.perf_counter()
    dataset = DATA_SOURCES.build("synthetic", cache_dir=cache)
    haptic = MODALITIES.build("haptic", dataset=dataset, cache_dir=cache / "preprocessed")
    haptic.prepare()
    args.cache = cache
    print(f"{dataset.path.name} ready in {time.perf_counter() - start:.0f} s", flush=True)
    with open(args.out, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["split", "adjective", "model", "train", "val", "test", "loss"])
        for spec in args.splits:
            rule, seed = spec.split(":")
            run_split(args, dataset, haptic, rule, int(seed), f)
    summarise(args.out)
    print(f"total {time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()

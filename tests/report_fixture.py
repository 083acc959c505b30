"""Jobs logged as `python -m tactile_exp` logs them on folder data sets, with held-out scores of
a chosen quality: what the comparison report's tests read (no training)."""

from __future__ import annotations

import numpy as np
from sklearn.metrics import roc_auc_score

from tactile_exp import stats
from tactile_exp.report.heldout import Evidence
from tactile_exp.report.runs import Group, Run
from tactile_exp.tracking import Tracker

LABELS = ("hard", "soft", "rough", "smooth", "thick", "thin", "squishy", "sticky")
N_OBJECTS = 16  # per data set; object o is positive for label j when (o + j) % 16 < 6
UNITS = 2  # test units per object


def label_of(obj: int, j: int) -> int:
    return int((obj + 3 * j) % N_OBJECTS < 6)


def log_job(
    tracker: Tracker,
    *,
    dataset: str,
    model: str,
    quality: float,
    fold: int,
    folds: int = 2,
    overrides: tuple[str, ...] = (),
    noise: str = "",
    seed: int = 0,
) -> str:
    """One fold's parent run (a folder data set ``dataset``, ``model=model``) and a child per
    label holding its ``scores.csv``: score = quality * label + N(0, 0.5), the noise drawn from
    (data set, ``noise`` or the model, fold): two jobs with the same ``noise`` key and quality
    score every unit alike (identical in effect)."""
    settings = {"model": model, **dict(o.split("=", 1) for o in overrides)}
    row_hash = f"{dataset}-{'-'.join(f'{k}={v}' for k, v in sorted(settings.items()))}-{seed}"
    params = {
        "choice.model": model,
        "choice.modality": "signals",
        "choice.schedule": "quick",
        "choice.data": "folder",
        "choice.split": "folds",
        "choice.combine_instances": "concat",
        "combine": "1",
        "model.name": model,
        "data.name": "folder",
        "data.path": f"/data/{dataset}",
        "split.name": "folds",
        "split.folds": str(folds),
        "split.fold": str(fold),
        "seed": str(seed),
        "schedule.epochs": "2",
        "schedule.finetune_epochs": "20",
        **{k: v for k, v in settings.items() if "." in k},
    }
    command = ["data=folder", f"data.path=/data/{dataset}", "split=folds", f"split.fold={fold}"]
    command += [f"model={model}", *overrides]
    tags = {
        "run_level": "parent",
        "row_hash": row_hash,
        "config_hash": f"{row_hash}-{fold}",
        "overrides": " ".join(command),
        "data.identity": f"{dataset}-{'0123456789ab'}",
        "data.labels": " ".join(LABELS),
        "data.layout": "none",
        "sweep_id": "bench",
    }
    rng = np.random.default_rng([fold, seed, *(ord(c) for c in dataset + (noise or model))])
    tested = [o for o in range(N_OBJECTS) if o % folds == fold]
    aucs = {}
    with tracker.run(f"{model}-concat-c1-s{seed}", params, tags) as job:
        for j, label in enumerate(LABELS):
            lines, ys, ss = ["unit,object_id,label,score"], [], []
            for o in tested:
                y = label_of(o, j)
                for u in range(UNITS):
                    score = quality * y + rng.normal(0, 0.5)
                    lines.append(f"{dataset}_{o}_{u},{o},{y},{score!r}")
                    ys.append(y)
                    ss.append(score)
            aucs[f"auc.{label}"] = roc_auc_score(ys, ss)
            child_tags = {"run_level": "child", "adjective": label}
            with tracker.run(f"adj={label}", {}, child_tags, job) as child:
                tracker.log_text(child, "\n".join(lines) + "\n", "scores.csv")
        tracker.log_metrics(job, {"mean_auc": float(np.mean(list(aucs.values()))), **aucs})
    return job


def scores(dataset: str, key: str, quality: float, seed: int = 0) -> stats.Evaluation:
    """Every object's pooled held-out units per label, as `log_job`'s folds pooled give them."""
    rng = np.random.default_rng([seed, *(ord(c) for c in dataset + key)])
    out = {}
    objects = np.repeat(np.arange(N_OBJECTS), UNITS)
    for j, label in enumerate(LABELS):
        y = np.array([label_of(o, j) for o in objects])
        out[label] = stats.HeldOut(objects, y, quality * y + rng.normal(0, 0.5, len(y)))
    return out


def group(
    dataset: str,
    model: str,
    quality: float,
    overrides: tuple[str, ...] = (),
    noise: str = "",
) -> tuple[Group, Evidence]:
    """A configuration on a data set, in memory: the group `runs.collect` would make of
    `log_job`'s runs, and its evidence (one seed, folds pooled)."""
    settings = {"model": model, **dict(o.split("=", 1) for o in overrides)}
    row_hash = f"{dataset}-{'-'.join(f'{k}={v}' for k, v in sorted(settings.items()))}"
    evaluation = scores(dataset, noise or model, quality)
    run = Run(
        run_id=f"{row_hash}-run",
        seed=0,
        start_time=0,
        mean_auc=float(np.mean([t.auc for t in evaluation.values()])),
        aucs={a: t.auc for a, t in evaluation.items()},
        data=f"{dataset}-0123456789ab",
        sweep_id="bench",
        labels=LABELS,
        layout="none",
    )
    g = Group(
        key=f"{row_hash}@{run.data}",
        row_hash=row_hash,
        method=f"{model}-concat-c1",
        row="",
        paper_auc=None,
        schedule="quick",
        schedule_epochs="2+20 epochs",
        split="folds",
        modality="signals",
        model=model,
        n_adjectives=len(LABELS),
        differences=(),
        params={"choice.model": model, "choice.schedule": "quick", "model.name": model}
        | {k: v for k, v in settings.items() if "." in k},
        overrides={k: v for k, v in settings.items()},
        runs={(0, -1): run},
    )
    return g, Evidence([evaluation])

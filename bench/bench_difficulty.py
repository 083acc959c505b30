"""How hard is the synthetic data set? Simple features + logistic regression, per adjective.

Haptic: per trial, per finger and EP, mean and std of baseline-subtracted PDC, TAC, TDC and the
electrode mean, PAC std, plus EP length and mean gripper aperture. Visual: per photograph, simple
features of the object in the V1 crop (``image_features``). Both: StandardScaler +
LogisticRegression trained on the published train split read from the file's split groups,
scored by ROC AUC on its test split (E1, E2); and, steadier, out-of-fold AUC of object-grouped
5-fold CV over all 60 objects (``cv_auc``).

    .venv/bin/python bench/bench_difficulty.py [--file PATH]   # default: the cached default
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import cv2
import h5py
import numpy as np
from sklearn.linear_model import LogisticRegression
from sklearn.metrics import roc_auc_score
from sklearn.model_selection import StratifiedGroupKFold
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from tactile_exp.data.layout import ADJECTIVES, BASELINE_STATE, EPS, TrialName, objects
from tactile_exp.data.phac2 import default_cache_dir
from tactile_exp.data.synthetic import SyntheticSpec, default_file
from tactile_exp.preprocess.visual import crop_box, crop_plate, find_plate

TOUCH_ONLY = ("absorbent", "squishy", "springy", "compressible")
SIGHT_MOSTLY = ("thick", "thin")
SIGHT_TOO = ("fuzzy", "hairy", "metallic", "textured", "bumpy", "smooth", "cool")


def haptic_features(g: h5py.Group) -> np.ndarray:
    state = g["state/controller_detail_state"][:]
    rest = state == BASELINE_STATE
    aperture = g["gripper_aperture/joint_position"][:]
    data = {
        (f, ch): g[f"biotacs/{f}/{ch}"][:].astype(float)
        for f in ("finger_0", "finger_1")
        for ch in ("pdc", "tac", "tdc", "electrodes", "pac")
    }
    for key, x in data.items():
        data[key] = x - x[rest].mean(axis=0)
    feats = []
    for ep in EPS.values():
        rows = state == ep
        feats += [rows.sum(), aperture[rows].mean()]
        for f in ("finger_0", "finger_1"):
            for ch in ("pdc", "tac", "tdc"):
                x = data[(f, ch)][rows]
                feats += [x.mean(), x.std()]
            e = data[(f, "electrodes")][rows].mean(axis=1)
            feats += [e.mean(), e.std(), data[(f, "pac")][rows].std()]
    return np.array(feats)


def image_features(path: Path) -> np.ndarray:
    """Simple features of the object in the V1 crop (plate found as in preprocessing).

    The object is the crop's centre band (half a plate radius wide) in the rows that differ
    from the background at the crop's sides. Features: its height and width; mean saturation
    and value and the value's spread; the fraction of specular pixels (near-white, grey);
    texture energy at a fine, a coarse and a bump scale; edge density in the object and in the
    whole crop; the fringe of strands just above the object's top.
    """
    img = cv2.imread(str(path))
    plate = find_plate(cv2.cvtColor(img, cv2.COLOR_BGR2RGB))
    x0 = crop_box(img.shape, plate)[0]
    crop = crop_plate(img, plate)  # padded at the image border, as V1
    f = crop.astype(np.float32)
    side = np.concatenate([f[:, :3], f[:, -3:]], axis=1).mean(axis=1)  # (rows, 3)
    differs = np.abs(f - side[:, None]).sum(axis=2) > 60
    mid, half = plate.cx - x0, 0.25 * plate.r
    band = slice(int(max(mid - half, 0)), int(mid + half) + 1)
    rows = differs[:, band].mean(axis=1) > 0.5
    if not rows.any():
        return np.zeros(12)
    top = int(np.argmax(rows))
    height = (len(rows) - top) / len(rows)
    fringe = differs[max(top - int(0.12 * plate.r), 0) : top].mean() if top else 0.0  # strands
    width = differs[rows].mean()
    hsv = cv2.cvtColor(crop, cv2.COLOR_BGR2HSV)[rows, band].reshape(-1, 3).astype(np.float32)
    s, v = hsv[:, 1], hsv[:, 2]
    specular = ((v > 235) & (s < 60)).mean()
    grey = cv2.cvtColor(crop, cv2.COLOR_BGR2GRAY).astype(np.float32)
    fine = cv2.GaussianBlur(grey, (0, 0), 1.0)
    coarse = cv2.GaussianBlur(grey, (0, 0), 4.0)
    relief = cv2.GaussianBlur(grey, (0, 0), 0.15 * plate.r)  # bumps are ~0.2 radii across
    edges = cv2.Canny(crop, 80, 160) > 0
    obj = (slice(None), band)
    return np.array(
        [
            height,
            width,
            s.mean() / 255,
            v.mean() / 255,
            v.std() / 255,
            specular,
            np.abs(grey - fine)[rows][:, band].mean() / 255,
            np.abs(fine - coarse)[rows][:, band].mean() / 255,
            np.abs(coarse - relief)[rows][:, band].mean() / 255,
            edges[obj][rows].mean(),
            edges.mean(),
            fringe,
        ]
    )


def auc(train_x, train_y, test_x, test_y) -> float:
    model = make_pipeline(StandardScaler(), LogisticRegression(C=1.0, max_iter=2000))
    model.fit(train_x, train_y)
    return float(roc_auc_score(test_y, model.decision_function(test_x)))


def split_names(f: h5py.File, adj: str) -> dict[str, dict[str, int]] | None:
    """part -> trial name -> label, from the file's split groups (None when absent)."""
    if adj not in f.get("train_test_sets", {}):
        return None
    out: dict[str, dict[str, int]] = {"train": {}, "test": {}}
    for group, label in (("train_test_sets", 1), ("train_test_negative_sets", 0)):
        for part in ("train", "test"):
            out[part].update(dict.fromkeys(f[f"{group}/{adj}/{part}"], label))
    return out


def cv_auc(x: np.ndarray, y: np.ndarray, groups: np.ndarray, seed: int = 0) -> float:
    """AUC of out-of-fold scores over all objects: object-grouped, label-stratified folds.

    Steadier than the published split's few test objects (1-3 positives for many adjectives).
    """
    positives = len(np.unique(groups[y == 1]))
    if positives < 2:
        return float("nan")
    folds = StratifiedGroupKFold(n_splits=min(5, positives), shuffle=True, random_state=seed)
    scores = np.empty(len(y))
    for train, test in folds.split(x, y, groups):
        model = make_pipeline(StandardScaler(), LogisticRegression(C=1.0, max_iter=2000))
        model.fit(x[train], y[train])
        scores[test] = model.decision_function(x[test])
    return float(roc_auc_score(y, scores))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--file", type=Path, default=None)
    ap.add_argument("--cache-dir", type=Path, default=default_cache_dir())
    args = ap.parse_args()
    path = args.file or default_file(args.cache_dir, SyntheticSpec())
    start = time.perf_counter()
    with h5py.File(path, "r") as f:
        names = [n for n in f if TrialName.parse(n)]
        feats = {n: haptic_features(f[n]) for n in names}
        splits = {a: split_names(f, a) for a in ADJECTIVES}
    print(f"haptic features of {len(names)} trials in {time.perf_counter() - start:.1f} s")
    info = {o.object_id: o for o in objects()}
    photos = {
        oid: sorted((path.parent / "photographs").glob(f"{o.group_stem}_[0-9][0-9].jpg"))
        for oid, o in info.items()
    }
    img = {oid: np.array([image_features(p) for p in ps]) for oid, ps in photos.items() if ps}
    trial_obj = np.array([TrialName.parse(n).object_id for n in names])
    hap_x = np.array([feats[n] for n in names])
    img_obj = np.concatenate([[o] * len(x) for o, x in img.items()])
    img_x = np.concatenate(list(img.values()))

    print("published split (E1) and object-grouped 5-fold CV over all 60 objects:")
    print(f"{'adjective':<13}{'haptic':>8}{'visual':>8}{'hap CV':>8}{'vis CV':>8}")
    rows = {}
    for adj in ADJECTIVES:
        label = {o: info[o].labels[adj] for o in info}
        hcv = cv_auc(hap_x, np.array([label[o] for o in trial_obj]), trial_obj)
        vcv = cv_auc(img_x, np.array([label[o] for o in img_obj]), img_obj)
        sp = splits[adj]
        if sp is None:
            print(f"{adj:<13}{'-':>8}{'-':>8}{hcv:8.3f}{vcv:8.3f}")
            continue
        xs = {p: np.array([feats[n] for n in sp[p]]) for p in sp}
        ys = {p: np.array(list(sp[p].values())) for p in sp}
        h = auc(xs["train"], ys["train"], xs["test"], ys["test"])
        obj = {p: {TrialName.parse(n).object_id: y for n, y in sp[p].items()} for p in sp}
        train_obj = {o: y for o, y in obj["train"].items() if o not in obj["test"] and o in img}
        test_obj = {o: y for o, y in obj["test"].items() if o in img}
        v = float("nan")
        if len(set(train_obj.values())) == 2 and len(set(test_obj.values())) == 2:
            parts = [
                (
                    np.concatenate([img[o] for o in d]),
                    np.concatenate([[y] * len(img[o]) for o, y in d.items()]),
                )
                for d in (train_obj, test_obj)
            ]
            v = auc(parts[0][0], parts[0][1], parts[1][0], parts[1][1])
        rows[adj] = (h, v, hcv, vcv)
        print(f"{adj:<13}{h:8.3f}{v:8.3f}{hcv:8.3f}{vcv:8.3f}")
    table = np.array(list(rows.values()))
    both = ~np.isnan(table[:, 1])
    print(f"mean haptic AUC {table[:, 0].mean():.3f} over {len(table)} adjectives")
    print(f"mean visual AUC {np.nanmean(table[:, 1]):.3f} over {both.sum()} adjectives")
    print(f"mean haptic AUC {table[both, 0].mean():.3f} over the same {both.sum()}")
    print(f"CV means: haptic {np.nanmean(table[:, 2]):.3f}, visual {np.nanmean(table[:, 3]):.3f}")
    for group in (TOUCH_ONLY, SIGHT_MOSTLY, SIGHT_TOO):
        g = np.nanmean([rows[a] for a in group if a in rows], axis=0)
        print(
            f"{'/'.join(group)}: haptic {g[0]:.3f}, visual {g[1]:.3f} "
            f"(CV: haptic {g[2]:.3f}, visual {g[3]:.3f})"
        )


if __name__ == "__main__":
    main()

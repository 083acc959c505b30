"""How hard is the synthetic data set? Simple features + logistic regression, per adjective.

Haptic: per trial, per finger and EP, mean and std of baseline-subtracted PDC, TAC, TDC and the
electrode mean, PAC std, plus EP length and mean gripper aperture. Visual: per photograph, mean
colour, colour std and edge density of the 2R x R crop above the plate (plate found by colour),
and the object's height (rows above the plate centre that differ from the image border).
Both: StandardScaler + LogisticRegression trained on the published train split read from the
file's split groups, scored by ROC AUC on its test split (E1, E2).

    .venv/bin/python bench/bench_difficulty.py [--file PATH]   # default: the cached default file
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
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from tactile_exp.data.layout import ADJECTIVES, BASELINE_STATE, EPS, TrialName, objects
from tactile_exp.data.synthetic import SyntheticSpec, default_file

TOUCH_ONLY = ("absorbent", "squishy", "springy")
SIGHT_MOSTLY = ("thick", "thin")


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
    img = cv2.imread(str(path))
    hsv = cv2.cvtColor(img, cv2.COLOR_BGR2HSV)
    plate = (hsv[..., 1] < 40) & (hsv[..., 2] > 140)
    ys, xs = np.nonzero(plate)
    cx = (xs.min() + xs.max()) / 2
    r = (xs.max() - xs.min()) / 2
    cy = ys.max() - 0.87 * r  # the plate's lowest point is cy + ry
    top, bottom = int(max(cy - 1.5 * r, 0)), int(max(cy - 0.5 * r, 1))
    crop = img[top:bottom, int(max(cx - r, 0)) : int(cx + r)]
    edges = cv2.Canny(cv2.cvtColor(crop, cv2.COLOR_BGR2GRAY), 80, 160)
    flat = crop.reshape(-1, 3).astype(float)
    # object height: rows above the plate centre whose middle differs from the image border
    rows = img[int(max(cy - 1.5 * r, 0)) : int(cy)].astype(float)
    middle = rows[:, int(cx - 0.2 * r) : int(cx + 0.2 * r)].mean(axis=1)
    border = np.concatenate([rows[:, :5], rows[:, -5:]], axis=1).mean(axis=1)
    height = (np.abs(middle - border).sum(axis=1) > 60).sum() / r
    return np.concatenate([flat.mean(axis=0), flat.std(axis=0), [edges.mean() / 255, height]])


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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--file", type=Path, default=None)
    ap.add_argument("--cache-dir", type=Path, default=Path("data_cache"))
    args = ap.parse_args()
    path = args.file or default_file(args.cache_dir, SyntheticSpec())
    start = time.perf_counter()
    with h5py.File(path, "r") as f:
        names = [n for n in f if TrialName.parse(n)]
        feats = {n: haptic_features(f[n]) for n in names}
        splits = {a: split_names(f, a) for a in ADJECTIVES}
    print(f"haptic features of {len(names)} trials in {time.perf_counter() - start:.1f} s")
    stems = {o.object_id: o.group_stem for o in objects()}
    photos = {
        oid: sorted((path.parent / "photographs").glob(f"{stem}_[0-9][0-9].jpg"))
        for oid, stem in stems.items()
    }
    img = {oid: np.array([image_features(p) for p in ps]) for oid, ps in photos.items() if ps}

    print(f"{'adjective':<13}{'haptic':>8}{'visual':>8}")
    rows = {}
    for adj in ADJECTIVES:
        sp = splits[adj]
        if sp is None:
            print(f"{adj:<13}{'-':>8}{'-':>8}")
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
        rows[adj] = (h, v)
        print(f"{adj:<13}{h:8.3f}{v:8.3f}")
    hap = np.array([r[0] for r in rows.values()])
    vis = np.array([r[1] for r in rows.values()])
    both = ~np.isnan(vis)
    print(f"mean haptic AUC {hap.mean():.3f} over {len(hap)} adjectives")
    print(f"mean visual AUC {np.nanmean(vis):.3f} over {both.sum()} adjectives")
    print(f"mean haptic AUC {hap[both].mean():.3f} over the same {both.sum()}")
    for group in (TOUCH_ONLY, SIGHT_MOSTLY):
        h = np.mean([rows[a][0] for a in group if a in rows])
        v = np.nanmean([rows[a][1] for a in group if a in rows])
        print(f"{'/'.join(group)}: haptic {h:.3f}, visual {v:.3f}")


if __name__ == "__main__":
    main()

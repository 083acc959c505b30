"""Tiny copies of each public upstream, written in its own layout (file names, formats), and a
recipe file that pins their checksum: what the public-data tests import. Nothing fetched."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import yaml

from tactile_exp.data.public import select, tree_sha256
from tactile_exp.data.readers import ICUB_SLICE
from tactile_exp.data.recipe import RECIPE_DIR, RECIPES

BIOTAC_HEADER = (
    "timestamp,tdc,tac,pdc,"
    + ",".join(f"pac{k}" for k in range(1, 23))
    + ","
    + ",".join(f"ele{k}" for k in range(1, 20))
)


def icub_values(obj: int, trial: int, k: int) -> list[list[float]]:
    """The 7 lines of time slice ``k`` of a trial: numbers that say where they are from."""
    return [[obj * 1000 + trial * 10 + k + j / 100 for j in range(n)] for n in ICUB_SLICE]


def write_icub(root: Path, slices: int = 2) -> Path:
    """iCubGraspDataset/<object>_<trial>.txt for the recipe's 10 objects x 20 trials, plus files
    the recipe leaves out (full_coke, a 21st trial) and the README."""
    folder = root / "iCubGraspDataset"
    folder.mkdir(parents=True)
    (root / "README.txt").write_text("iCub Grasp Dataset\n")
    objects = [*RECIPES.build("icub_grasp").objects, "full_coke"]
    for i, obj in enumerate(objects):
        for trial in range(1, 22 if obj == "none" else 21):
            lines = ["-10000"]
            for k in range(slices):
                lines += [" ".join(f"{v:g}" for v in row) for row in icub_values(i, trial, k)]
            (folder / f"{obj}_{trial}.txt").write_text("\n".join(lines) + "\n")
    return root


def write_biotac(root: Path, rows: int = 3) -> Path:
    """raw_data/matX/matX_N_bio.csv for 20 materials x 50 slides (a trailing comma on each row,
    as the upstream's), with a cartesian-position CSV beside each that is not a trial."""
    for m in range(1, 21):
        folder = root / "raw_data" / f"mat{m}"
        folder.mkdir(parents=True)
        for n in range(1, 51):
            body = [
                f"{1581073084 + k * 0.01:.6f}," + ",".join(str(m + n + k + c) for c in range(44))
                for k in range(rows)
            ]
            (folder / f"mat{m}_{n}_bio.csv").write_text(
                "\n".join([BIOTAC_HEADER, *(b + "," for b in body)]) + "\n"
            )
            (folder / f"mat{m}_{n}_cp.csv").write_text("x,y\n1,2\n")
    return root


def write_bolt(root: Path, trials: int = 2, frames: int = 6) -> Path:
    """training_tests/<object>.h5, each trial a group with finger_0 and finger_1 holding tdc,
    tac, pdc, pac (frames x 22) and electrodes (frames x 19), as PyTables wrote them."""
    folder = root / "training_tests"
    folder.mkdir(parents=True)
    for i, obj in enumerate(RECIPES.build("penn_bolt").objects):
        with h5py.File(folder / f"{obj}.h5", "w") as f:
            for t in range(1, trials + 1):
                g = f.create_group(f"{obj}_pdc100_1cm_{t:02d}")
                g["timestamps"] = np.arange(frames) // 100
                for finger in (0, 1):
                    base = i * 1000 + t * 100 + finger * 50
                    h = g.create_group(f"finger_{finger}")
                    h["tdc"] = np.full(frames, base + 1)
                    h["tac"] = np.full(frames, base + 2)
                    h["pdc"] = np.full(frames, base + 3)
                    h["pac"] = np.tile(np.arange(22) + base + 4, (frames, 1))
                    h["electrodes"] = np.tile(np.arange(19) + base + 30, (frames, 1))
    return root


def pinned_recipe(name: str, src: Path, out: Path) -> Path:
    """Recipe ``name`` with its sha256 pinned to the tiny files under ``src`` (a recipe file of
    one's own, as ``public import FILE.yaml`` reads it)."""
    node = yaml.safe_load((RECIPE_DIR / f"{name}.yaml").read_text())
    files = [f for fs in select(RECIPES.build(name), src).values() for f in fs]
    node["sha256"] = tree_sha256(src, files)
    out.write_text(yaml.safe_dump(node, sort_keys=False))
    return out

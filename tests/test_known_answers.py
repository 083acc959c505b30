# Cross-cutting, so not tests/test_<module>.py: whole jobs on data whose AUC is
# known, so a fault anywhere between the file and the logged AUC shows as a wrong number.
"""End-to-end jobs on data whose answer is known: labels written into the signals give an AUC
near 1, labels shuffled across objects give an AUC near chance.

The file has all 60 objects with 2 trials each; each of four adjectives drives its own scalar
channel (a ramp over the trial plus an offset for positives), everything else is noise.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
from phac2_fixture import N_ROWS, OBJECTS, trial_names, write_trial

from tactile_exp.config import settings_from_config
from tactile_exp.data.layout import ADJECTIVES
from tactile_exp.experiment import run

# adjective -> the channel (both fingers) its label drives; four with many positive objects (23-28
# of 60), so a 90/10 object split leaves 2-3 positive and 3-4 negative test objects each.
CHANNELS = {"smooth": "pac", "solid": "pdc", "hard": "tac", "compressible": "tdc"}
ADJS = "[" + ",".join(CHANNELS) + "]"
SEEDS = (0, 1, 2)


def write_known(path: Path, shuffle_seed: int | None) -> Path:
    """Signals carry each object's true labels; the file's labels are the true ones, or (with
    `shuffle_seed`) each adjective's labels permuted across the objects."""
    ids = sorted(OBJECTS)
    told = {o: set(OBJECTS[o].positives) for o in ids}
    if shuffle_seed is not None:
        rng = np.random.default_rng(shuffle_seed)
        told = {o: set() for o in ids}
        for adj in ADJECTIVES:
            holders = [o for o in ids if adj in OBJECTS[o].positives]
            for o in rng.permutation(ids)[: len(holders)]:
                told[int(o)].add(adj)
    ramp = np.linspace(0, 1800, N_ROWS).astype(np.int64)
    with h5py.File(path, "w") as f:
        for i, name in enumerate(trial_names(tuple(ids), 2)):
            obj = int(name[-6:-3])
            write_trial(f, name, (), seed=i)
            for adj, channel in CHANNELS.items():
                for finger in ("finger_0", "finger_1") if adj in OBJECTS[obj].positives else ():
                    data = f[f"{name}/biotacs/{finger}/{channel}"]
                    data[...] += ramp[:, None] if channel == "pac" else ramp
            del f[f"{name}/adjectives"]
            positives = [a.encode() for a in ADJECTIVES if a in told[obj]]
            f[f"{name}/adjectives"] = np.array(positives, dtype="S12")
    return path


def _mean_aucs(tiny_config, files: dict[int, Path]) -> list[float]:
    """Each seed's job (split and training seed) on its file: the mean AUCs."""
    out = []
    for seed, path in files.items():
        overrides = [
            "data=phac2",
            f"data.path={path}",
            "split=random",
            f"seed={seed}",
            "model=linear",
            "combine_instances=separate",
            "modality.steps=20",
            "modality.offsets=1",
        ]
        result = run(settings_from_config(tiny_config(overrides, adjectives=ADJS)))
        assert set(result.results) == set(CHANNELS)
        out.append(result.means["mean_auc"])
    return out


def test_labels_in_the_signals_give_mean_auc_above_0_9(tiny_config, tmp_path):
    path = write_known(tmp_path / "easy.h5", None)
    aucs = _mean_aucs(tiny_config, {s: path for s in SEEDS})
    assert min(aucs) > 0.9, aucs


def test_shuffled_labels_give_mean_auc_near_chance(tiny_config, tmp_path):
    """Under shuffled labels a test AUC over ~3 positive x ~4 negative objects has a standard
    deviation of about sqrt((3 + 4 + 1) / (12 * 3 * 4)) = 0.24 (Mann-Whitney, objects as the
    units); the mean over 4 adjectives x 3 seeds (each seed its own permutation and split) has
    about 0.24 / sqrt(12) = 0.07, so 0.5 +- 0.2 is a band of about 3 sigma."""
    files = {s: write_known(tmp_path / f"shuffled{s}.h5", 100 + s) for s in SEEDS}
    aucs = _mean_aucs(tiny_config, files)
    assert abs(np.mean(aucs) - 0.5) < 0.2, aucs

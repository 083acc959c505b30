"""Synthetic PHAC-2: the embedded default data set, written in the real file layout (D5).

The real release cannot be downloaded here, so every code path runs on a file this module writes.
It uses the 60 real objects, their labels and the published split (``layout``), and the exact
layout of PHAC2_FORMAT.md §1: datasets, shapes, dtypes, S30 state strings, hard links.

Generative model
----------------
Labels never enter a signal directly. Each object first gets latent physical properties in [0, 1],
drawn (seeded) from a per-material base, plus label effects, plus object noise (``_NOISE``):
stiffness, roughness, thermal effusivity, friction, thickness, hairiness, porosity, springiness,
stickiness, crinkliness, bumpiness, and visual ones (hue, saturation, value, gloss, texture
contrast, size; metalness and transparency are seen only, drawn from their own random stream so
adding them moved no haptic property). ``draw_object_properties`` draws a new object of a
material the same way without label effects (visual pre-training). Two derived quantities set
the mechanics: ``indent_500`` (indentation in m at which the firmer finger reads +500 counts;
20 mm soft ... 1.2 mm stiff) and ``grip_width`` (object width between the fingers; mostly
object shape, only weakly thickness).
Every signal then follows from the properties through simple physics:

- gripper: the controller of §1.4 (tap, squeeze, hold, two slides, every detail state). The
  squeeze closes at 2.5 mm/s until max PDC over the fingers reaches baseline + 500, then reopens
  until it falls to +10; hold closes to 50 % of that travel, slides to 20 % / 10 %. Stiff objects
  therefore give a steep PDC rise and little travel; thick ones a slightly wider aperture.
- PDC: 500 * (indentation / indent_500) ** n per finger (per-trial finger share), n = 1.3 (near
  Hertz, solids) up to 1.8 for soft porous foams (cell collapse, then densification), so the
  squeeze rise *shape* carries the material. Then a standard linear solid: 2 ... 37 % of the
  load relaxes (porosity, viscous softness) with a time constant of 0.7 s (open cells) ... 4.2 s
  (dense); non-springy soft objects recover slowly after unloading (0.2 ... 2.2 s, pressure falls
  faster than it rose), sticky ones release late, springy soft ones ring at 1 ... 3.5 Hz.
- PAC (2200 Hz, 22 per row, column offsets of §1.5): rest noise, contact noise, make/break
  transients and rare full-scale spikes; while sliding, a random surface profile swept at the
  slide speed (asperity spacing 0.3 mm fine ... 3 mm coarse by roughness, so the vibration sits
  near speed / spacing: 3-33 Hz in the slow slide, 8-83 Hz in the fast one; 10 Hz AC coupling),
  broadband fibre noise (hairiness), bump impulses (bumpiness, spaced along the slide) and
  stick-slip bursts (stickiness, friction); crackle while squeezing crinkly objects. Impulses
  ring through a 250 Hz resonator. The vibration's amplitude scales with the label-free contact
  area and the pressure; its frequency content does not.
- TAC: contact heat-flux transient, +60 ... +160 counts by effusivity times a per-trial
  sensor-minus-object temperature factor (0.6 ... 1.4), negative at release; it decays with the
  thermal time constant, 0.8 s (metal, glass draw heat fast) ... 4.8 s (insulators). TDC: drift
  over the run from +8 (insulating) to -13 (metal, glass), a per-contact cooling step with the
  same time constant, plus sensor random walk.
- electrodes: per-finger baseline pattern of §5, a pressure-driven pattern (E7-E10, E17 down;
  E1, E4, E6, E11, E14, E16 up) and a large local drop at the contact edge, mirrored between the
  fingers (E1..E6 <-> E11..E16); shear by friction and a bump pattern while sliding.
- photographs (``render``): height from thickness (strongly), width from size, colour, grain
  (roughness, texture contrast), shaded bumps, a specular streak (gloss), banded reflections
  (metalness), the background through glass (transparency), soft outline and strands
  (hairiness). Touch-only properties (stiffness, porosity, springiness, ...) are not drawn.
  The 8 views differ in what they show (version 5): low side views show the height, high
  close top views the surface (grain, bumps, fuzz, lustre); some views are defocused or partly
  occluded, so one view is a partial measurement and the 8 together tell more.

Noise: object properties scatter around material + label effects with sigma 0.32 (0.12 for
thickness, size, metalness and transparency, 0.18 for the other appearance properties), and a
label-free object "contact area" (0.5 ... 1.5) scales thermal and texture responses. Per trial:
every property again (sigma 0.12), finger shares and contact position, stiffness (+-10 %), grip
width, speeds and durations, sensor baselines and drift. Absorbent, squishy and springy act only
through touch; thick and thin mostly through sight (the gripper sees thickness weakly and noisily);
nice and unpleasant only through the weak label effects of ``_LABEL_EFFECTS``.

File: the real file's filters, gzip + shuffle, with one chunk per trial dataset (the real file
has PyTables' chunks of ~64 KiB, e.g. (431, 19); whatever reads the real file reads this). The
generator applies both filters itself, ``_write_array``: the shuffle as a byte transpose, the
deflate by ISA-L (``isal``, its level 1; the filter records gzip level 1) at about a seventh of
zlib's level-1 CPU, which was three quarters of the write time, in a 2 % smaller file. One chunk
per dataset also reads faster (fewer chunks) although ISA-L's streams inflate ~25 % slower than
zlib's. Objects are spread over worker processes one at a time, each writing a part file that is
copied in without recompression; the parent logs progress.

Measured with ``bench/bench_data.py --before REV`` (2026-11-26, the 2-core development machine
shared with another job; REV = the previous generator: HDF5's zlib level 1, h5py's automatic
chunks such as (1042, 3) for an (8329, 19) array): the full default file holds the same arrays,
attributes, links and JPEG bytes; generating it took 81.4 / 69.6 -> 46.9 / 45.3 s CPU and 47.1 /
35.4 -> 23.8 / 23.0 s wall (2 rounds each, alternating); the file is 600 -> 588 MB; reading every
trial's datasets 23.6 / 19.5 -> 14.8 / 15.4 s. Part of the CPU saving is in the simulation and
the rendering: the same operations on the same values in fewer passes.

Generator version 5 = version 4 with photographs whose views differ in what they show
(``render``: a camera elevation per view index, from low side views that show the height to
high close top views that show the surface, plus per-view defocus and occlusion). Only the
photographs changed: the trials (every HDF5 array) are bit-identical to version 4's, checked by
``tests/test_synthetic.py``, so haptic results measured on version 4 hold.
Measured on version 5 (full default file, seed 0): ``bench_difficulty``'s simple per-photograph
features score lower, since one view is now a partial measurement: visual E1 0.622 (version 4
0.693), CV 0.663 (0.709); thick/thin by sight E1 0.740 (0.889), CV 0.798 (0.954), still above
touch (0.636, CV 0.551); touch-only absorbent/squishy/springy/compressible by sight E1 0.361
(touch 0.647). The views now differ: 45 % of these features' variance lies within objects
(version 4: 10 %), 34 % of the pretrained trunk's (10.5 %). Rows K and L: README.

Generator version 4 = version 3's photographs (what sight can tell) + version 3's dynamics,
developed side by side; the two sections below were measured on each change
alone (the other part at version 2). Re-measured on version 4 with ``bench_difficulty.py``:
haptic E1 0.774 (CV 0.744), visual E1 0.693 (CV 0.709), thick/thin by sight 0.889 vs touch
0.636: the same figures as each change alone, since the visual properties are drawn from
their own random stream and the haptic signals never read them.

Photographs. Difficulty, measured on the full default file (seed 0, generator version 3) with
``TACTILE_EXP_CACHE=... .venv/bin/python bench/bench_difficulty.py``: per-trial mean/std features
per EP and finger, and simple features of the object in each photograph's V1 crop (height,
width, saturation, value, specular fraction, texture energy at three scales, edge density,
strand fringe); StandardScaler + LogisticRegression on the published train split, ROC AUC on its
test split ("E1"), and out-of-fold AUC of object-grouped 5-fold CV over all 60 objects ("CV").
The published test sets hold 1-3 positive objects for most adjectives, so E1 AUCs swing with
single objects; CV is steadier.

- haptic: E1 mean AUC 0.849 over the 24 adjectives (0.829 over the 21 with a visual score);
  weakest smooth 0.56, soft 0.64, bumpy 0.64, textured 0.64; strongest rough, sticky 1.00.
- visual: E1 mean AUC 0.693 over 21 adjectives (nice, sticky, unpleasant have one positive
  object, split by trial), CV 0.709. Generator version 2 scored 0.645 (E1) and 0.700 (CV) with
  the same features, 0.504 (E1) with the earlier, cruder ones.
- thick/thin, by sight vs touch: E1 0.81/0.97 vs 0.38/0.94, CV 0.93/0.98 vs 0.33/0.84.
- seen adjectives, visual E1 (CV): fuzzy 0.94 (0.46), hairy 0.62 (0.88), metallic 1.00 (0.95),
  textured 0.84 (0.73), bumpy 0.75 (0.47), smooth 0.62 (0.71), cool 0.99 (0.80); mean 0.82
  (haptic 0.80). Fuzzy and bumpy have 7 and 3 positive objects and the latent hairiness and
  bumpiness scatter (noise 0.32), so CV's few-positive folds are weak for them.
- touch-only absorbent/squishy/springy/compressible by sight: E1 0.19/0.43/0.01/0.63 (touch
  0.73/0.68/0.76/0.82), CV 0.74/0.51/0.75/0.58. Nothing of porosity, stiffness or springiness is
  drawn; what sight finds is the material (foam: thick, saturated), and on the published split
  that cue inverts (springy's one test positive is a thin, glossy silicone block).

Haptic dynamics. Difficulty, measured on the full default file (seed 0, published splits).
``bench_difficulty``: per-trial mean/std features per EP and finger, StandardScaler +
LogisticRegression on the train split, ROC AUC on its test split (``PYTHONPATH=$PWD
.venv/bin/python bench/bench_difficulty.py --cache-dir DIR``). Generator version 2 -> 3
(3: dynamics carry the physics):

- haptic: mean AUC 0.849 -> 0.774 over the 24 adjectives (0.829 -> 0.751 over the 21 with a
  visual score). Version 3: weakest springy 0.18, smooth 0.33, thick 0.45, bumpy 0.54; strongest
  porous, sticky 1.00. Lower because amplitudes now carry nuisances (temperature difference,
  contact area) while time constants and spectra, which these features do not see, carry the
  properties.
- visual (mean colour, colour std, edge density and height of the crop): mean AUC 0.50 over 21
  adjectives in both (nice, sticky, unpleasant have one positive object, split by trial). Such
  tiny features miss most of the appearance cues (random hue dominates the colour mean), and
  material confounds invert some small test sets (hard 0.02, fuzzy 0.00).
- touch-only absorbent/squishy/springy: haptic 0.72 -> 0.55 vs visual 0.35; thick/thin: haptic
  0.66 -> 0.64 vs visual 0.80.

Levels vs dynamics (``PYTHONPATH=$PWD .venv/bin/python bench/bench_dynamics.py``): logistic
regressions on the P1-P6 ConvNet inputs (normaliser and PCA fitted per split), mean test AUC over
24 adjectives, version 2 -> 3: levels (per-channel mean/std) 0.824 -> 0.745; first-difference
mean/std 0.842 -> 0.794; level- and amplitude-free shape (band energy fractions, block means)
0.771 -> 0.820; both dynamic sets 0.809 -> 0.831; the flattened input 0.695 -> 0.706.
"""

from __future__ import annotations

import fcntl
import hashlib
import json
import logging
import math
import os
import shutil
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass
from pathlib import Path

import cv2
import h5py
import numpy as np
from isal import isal_zlib
from scipy.signal import lfilter

from tactile_exp import pools
from tactile_exp.data import render
from tactile_exp.data.layout import (
    ADC_MAX,
    ADJECTIVES,
    NEGATIVE_SPLIT_GROUP,
    PAC_PER_ROW,
    POSITIVE_SPLIT_GROUP,
    ROW_RATE_HZ,
    ObjectInfo,
    objects,
    published_test_split,
)

GENERATOR_VERSION = 5
log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SyntheticSpec:
    """What to generate. Small specs (duration_scale ~0.1, trials 2) keep tests fast."""

    seed: int = 0
    object_ids: tuple[int, ...] | None = None  # None = all 60 real objects
    trials: int = 10  # trials per object
    duration_scale: float = 1.0  # scales EP and other state lengths
    views: int = 8  # photographs per object
    image_width: int = 480
    image_height: int = 320

    def __post_init__(self) -> None:
        if not 1 <= self.trials <= 99:
            raise ValueError(f"SyntheticSpec.trials={self.trials}: expected 1..99")
        if not 0.01 <= self.duration_scale <= 10:
            raise ValueError(
                f"SyntheticSpec.duration_scale={self.duration_scale}: expected 0.01..10"
            )
        if self.views < 0:
            raise ValueError(f"SyntheticSpec.views={self.views}: expected >= 0")
        if min(self.image_width, self.image_height) < 32:
            raise ValueError(
                f"SyntheticSpec image {self.image_width}x{self.image_height}: expected >= 32x32"
            )
        if self.object_ids is not None:
            known = {o.object_id for o in objects()}
            unknown = sorted(set(self.object_ids) - known)
            if unknown or not self.object_ids:
                raise ValueError(
                    f"SyntheticSpec.object_ids: unknown ids {unknown} (expected a non-empty "
                    "subset of the 60 PHAC-2 object ids)"
                )


def _objects(spec: SyntheticSpec) -> list[ObjectInfo]:
    wanted = None if spec.object_ids is None else set(spec.object_ids)
    return [o for o in objects() if wanted is None or o.object_id in wanted]


# ------------------------------------------------------------------------- latent object model
_PROPS = (
    "stiffness", "roughness", "effusivity", "friction", "thickness", "hairiness", "porosity",
    "springiness", "stickiness", "crinkliness", "bumpiness",
    "saturation", "value", "gloss", "texture_contrast", "size",
)  # fmt: skip
_MATERIAL_BASE: dict[str, tuple[float, ...]] = {  # in the order of _PROPS
    "foam":    (.12, .30, .05, .50, .55, .05, .50, .40, .05, .02, .20, .60, .70, .05, .35, .60),
    "plastic": (.75, .20, .40, .35, .45, .00, .05, .20, .05, .10, .10, .55, .60, .50, .15, .55),
    "paper":   (.60, .25, .20, .40, .35, .02, .20, .15, .00, .15, .05, .50, .70, .25, .20, .60),
    "fabric":  (.25, .40, .15, .55, .30, .35, .40, .20, .05, .05, .15, .45, .60, .05, .40, .55),
    "organic": (.60, .55, .25, .60, .50, .30, .40, .15, .05, .10, .30, .50, .50, .05, .60, .55),
    "stone":   (.97, .70, .60, .60, .60, .00, .35, .00, .00, .00, .35, .35, .50, .05, .60, .60),
    "glass":   (.97, .02, .80, .20, .45, .00, .00, .00, .05, .00, .00, .30, .70, .90, .05, .50),
    "metal":   (1.0, .10, 1.0, .25, .50, .00, .00, .00, .00, .00, .05, .10, .60, .85, .10, .55),
}  # fmt: skip
MATERIALS: tuple[str, ...] = tuple(_MATERIAL_BASE)  # draw_object_properties accepts these
_LABEL_EFFECTS: dict[str, dict[str, float]] = {
    "absorbent": {"porosity": 0.25},
    "bumpy": {"bumpiness": 0.5, "texture_contrast": 0.15},
    "compressible": {"stiffness": -0.15},
    "cool": {"effusivity": 0.3},
    "crinkly": {"crinkliness": 0.6},
    "fuzzy": {"hairiness": 0.3, "roughness": 0.05},
    "hairy": {"hairiness": 0.45},
    "hard": {"stiffness": 0.15},
    "metallic": {"effusivity": 0.15, "gloss": 0.3, "saturation": -0.2},
    "nice": {"friction": -0.05, "roughness": -0.05},  # subjective: weak
    "porous": {"porosity": 0.3, "texture_contrast": 0.05},
    "rough": {"roughness": 0.35, "friction": 0.1, "texture_contrast": 0.2},
    "scratchy": {"roughness": 0.25, "hairiness": 0.1},
    "slippery": {"friction": -0.3, "gloss": 0.2},
    "smooth": {"roughness": -0.2, "texture_contrast": -0.15, "gloss": 0.1},
    "soft": {"stiffness": -0.12},
    "solid": {"stiffness": 0.1},
    "springy": {"springiness": 0.5},
    "squishy": {"stiffness": -0.15, "springiness": 0.1},
    "sticky": {"stickiness": 0.7, "friction": 0.3},
    "textured": {"roughness": 0.15, "bumpiness": 0.2, "texture_contrast": 0.25},
    "thick": {"thickness": 0.35, "size": 0.2},
    "thin": {"thickness": -0.35},
    "unpleasant": {"roughness": 0.05, "hairiness": 0.05},  # subjective: weak
}
_NOISE = 0.32  # object-level property noise (sigma, in property units) ...
_SHARP = {  # ... except these: thick/thin stay visible, appearance is less noisy than touch
    "thickness": 0.12, "size": 0.12, "saturation": 0.18, "value": 0.18, "gloss": 0.18,
    "texture_contrast": 0.18,
}  # fmt: skip
_TRIAL_NOISE = 0.12  # per-trial: contact position and local variation of the surface


_VISUAL_PROPS = ("metalness", "transparency")  # seen only: no signal reads them
_VISUAL_BASE: dict[str, tuple[float, float]] = {  # in the order of _VISUAL_PROPS
    "foam": (0.0, 0.0), "plastic": (0.08, 0.08), "paper": (0.0, 0.0), "fabric": (0.0, 0.0),
    "organic": (0.0, 0.0), "stone": (0.05, 0.0), "glass": (0.2, 0.65), "metal": (0.85, 0.0),
}  # fmt: skip
_VISUAL_LABEL_EFFECTS = {"metallic": {"metalness": 0.4}}
_VISUAL_NOISE = 0.12


def object_properties(spec: SyntheticSpec) -> dict[int, dict[str, float]]:
    """Latent properties of each object of ``spec`` (the only input of every signal and image)."""
    return {obj.object_id: _properties(spec.seed, obj) for obj in _objects(spec)}


def _properties(seed: int, obj: ObjectInfo) -> dict[str, float]:
    """One object's latent properties, from its own seeded streams."""
    rng = np.random.default_rng([seed, obj.object_id, 0])
    visual_rng = np.random.default_rng([seed, obj.object_id, 0, 1])  # own stream
    return _draw(obj.material, obj.positives, rng, visual_rng)


def draw_object_properties(material: str, rng: np.random.Generator) -> dict[str, float]:
    """Latent properties of a newly drawn object of ``material`` (one of ``_MATERIAL_BASE``).

    Drawn like the 60 objects' (material base plus the same object noise) but with no label
    effects, so new objects (e.g. for visual pre-training) carry nothing of the 60's labels.
    """
    if material not in _MATERIAL_BASE:
        raise ValueError(f"material {material!r}: expected one of {sorted(_MATERIAL_BASE)}")
    return _draw(material, (), rng, rng)


def _draw(
    material: str,
    positives: tuple[str, ...],
    rng: np.random.Generator,
    visual_rng: np.random.Generator,
) -> dict[str, float]:
    base = dict(zip(_PROPS, _MATERIAL_BASE[material], strict=True))
    visual = dict(zip(_VISUAL_PROPS, _VISUAL_BASE[material], strict=True))
    for adj in positives:
        for prop, delta in _LABEL_EFFECTS[adj].items():
            base[prop] += delta
        for prop, delta in _VISUAL_LABEL_EFFECTS.get(adj, {}).items():
            visual[prop] += delta
    props = {
        k: float(np.clip(v + rng.normal(0, _SHARP.get(k, _NOISE)), 0, 1)) for k, v in base.items()
    }
    props["hue"] = float(rng.uniform(0, 1))
    props["contact_area"] = float(rng.uniform(0.5, 1.5))  # shape nuisance, label-free
    soft, hard = math.log(20e-3), math.log(1.2e-3)
    props["indent_500"] = math.exp(soft + (hard - soft) * props["stiffness"])
    shape = float(rng.uniform(0, 0.04))  # object width between the fingers, not thickness
    width = 0.012 + 0.012 * props["thickness"] + shape
    props["grip_width"] = max(width, props["indent_500"] + 0.004)
    for k, v in visual.items():
        props[k] = float(np.clip(v + visual_rng.normal(0, _VISUAL_NOISE), 0, 1))
    return props


# ------------------------------------------------------------------------------ trial signals
_SLOW, _FAST, _POSITION_SPEED = 2.5e-3, 25e-3, 5e-3  # gripper speeds, m/s (PB:ctrl)
_OPEN_MAX = 0.08
_E_BASE = np.array(
    [
        [3236, 3664, 3660, 3549, 3647, 3465, 3274, 3400, 3374, 3475,
         3078, 3614, 3642, 3478, 3629, 3507, 3602, 3659, 3626],
        [3187, 3660, 3672, 3548, 3654, 3479, 3322, 3422, 3432, 3516,
         3156, 3659, 3683, 3546, 3650, 3519, 3621, 3677, 3556],
    ],
    dtype=float,
)  # fmt: skip
_MIRROR = np.array([10, 11, 12, 13, 14, 15, 6, 7, 8, 9, 0, 1, 2, 3, 4, 5, 16, 17, 18])
_E_PRESS = np.zeros(19)  # finger_0 response per +150 counts of PDC
_E_PRESS[[6, 7, 8, 9, 16]] = -45.0
_E_PRESS[[0, 3, 5, 10, 13, 15]] = 35.0
_E_EDGE = np.zeros(19)  # finger_0 local drop at +500 (E11, E12); finger_1 gets E1, E2
_E_EDGE[[10, 11]] = [-700.0, -220.0]
_E_SHEAR = np.zeros(19)
_E_SHEAR[[1, 2, 4, 11, 12, 14]] = [20.0, 12.0, -12.0, -20.0, -12.0, 12.0]
_E_EDGE_COLS = (np.flatnonzero(_E_EDGE), np.flatnonzero(_E_EDGE[_MIRROR]))  # per finger
_E_SHEAR_COLS = (np.flatnonzero(_E_SHEAR), np.flatnonzero(_E_SHEAR[_MIRROR]))
_PAC_BASE = (2054.5, 2030.5)
_PAC_COL_OFFSET = np.zeros(PAC_PER_ROW)
_PAC_COL_OFFSET[:4] = [-2.0, -1.5, -1.0, -0.5]
_PAC_COL_OFFSET[19:] = [2.0, 3.0, 4.0]
_PAC_RATE = ROW_RATE_HZ * PAC_PER_ROW
_GZIP_LEVEL = 1  # ISA-L's level 1 (of 0-3); the gzip filter records it too


def _lowpass(x: np.ndarray, tau_rows: float) -> np.ndarray:
    a = math.exp(-1.0 / max(tau_rows, 1e-3))
    return lfilter([1 - a], [1, -a], x, axis=0)


def _resonator(x: np.ndarray, freq: float, zeta: float, rate: float) -> np.ndarray:
    """Damped ringing at ``freq`` Hz excited by ``x`` (impulse response peaks near 1)."""
    w0 = 2 * math.pi * freq / rate
    r = math.exp(-zeta * w0)
    w = w0 * math.sqrt(1 - zeta**2)
    return lfilter([math.sin(w)], [1, -2 * r * math.cos(w), r * r], x, axis=0)


def _pressure(delta: np.ndarray, p: dict[str, float], shares: np.ndarray, rows_s: float):
    """Noise-free PDC above baseline, (n, 2), for an indentation trajectory (m per row).

    Elastic law 500 * u ** n (u = indentation / indent_500): n = 1.3 near Hertz for solids, up
    to 1.8 for soft porous foams (cell collapse, then densification), so the squeeze rise shape
    depends on the material, not only its duration. Then a standard linear solid: a fraction of
    the load relaxes with a time constant set by porosity (air leaving open cells is quick) and
    viscous softness; non-springy soft objects recover slowly after unloading (pressure falls
    faster than it rose); sticky ones release late; springy soft ones ring at a frequency that
    rises with springiness.
    """
    soft = 1 - p["stiffness"]
    n_exp = 1.3 + 0.5 * p["porosity"] * soft
    el = 500 * (np.clip(delta, 0, None) / p["indent_500"]) ** n_exp
    el = el[:, None] * shares[None, :]
    relaxed = 0.02 + 0.25 * p["porosity"] + 0.1 * (1 - p["springiness"]) * soft
    tau_relax = (0.7 + 3.5 * (1 - p["porosity"])) * rows_s
    recover = (0.2 + 2.0 * (1 - p["springiness"])) * rows_s
    unload = np.clip(_lowpass(el, recover) - el, 0, None)
    release = np.clip(_lowpass(el, 1.0 * rows_s) - el, 0, None)
    ring_hz = 1.0 + 2.5 * p["springiness"]
    rebound = _resonator(np.diff(el, axis=0, prepend=0), ring_hz / rows_s, 0.12, 1.0)
    return (
        el
        - relaxed * _lowpass(el, tau_relax)
        + 0.8 * p["stickiness"] * release
        - 0.5 * (1 - p["springiness"]) * soft * unload
        + 2.0 * p["springiness"] * soft * rebound
    )


class _Timeline:
    """Accumulates controller states with the gripper aperture and arm height of every row."""

    def __init__(self, scale: float, rng: np.random.Generator) -> None:
        self.rows_s = ROW_RATE_HZ * scale  # rows per (unscaled) second
        self.rng = rng
        self.detail: list[tuple[str, int]] = []
        self.code: list[np.ndarray] = []
        self.g: list[np.ndarray] = [np.array([_OPEN_MAX])]
        self.z: list[np.ndarray] = [np.array([0.25])]

    @property
    def gripper(self) -> float:
        return float(self.g[-1][-1])

    @property
    def height(self) -> float:
        return float(self.z[-1][-1])

    def rows(self, seconds: float, jitter: float = 0.08) -> int:
        return max(2, round(seconds * self.rows_s * self.rng.uniform(1 - jitter, 1 + jitter)))

    def add(self, state: str, code: int, g: np.ndarray, z: np.ndarray | None = None) -> None:
        n = len(g)
        self.detail.append((state, n))
        self.code.append(np.full(n, code))
        self.g.append(g)
        self.z.append(np.full(n, self.height) if z is None else z)

    def move(self, state: str, code: int, target: float, speed: float, wait_s: float = 0.0):
        n = max(2, math.ceil(abs(target - self.gripper) / (speed / self.rows_s)))
        g = np.linspace(self.gripper, target, n + 1)[1:]
        if wait_s:
            g = np.concatenate([g, np.full(self.rows(wait_s), target)])
        self.add(state, code, g)

    def wait(self, state: str, code: int, seconds: float, dz: float = 0.0, jitter: float = 0.08):
        n = self.rows(seconds, jitter)
        z = np.linspace(self.height, self.height + dz, n + 1)[1:]
        self.add(state, code, np.full(n, self.gripper), z)

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return np.concatenate(self.g[1:]), np.concatenate(self.z[1:]), np.concatenate(self.code)


def _controller(p: dict[str, float], w: float, shares: np.ndarray, tl: _Timeline) -> float:
    """Run the controller of §1.4 into ``tl``; returns the squeeze travel (m)."""
    tl.wait("DISABLED", 0, 0.5)
    tl.wait("OPEN_GRIPPER_MAX", 0, 2.0)
    n = tl.rows(4.0)
    z = np.linspace(tl.height, 0.05, n + 1)[1:]
    tl.add("MOVE_ARM_START_POSITION", 0, np.full(n, _OPEN_MAX), z)
    tl.code[-1][n // 2 :] = 7
    tl.move("MOVE_GRIPPER_FAST_CLOSE", 5, w - 0.3 * p["indent_500"], _FAST)
    tl.move("OPEN_GRIPPER_BY_2CM_FAST", 5, tl.gripper + 0.02, _FAST, wait_s=0.3)
    tl.move("FIND_CONTACT_CLOSE_GRIPPER_SLO", 3, w, _SLOW)

    step = _SLOW / tl.rows_s
    g_prefix = tl.arrays()[0]
    close = w - step * np.arange(1, math.ceil(3.0 * p["indent_500"] / step) + 2)
    pdc = _pressure(w - np.concatenate([g_prefix, close]), p, shares, tl.rows_s)
    above = np.flatnonzero(pdc[len(g_prefix) :].max(axis=1) >= 500)
    close = close[: (above[0] + 1 if above.size else len(close))]
    travel = w - float(close[-1])
    reopen = close[-1] + step * np.arange(1, math.ceil(travel / step) + int(8 * tl.rows_s))
    traj = np.concatenate([g_prefix, close, reopen])
    pdc = _pressure(w - traj, p, shares, tl.rows_s)[len(g_prefix) + len(close) :]
    below = np.flatnonzero(pdc.max(axis=1) <= 10)
    reopen = reopen[: (below[0] + 1 if below.size else len(reopen))]
    tl.add("SQUEEZE_SET_PRESSURE_SLOW", 3, np.concatenate([close, reopen]))

    tl.move("OPEN_GRIPPER_BY_2CM_FAST", 3, tl.gripper + 0.02, _FAST, wait_s=1.0)
    tl.move("CLOSE_GRIPPER_SLOW_TO_POSITION", 1, w - 0.5 * travel, _POSITION_SPEED)
    tl.wait("HOLD_FOR_10_SECONDS", 1, 10.0, jitter=0.01)
    tl.move("OPEN_GRIPPER_BY_2CM_FAST", 1, tl.gripper + 0.02, _FAST)
    tl.wait("MOVE_UP_START_HEIGHT", 1, 3.0, dz=0.05)
    slides = ((2, 0.2, "SLIDE_5CM", 5.0), (6, 0.1, "MOVE_DOWN_5CM", 2.0))
    for code, fraction, slide, slide_s in slides:
        tl.move("CLOSE_GRIPPER_SLOW_TO_POSITION", code, w - fraction * travel, _POSITION_SPEED)
        tl.wait(slide, code, slide_s, dz=-0.05, jitter=0.05)
        tl.wait("SLIDE_DONE_WAIT_5", code, 5.0)
        tl.move("OPEN_GRIPPER_FAST_2CM", code, tl.gripper + 0.02, _FAST)
        if code == 2:
            tl.wait("MOVE_UP_5CM", code, 3.0, dz=0.05)
    tl.move("OPEN_GRIPPER_FAST_MAX", 6, _OPEN_MAX, _FAST, wait_s=1.0)
    return travel


def _texture(p: dict[str, float], pos: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Unit-variance skin vibration from a random surface profile swept at positions ``pos``.

    The profile's asperities are spaced ~``wavelength`` apart (0.3 mm fine ... 3 mm coarse, by
    roughness), so sliding at speed v puts the vibration near v / wavelength: 3-33 Hz in the
    slow slide (1 cm/s), 8-83 Hz in the fast one (2.5 cm/s), as Fishel & Loeb's fineness (the
    spectral centroid) follows texture spacing and speed. PAC is AC-coupled (10 Hz high-pass).
    """
    wavelength = 0.3e-3 * math.exp(2.3 * p["roughness"])
    dx = wavelength / 8
    lo = float(pos.min())
    grid = rng.standard_normal(int((float(pos.max()) - lo) / dx) + 2)
    profile = _resonator(grid, 1 / 8, 0.15, 1.0)
    h = np.interp(pos, lo + dx * np.arange(len(grid)), profile / (profile.std() + 1e-12))
    return h - _lowpass(h, _PAC_RATE / (2 * math.pi * 10.0))


def _pac(
    p: dict[str, float],
    finger: int,
    pdc: np.ndarray,
    slide_pos: np.ndarray,
    squeezing: np.ndarray,
    rng: np.random.Generator,
) -> np.ndarray:
    """(N, 22) PAC counts of one finger.

    Per-sample values that only depend on the row are computed per row and then repeated, and
    the sample-rate arrays are updated in place: the same operations on the same values as the
    plain expressions in the comments, so the counts are the same bits, at less CPU.
    """
    n = len(pdc)
    contact = np.clip(pdc / 40.0, 0, 1)
    c22 = np.repeat(contact, PAC_PER_ROW)
    pos = np.interp(np.arange(n * PAC_PER_ROW) / PAC_PER_ROW, np.arange(n), slide_pos)
    sliding = np.diff(pos, prepend=pos[0])  # c22 * clip(|diff(pos)| * rate / 0.01, 0, 3)
    np.abs(sliding, out=sliding)
    sliding *= _PAC_RATE  # m/s
    sliding /= 0.01
    np.clip(sliding, 0, 3, out=sliding)
    sliding *= c22
    press = np.repeat(np.sqrt(np.clip(pdc / 100.0, 0, 1.5)), PAC_PER_ROW)
    gain = np.sqrt(sliding)  # contact_area * sqrt(sliding) * press
    np.multiply(p["contact_area"], gain, out=gain)
    gain *= press
    # sigma = uniform + 2.5 * c22 + fibres (broadband: hairs and fibres flicking)
    x = np.repeat(rng.uniform(3.0, 4.5) + 2.5 * contact, PAC_PER_ROW)
    x += (4 + 30 * p["hairiness"]) * gain
    np.multiply(rng.standard_normal(len(c22), dtype=np.float32), x, out=x)  # noise * sigma
    gain *= 6 + 100 * p["roughness"] ** 1.5
    gain *= _texture(p, pos, rng)
    x += gain

    kicks = np.zeros(len(c22))
    edges = np.flatnonzero(np.diff((contact > 0.5).astype(int))) + 1
    kicks[edges * PAC_PER_ROW] = (150 + 250 * p["stiffness"]) * rng.uniform(0.6, 1.4, len(edges))
    cell = pos / 0.004  # a bump where floor(pos / 0.004) changes
    np.floor(cell, out=cell)
    bump = np.flatnonzero(cell[1:] != cell[:-1]) + 1
    bump = bump[sliding[bump] > 0.1]
    kicks[bump] += 300 * p["bumpiness"] * press[bump] * rng.choice([-1, 1], len(bump))
    u = rng.random(len(c22))  # one draw for three disjoint event kinds (by phase and by tail)
    slip_rate = (6 * p["stickiness"] + 1.5 * p["friction"]) / _PAC_RATE
    np.clip(sliding, 0, 1, out=sliding)
    sliding *= slip_rate
    slips = np.flatnonzero(u < sliding)
    kicks[slips] += (100 + 700 * p["stickiness"]) * rng.normal(0, 1, len(slips))
    crackle_rate = 80 * p["crinkliness"] ** 2 / _PAC_RATE
    crack = np.flatnonzero(u < np.repeat(crackle_rate * squeezing, PAC_PER_ROW))
    kicks[crack] += 500 * p["crinkliness"] * rng.normal(0, 1, len(crack))
    x += _PAC_BASE[finger]  # PAC_BASE + x + resonator(kicks)
    x += _resonator(kicks, 250.0, 0.08, _PAC_RATE)
    spikes = np.flatnonzero(u > np.repeat(1 - 0.002 * contact, PAC_PER_ROW))
    x[spikes] = rng.choice([0, ADC_MAX], len(spikes))
    pac = x.reshape(n, PAC_PER_ROW)
    pac += _PAC_COL_OFFSET
    np.rint(pac, out=pac)
    np.clip(pac, 0, ADC_MAX, out=pac)
    return pac.astype(np.int64)


def _trial(p: dict[str, float], scale: float, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """All datasets of one trial group, keyed by their path inside the group."""
    shares = np.clip(1 + rng.normal(0, 0.12, 2), 0.6, 1.4)
    shares /= shares.max()
    q = {
        k: float(np.clip(v + rng.normal(0, _TRIAL_NOISE), 0, 1))
        for k, v in p.items()
        if k in _PROPS
    }
    q.update(
        indent_500=p["indent_500"] * rng.uniform(0.9, 1.1),
        grip_width=p["grip_width"],
        contact_area=p["contact_area"] * rng.uniform(0.8, 1.2),
    )
    p = q
    w = max(p["grip_width"] + rng.normal(0, 0.003), q["indent_500"] + 0.003)
    tl = _Timeline(scale, rng)
    _controller(q, w, shares, tl)
    g, z, code = tl.arrays()
    n = len(g)
    rows_s = tl.rows_s
    pdc = _pressure(w - g, q, shares, rows_s)  # (n, 2)
    detail = np.concatenate([np.full(k, s.encode(), dtype="S30") for s, k in tl.detail])
    squeezing = (detail == b"SQUEEZE_SET_PRESSURE_SLOW") & (np.diff(g, prepend=g[0]) < 0)
    slide_pos = -z

    out: dict[str, np.ndarray] = {}
    contact_time = np.cumsum(np.clip(pdc / 40.0, 0, 1), axis=0)
    heat = contact_time / max(contact_time[-1].max(), 1.0)
    pos = np.cumsum(np.abs(np.diff(slide_pos, prepend=slide_pos[0])))
    sliding = np.abs(np.diff(slide_pos, prepend=slide_pos[0])) * rows_s > 1e-3
    edge = np.clip(0.6 + rng.normal(0, 0.25), 0.1, 1.3)
    # contact cooling: effusive (metal, glass) objects draw heat fast, insulators slowly
    tau_heat = (0.8 + 4.0 * (1 - p["effusivity"])) * rows_s
    for f in range(2):
        pf = pdc[:, f]
        contact = np.clip(pf / 40.0, 0, 1)
        base_pdc = rng.normal((857, 797)[f], (3, 8)[f])
        drift = np.cumsum(rng.normal(0, 0.02, n))
        out[f"biotacs/finger_{f}/pdc"] = base_pdc + pf + 0.2 * drift + rng.normal(0, 0.3, n)
        warmth = rng.uniform(0.6, 1.4)  # sensor-minus-object temperature: room, warm-up
        tac_amp = (60 + 100 * p["effusivity"]) * p["contact_area"] * warmth
        tac = tac_amp * (contact - _lowpass(contact, tau_heat))
        out[f"biotacs/finger_{f}/tac"] = rng.normal(2040, 15) + tac + rng.normal(0, 1.25, n)
        tdc = (8 - 21 * p["effusivity"]) * p["contact_area"] * _lowpass(heat[:, f], 3 * rows_s)
        tdc += (3 - 14 * p["effusivity"]) * warmth * _lowpass(contact, tau_heat)
        out[f"biotacs/finger_{f}/tdc"] = (
            rng.uniform(1850, 2080) + tdc + drift + rng.normal(0, 0.35, n)
        )
        mirror = _MIRROR if f else np.arange(19)
        gain = rng.normal(1, 0.15, 19)
        e0 = _E_BASE[f] + rng.normal(0, 15, 19)
        e = np.outer(pf / 150, (_E_PRESS * gain)[mirror])
        e += e0
        # the edge and shear patterns: added where nonzero (elsewhere they would add 0)
        cols = _E_EDGE_COLS[f]
        e[:, cols] += np.outer(edge * (np.clip(pf, 0, None) / 500) ** 2, _E_EDGE[mirror][cols])
        shear = p["friction"] * contact * sliding * np.clip(pf / 100, 0, 1.5)
        cols = _E_SHEAR_COLS[f]
        e[:, cols] += np.outer(shear, _E_SHEAR[mirror][cols])
        bumps = p["bumpiness"] * contact * np.sin(2 * np.pi * pos / 0.006 + rng.uniform(0, 6.3))
        e += np.outer(25 * bumps, gain[mirror])
        noise = rng.normal(0, 0.45, (n, 19))
        noise += e
        out[f"biotacs/finger_{f}/electrodes"] = noise
        out[f"biotacs/finger_{f}/pac"] = _pac(p, f, pf, slide_pos, squeezing, rng)
    for key in list(out):
        if not key.endswith("pac"):
            v = np.rint(out[key], out=out[key])
            out[key] = np.clip(v, 0, ADC_MAX, out=v).astype(np.int64)

    total = pdc.sum(axis=1)
    vel = np.diff(g, prepend=g[0]) * rows_s
    vib = np.sqrt(np.clip(total / 200, 0, 1)) * sliding * (0.05 + 0.5 * p["roughness"])
    out["accelerometer"] = (
        np.array([0.3, -0.5, -9.7]) + rng.normal(0, 1, (n, 3)) * (0.03 + vib)[:, None]
    )
    out["gripper_aperture/joint_position"] = g + rng.normal(0, 2e-5, n)
    out["gripper_aperture/joint_velocity"] = vel + rng.normal(0, 1e-4, n)
    out["gripper_aperture/joint_effort"] = -0.012 * total - 2.0 * vel + rng.normal(0, 0.05, n)
    out["state/controller_state"] = code.astype(np.int64)
    out["state/controller_detail_state"] = detail

    valid = np.arange(n) >= tl.rows(0.3)
    xyz = np.array([0.62, 0.18, 0.0]) + rng.normal(0, 0.002, 3)
    translation = np.column_stack([np.full(n, xyz[0]), np.full(n, xyz[1]), xyz[2] + z])
    rotation = np.tile([0.0, 0.7071, 0.0, 0.7071], (n, 1)) + rng.normal(0, 1e-4, (n, 4))
    translation[~valid] = 0.0
    rotation[~valid] = 0.0
    out["transforms/translation"] = translation
    out["transforms/rotation"] = rotation
    out["transforms/child_frame_id"] = np.where(valid, b"/l_gripper_tool", b"NOT_VALID").astype(
        "S15"
    )
    out["transforms/parent_frame_id"] = np.where(valid, b"/torso_lift_lin", b"NOT_VALID").astype(
        "S15"
    )
    t0 = 1_358_000_000 + int(rng.integers(0, 10_000_000))
    m = int(n * rng.uniform(2.4, 2.8))
    out["timestamps"] = np.sort(t0 + np.floor(rng.uniform(0, n / ROW_RATE_HZ, m))).astype(np.int64)
    return out


# ------------------------------------------------------------------------------- split groups
def _split_members(
    objs: list[ObjectInfo], trials: int
) -> dict[str, dict[tuple[str, str], list[str]]]:
    """Published split restricted to what exists: adjective -> (group, part) -> trial names.

    Adjectives that would lack a positive or a negative on either side are left out (and logged).
    """
    table: dict[tuple[str, int], tuple[int, ...] | None] = {
        (r.adjective, r.object_id): r.trials for r in published_test_split()
    }
    names = {o.object_id: [f"{o.group_stem}_{t:02d}" for t in range(1, trials + 1)] for o in objs}
    out = {}
    for adj in ADJECTIVES:
        parts: dict[tuple[str, str], list[str]] = {}
        for group, label in ((POSITIVE_SPLIT_GROUP, 1), (NEGATIVE_SPLIT_GROUP, 0)):
            train, test = [], []
            for o in (o for o in objs if o.labels[adj] == label):
                oid, listed = o.object_id, (adj, o.object_id)
                if listed not in table:
                    train += names[oid]
                elif table[listed] is None:
                    test += names[oid]
                else:
                    chosen = {t for t in table[listed] if t <= trials} or set(
                        range(trials // 2 + 1, trials + 1)
                    )
                    for t, name in enumerate(names[oid], start=1):
                        (test if t in chosen else train).append(name)
            parts[(group, "train")], parts[(group, "test")] = train, test
        if all(parts.values()):
            out[adj] = parts
        else:
            empty = ", ".join(f"{g}/{adj}/{part}" for (g, part), v in parts.items() if not v)
            log.info("synthetic PHAC-2: no split groups for %s (%s would be empty)", adj, empty)
    return out


# ------------------------------------------------------------------------------------ writing
def _write_array(grp: h5py.Group, key: str, arr: np.ndarray) -> None:
    """``arr`` (not empty) as one chunk under gzip + shuffle, the filters done here: bytes
    regrouped as the shuffle filter does (byte k of every element together, k = 0, 1, ...), then
    deflated by ISA-L. Any reader's gzip and shuffle filters decode it (module docstring)."""
    arr = np.ascontiguousarray(arr)
    ds = grp.create_dataset(
        key,
        shape=arr.shape,
        dtype=arr.dtype,
        chunks=arr.shape,
        compression="gzip",
        compression_opts=_GZIP_LEVEL,
        shuffle=True,
    )
    planes = cv2.transpose(arr.view(np.uint8).reshape(arr.size, -1))  # 3x numpy's .T copy
    ds.id.write_direct_chunk((0,) * arr.ndim, isal_zlib.compress(planes, _GZIP_LEVEL))


def _write_trial(f: h5py.File, name: str, data: dict[str, np.ndarray], obj: ObjectInfo) -> None:
    grp = f.create_group(name)
    for key, arr in data.items():
        _write_array(grp, key, arr)
    pos = [a.encode() for a in ADJECTIVES if obj.labels[a]]
    neg = [a.encode() for a in ADJECTIVES if not obj.labels[a]]
    grp.create_dataset("adjectives", data=np.array(pos, dtype="S12"))
    grp.create_dataset("adjectives_neg", data=np.array(neg, dtype="S12"))


def _write_links(f: h5py.File, objs: list[ObjectInfo], trials: int) -> None:
    for adj in ADJECTIVES:
        for group, label in (("adjectives", 1), ("adjectives_neg", 0)):
            g = f.require_group(f"{group}/{adj}")
            for o in objs:
                if o.labels[adj] == label:
                    for t in range(1, trials + 1):
                        g[f"{o.group_stem}_{t:02d}"] = f[f"{o.group_stem}_{t:02d}"]
    for adj, parts in _split_members(objs, trials).items():
        for (group, part), names in parts.items():
            g = f.require_group(f"{group}/{adj}/{part}")
            for name in names:
                g[name] = f[name]


def _write_part(part: Path, photos: Path, spec: SyntheticSpec, object_id: int) -> None:
    """One object's trials (and photographs) into a file of its own: one worker task."""
    obj = next(o for o in objects() if o.object_id == object_id)
    props = _properties(spec.seed, obj)
    with h5py.File(part, "w") as f:
        for t in range(1, spec.trials + 1):
            rng = np.random.default_rng([spec.seed, object_id, t])
            _write_trial(
                f, f"{obj.group_stem}_{t:02d}", _trial(props, spec.duration_scale, rng), obj
            )
    for view in range(spec.views):
        shot = render.render_view(
            props, view, spec.image_width, spec.image_height, seed=(spec.seed, object_id)
        )
        render.write_jpeg(photos / f"{obj.group_stem}_{view:02d}.jpg", shot.image)


def _workers(spec: SyntheticSpec, n_objects: int) -> int:
    """Processes for ``n_objects``: one for small files (starting workers costs more)."""
    work = n_objects * spec.trials * spec.duration_scale + n_objects * spec.views / 20
    return 1 if work < 60 else max(1, min(os.cpu_count() or 1, 8, n_objects))


def _progress(done: int, total: int, start: float) -> None:
    """One line per tenth of the objects: the default file takes half a minute or more."""
    if done == total or done % max(1, total // 10) == 0:
        log.info(
            "synthetic PHAC-2: %d/%d objects (%.0f s)", done, total, time.perf_counter() - start
        )


def _write_parts(
    parts: list[Path], photos: Path, spec: SyntheticSpec, ids: list[int], n_workers: int
) -> None:
    """Every object's part file, on ``n_workers`` processes (objects handed out one at a time,
    so a worker on a busier core takes fewer), with progress in this process's log."""
    start = time.perf_counter()
    if n_workers == 1:
        for done, (part, oid) in enumerate(zip(parts, ids, strict=True), 1):
            _write_part(part, photos, spec, oid)
            _progress(done, len(ids), start)
        return
    ctx = pools.start_context("forkserver")  # safe when the parent has threads
    with ProcessPoolExecutor(n_workers, mp_context=ctx) as pool:
        jobs = [
            pool.submit(_write_part, part, photos, spec, oid)
            for part, oid in zip(parts, ids, strict=True)
        ]
        for done, job in enumerate(as_completed(jobs), 1):
            job.result()
            _progress(done, len(ids), start)


def generate(path: Path, spec: SyntheticSpec = SyntheticSpec(), workers: int | None = None) -> Path:
    """Write the synthetic file at ``path`` and its JPEGs to ``path.parent / "photographs"``.

    Atomic: both are written under temporary names in the same folder and moved into place at
    the end, so a failure leaves neither a partial file nor a partial photo folder. Each object
    is a worker task writing a part file, copied in (in object order, without recompression);
    every object's signals come from its own seeded stream, so the data do not depend on the
    number of workers: ``workers`` processes, or (None) one for a small file and up to 8 for a
    large one.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tag = f".tmp-{os.getpid()}"
    tmp_h5 = path.with_name(f".{path.name}{tag}")
    photos = path.parent / "photographs"
    tmp_photos = path.parent / f".photographs{tag}"
    objs = _objects(spec)
    ids = [o.object_id for o in objs]
    parts = [path.with_name(f".{path.name}{tag}.part{oid}") for oid in ids]
    try:
        tmp_photos.mkdir()
        n_workers = _workers(spec, len(ids)) if workers is None else workers
        _write_parts(parts, tmp_photos, spec, ids, n_workers)
        with h5py.File(tmp_h5, "w") as f:
            f.attrs["TITLE"] = "Aggregated BOLT Data (synthetic)"
            f.attrs["GENERATOR_VERSION"] = GENERATOR_VERSION
            f.attrs["spec"] = json.dumps(asdict(spec))
            for part in parts:
                with h5py.File(part, "r") as src:
                    for name in src:
                        src.copy(src[name], f, name=name)
                part.unlink()
            _write_links(f, objs, spec.trials)
        old = path.parent / f".photographs-old{tag}"
        if photos.exists():
            os.replace(photos, old)
        os.replace(tmp_photos, photos)
        shutil.rmtree(old, ignore_errors=True)
        os.replace(tmp_h5, path)
    finally:
        for tmp in (tmp_h5, *parts):
            tmp.unlink(missing_ok=True)
        shutil.rmtree(tmp_photos, ignore_errors=True)
    return path


def spec_hash(spec: SyntheticSpec) -> str:
    """Short stable hash of a spec (part of the cache folder name)."""
    return hashlib.sha256(json.dumps(asdict(spec), sort_keys=True).encode()).hexdigest()[:10]


def default_file(cache_dir: Path, spec: SyntheticSpec = SyntheticSpec()) -> Path:
    """The cached file for ``spec`` under ``cache_dir``; generated on first use, reused after."""
    folder = Path(cache_dir) / f"synthetic-v{GENERATOR_VERSION}-{spec_hash(spec)}"
    path = folder / "phac_synthetic.h5"
    if path.exists():
        return path
    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # concurrent jobs: one generates, the others wait
        if not path.exists():
            log.info("generating synthetic PHAC-2 data at %s (first use)", path)
            start = time.perf_counter()
            generate(path, spec)
            log.info("generated %s in %.1f s", path, time.perf_counter() - start)
    return path

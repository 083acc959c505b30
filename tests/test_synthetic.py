"""The synthetic PHAC-2 generator: layout, physics, splits, determinism, atomicity, caching."""

from __future__ import annotations

import copy
import logging
from pathlib import Path

import cv2
import h5py
import numpy as np
import pytest

from tactile_exp.data import render, synthetic
from tactile_exp.data.layout import (
    ADJECTIVES,
    BASELINE_STATE,
    EPS,
    TrialName,
    objects,
    published_test_split,
)
from tactile_exp.data.synthetic import SyntheticSpec, default_file, generate, object_properties

TINY = SyntheticSpec(trials=2, duration_scale=0.1, views=1, image_width=96, image_height=64)
STATES = [  # (detail state, coarse codes) in trial order (PHAC2_FORMAT §1.4)
    ("DISABLED", {0}),
    ("OPEN_GRIPPER_MAX", {0}),
    ("MOVE_ARM_START_POSITION", {0, 7}),
    ("MOVE_GRIPPER_FAST_CLOSE", {5}),
    ("OPEN_GRIPPER_BY_2CM_FAST", {5}),
    ("FIND_CONTACT_CLOSE_GRIPPER_SLO", {3}),
    ("SQUEEZE_SET_PRESSURE_SLOW", {3}),
    ("OPEN_GRIPPER_BY_2CM_FAST", {3}),
    ("CLOSE_GRIPPER_SLOW_TO_POSITION", {1}),
    ("HOLD_FOR_10_SECONDS", {1}),
    ("OPEN_GRIPPER_BY_2CM_FAST", {1}),
    ("MOVE_UP_START_HEIGHT", {1}),
    ("CLOSE_GRIPPER_SLOW_TO_POSITION", {2}),
    ("SLIDE_5CM", {2}),
    ("SLIDE_DONE_WAIT_5", {2}),
    ("OPEN_GRIPPER_FAST_2CM", {2}),
    ("MOVE_UP_5CM", {2}),
    ("CLOSE_GRIPPER_SLOW_TO_POSITION", {6}),
    ("MOVE_DOWN_5CM", {6}),
    ("SLIDE_DONE_WAIT_5", {6}),
    ("OPEN_GRIPPER_FAST_2CM", {6}),
    ("OPEN_GRIPPER_FAST_MAX", {6}),
]
BIOTAC = {"electrodes": (19,), "pac": (22,), "pdc": (), "tac": (), "tdc": ()}
FLOATS = {
    "accelerometer": (3,),
    "gripper_aperture/joint_position": (),
    "gripper_aperture/joint_velocity": (),
    "gripper_aperture/joint_effort": (),
    "transforms/translation": (3,),
    "transforms/rotation": (4,),
}


@pytest.fixture(scope="module")
def tiny(tmp_path_factory) -> Path:
    return generate(tmp_path_factory.mktemp("tiny") / "phac.h5", TINY)


@pytest.fixture(scope="module")
def full_length(tmp_path_factory) -> Path:
    """Two objects (soft sponge, brick) at realistic duration."""
    spec = SyntheticSpec(object_ids=(101, 508), trials=1, views=0)
    return generate(tmp_path_factory.mktemp("full") / "phac.h5", spec)


def runs(states: np.ndarray) -> list[tuple[bytes, int, int]]:
    """(state, start, stop) of each run of equal consecutive values."""
    cut = np.flatnonzero(states[1:] != states[:-1]) + 1
    starts = np.concatenate([[0], cut])
    stops = np.concatenate([cut, [len(states)]])
    return [(states[a], int(a), int(b)) for a, b in zip(starts, stops, strict=True)]


def baseline(g: h5py.Group, finger: int, channel: str) -> float:
    rest = g["state/controller_detail_state"][:] == BASELINE_STATE
    return float(g[f"biotacs/finger_{finger}/{channel}"][:][rest].mean())


def test_trial_groups_datasets_shapes_and_dtypes(tiny):
    with h5py.File(tiny, "r") as f:
        trials = [TrialName.parse(n) for n in f if TrialName.parse(n)]
        assert len(trials) == 120
        assert {(t.object_id, t.trial) for t in trials} == {
            (o.object_id, t) for o in objects() for t in (1, 2)
        }
        assert {n for n in f if not TrialName.parse(n)} == {
            "adjectives", "adjectives_neg", "train_test_sets", "train_test_negative_sets"
        }  # fmt: skip
        for t in trials[::17]:
            g = f[t.name]
            n = g["state/controller_detail_state"].shape[0]
            for finger in ("finger_0", "finger_1"):
                for ch, tail in BIOTAC.items():
                    ds = g[f"biotacs/{finger}/{ch}"]
                    assert ds.shape == (n, *tail) and ds.dtype == np.int64, (t.name, ch)
                    assert ds.compression == "gzip" and ds.shuffle
                    values = ds[:]
                    assert values.min() >= 0 and values.max() <= 4095
            for key, tail in FLOATS.items():
                assert g[key].shape == (n, *tail) and g[key].dtype == np.float64, key
            assert g["state/controller_state"].dtype == np.int64
            assert g["state/controller_detail_state"].dtype == np.dtype("S30")
            for key in ("child_frame_id", "parent_frame_id"):
                assert g[f"transforms/{key}"].dtype == np.dtype("S15")
            assert g["transforms/child_frame_id"][-1] == b"/l_gripper_tool"
            assert g["transforms/child_frame_id"][0] == b"NOT_VALID"
            assert not g["transforms/rotation"][0].any()
            stamps = g["timestamps"][:]
            assert stamps.dtype == np.int64 and stamps.shape[0] != n
            assert np.all(np.diff(stamps) >= 0)
            obj = next(o for o in objects() if o.object_id == t.object_id)
            assert g["adjectives"].dtype == np.dtype("S12")
            assert [a.decode() for a in g["adjectives"][:]] == list(obj.positives)
            neg = [a for a in ADJECTIVES if a not in obj.positives]
            assert [a.decode() for a in g["adjectives_neg"][:]] == neg


def test_trial_datasets_are_one_chunk_each_and_decode_to_the_simulated_arrays(tiny):
    """The generator shuffles and deflates each array itself and writes it as one chunk: HDF5's
    gzip and shuffle filters (any reader's) give back exactly the simulated values."""
    props = object_properties(TINY)
    with h5py.File(tiny, "r") as f:
        for name in ("car_sponge_101_02", "brick_508_01", "pinball_launcher_703_02"):
            t = TrialName.parse(name)
            rng = np.random.default_rng([TINY.seed, t.object_id, t.trial])
            expected = synthetic._trial(props[t.object_id], TINY.duration_scale, rng)
            assert sorted(expected) == sorted(
                k for k in _dataset_paths(f[name]) if not k.startswith("adjectives")
            )
            for key, arr in expected.items():
                ds = f[name][key]
                assert ds.chunks == ds.shape and ds.compression == "gzip" and ds.shuffle, key
                values = ds[()]
                assert values.dtype == arr.dtype and values.shape == arr.shape, key
                assert values.tobytes() == arr.tobytes(), key


def _dataset_paths(group: h5py.Group) -> list[str]:
    out: list[str] = []
    group.visititems(lambda k, v: out.append(k) if isinstance(v, h5py.Dataset) else None)
    return out


def test_full_state_sequence_with_contiguous_eps(tiny):
    with h5py.File(tiny, "r") as f:
        for name in ("car_sponge_101_01", "brick_508_02", "cologne_container__602_01"):
            g = f[name]
            detail = g["state/controller_detail_state"][:]
            code = g["state/controller_state"][:]
            seq = runs(detail)
            assert [s.decode() for s, _, _ in seq] == [s for s, _ in STATES]
            for (_, a, b), (state, codes) in zip(seq, STATES, strict=True):
                assert set(np.unique(code[a:b]).tolist()) == codes, state
            for ep in EPS.values():
                assert sum(s == ep for s, _, _ in seq) == 1  # one contiguous block


def test_realistic_ep_lengths_at_full_duration(full_length):
    with h5py.File(full_length, "r") as f:
        lengths = {}
        for name in ("car_sponge_101_01", "brick_508_01"):
            detail = f[name]["state/controller_detail_state"][:]
            ep = {k: int((detail == v).sum()) for k, v in EPS.items()}
            assert 5000 <= len(detail) <= 9000, name
            assert 950 <= ep["hold"] <= 1050
            assert 430 <= ep["slow_slide"] <= 570
            assert 170 <= ep["fast_slide"] <= 230
            assert 60 <= ep["squeeze"] <= 2200
            lengths[name] = ep["squeeze"]
        # stiff brick: steep rise, short squeeze; soft sponge: long travel
        assert lengths["car_sponge_101_01"] > 5 * lengths["brick_508_01"]


def test_squeeze_stops_at_baseline_plus_500(tiny, full_length):
    # at duration_scale 0.1 one row closes 0.25 mm, so stiff objects overshoot by a step
    # (up to +30 % at indent_500 = 1.2 mm with the near-Hertz exponent 1.3)
    for path, top in ((tiny, 650), (full_length, 515)):
        with h5py.File(path, "r") as f:
            for name in [n for n in f if TrialName.parse(n)][::7]:
                g = f[name]
                sq = g["state/controller_detail_state"][:] == EPS["squeeze"]
                rise = [g[f"biotacs/finger_{i}/pdc"][:][sq] - baseline(g, i, "pdc") for i in (0, 1)]
                peak = np.max(np.maximum(*rise))
                assert 495 <= peak <= top, (name, peak)
                hold = g["state/controller_detail_state"][:] == EPS["hold"]
                hold_rise = max(
                    (g[f"biotacs/finger_{i}/pdc"][:][hold] - baseline(g, i, "pdc")).mean()
                    for i in (0, 1)
                )
                assert 100 <= hold_rise <= 300, (name, hold_rise)  # 50 % of the travel


def test_baselines_and_electrode_mirror(full_length):
    with h5py.File(full_length, "r") as f:
        g = f["brick_508_01"]
        assert 840 <= baseline(g, 0, "pdc") <= 875 and 765 <= baseline(g, 1, "pdc") <= 830
        assert 2045 <= baseline(g, 0, "pac") <= 2065 and 2020 <= baseline(g, 1, "pac") <= 2040
        sq = g["state/controller_detail_state"][:] == EPS["squeeze"]
        rest = g["state/controller_detail_state"][:] == BASELINE_STATE
        drops = []
        for i in (0, 1):
            e = g[f"biotacs/finger_{i}/electrodes"][:]
            drops.append(e[sq].min(axis=0) - e[rest].mean(axis=0))
        assert np.argmin(drops[0]) == 10 and np.argmin(drops[1]) == 0  # E11 vs E1: mirrored


def test_hard_links_resolve_to_trial_groups(tiny):
    labels = {o.object_id: o.labels for o in objects()}
    with h5py.File(tiny, "r") as f:
        for group, label in (("adjectives", 1), ("adjectives_neg", 0)):
            for adj in ADJECTIVES:
                names = list(f[f"{group}/{adj}"])
                expected = sum(labels[o][adj] == label for o in labels) * 2
                assert len(names) == expected, (group, adj)
                for name in names:
                    assert f[f"{group}/{adj}/{name}"] == f[name]  # the same HDF5 object
                    assert labels[TrialName.parse(name).object_id][adj] == label
        link = f["train_test_sets/soft/train"]
        assert all(link[n] == f[n] for n in link)


def test_split_groups_equal_published_table(tiny):
    table = published_test_split()
    labels = {o.object_id: o.labels for o in objects()}
    with h5py.File(tiny, "r") as f:
        assert set(f["train_test_sets"]) == set(ADJECTIVES) - {"sticky", "unpleasant"}
        for adj in f["train_test_sets"]:
            for group, label in (("train_test_sets", 1), ("train_test_negative_sets", 0)):
                test = {TrialName.parse(n) for n in f[f"{group}/{adj}/test"]}
                train = {TrialName.parse(n) for n in f[f"{group}/{adj}/train"]}
                rows = [r for r in table if r.adjective == adj and r.label == label]
                want = {(r.object_id, t) for r in rows for t in (r.trials or (1, 2)) if t <= 2}
                assert {(t.object_id, t.trial) for t in test} == want, (adj, group)
                everything = {(o, t) for o in labels if labels[o][adj] == label for t in (1, 2)}
                assert {(t.object_id, t.trial) for t in train} == everything - want
    nice_test = {n for n in h5py.File(tiny, "r")["train_test_sets/nice/test"]}
    assert nice_test == {"microfiber_applicator_pad_111_02"}


def test_split_restricted_to_subsets(caplog):
    objs = list(objects())
    with caplog.at_level(logging.INFO, logger="tactile_exp.data.synthetic"):
        one = synthetic._split_members(objs, trials=1)
    assert "nice" not in one and "sticky" not in one  # single trial: no positive left to train
    assert "no split groups for nice" in caplog.text
    three = synthetic._split_members(objs, trials=3)
    nice = three["nice"]
    assert nice[("train_test_sets", "test")] == ["microfiber_applicator_pad_111_02"]
    assert nice[("train_test_sets", "train")] == [
        "microfiber_applicator_pad_111_01",
        "microfiber_applicator_pad_111_03",
    ]
    assert "sticky" not in three  # listed trials 01-03 cover all: no train positive
    subset = [o for o in objs if o.object_id in (101, 119, 410, 508, 507, 509, 503, 120, 703)]
    part = synthetic._split_members(subset, trials=2)
    assert "bumpy" not in part and "absorbent" in part  # no bumpy object in the subset
    test_pos = {n[:-3] for n in part["absorbent"][("train_test_sets", "test")]}
    assert test_pos == {"non_bumpy_foam_119", "flour_sack_410"}


def test_same_seed_same_arrays_other_seed_differs(tmp_path):
    spec = SyntheticSpec(object_ids=(101, 703), trials=1, duration_scale=0.1, views=1,
                         image_width=96, image_height=64)  # fmt: skip
    a = generate(tmp_path / "a" / "x.h5", spec)
    b = generate(tmp_path / "b" / "x.h5", spec)
    c = generate(tmp_path / "c" / "x.h5", SyntheticSpec(**{**spec.__dict__, "seed": 1}))

    def arrays(path: Path) -> dict[str, np.ndarray]:
        out = {}
        with h5py.File(path, "r") as f:
            f["car_sponge_101_01"].visititems(
                lambda k, v: out.__setitem__(k, v[:]) if isinstance(v, h5py.Dataset) else None
            )
        return out

    xa, xb, xc = arrays(a), arrays(b), arrays(c)
    assert xa.keys() == xb.keys() and len(xa) == 23
    assert all(np.array_equal(xa[k], xb[k]) for k in xa)
    assert not np.array_equal(xa["biotacs/finger_0/pac"][:100], xc["biotacs/finger_0/pac"][:100])
    jpg = "pinball_launcher_703_00.jpg"
    assert (a.parent / "photographs" / jpg).read_bytes() == (
        b.parent / "photographs" / jpg
    ).read_bytes()


def test_photographs_never_touch_the_trials(tmp_path, monkeypatch):
    """The renderer draws from streams of its own: trials are the same whatever it paints.

    So a renderer change (generator version 4 -> 5 changed only the photographs) leaves every
    haptic array bit-identical and haptic results measured before it valid.
    """
    spec = SyntheticSpec(object_ids=(101, 703), trials=1, duration_scale=0.1, views=1,
                         image_width=96, image_height=64)  # fmt: skip
    a = generate(tmp_path / "a" / "x.h5", spec)

    def blank(props, view, width, height, seed=0):
        return render.View(np.zeros((height, width, 3), np.uint8), (width / 2, height / 2), 1.0)

    monkeypatch.setattr(render, "render_view", blank)
    b = generate(tmp_path / "b" / "x.h5", SyntheticSpec(**{**spec.__dict__, "views": 3}))

    def arrays(path: Path) -> dict[str, bytes]:
        out = {}
        with h5py.File(path, "r") as f:
            f.visititems(
                lambda k, v: out.__setitem__(k, v[()].tobytes() + str(v.dtype).encode())
                if isinstance(v, h5py.Dataset) else None
            )  # fmt: skip
        return out

    xa, xb = arrays(a), arrays(b)
    assert len(xa) > 40 and xa == xb
    jpgs = sorted(p.name for p in (b.parent / "photographs").iterdir())
    assert len(jpgs) == 6 and cv2.imread(str(b.parent / "photographs" / jpgs[0])).max() == 0


@pytest.mark.parametrize(
    "failing",
    [(synthetic.render, "write_jpeg"), (synthetic.os, "replace")],
    ids=["while objects are written", "while files move into place"],
)
def test_generation_failure_leaves_nothing(tmp_path, monkeypatch, failing):
    def boom(*args, **kwargs):
        raise RuntimeError("disk full")

    monkeypatch.setattr(*failing, boom)
    spec = SyntheticSpec(object_ids=(101,), trials=1, duration_scale=0.1, views=1,
                         image_width=96, image_height=64)  # fmt: skip
    with pytest.raises(RuntimeError, match="disk full"):
        generate(tmp_path / "x.h5", spec)
    assert list(tmp_path.iterdir()) == []


def test_default_file_generates_once(tmp_path, monkeypatch, caplog):
    spec = SyntheticSpec(object_ids=(508,), trials=1, duration_scale=0.1, views=1,
                         image_width=96, image_height=64)  # fmt: skip
    with caplog.at_level(logging.INFO, logger="tactile_exp.data.synthetic"):
        path = default_file(tmp_path, spec)
    assert path.name == "phac_synthetic.h5" and path.is_file()
    assert path.parent.name.startswith(f"synthetic-v{synthetic.GENERATOR_VERSION}-")
    assert "generated" in caplog.text
    assert (path.parent / "photographs" / "brick_508_00.jpg").is_file()

    def fail(*args, **kwargs):
        raise AssertionError("regenerated")

    monkeypatch.setattr(synthetic, "generate", fail)
    assert default_file(tmp_path, spec) == path
    other = SyntheticSpec(object_ids=(508,), trials=1, duration_scale=0.1, views=0, seed=3)
    with pytest.raises(AssertionError, match="regenerated"):
        default_file(tmp_path, other)


def test_properties_follow_labels_and_material():
    props = object_properties(SyntheticSpec())
    info = {o.object_id: o for o in objects()}

    def mean(prop: str, adj: str, label: int) -> float:
        return np.mean([p[prop] for o, p in props.items() if info[o].labels[adj] == label])

    assert mean("stiffness", "hard", 1) > mean("stiffness", "hard", 0) + 0.3
    assert mean("effusivity", "cool", 1) > mean("effusivity", "cool", 0) + 0.3
    assert mean("thickness", "thick", 1) > mean("thickness", "thin", 1) + 0.3
    assert mean("springiness", "springy", 1) > mean("springiness", "springy", 0) + 0.3
    assert object_properties(SyntheticSpec()) == props
    assert object_properties(SyntheticSpec(seed=1))[101] != props[101]
    assert set(object_properties(SyntheticSpec(object_ids=(101, 508)))) == {101, 508}


def simulate(change: dict[str, float], scale: float = 0.3) -> dict[str, np.ndarray]:
    """One trial of brick 508 with some properties changed; same random stream every time."""
    props = {**object_properties(SyntheticSpec(object_ids=(508,)))[508], **change}
    return synthetic._trial(props, scale, np.random.default_rng(7))


def ep_rows(trial: dict[str, np.ndarray], ep: str) -> np.ndarray:
    return trial["state/controller_detail_state"] == EPS[ep]


def rest_mean(trial: dict[str, np.ndarray], key: str) -> float:
    return float(trial[key][trial["state/controller_detail_state"] == BASELINE_STATE].mean())


def test_cool_materials_give_large_tac_transient_and_tdc_drop():
    cool, warm = simulate({"effusivity": 1.0}), simulate({"effusivity": 0.0})
    tac = {k: t["biotacs/finger_0/tac"].max() - rest_mean(t, "biotacs/finger_0/tac")
           for k, t in (("cool", cool), ("warm", warm))}  # fmt: skip
    assert tac["cool"] > 1.8 * tac["warm"] and tac["warm"] > 15
    tdc = {k: t["biotacs/finger_0/tdc"][-50:].mean() - rest_mean(t, "biotacs/finger_0/tdc")
           for k, t in (("cool", cool), ("warm", warm))}  # fmt: skip
    assert tdc["cool"] < tdc["warm"] - 10


def test_roughness_and_stickiness_make_slide_vibration():
    def slide_std(t):  # without the full-scale spikes, which would dominate a plain std
        pac = t["biotacs/finger_0/pac"][ep_rows(t, "slow_slide")]
        return pac[(pac > 0) & (pac < 4095)].std()

    smooth = simulate(
        {"roughness": 0.0, "bumpiness": 0.0, "stickiness": 0.0, "hairiness": 0.0, "friction": 0.0}
    )
    rough = simulate(
        {"roughness": 1.0, "bumpiness": 0.0, "stickiness": 0.0, "hairiness": 0.0, "friction": 0.0}
    )
    sticky = simulate(
        {"roughness": 0.0, "bumpiness": 0.0, "stickiness": 1.0, "hairiness": 0.0, "friction": 0.0}
    )
    assert slide_std(rough) > 3 * slide_std(smooth)
    assert slide_std(sticky) > 2 * slide_std(smooth)


def test_stiffness_sets_travel_and_porosity_creeps_in_hold():
    stiff = simulate({"indent_500": 1.5e-3})
    soft = simulate({"indent_500": 15e-3})
    pos = "gripper_aperture/joint_position"
    closing = {k: t[pos][ep_rows(t, "squeeze")] for k, t in (("s", stiff), ("f", soft))}
    travel = {k: g[0] - g.min() for k, g in closing.items()}
    assert travel["f"] > 5 * travel["s"]
    assert closing["f"].argmin() > 5 * closing["s"].argmin()  # rows to reach +500
    porous, dense = simulate({"porosity": 1.0}), simulate({"porosity": 0.0})
    for t, lo, hi in ((porous, 0.2, 0.5), (dense, -0.05, 0.05)):
        hold = t["biotacs/finger_0/pdc"][ep_rows(t, "hold")].astype(float)
        creep = (hold[:10].mean() - hold[-10:].mean()) / (
            hold[:10].mean() - rest_mean(t, "biotacs/finger_0/pdc")
        )
        assert lo <= creep <= hi, creep


def pac_centroid(trial: dict[str, np.ndarray], ep: str) -> float:
    """Spectral centroid (Hz, below 200 Hz) of finger 0's 2200 Hz PAC stream during ``ep``."""
    pac = trial["biotacs/finger_0/pac"][ep_rows(trial, ep)].astype(float).ravel()
    pac = np.where((pac > 0) & (pac < 4095), pac, np.median(pac))  # full-scale spikes out
    power = np.abs(np.fft.rfft(pac - pac.mean())) ** 2
    freq = np.fft.rfftfreq(len(pac), 1 / 2200)
    band = freq < 200
    return float((power[band] * freq[band]).sum() / power[band].sum())


def test_texture_vibration_frequency_follows_spacing_and_speed():
    # coarse (rough) asperities vibrate slower; the fast slide moves the same texture higher
    quiet = {"bumpiness": 0.0, "stickiness": 0.0, "hairiness": 0.0, "friction": 0.0}
    fine = simulate({**quiet, "roughness": 0.0}, scale=1.0)
    medium = simulate({**quiet, "roughness": 0.5}, scale=1.0)
    coarse = simulate({**quiet, "roughness": 1.0}, scale=1.0)
    assert pac_centroid(coarse, "fast_slide") < 0.5 * pac_centroid(fine, "fast_slide")
    assert pac_centroid(medium, "fast_slide") > 1.5 * pac_centroid(medium, "slow_slide")


def test_thermal_transient_decays_faster_on_effusive_materials():
    def tail_fraction(t):  # TAC in the second half of the hold relative to its peak there
        tac = t["biotacs/finger_0/tac"].astype(float) - rest_mean(t, "biotacs/finger_0/tac")
        hold = tac[ep_rows(t, "hold")]
        return hold[len(hold) // 2 :].mean() / hold.max()

    cool, warm = simulate({"effusivity": 1.0}, 1.0), simulate({"effusivity": 0.0}, 1.0)
    assert tail_fraction(cool) < 0.05 < 0.15 < tail_fraction(warm)


def _pac_reference(p, finger, pdc, slide_pos, squeezing, rng):
    """``synthetic._pac`` as plain whole-array expressions, the reference for its faster form."""
    from tactile_exp.data.layout import ADC_MAX, PAC_PER_ROW

    n = len(pdc)
    contact = np.clip(pdc / 40.0, 0, 1)
    c22 = np.repeat(contact, PAC_PER_ROW)
    pos = np.interp(np.arange(n * PAC_PER_ROW) / PAC_PER_ROW, np.arange(n), slide_pos)
    speed = np.abs(np.diff(pos, prepend=pos[0])) * synthetic._PAC_RATE
    sliding = c22 * np.clip(speed / 0.01, 0, 3)
    press = np.sqrt(np.clip(np.repeat(pdc, PAC_PER_ROW) / 100.0, 0, 1.5))
    gain = p["contact_area"] * np.sqrt(sliding) * press
    fibres = (4 + 30 * p["hairiness"]) * gain
    sigma = rng.uniform(3.0, 4.5) + 2.5 * c22 + fibres
    x = rng.standard_normal(len(c22), dtype=np.float32) * sigma
    x += (6 + 100 * p["roughness"] ** 1.5) * gain * synthetic._texture(p, pos, rng)
    kicks = np.zeros(len(c22))
    edges = np.flatnonzero(np.diff((contact > 0.5).astype(int))) + 1
    kicks[edges * PAC_PER_ROW] = (150 + 250 * p["stiffness"]) * rng.uniform(0.6, 1.4, len(edges))
    bump = np.flatnonzero(np.diff(np.floor(pos / 0.004)) != 0) + 1
    bump = bump[sliding[bump] > 0.1]
    kicks[bump] += 300 * p["bumpiness"] * press[bump] * rng.choice([-1, 1], len(bump))
    u = rng.random(len(c22))
    slip_rate = (6 * p["stickiness"] + 1.5 * p["friction"]) / synthetic._PAC_RATE
    slips = np.flatnonzero(u < slip_rate * np.clip(sliding, 0, 1))
    kicks[slips] += (100 + 700 * p["stickiness"]) * rng.normal(0, 1, len(slips))
    crackle_rate = 80 * p["crinkliness"] ** 2 / synthetic._PAC_RATE
    crack = np.flatnonzero(u < crackle_rate * np.repeat(squeezing, PAC_PER_ROW))
    kicks[crack] += 500 * p["crinkliness"] * rng.normal(0, 1, len(crack))
    ring = synthetic._resonator(kicks, 250.0, 0.08, synthetic._PAC_RATE)
    pac = synthetic._PAC_BASE[finger] + x + ring
    spikes = np.flatnonzero(u > 1 - 0.002 * c22)
    pac[spikes] = rng.choice([0, ADC_MAX], len(spikes))
    pac = pac.reshape(n, PAC_PER_ROW) + synthetic._PAC_COL_OFFSET
    return np.clip(np.rint(pac), 0, ADC_MAX).astype(np.int64)


def test_pac_equals_the_plain_expressions_bit_for_bit(monkeypatch):
    """_pac computes per row what only depends on the row, and in place: the same operations on
    the same values, so the same bits and the same random draws as the plain expressions."""
    fast = synthetic._pac
    calls = []

    def both(p, finger, pdc, slide_pos, squeezing, rng):
        twin = copy.deepcopy(rng)
        out = fast(p, finger, pdc, slide_pos, squeezing, rng)
        ref = _pac_reference(p, finger, pdc, slide_pos, squeezing, twin)
        calls.append(out.dtype == ref.dtype and out.tobytes() == ref.tobytes())
        assert rng.bit_generator.state == twin.bit_generator.state
        return out

    monkeypatch.setattr(synthetic, "_pac", both)
    props = object_properties(SyntheticSpec(object_ids=(118, 318, 509)))  # bumpy, crinkly, sticky
    for oid, p in props.items():
        synthetic._trial(p, 0.5, np.random.default_rng([0, oid, 1]))
    assert calls == [True] * 6


def test_porous_foam_pressure_rises_late_in_squeeze():
    def half_time_fraction(t):  # PDC halfway to the squeeze peak, as a fraction of the peak
        pdc = t["biotacs/finger_0/pdc"].astype(float) - rest_mean(t, "biotacs/finger_0/pdc")
        sq = pdc[ep_rows(t, "squeeze")]
        return sq[sq.argmax() // 2] / sq.max()

    soft = {"stiffness": 0.1, "indent_500": 12e-3, "springiness": 0.2}
    foam = simulate({**soft, "porosity": 1.0}, 1.0)
    rubber = simulate({**soft, "porosity": 0.0}, 1.0)
    assert half_time_fraction(foam) < half_time_fraction(rubber) - 0.05


@pytest.mark.parametrize(
    ("kwargs", "key"),
    [({"trials": 0}, "trials"), ({"duration_scale": 0}, "duration_scale"),
     ({"object_ids": (999,)}, "object_ids"), ({"image_width": 8}, "image")],
)  # fmt: skip
def test_bad_spec_is_rejected(kwargs, key):
    with pytest.raises(ValueError, match=key):
        SyntheticSpec(**kwargs)


def test_worker_processes_write_the_same_file(tmp_path, caplog):
    """Objects are handed to the workers one at a time; the parent logs the progress."""
    spec = SyntheticSpec(object_ids=(101, 508, 703), trials=1, duration_scale=0.1, views=1,
                         image_width=96, image_height=64)  # fmt: skip
    caplog.set_level(logging.INFO, logger=synthetic.__name__)
    serial = generate(tmp_path / "serial" / "x.h5", spec)
    parallel = generate(tmp_path / "parallel" / "x.h5", spec, workers=2)
    progress = [
        r.getMessage().split(" (")[0] for r in caplog.records if "objects" in r.getMessage()
    ]
    assert progress == [f"synthetic PHAC-2: {i}/3 objects" for i in (1, 2, 3)] * 2
    with h5py.File(serial, "r") as a, h5py.File(parallel, "r") as b:
        assert sorted(a) == sorted(b)
        for name in ("car_sponge_101_01", "pinball_launcher_703_01"):
            for key in ("biotacs/finger_1/pac", "state/controller_detail_state"):
                assert np.array_equal(a[name][key][:], b[name][key][:])
        assert sorted(a["adjectives/hard"]) == sorted(b["adjectives/hard"]) == ["brick_508_01"]
    assert sorted(p.name for p in (parallel.parent / "photographs").iterdir()) == [
        "brick_508_00.jpg", "car_sponge_101_00.jpg", "pinball_launcher_703_00.jpg"
    ]  # fmt: skip

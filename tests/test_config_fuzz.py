# Cross-cutting, so not tests/test_<module>.py: hypothesis drives config values
# through settings_from_config and the engine's open_data/classify, where a crash would show.
"""Config fuzzing: every numeric or list value either runs on tiny data or stops
before any run with a one-line ``ConfigError`` naming the key; never a crash deep in training."""

from __future__ import annotations

import math

import numpy as np
from conftest import TINY_DATA
from hypothesis import HealthCheck, Phase, event, given, settings
from hypothesis import strategies as st

from tactile_exp.config import settings_from_config
from tactile_exp.data.layout import ADJECTIVES, DataError, Instances
from tactile_exp.errors import ConfigError
from tactile_exp.experiment import open_data
from tactile_exp.pipeline import AdjectivePipeline

FUZZ = settings(
    max_examples=10,
    deadline=None,
    phases=[Phase.explicit, Phase.reuse, Phase.generate],  # no shrinking: each try trains
    derandomize=True,  # the same examples every run: CI stays reproducible
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
SMALL_INT = st.integers(-2, 6)
REAL = st.one_of(
    st.sampled_from([0.0, -0.5, 1.0, 1.5, math.inf, -math.inf, math.nan]),
    st.floats(-0.1, 1.2, allow_nan=False),
)


def _fmt(value: object) -> str:
    if isinstance(value, list):
        return "[" + ",".join(_fmt(v) for v in value) + "]"
    return str(value)


def _tiny_instances(steps: int) -> Instances:
    """4 objects x 2 trials x 2 instances of (64, steps): objects 1 and 2 positive."""
    rng = np.random.default_rng(0)
    obj = np.repeat([1, 2, 3, 4], 4)
    trial = np.array([f"o{o}_t{i // 2 % 2}" for i, o in enumerate(obj)], dtype=object)
    y = (obj <= 2).astype(np.int64)
    X = rng.normal(size=(16, 64, steps)).astype(np.float32) + y[:, None, None]
    return Instances(X, y, trial, obj)


def _check(compose_config, cache_dir, values: dict[str, object]) -> None:
    overrides = [
        *TINY_DATA,
        f"cache_dir={cache_dir}",
        "schedule=tiny",
        "model.impl=torch",
        "adjectives=[hard]",
        *(f"{k}={_fmt(v)}" for k, v in values.items()),
    ]
    try:
        cfg = compose_config(overrides)
        s = settings_from_config(cfg)
        open_data(s)
    except ConfigError as err:
        message = str(err)
        assert "\n" not in message
        key = message.split(":", 1)[0]
        # the key typed (or its group); model.groups when a modality value (pca_components)
        # changes the channels the ConvNet's groups must divide, checked when the data opens
        assert key in values or key in ("model", "model.groups"), message
        event(f"refused: {key}")
        return
    steps = int(s.modality.params["steps"])
    data = _tiny_instances(steps)
    pipeline = AdjectivePipeline(s.modality, s.model, s.combiner, s.combine)
    pipeline.fit_instances(data)
    scores, units = pipeline.score(data)
    assert len(scores) == len(units) and np.isfinite(scores).all()
    event("trained")


def _one_broken(valid: dict[str, st.SearchStrategy], wild: dict[str, st.SearchStrategy]):
    """Valid values for every key but (at most) one, which takes any value of its wide range:
    each example probes one key, and about half of them train."""
    keys = sorted(valid)

    @st.composite
    def draw(draw_value) -> dict[str, object]:
        values = {k: draw_value(valid[k]) for k in keys}
        broken = draw_value(st.sampled_from([None, *keys]))
        if broken is not None:
            values[broken] = draw_value(wild[broken])
        return values

    return draw()


SCHEDULE = _one_broken(
    valid={
        "schedule.epochs": st.integers(1, 3),
        "schedule.lr": st.floats(1e-4, 0.5),
        "schedule.momentum": st.floats(0.0, 0.95),
        "schedule.batch_size": st.integers(4, 20),
        "combine": st.integers(1, 2),
    },
    wild={
        "schedule.epochs": st.integers(-1, 3),
        "schedule.lr": REAL,
        "schedule.momentum": REAL,
        "schedule.batch_size": st.integers(-1, 20),
        "combine": st.integers(-1, 3),
    },
)
ARCHITECTURE = _one_broken(
    valid={
        "model.kernel_sizes": st.lists(st.integers(1, 7), min_size=3, max_size=3),
        "model.widths": st.lists(st.integers(1, 3), min_size=3, max_size=3),
        "model.strides": st.lists(st.integers(1, 3), min_size=3, max_size=3),
        "modality.steps": st.integers(20, 60),
        "modality.offsets": st.integers(1, 3),
        "modality.pca_components": st.integers(1, 19),
    },
    wild={
        "model.kernel_sizes": st.lists(st.integers(-1, 40), min_size=2, max_size=4),
        "model.widths": st.lists(SMALL_INT, min_size=2, max_size=4),
        "model.strides": st.lists(SMALL_INT, min_size=3, max_size=3),
        "modality.steps": st.integers(-1, 60),
        "modality.offsets": st.integers(-1, 3),
        "modality.pca_components": st.integers(-1, 21),
    },
)


@FUZZ
@given(values=SCHEDULE)
def test_schedule_values(compose_config, cache_dir, values):
    _check(compose_config, cache_dir, values)


@FUZZ
@given(values=ARCHITECTURE)
def test_architecture_and_preprocessing_values(compose_config, cache_dir, values):
    _check(compose_config, cache_dir, values)


@FUZZ
@given(
    adjectives=st.lists(st.sampled_from([*ADJECTIVES[:4], "hard", "fluffy", "HARD"]), max_size=4),
    seed=st.integers(-3, 2**32 + 1),
)
def test_adjectives_and_seed(compose_config, cache_dir, adjectives, seed):
    overrides = [f"adjectives={_fmt(adjectives)}", f"seed={seed}"]
    try:
        s = settings_from_config(compose_config(overrides))
        open_data(s)  # the names are checked against the data set's labels when it opens
    except (ConfigError, DataError) as err:
        assert str(err).split(":", 1)[0] in ("adjectives", "seed"), str(err)
        return
    assert list(s.adjectives) == adjectives and s.seed == seed
    assert len(set(adjectives)) == len(adjectives) and set(adjectives) <= set(ADJECTIVES)
    assert 0 <= seed < 2**32

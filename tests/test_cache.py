"""The model caches: a model kept under its training key comes back as it was stored, with the
caller's unkeyed settings; ``NoCache`` trains every time."""

from __future__ import annotations

import numpy as np

from tactile_exp.cache import MemoryCache, NoCache
from tactile_exp.data.layout import Instances
from tactile_exp.models import MODELS


def _trained(calls: list[int], lr: float = 0.5):
    def train():
        calls.append(1)
        rng = np.random.default_rng(0)
        y = np.arange(40) % 2
        X = rng.normal(size=(40, 7)).astype(np.float32) + y[:, None]
        data = Instances(X, y, np.array([f"t{i}" for i in range(40)], object), y)
        model = MODELS.build("linear", schedule={"epochs": 2, "batch_size": 16, "head": {"lr": lr}})
        return model, model.fit(data)

    return train


def test_memory_cache_trains_once_per_key_and_gives_back_the_stored_model():
    cache, calls = MemoryCache(), []
    first = cache.get_or_train("k", _trained(calls))
    assert first.source is None and first.history and calls == [1]
    found = cache.get_or_train("k", _trained(calls), overrides={"schedule.head": {"lr": 0.1}})
    assert calls == [1] and found.source == "k" and found.history == {}
    assert found.model is not first.model  # loaded from its files, as from a store
    X = np.random.default_rng(1).normal(size=(5, 7)).astype(np.float32)
    np.testing.assert_array_equal(
        found.model.decision_function(X), first.model.decision_function(X)
    )
    assert found.model.head().schedule.lr == 0.1  # the caller's unkeyed setting
    cache.get_or_train("other", _trained(calls))
    assert calls == [1, 1] and cache.keys == ["k", "other"]


def test_no_cache_trains_every_time():
    calls: list[int] = []
    for _ in range(2):
        assert NoCache().get_or_train("k", _trained(calls)).source is None
    assert calls == [1, 1]

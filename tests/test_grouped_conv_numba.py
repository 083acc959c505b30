"""The compiled (numba) grouped conv stack's layout, its parallel parts, and what its compile
ahead leaves for a job (its values against ``F.conv1d``: tests/test_grouped_conv_autograd.py).

The first compiled call in a run compiles the kernels into the session's ``NUMBA_CACHE_DIR``
(conftest); every later test reuses them.
"""

import subprocess
import sys
import time

import numpy as np
import pytest


@pytest.mark.parametrize("parts", [[(0, 3)], [(0, 1), (1, 3)], [(0, 2), (2, 3)]])
def test_to_layout_fills_every_block_whatever_the_split(parts):
    """A batch of 37 padded to 48 lanes: whole tiles, the last instance one value at a time,
    zero padding, and 21 steps (16 in tiles); each task's blocks alone, in any split."""
    from tactile_exp.models.grouped_conv_numba import LANES, to_layout

    rng = np.random.default_rng(3)
    x = rng.standard_normal((37, 2 * 3, 21), dtype=np.float32)  # 3 groups of 2 channels
    out = np.full((3, 2, 21, 3 * LANES), np.nan, np.float32)
    for start, stop in parts:
        to_layout(x, 3, out, start, stop)
    want = np.zeros_like(out)
    for c in range(6):
        want[c % 3, c // 3, :, :37] = x[:, c, :].T
    np.testing.assert_array_equal(out, want)


def test_warm_up_compiles_every_signature_a_training_step_and_scoring_use():
    """The job's compile ahead (``HapticCNN.kernels``: this module's, the tiled step's and the
    layer's ``warm_up``) must leave nothing for the job to compile: in a fresh process, after
    them, a HapticCNN's fit, features and scores add no signature, and the stack's backward
    (``grouped_conv_autograd``), which the usual losses never run, is never compiled."""
    code = """
import numpy as np
from tactile_exp.data.layout import Instances
from tactile_exp.models import MODELS, convnet_tiles, grouped_conv_autograd, linear_sgd
from tactile_exp.models import grouped_conv_numba as kernels
from tactile_exp.models.schedule import Schedule

def signatures():
    return {name: len(f.signatures)
            for module in (kernels, convnet_tiles, linear_sgd, grouped_conv_autograd)
            for name, f in vars(module).items() if hasattr(f, "signatures")}

model = MODELS.build("haptic_cnn", schedule=Schedule(epochs=1, finetune_epochs=1, batch_size=16))
for module in model.kernels():
    __import__(module, fromlist=["warm_up"]).warm_up()
before = signatures()
rng = np.random.default_rng(0)
X = rng.normal(size=(40, 32, 150)).astype(np.float32)
y = np.arange(40) % 2
model.fit(Instances(X, y, np.arange(40), np.arange(40)))
head = model.head()
head.fit(Instances(model.transform(X), y, np.arange(40), np.arange(40)))
head.decision_function(model.transform(X[:5]))
entry = ("stack_forward", "to_layout", "from_layout", "_tiles", "_epoch", "_gram_epoch")
print(before == signatures(), *(before[name] for name in entry),
      signatures()["stack_backward"], signatures()["into_layout"])
"""
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout.split()
    # the entry points compiled by warm_up, nothing after it; the backward's never
    assert out == ["True"] + ["1"] * 6 + ["0", "0"]


@pytest.mark.parametrize("count", [1, 2, 5, 63, 64])
def test_in_parallel_runs_every_index_once_this_threads_part_the_largest(count, monkeypatch):
    """The parts cover ``range(count)`` once each, in order by slot; where they cannot be equal
    this thread's (slot 0, started first) is the larger, so it is the one that finishes last.
    Three parts whatever the machine's cores (the pool queues what its threads cannot take)."""
    import threading

    from tactile_exp.models import grouped_conv_numba as kernels

    monkeypatch.setattr(kernels.numba, "get_num_threads", lambda: 3)
    calls = []

    def task(slot: int, start: int, stop: int) -> None:
        calls.append((slot, start, stop, threading.get_ident()))

    kernels._in_parallel(task, count)
    calls.sort()
    assert [c[0] for c in calls] == list(range(min(count, 3)))
    assert [i for _, a, b, _ in calls for i in range(a, b)] == list(range(count))
    sizes = [b - a for _, a, b, _ in calls]
    assert sizes[0] == max(sizes) and max(sizes) - min(sizes) <= 1
    assert calls[0][3] == threading.get_ident()  # slot 0 ran here


def test_in_parallel_returns_only_when_every_part_has_finished(monkeypatch):
    """A part that fails here leaves no other still running when the error reaches the caller
    (it would write into buffers the next call hands out)."""
    from tactile_exp.models import grouped_conv_numba as kernels

    monkeypatch.setattr(kernels.numba, "get_num_threads", lambda: 2)
    finished = []

    def task(slot: int, start: int, stop: int) -> None:
        if slot == 0:
            raise RuntimeError("part 0 failed")
        time.sleep(0.2)
        finished.append(slot)

    with pytest.raises(RuntimeError, match="part 0 failed"):
        kernels._in_parallel(task, 4)
    assert finished == [1]

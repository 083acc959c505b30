# Cross-cutting, so not tests/test_<module>.py: the CUDA device path through models,
# train and store, kept apart because it skips without a GPU and is run by hand on one.
"""The GPU path (``device=auto`` on a CUDA machine): same models, same numbers as on CPU.

Skipped where torch sees no GPU (CI); run on a GPU machine with ``pytest tests/test_gpu.py``.
"""

import numpy as np
import pytest
import torch
from sklearn.metrics import roc_auc_score
from test_models import FAST, easy_case

from tactile_exp.artifacts import read_model, write_model
from tactile_exp.models import MODELS
from tactile_exp.models.schedule import Schedule
from tactile_exp.preprocess.trunk import build_trunk, pooled_features
from tactile_exp.train import device_name

pytestmark = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU")

GPU = {**FAST, "device": "auto"}


def test_auto_names_the_gpu_for_the_runs_device_tag():
    assert device_name("auto") == f"cuda:0 ({torch.cuda.get_device_name(0)})"
    assert device_name("cpu") == "cpu"


@pytest.mark.parametrize(
    ("name", "steps", "schedule"),
    [
        ("haptic_cnn", 60, FAST["schedule"]),
        ("haptic_lstm", 20, Schedule(epochs=15, finetune_epochs=5, batch_size=25, lr=0.05)),
    ],
)
def test_auto_trains_on_the_gpu_and_scores_as_the_cpu_does(name, steps, schedule):
    """``device=auto`` puts the model on the GPU with torch's kernels (cuDNN; the compiled ones
    refuse a GPU tensor), and from the same seed it ends where the CPU's compiled kernels end
    (TF32 off: IEEE float32 on both)."""
    train, test = easy_case(120, steps=steps), easy_case(60, steps=steps, seed=1)
    scores = {}
    for device in ("cpu", "auto"):
        model = MODELS.build(name, seed=3, **{**GPU, "schedule": schedule, "device": device})
        model.fit(train)
        scores[device] = model.decision_function(test.X)
        params = [*model.body_.parameters(), *model.classifier_.parameters()]
        assert {p.device.type for p in params} == {"cpu" if device == "cpu" else "cuda"}
    np.testing.assert_allclose(scores["auto"], scores["cpu"], rtol=1e-3, atol=1e-4)
    auc = {k: roc_auc_score(test.y, v) for k, v in scores.items()}
    assert auc["cpu"] > 0.7  # it learnt something, so equal AUCs mean something
    assert abs(auc["auto"] - auc["cpu"]) < 0.01


def test_a_model_trained_on_the_gpu_loads_and_predicts_on_cpu(tmp_path):
    """The store keeps CPU tensors, so a GPU-trained model predicts on a machine without one."""
    train = easy_case(80, steps=60)
    model = MODELS.build("haptic_cnn", seed=1, **GPU)
    model.fit(train)
    assert next(model.body_.parameters()).is_cuda
    write_model(tmp_path, "haptic_cnn", model)
    on_cpu = read_model(tmp_path, "gpu-trained", overrides={"device": "cpu"})
    assert next(on_cpu.body_.parameters()).device.type == "cpu"
    np.testing.assert_allclose(
        on_cpu.decision_function(train.X), model.decision_function(train.X), rtol=1e-4, atol=1e-5
    )


def test_googlenet_features_on_the_gpu_equal_the_cpus():
    trunk = build_trunk(None, seed=0)
    images = np.random.default_rng(0).standard_normal((6, 3, 224, 224)).astype(np.float32)
    on_cpu = pooled_features(trunk, images, batch_size=4, device="cpu")
    on_gpu = pooled_features(trunk, images, batch_size=4, device="cuda")
    assert on_gpu.shape == (6, 832)
    np.testing.assert_allclose(on_gpu, on_cpu, rtol=1e-3, atol=1e-5)


@pytest.mark.parametrize("name", ["linear", "haptic_cnn", "haptic_lstm", "visual_googlenet"])
def test_compiled_kernels_on_a_gpu_are_refused_when_built(name):
    with pytest.raises(ValueError, match="impl='compiled' runs on CPU only; device is cuda"):
        MODELS.build(name, impl="compiled", device="cuda")

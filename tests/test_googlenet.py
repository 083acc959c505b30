"""GoogLeNet (M3): torchvision layout, trunk up to inception (5a), weights loading, loss layer."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from sklearn.metrics import roc_auc_score

from tactile_exp.data.layout import Instances
from tactile_exp.models import MODELS
from tactile_exp.models.googlenet import (
    GoogLeNet,
    build_trunk,
    load_weights,
    pooled_features,
    xavier_init,
)
from tactile_exp.models.schedule import Schedule

# torchvision's GoogLeNet(aux_logits=False): module names and parameter count (DEPS.md section 5)
INCEPTIONS = ("3a", "3b", "4a", "4b", "4c", "4d", "4e", "5a", "5b")
BRANCH_CONVS = ("branch1", "branch2.0", "branch2.1", "branch3.0", "branch3.1", "branch4.1")
BN = ("weight", "bias", "running_mean", "running_var", "num_batches_tracked")


def torchvision_keys() -> set[str]:
    convs = ["conv1", "conv2", "conv3"]
    convs += [f"inception{i}.{b}" for i in INCEPTIONS for b in BRANCH_CONVS]
    keys = {f"{c}.conv.weight" for c in convs} | {f"{c}.bn.{k}" for c in convs for k in BN}
    return keys | {"fc.weight", "fc.bias"}


@pytest.fixture(scope="module")
def net() -> GoogLeNet:
    return xavier_init(GoogLeNet(transform_input=True), seed=1).eval()


@pytest.fixture(scope="module")
def images() -> torch.Tensor:
    """Small inputs keep the tests fast; the 224x224 geometry is checked once."""
    return torch.randn(2, 3, 64, 64, generator=torch.Generator().manual_seed(0))


def test_state_dict_has_torchvision_keys_and_size(net):
    state = net.state_dict()
    assert len(state) == 344 and set(state) == torchvision_keys()
    assert sum(p.numel() for p in net.parameters()) == 6_624_904
    assert state["inception4a.branch3.1.conv.weight"].shape[2:] == (3, 3)  # torchvision's quirk
    assert not any(k.endswith("conv.bias") for k in state)


def test_weights_round_trip_strictly_through_a_file(images, tmp_path):
    net = xavier_init(GoogLeNet(transform_input=True), seed=3).eval()
    with torch.no_grad():  # non-trivial BatchNorm statistics must travel too
        for m in net.modules():
            if isinstance(m, torch.nn.BatchNorm2d):
                m.running_mean.uniform_(-0.1, 0.1)
                m.running_var.uniform_(0.5, 2.0)
    plain, wrapped = tmp_path / "plain.pth", tmp_path / "wrapped.pth"
    torch.save(net.state_dict(), plain)
    aux = {"aux1.conv.conv.weight": torch.zeros(128, 512, 1, 1), "aux2.fc2.bias": torch.zeros(9)}
    torch.save({"state_dict": {**net.state_dict(), **aux}, "epoch": 3}, wrapped)
    with torch.inference_mode():
        expected = net(images)
        for path in (plain, wrapped):
            other = load_weights(xavier_init(GoogLeNet(transform_input=True), seed=2), path)
            torch.testing.assert_close(other.eval()(images), expected)
        trunk = build_trunk(plain)  # takes network_input's [-1, 1] input: no transform_input
        assert trunk.transform_input is False
        mapped = net._transform_input(images)
        torch.testing.assert_close(trunk.features(mapped), net.features(images))


def test_trunk_stops_at_inception_5a_and_is_l2_normalised(net, images):
    with torch.inference_mode():
        assert net.inception5a_map(torch.zeros(1, 3, 224, 224)).shape == (1, 832, 7, 7)
        fmap = net.inception5a_map(images)
        features = net.features(images)
        assert features.shape == (2, 832)
        np.testing.assert_allclose(features.norm(dim=1).numpy(), 1.0, rtol=1e-5)
        pooled = fmap.mean(dim=(2, 3))
        torch.testing.assert_close(features, pooled / pooled.norm(dim=1, keepdim=True))
        logits = net(images)
        changed = xavier_init(GoogLeNet(transform_input=True), seed=1).eval()
        torch.nn.init.zeros_(changed.inception5b.branch1.conv.weight)
        torch.testing.assert_close(changed.features(images), features)  # 5b is not in the trunk
        assert not torch.allclose(changed(images), logits)


def test_transform_input_maps_imagenet_normalised_input_to_minus_one_one():
    pixels = torch.tensor([0.0, 127.5, 255.0]).view(1, 1, 3, 1).expand(1, 3, 3, 1)
    mean = torch.tensor([0.485, 0.456, 0.406]).view(1, 3, 1, 1)
    std = torch.tensor([0.229, 0.224, 0.225]).view(1, 3, 1, 1)
    x = (pixels / 255 - mean) / std
    mapped = GoogLeNet(transform_input=True)._transform_input(x)
    torch.testing.assert_close(mapped, (pixels / 255 - 0.5) / 0.5)


def test_pooled_features_batches_and_memory_formats_agree(net, images):
    with torch.inference_mode():
        expected = net.features(images).numpy()
    x = images.numpy()
    for batch, channels_last in ((1, True), (2, False), (32, True)):
        got = pooled_features(net, x, batch_size=batch, channels_last=channels_last)
        assert got.dtype == np.float32
        np.testing.assert_allclose(got, expected, atol=1e-5)
    with pytest.raises(ValueError, match=r"\(n, 3, H, W\)"):
        pooled_features(net, x[:, :2])


def test_load_weights_errors_name_the_file_and_the_keys(net, tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.pth"):
        load_weights(GoogLeNet(), tmp_path / "nope.pth")
    junk = tmp_path / "junk.pth"
    junk.write_bytes(b"not a torch file")
    with pytest.raises(ValueError, match="junk.pth: cannot read"):
        load_weights(GoogLeNet(), junk)
    listed = tmp_path / "list.pth"
    torch.save([torch.zeros(1)], listed)
    with pytest.raises(ValueError, match="list.pth: expected a state_dict"):
        load_weights(GoogLeNet(), listed)
    state = dict(net.state_dict())
    del state["inception4c.branch2.1.bn.running_var"]
    state["classifier.weight"] = torch.zeros(1)
    broken = tmp_path / "broken.pth"
    torch.save(state, broken)
    with pytest.raises(ValueError, match="broken.pth") as err:
        load_weights(GoogLeNet(), broken)
    assert "inception4c.branch2.1.bn.running_var" in str(err.value)
    assert "classifier.weight" in str(err.value)
    minc = tmp_path / "minc23.pth"
    minc_fc = {"fc.weight": torch.zeros(23, 1024), "fc.bias": torch.zeros(23)}
    torch.save({**net.state_dict(), **minc_fc}, minc)
    with pytest.raises(ValueError, match=r"minc23.pth: tensor shapes.*fc.weight \(23, 1024\)"):
        load_weights(GoogLeNet(num_classes=1000), minc)
    assert build_trunk(minc).fc.out_features == 23  # the trunk adopts the file's class count


def _features(n: int, seed: int) -> Instances:
    """Unit-norm 832-d rows whose direction depends on the label."""
    rng = np.random.default_rng(seed)
    y = np.arange(n) % 2
    X = np.abs(rng.normal(size=(n, 832))) + 0.6 * y[:, None] * (np.arange(832) < 50)
    X /= np.linalg.norm(X, axis=1, keepdims=True)
    return Instances(X.astype(np.float32), y, np.arange(n).astype(str), np.arange(n))


def test_loss_layer_learns_on_l2_features_and_rejects_other_rows():
    model = MODELS.build(
        "visual_googlenet", schedule=Schedule(epochs=60, finetune_epochs=20, batch_size=64)
    )
    train, test = _features(200, 0), _features(100, 1)
    history = model.fit(train)
    assert len(history["train_loss"]) == 60 and len(history["finetune_loss"]) == 20
    assert history["train_loss"][-1] < history["train_loss"][0]
    assert roc_auc_score(test.y, model.decision_function(test.X)) > 0.9
    trained = [*model.body_.parameters(), *model.classifier_.parameters()]
    assert sum(p.numel() for p in trained) == 833  # only the loss layer: the trunk stays frozen
    np.testing.assert_array_equal(model.transform(test.X), test.X)  # the trunk is upstream
    assert type(model.head()).__name__ == "LinearModel"
    y = np.array([0, 1, 0, 1])
    bad = Instances(np.zeros((4, 1024), np.float32), y, np.zeros(4), np.zeros(4))
    with pytest.raises(ValueError, match=r"visual_googlenet expects .* \(n, 832\)"):
        model.fit(bad)

"""``python -m tactile_exp.weights pretrain``: material pre-training on newly drawn objects."""

from __future__ import annotations

import os

import pytest
import torch

from tactile_exp.preprocess.trunk import CaffeGoogLeNet, build_trunk, read_state_dict, xavier_init
from tactile_exp.weights import __main__ as cli
from tactile_exp.weights import pretrain as pretrain_module
from tactile_exp.weights.pretrain import PretrainSettings, pretrain

TINY = PretrainSettings(
    objects=16, views=1, size=32, epochs=1, image_width=160, image_height=120, seed=3
)


def test_tiny_pretraining_writes_a_caffe_trunk_that_differs_from_its_init(tmp_path):
    out = tmp_path / "material.pth"
    figures = pretrain(TINY, out)
    assert figures["held_out_images"] == 8  # one object per material, never trained on
    assert figures["train_images"] == 8
    assert 0 <= figures["held_out_accuracy"] <= 1
    trunk = build_trunk(out, layout="caffe")  # the visual modality's loader
    assert read_state_dict(out)[1] == "caffe"
    init = xavier_init(CaffeGoogLeNet(), TINY.seed).state_dict()
    state = trunk.state_dict()
    trained = [k for k in state if not torch.equal(state[k], init[k])]
    assert trained and all(k.startswith("inception_5a.") for k in trained)
    assert torch.equal(state["conv1.weight"], init["conv1.weight"])  # random lower layers kept


def test_photographs_are_new_objects_balanced_over_materials():
    images, material, obj = pretrain_module.material_photographs(TINY)
    assert images.shape == (16, 3, 32, 32)
    assert sorted(material.tolist()) == sorted(list(range(8)) * 2)
    assert len(set(obj.tolist())) == 16
    assert images.std() > 10  # real crops, not blank


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--size", "16"], "size must be in 32..512"),
        (["--objects", "8"], "objects must be >= 16"),
        (["--views", "0"], "views must be >= 1"),
        (["--holdout", "1.5"], "holdout"),
    ],
)
def test_impossible_settings_fail_before_any_work(tmp_path, monkeypatch, capsys, args, message):
    monkeypatch.setattr(pretrain_module, "material_photographs", _no_work)
    assert cli.main(["pretrain", str(tmp_path / "w.pth"), *args]) == 2
    assert message in capsys.readouterr().err


def test_unwritable_output_fails_before_any_work(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(pretrain_module, "material_photographs", _no_work)
    assert cli.main(["pretrain", str(tmp_path / "nowhere" / "w.pth")]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert cli.main(["pretrain", str(tmp_path)]) == 2
    assert "is a folder" in capsys.readouterr().err
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o500)
    if not os.access(locked, os.W_OK):  # root may write anyway
        assert cli.main(["pretrain", str(locked / "w.pth")]) == 2
        assert "not writable" in capsys.readouterr().err


def _no_work(*args, **kwargs):
    raise AssertionError("bad settings must fail before rendering")

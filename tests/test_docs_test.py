"""TACTILE_EXP_DOCS_TEST: what the documentation's command test shortens, and nothing unset."""

from __future__ import annotations

from omegaconf import OmegaConf

from tactile_exp import docs_test


def test_unset_changes_nothing(compose_config, monkeypatch):
    monkeypatch.delenv(docs_test.ENV, raising=False)
    cfg = compose_config(["experiment=quick_table1_i"])
    assert docs_test.shorten(cfg) is cfg


def test_set_shortens_every_job_the_same_way(compose_config, monkeypatch):
    monkeypatch.setenv(docs_test.ENV, "metallic,soft")
    cfg = docs_test.shorten(compose_config(["experiment=quick_table1_i"]))
    assert list(cfg.adjectives) == ["metallic", "soft"]
    assert (cfg.schedule.epochs, cfg.schedule.finetune_epochs, cfg.schedule.head.epochs) == (
        2,
        1,
        2,
    )
    assert (cfg.data.trials, cfg.data.views, cfg.data.duration_scale) == (2, 1, 0.1)
    assert cfg.schedule.lr == 0.01  # the rest of the schedule as composed
    # A command's own list is cut to the chosen adjectives, else to its first.
    own = docs_test.shorten(compose_config(["adjectives=[hard,soft,thick]"]))
    assert list(own.adjectives) == ["soft"]
    assert list(docs_test.shorten(compose_config(["adjectives=[hard]"])).adjectives) == ["hard"]
    # Another data set keeps its own labels and data settings.
    folder = compose_config(["data=folder", "data.path=x", "modality=signals"])
    out = docs_test.shorten(folder)
    assert out.adjectives is None and OmegaConf.to_container(out.data) == OmegaConf.to_container(
        folder.data
    )

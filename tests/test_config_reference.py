"""The generated configuration reference: it is current, complete, and reads comments right."""

from __future__ import annotations

from pathlib import Path

from tactile_exp import config_reference as ref

PAGE = ref.ROOT / "docs" / "configuration.md"


def test_committed_page_is_current():
    """Fails when conf/ changed and the page was not regenerated."""
    assert PAGE.read_text() == ref.generate(), (
        f"docs/configuration.md is stale: run `{ref.COMMAND}`"
    )


def test_every_group_and_option_is_on_the_page():
    page = ref.generate()
    groups = ref.options()
    assert {"data", "model", "schedule", "experiment", "sweep", "tracking"} <= set(groups)
    n = 0
    for group, opts in groups.items():
        assert f"### {group}\n" in page
        for o in opts:
            n += 1
            assert f"#### `{group}={o.name}`" in page
            assert o.text.rstrip("\n") in page  # the file with its comments, verbatim
    files = [p.relative_to(ref.CONF).parts for p in ref.CONF.rglob("*.yaml")]
    assert n == len([f for f in files if len(f) > 1 and f[0] not in ref.SKIP_GROUPS])


def test_defaults_come_from_the_defaults_list():
    assert ref.defaults()["model"] == "haptic_cnn"
    assert ref.defaults()["schedule"] == "paper"
    assert "experiment" not in ref.defaults()  # `experiment: null`


def test_method_items_and_ranges():
    items = ref.method_items()
    assert items["T3"].startswith("SGD, constant learning rate 0.01")
    assert "200 epochs" in items["T3"]  # a continuation line joined
    assert ref.cited("P1-P3 and T4; not X9 or 5a", items) == ["P1", "P2", "P3", "T4"]
    assert ref.cited("V1-V2", items) == ["V1", "V2"]


def test_ours_comments_found_with_their_keys(tmp_path: Path):
    text = (
        "# M1: a model. The widths are ours.\n"
        "name: m\n"
        "# Ours: more workers,\n"
        "# continued here.\n"
        "workers: 1\n"
        "head:\n"
        "  lr: 0.1     # ours: because\n"
        "              # of this\n"
        "  batch: 3    # T3's\n"
    )
    assert ref.ours(text) == [
        ("-", "M1: a model. The widths are ours."),
        ("workers", "Ours: more workers, continued here."),
        ("head.lr", "ours: because of this"),
    ]


def test_a_new_option_and_its_ours_comment_appear(tmp_path: Path):
    conf = tmp_path / "conf"
    (conf / "model").mkdir(parents=True)
    (conf / "config.yaml").write_text("defaults:\n  - model: a\nseed: 0\n")
    (conf / "model" / "a.yaml").write_text("# M2: an LSTM.\nname: a\nunits: 7  # ours\n")
    page = ref.generate(conf, ref.METHOD)
    assert "| `model=a` | M2: an LSTM. | M2 |" in page
    assert "| `conf/model/a.yaml` | `units` | ours |" in page
    assert "| M2 | Haptic LSTM" in page

"""Configurations named by what differs, data sets by their names, specs that pick one."""

import pytest
from report_fixture import group

from tactile_exp.report import configurations
from tactile_exp.report.configurations import Spec, SpecError


def _groups():
    return [
        group("slip", "linear", 1.0)[0],
        group("slip", "haptic_cnn", 1.0, ("model.groups=24",))[0],
        group("slip", "haptic_cnn", 1.0, ("model.groups=24", "combine=10"))[0],
        group("slide", "linear", 1.0)[0],
    ]


def test_names_say_what_differs_and_are_shared_across_data_sets():
    groups = _groups()
    for g in groups[2:3]:
        g.params["combine"] = "10"
    for g in groups[:2] + groups[3:]:
        g.params["combine"] = "1"
    names = configurations.names(groups)
    assert [names[g.key] for g in groups] == [
        "model=linear combine=1",
        "model=haptic_cnn combine=1 model.groups=24",
        "model=haptic_cnn combine=10 model.groups=24",
        "model=linear combine=1",  # the same configuration on another data set
    ]
    assert not any("fold" in n or "seed" in n or "data" in n for n in names.values())


def test_an_experiment_file_names_its_bundle_and_what_differs_within_it():
    """The benchmark's experiment files each set a model and a modality: the file is the name;
    a setting that also differs between runs of one file (seed aside) is named beside it."""
    made = [
        group("grasp", "haptic_lstm", 1.0, ("experiment=benchmark_lstm",))[0],
        group("grasp", "haptic_cnn", 1.0, ("experiment=benchmark_convnet",))[0],
        group("grasp", "haptic_cnn", 1.0, ("experiment=benchmark_convnet", "model.widths=8"))[0],
        group("slide", "haptic_lstm", 1.0, ("experiment=benchmark_lstm",))[0],
    ]
    for g in made:
        g.params["choice.experiment"] = g.overrides.pop("experiment")
    names = configurations.names(made)
    assert [names[g.key] for g in made] == [
        "experiment=benchmark_lstm",
        "experiment=benchmark_convnet",
        "experiment=benchmark_convnet model.widths=8",
        "experiment=benchmark_lstm",
    ]


def test_a_lone_configuration_is_named_by_its_model_and_ties_by_their_hash():
    (g, _) = group("slip", "linear", 1.0)
    assert configurations.names([g]) == {g.key: "model=linear"}
    twin = group("slip", "linear", 1.0)[0]
    twin.key, twin.row_hash = "other@slip-0123456789ab", "abcdef123"
    names = configurations.names([g, twin])
    assert names[g.key] != names[twin.key] and names[twin.key] == "model=linear #abcdef"


def test_data_sets_are_named_by_their_files_and_told_apart_by_digest():
    a, b = group("slip", "linear", 1.0)[0], group("slip", "linear", 1.0)[0]
    b.runs[0, -1] = type(b.first_run)(**{**vars(b.first_run), "data": "slip-fedcba987654"})
    assert configurations.dataset(a) == "slip"
    assert {configurations.dataset(g, [a, b]) for g in (a, b)} == {"slip (012345)", "slip (fedcba)"}
    assert list(configurations.by_dataset(_groups())) == ["slide", "slip"]


def test_a_spec_picks_the_one_configuration_it_names():
    groups = _groups()[:3]
    names = configurations.names(groups)
    assert Spec.parse("model=linear").pick(groups, names) is groups[0]
    assert Spec.parse("model=haptic_cnn combine=10").pick(groups, names) is groups[2]
    assert Spec.parse("model=lstm").pick(groups, names) is None
    with pytest.raises(SpecError, match=r"matches 2 configurations on slip .*tells them apart"):
        Spec.parse("model=haptic_cnn").pick(groups, names)
    with pytest.raises(SpecError, match="expected key=value"):
        Spec.parse("haptic_cnn")


def test_the_split_names_a_configuration_only_where_it_tells_two_apart():
    a = group("slip", "linear", 1.0, ("split.folds=5",))[0]
    b = group("grasp", "linear", 1.0, ("split.folds=2",))[0]  # each data set's own K
    c = group("grasp", "linear", 1.0, ("split.folds=3",))[0]
    c.key, c.row_hash = "k3@grasp-0123456789ab", "k3hash"
    assert configurations.names([a, b]) == {a.key: "model=linear", b.key: "model=linear"}
    names = configurations.names([a, b, c])
    assert names[a.key] == "model=linear"
    assert (names[b.key], names[c.key]) == (
        "model=linear split.folds=2",
        "model=linear split.folds=3",
    )


def test_a_group_a_model_does_not_read_names_no_one():
    cnn = group("slip", "haptic_cnn", 1.0)[0]
    rocket = group("slip", "minirocket", 1.0)[0]
    rocket.params.pop("choice.schedule")  # a model without epochs: no schedule in its config
    names = configurations.names([cnn, rocket])
    assert (names[cnn.key], names[rocket.key]) == ("model=haptic_cnn", "model=minirocket")
    other = group("slip", "haptic_cnn", 1.0, ("schedule=paper",))[0]
    other.params["choice.schedule"] = "paper"
    assert configurations.names([cnn, rocket, other])[other.key] == (
        "model=haptic_cnn schedule=paper"
    )

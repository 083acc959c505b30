"""A finished job's spec: its logged config read once, typed, and refused with the key named."""

import pytest

from tactile_exp.artifacts import ArtifactError
from tactile_exp.jobs import JobSpec

CONFIG = {
    "data": {"name": "phac2", "path": "/data/phac2.h5"},
    "modality": {"name": "haptic", "_module_": "x", "steps": 150},
    "model": {"name": "haptic_cnn", "schedule": {"epochs": 2}},
    "combine_instances": {"name": "concat"},
    "combine": 10,
    "paper": {"row": "J", "auc": 82.1},
}


def test_spec_of_a_logged_config():
    spec = JobSpec.of(CONFIG, "run X")
    assert (spec.modality.name, spec.modality.params) == ("haptic", {"steps": 150})
    assert (spec.model.name, spec.combiner, spec.combine, spec.row) == (
        "haptic_cnn", "concat", 10, "J")  # fmt: skip
    assert spec.data.params == {"path": "/data/phac2.h5"}
    assert JobSpec.of(CONFIG | {"paper": None}, "run X").row is None


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"modality": None}, "^run X: modality is not a mapping with a name$"),
        ({"combine": "ten"}, "^run X: artifact config.yaml: missing or bad entry"),
        ({"combine_instances": {}}, "^run X: combine_instances is not a mapping with a name$"),
    ],
)
def test_a_config_that_is_not_a_jobs_names_the_run_and_key(change, message):
    with pytest.raises(ArtifactError, match=message):
        JobSpec.of(CONFIG | change, "run X")
    with pytest.raises(ArtifactError, match="is not a job's config"):
        JobSpec.of(["not", "a", "mapping"], "run X")

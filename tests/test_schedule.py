"""The ``Schedule`` value: built from the ``schedule`` config node, checked, and its head's."""

import dataclasses
import json
import pickle

import pytest
import yaml
from conftest import CONF

from tactile_exp.models.schedule import Schedule, ScheduleError


def test_every_schedule_file_builds_the_paper_values_where_it_sets_none():
    paper = Schedule.of(yaml.safe_load((CONF / "schedule" / "paper.yaml").read_text()))
    assert dataclasses.replace(paper, head=None) == Schedule()  # the defaults are T3's
    assert paper.head == Schedule(200, 100, 32, 0.001, 0.9)
    assert paper.for_head() is paper.head


def test_a_head_takes_what_its_node_lacks_from_the_model_and_has_no_head_of_its_own():
    schedule = Schedule.of({"epochs": 3, "batch_size": 8, "momentum": 0.5, "head": {"lr": 0.2}})
    assert schedule.head == Schedule(epochs=3, batch_size=8, lr=0.2, momentum=0.5)
    assert Schedule.of({"epochs": 3}).for_head() == Schedule(epochs=3)
    assert Schedule.of(schedule) is schedule and Schedule.of(None) == Schedule()
    with pytest.raises(ScheduleError, match=r"^schedule.head.head: a head has no head"):
        Schedule(head=Schedule(head=Schedule()))


@pytest.mark.parametrize(
    ("node", "key", "line"),
    [
        ({"epochs": 0}, "epochs", "schedule.epochs: epochs must be an int >= 1, got 0"),
        ({"epochs": 2.5}, "epochs", "schedule.epochs: epochs must be an int >= 1, got 2.5"),
        ({"finetune_epochs": -1}, "finetune_epochs", "schedule.finetune_epochs: finetune_epochs"),
        ({"batch_size": True}, "batch_size", "schedule.batch_size: batch_size must be an int"),
        ({"lr": float("nan")}, "lr", "schedule.lr: lr must be > 0 and finite, got nan"),
        ({"momentum": 1.0}, "momentum", "schedule.momentum: momentum must be in [0, 1), got 1.0"),
        ({"head": {"lr": 0}}, "head.lr", "schedule.head.lr: lr must be > 0 and finite, got 0"),
        ({"epoch": 2}, "epoch", "schedule.epoch: unknown key; allowed: epochs, finetune_epochs,"),
        ({"head": {"head": {}}}, "head.head", "schedule.head.head: unknown key; allowed: epochs,"),
        ({"head": 3}, "head", "schedule.head: expected a mapping of epochs, finetune_epochs,"),
    ],
)
def test_a_bad_value_names_its_key(node, key, line):
    with pytest.raises(ScheduleError) as err:
        Schedule.of(node)
    assert err.value.key == key and str(err.value).startswith(line)
    again = pickle.loads(pickle.dumps(err.value))  # as a worker process hands it back
    assert (again.key, str(again)) == (key, str(err.value))


def test_a_schedule_stored_as_json_reads_back_equal():
    """The store writes a model's Schedule with ``dataclasses.asdict`` (``head: null`` where
    there is none, at either level); ``Schedule.of`` gives the same value back."""
    for schedule in (Schedule(epochs=3), Schedule(epochs=3, head=Schedule(lr=0.5))):
        assert Schedule.of(json.loads(json.dumps(dataclasses.asdict(schedule)))) == schedule

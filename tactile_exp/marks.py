"""What each setting is to a job, marked once: every hash and every list of settings derives here.

``MARKS`` holds one `Mark` per top-level key of ``conf/config.yaml`` and per dotted key a mark
applies to alone. What the marks decide:

- ``config_hash`` (``config.py``): a finished job with the same hash is skipped; ``hashed=False``
  keys are left out of it, ``hashed_unless`` keys while they hold that value.
- run names and axes (``config.axes``): ``named=False`` keys are left out.
- the training key (``keys.py``): a model reused across jobs; ``keyed=False`` parameters of every
  model (``model.<param>``) or modality (``modality.<param>``) are left out of it.
- a search (``search.py``): ``fixed`` keys (and everything under them) may not be sampled, with
  the reason it prints; ``search_only`` keys are the search's, left out of its final command.

A top-level key without a mark is refused at the config edge (``config.check_marked``), so a new
key is sorted once, here. A component's parameter needs no mark: unmarked, it is hashed and keyed,
so a new parameter makes a new job and a new model, never a wrong skip or reuse.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

UNSET: Any = object()  # `Mark.hashed_unless` default: hashed at every value
KEYED_GROUPS = ("model", "modality")  # whose parameters `Mark.keyed` applies to
# The groups a model's YAML may take values from (``Model.reads``): a job whose model reads
# none of a group's values leaves the group out of its hash, run name and logged config.
MODEL_GROUPS = ("schedule", "loss")


@dataclass(frozen=True)
class Mark:
    """One setting's marks; unmarked means hashed, named, keyed and searchable."""

    hashed: bool = True  # part of the config hash (top-level keys)
    named: bool = True  # part of run names and axes (top-level keys)
    keyed: bool = True  # part of the training key (``model.<param>``, ``modality.<param>``)
    fixed: str = ""  # why a search may not sample it; "" when it may
    search_only: bool = False  # a search's own setting, left out of its final evaluation
    hashed_unless: Any = UNSET  # left out of the hash at this value (keys added after jobs ran)


MARKS: dict[str, Mark] = {
    "data": Mark(fixed="it changes the data, so the question, not the answer"),
    "modality": Mark(),
    "modality.fit_on": Mark(fixed="it changes the objects the features are fitted on"),
    # Where or how fast features are computed, not which features.
    "modality.device": Mark(keyed=False),
    "modality.batch_size": Mark(keyed=False),
    "model": Mark(),
    # The T4 head's schedule inside the model's ``schedule``, the kernels and the device change
    # neither the representation nor the instance classifier: a model is reused across them.
    "model.schedule.head": Mark(keyed=False),
    "model.impl": Mark(keyed=False),
    "model.device": Mark(keyed=False),
    "schedule": Mark(),
    "loss": Mark(),
    "combine_instances": Mark(),
    "combine": Mark(),
    "split": Mark(fixed="it changes the split, so the question, not the answer"),
    "seed": Mark(
        fixed="it decides the split and the initialisation: a search over seeds selects on luck"
    ),
    "device": Mark(),
    "cache_dir": Mark(named=False),  # hashed: left out, every stored job's hash would change
    "validation": Mark(fixed="it decides the objects the search selects on"),
    "validation.fraction": Mark(search_only=True),  # a search's trials need > 0, its final run 0
    "adjectives": Mark(fixed="it changes the labels, so the question, not the answer"),
    "labels": Mark(),
    # Added after jobs were stored: at null a job keeps the hash it had before the key existed.
    "labels.min_objects": Mark(hashed_unless=None),
    # Where results go or what they are compared with, not what they are.
    "tracking": Mark(hashed=False, named=False, fixed="it decides where trials are recorded"),
    "hydra": Mark(hashed=False, named=False, search_only=True),
    "paper": Mark(hashed=False),  # the paper's figure for the row, for comparison only
    # Only feeds the visual modalities' nodes, hashed there: a haptic row is the same job
    # whatever trunk weights the grid was given.
    "trunk": Mark(hashed=False),
    # How fast a job runs, not its results (beyond float rounding): not rerun for it.
    "workers": Mark(hashed=False),
    # What the job returns to Hydra; ``study`` only tags it: a search trial is the same job as
    # the plain run of its values, skipped once either finished.
    "objective": Mark(hashed=False, named=False, fixed="it decides what the search selects on"),
    "study": Mark(
        hashed=False,
        named=False,
        fixed="it names the search and its trials",
        search_only=True,
    ),
    "sweep": Mark(hashed=False, named=False),  # what a sweep does with its other jobs
    # What is logged about a job's test scores, not what is trained: not rerun for it.
    "metrics": Mark(hashed=False, named=False),
}


def check(marks: dict[str, Mark]) -> None:
    """Every mark does something where it stands: hash and name marks on top-level keys,
    ``keyed`` on a model's or modality's parameter, ``hashed_unless`` on a dotted key."""
    for key, mark in marks.items():
        top, _, rest = key.partition(".")
        if rest and not (mark.hashed and mark.named):
            raise ValueError(f"{key}: hashed/named mark only top-level keys; mark {top}")
        if not mark.keyed and (top not in KEYED_GROUPS or not rest):
            raise ValueError(f"{key}: keyed marks a parameter of {' or '.join(KEYED_GROUPS)}")
        if mark.hashed_unless is not UNSET and not rest:
            raise ValueError(f"{key}: hashed_unless marks a key inside a top-level node")
        if rest and top not in marks:
            raise ValueError(f"{key}: its top-level key {top} has no mark")


def top_level(marks: dict[str, Mark] = MARKS) -> tuple[str, ...]:
    """The top-level keys a config may hold."""
    return tuple(k for k in marks if "." not in k)


def unhashed(marks: dict[str, Mark] = MARKS) -> tuple[str, ...]:
    return tuple(k for k, m in marks.items() if not m.hashed)


def unnamed(marks: dict[str, Mark] = MARKS) -> tuple[str, ...]:
    return tuple(k for k, m in marks.items() if not m.named)


def unkeyed(group: str, marks: dict[str, Mark] = MARKS) -> tuple[str, ...]:
    """The parameters of every ``group`` component left out of the training key, dotted."""
    prefix = f"{group}."
    return tuple(
        k.removeprefix(prefix) for k, m in marks.items() if k.startswith(prefix) and not m.keyed
    )


def added_at_default(marks: dict[str, Mark] = MARKS) -> dict[str, Any]:
    """``{top-level key: node}``: a top-level node equal to this is left out of the hash."""
    out: dict[str, Any] = {}
    for key, mark in marks.items():
        if mark.hashed_unless is UNSET:
            continue
        *parents, leaf = key.split(".")
        node = out
        for parent in parents:
            node = node.setdefault(parent, {})
        node[leaf] = mark.hashed_unless
    return out


def fixed(marks: dict[str, Mark] = MARKS) -> dict[str, str]:
    """``{key: why}`` of the keys a search may not sample."""
    return {k: m.fixed for k, m in marks.items() if m.fixed}


def search_only(marks: dict[str, Mark] = MARKS) -> tuple[str, ...]:
    """Override prefixes of a search's own keys: the key set, under it, or its config group."""
    return tuple(p for k, m in marks.items() if m.search_only for p in (f"{k}=", f"{k}.", f"{k}/"))


check(MARKS)

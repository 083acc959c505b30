"""What the report compares: configurations, each named by what differs, on data sets.

A configuration is a group of runs (``runs.Group``) minus its data set: the config-group choices
and command-line settings that set it apart from the others in the report (``model=linear``,
``model=haptic_cnn model.groups=24``, ``combine=10``), never the seed, the fold or the data. The
same name on two data sets is the same configuration, which is what lets the report rank
configurations across data sets. A data set is the data identity its runs logged (the
``data.identity`` tag), shown by its file or folder name.
"""

from __future__ import annotations

import re
import shlex
from dataclasses import dataclass

from tactile_exp.report.runs import Group

# Settings that never name a configuration: the data set (its own axis), where a run went, and
# what varies inside one configuration (the seed, the tested fold).
IGNORED = (
    "seed",
    "split.fold",
    "data",
    "tracking",
    "device",
    "cache_dir",
    "hydra",
    "sweep",
    "adjectives",
    "labels",
    "trunk",
    "modality.weights",
    "modality.layout",
    "modality.visual.weights",
    "modality.visual.layout",
)
# Config groups a name spells first, in this order; other settings follow alphabetically.
GROUP_ORDER = (
    "experiment",
    "modality",
    "model",
    "combine_instances",
    "combine",
    "loss",
    "schedule",
    "split",
)
UNKNOWN_DATA = "unknown data"
_DIGEST = re.compile(r"-[0-9a-f]{12}$")


def _ignored(key: str) -> bool:
    return any(key == k or key.startswith(f"{k}.") for k in IGNORED)


def settings(g: Group) -> dict[str, str]:
    """What a group sets: its config-group choices (``model: linear``) and its command-line
    overrides (``model.groups: 24``), less the settings that never name a configuration."""
    out = {
        k.removeprefix("choice."): v
        for k, v in g.params.items()
        if k.startswith("choice.") and v != "None" and not _ignored(k.removeprefix("choice."))
    }
    out |= {k: v for k, v in g.overrides.items() if not _ignored(k) and k not in out}
    return out


def _value(g: Group, key: str, own: dict[str, str]) -> str | None:
    """A setting's value in ``g``: set, or resolved (``params``), or absent (None)."""
    return own.get(key, g.params.get(key))


def _order(key: str) -> tuple[int, str]:
    return (GROUP_ORDER.index(key), "") if key in GROUP_ORDER else (len(GROUP_ORDER), key)


def _protocol(key: str) -> bool:
    """The split is the data set's evaluation protocol (each data set declares its own K), not
    part of a configuration: named only where it tells two groups on one data set apart."""
    return key == "split" or key.startswith("split.")


def _differing(groups: list[Group], own: dict[str, dict[str, str]], keys: list[str]) -> list[str]:
    """The keys whose values differ. A config group some groups do not have (a model without
    epochs reads no ``schedule``) differs only where two groups chose differently; a setting
    (``model.groups``) or the experiment file also where one group has it and another not."""
    out = []
    for k in keys:
        values = {_value(g, k, own[g.key]) for g in groups}
        if "." not in k and k != "experiment":
            values.discard(None)
        if len(values) > 1:
            out.append(k)
    return out


def _within_experiments(
    groups: list[Group], own: dict[str, dict[str, str]], differing: list[str]
) -> list[str]:
    """Where the experiment file differs it names the bundle it sets (``experiment=
    benchmark_lstm``, not also ``model=haptic_lstm``): another key is kept only where it
    differs between two groups of one experiment file."""
    if "experiment" not in differing:
        return differing
    kept = []
    for k in differing:
        values: dict[str | None, set[str | None]] = {}
        for g in groups:
            values.setdefault(_value(g, "experiment", own[g.key]), set()).add(
                _value(g, k, own[g.key])
            )
        if k == "experiment" or any(len(v) > 1 for v in values.values()):
            kept.append(k)
    return kept


def _parts(g: Group, own: dict[str, str], keys: list[str]) -> list[str]:
    return [f"{k}={v}" for k in keys if (v := _value(g, k, own)) not in (None, "None")]


def names(groups: list[Group]) -> dict[str, str]:
    """Group key -> its configuration's name: the settings whose values differ among the
    groups, ``key=value`` in `GROUP_ORDER`, the split left out. Groups on one data set never
    share a name (a tie gets the split settings that differ, else its row hash); groups on
    different data sets share one when their settings do."""
    own = {g.key: settings(g) for g in groups}
    keys = sorted({k for s in own.values() for k in s}, key=_order)
    differing = _within_experiments(
        groups, own, _differing(groups, own, [k for k in keys if not _protocol(k)])
    )
    out = {
        g.key: " ".join(_parts(g, own[g.key], differing)) or _fallback(g, own[g.key])
        for g in groups
    }
    by_place: dict[tuple[str, str], list[Group]] = {}
    for g in groups:
        by_place.setdefault((dataset(g, groups), out[g.key]), []).append(g)
    for alike in by_place.values():
        if len(alike) < 2:
            continue
        split = _differing(alike, own, [k for k in keys if _protocol(k)])
        for g in alike:
            out[g.key] = " ".join([out[g.key], *_parts(g, own[g.key], split)])
        if len({out[g.key] for g in alike}) < len(alike):
            for g in alike:
                out[g.key] += f" #{g.row_hash[:6]}"
    return out


def _fallback(g: Group, own: dict[str, str]) -> str:
    """A lone configuration's name: its experiment file, else its model."""
    for key in ("experiment", "model"):
        if key in own:
            return f"{key}={own[key]}"
    return g.method


def _stem(identity: str) -> str:
    return _DIGEST.sub("", identity) or identity


def dataset(g: Group, groups: list[Group] | None = None) -> str:
    """The data set ``g`` ran on, by its file or folder name; with ``groups``, a name that
    two data identities share gets each one's digest."""
    identity = g.first_run.data
    if not identity:
        return UNKNOWN_DATA
    stem = _stem(identity)
    if groups is not None:
        alike = {h.first_run.data for h in groups if _stem(h.first_run.data) == stem}
        if len(alike) > 1:
            return f"{stem} ({identity[len(stem) + 1 :][:6]})"
    return stem


def by_dataset(groups: list[Group]) -> dict[str, list[Group]]:
    """The groups of each data set, data sets in name order."""
    out: dict[str, list[Group]] = {}
    for g in groups:
        out.setdefault(dataset(g, groups), []).append(g)
    return dict(sorted(out.items()))


class SpecError(ValueError):
    """A configuration spec that names no configuration, or several."""


@dataclass(frozen=True)
class Spec:
    """``model=haptic_cnn model.groups=24``: the settings a configuration must have."""

    text: str
    items: tuple[tuple[str, str], ...]

    @classmethod
    def parse(cls, text: str) -> Spec:
        items = []
        for word in shlex.split(text):
            key, sep, value = word.partition("=")
            if not sep or not key or not value:
                raise SpecError(f"{text!r}: expected key=value settings, e.g. model=linear")
            items.append((key, value))
        if not items:
            raise SpecError("an empty configuration spec: expected e.g. model=linear")
        return cls(text.strip(), tuple(items))

    def matches(self, g: Group) -> bool:
        own = settings(g)
        return all(_value(g, k, own) == v for k, v in self.items)

    def pick(self, groups: list[Group], names: dict[str, str]) -> Group | None:
        """The one group of ``groups`` (one data set's) this spec names: the only match, or the
        match whose name is exactly the spec; None when nothing matches."""
        found = [g for g in groups if self.matches(g)]
        if len(found) > 1:
            exact = [g for g in found if set(names[g.key].split()) == set(self.text.split())]
            if len(exact) != 1:
                listed = "; ".join(names[g.key] for g in found)
                raise SpecError(
                    f"{self.text!r} matches {len(found)} configurations on "
                    f"{dataset(found[0])} ({listed}): add the setting that tells them apart"
                )
            found = exact
        return found[0] if found else None

"""What a public data set's recipe declares, read from its YAML file (``recipes/<name>.yaml``).

``python -m tactile_exp.data public list|import`` (`tactile_exp.data.public`) reads them.

A recipe names its upstream (repository and pinned commit, or DOI), what it holds, its licence as
the upstream states it, which of the upstream's files are trials (a pattern whose group
``object`` names the object and ``trial`` numbers the trial), how many there are and their
checksum, the reader that turns a file into (channels, time) arrays, the rate and channel names,
the label table with where each label comes from, and the split it is evaluated with. Its frozen
folds ship beside it (``frozen_folds/<name>.yaml``, `tactile_exp.data.frozen`). Every recipe file is
registered in `RECIPES` under its name; a recipe file of one's own is read by `find`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import yaml

from tactile_exp.data.folder import NAME
from tactile_exp.data.frozen import FrozenFolds
from tactile_exp.data.layout import DataError
from tactile_exp.registry import Registry

HERE = Path(__file__).parent
RECIPE_DIR, FOLDS_DIR = HERE / "recipes", HERE / "frozen_folds"
KEYS = {
    "name": "the recipe's name",
    "title": "what the data set is called",
    "upstream": "{repository: OWNER/NAME, commit: SHA}, {doi: ...} or {release: words}",
    "holds": "what it holds, in a sentence",
    "licence": "the licence as the upstream states it (or that it states none)",
    "reader": "how a file becomes trials: a reader of tactile_exp.data.readers",
    "files": "a regular expression on each file's path whose group 'object' names the object",
    "count": "how many files the recipe takes",
    "sha256": "the checksum of those files (`tree_sha256`), or null: counts only",
    "sensor": "the sensor's name",
    "rate_hz": "samples per second along a trial's time axis",
    "rate_source": "where the rate comes from",
    "channels": "the channel names, in a trial's row order",
    "objects": "object -> the upstream's description of it",
    "labels": "label -> {source: upstream | ours, from: where, positive: [OBJECT, ...]}",
    "split": "{folds: K, resamples: R}: the frozen folds it is evaluated with",
}
OPTIONAL = {"trials": "[FIRST, LAST]: the trial numbers taken (group 'trial'); default all"}
# A file the existing reader takes as it is (PHAC-2: data=phac2) carries its own channels,
# objects, labels and split: the recipe says so in words instead of listing them.
OWN_READER = "phac2"
SELF_DESCRIBED = ("channels", "objects", "labels", "split")
LABEL_SOURCES = ("upstream", "ours")


@dataclass(frozen=True)
class Label:
    source: str  # upstream: the upstream's own table; ours: derived by us from its descriptions
    origin: str  # where it comes from, in words
    positive: tuple[str, ...]


@dataclass(frozen=True)
class Recipe:
    name: str
    title: str
    upstream: dict[str, str]
    holds: str
    licence: str
    reader: str
    files: re.Pattern[str]
    count: int
    sha256: str | None
    sensor: str
    rate_hz: float
    rate_source: str
    channels: tuple[str, ...]
    objects: dict[str, str]
    labels: dict[str, Label]
    folds: int
    resamples: int
    trials: tuple[int, int] | None = None
    file: Path | None = None
    described: dict[str, str] | None = None  # SELF_DESCRIBED key -> words (the own reader's)

    @classmethod
    def load(cls, file: Path) -> Recipe:
        """The recipe in ``file``; one-line `DataError` naming the file and key when off."""
        try:
            node = yaml.safe_load(file.read_text())
        except OSError as e:
            raise DataError(f"{file}: cannot read ({e.strerror}); expected a recipe") from None
        except yaml.YAMLError:
            raise DataError(f"{file}: not valid YAML; expected a recipe") from None
        if not isinstance(node, dict):
            raise DataError(f"{file}: expected a mapping with {', '.join(KEYS)}")
        if node.get("reader") == OWN_READER:
            described = {k: " ".join(str(node.get(k, "")).split()) for k in SELF_DESCRIBED}
            node = {**node, "channels": [], "objects": {}, "labels": {}}
            node["split"] = {"folds": 0, "resamples": 0}
        else:
            described = None
        if "labels" not in node or (not node["labels"] and described is None):
            raise DataError(
                f"{file}: no label table (labels: {KEYS['labels']}); a recipe names every label "
                "and where it comes from"
            )
        missing = [k for k in KEYS if k not in node]
        extra = sorted(set(node) - set(KEYS) - set(OPTIONAL))
        if missing or extra:
            what = f"missing {missing}" if missing else f"unknown key(s) {extra}"
            raise DataError(f"{file}: {what}; expected {', '.join(KEYS)}")
        try:
            files = re.compile(str(node["files"]))
        except re.error as err:
            raise DataError(f"{file}: files: not a regular expression ({err})") from None
        if "object" not in files.groupindex:
            raise DataError(f"{file}: files: {files.pattern!r} has no group 'object'")
        objects = {str(k): str(v) for k, v in (node["objects"] or {}).items()}
        bad = [o for o in objects if not NAME.fullmatch(o)]
        if bad or (not objects and described is None):
            raise DataError(f"{file}: objects: {bad or 'none'}, expected names of letters, digits")
        labels = {}
        for label, spec in node["labels"].items():
            where = f"{file}: labels.{label}"
            if not isinstance(spec, dict) or set(spec) != {"source", "from", "positive"}:
                raise DataError(f"{where}: expected {KEYS['labels'].split('-> ')[1]}")
            if spec["source"] not in LABEL_SOURCES:
                raise DataError(f"{where}.source: {spec['source']!r}, expected upstream or ours")
            unknown = sorted(set(spec["positive"]) - set(objects))
            if unknown:
                raise DataError(f"{where}.positive: {unknown} are not objects of the recipe")
            labels[str(label)] = Label(spec["source"], str(spec["from"]), tuple(spec["positive"]))
        split = node["split"]
        if not isinstance(split, dict) or set(split) != {"folds", "resamples"}:
            raise DataError(f"{file}: split: {split!r}, expected {KEYS['split']}")
        trials = node.get("trials")
        try:
            return cls._build(file, node, files, objects, labels, split, trials, described)
        except (TypeError, ValueError, AttributeError, IndexError) as err:
            raise DataError(f"{file}: a value of the wrong kind ({err})") from None

    @classmethod
    def _build(
        cls,
        file: Path,
        node: dict,
        files: re.Pattern[str],
        objects: dict[str, str],
        labels: dict[str, Label],
        split: dict,
        trials: list | None,
        described: dict[str, str] | None,
    ) -> Recipe:
        return cls(
            name=str(node["name"]),
            title=str(node["title"]),
            upstream={str(k): str(v) for k, v in node["upstream"].items()},
            holds=" ".join(str(node["holds"]).split()),
            licence=" ".join(str(node["licence"]).split()),
            reader=str(node["reader"]),
            files=files,
            count=int(node["count"]),
            sha256=None if node["sha256"] is None else str(node["sha256"]),
            sensor=str(node["sensor"]),
            rate_hz=float(node["rate_hz"]),
            rate_source=" ".join(str(node["rate_source"]).split()),
            channels=tuple(str(c) for c in node["channels"]),
            objects=objects,
            labels=labels,
            folds=int(split["folds"]),
            resamples=int(split["resamples"]),
            trials=None if trials is None else (int(trials[0]), int(trials[1])),
            file=file,
            described=described,
        )

    def label_table(self) -> dict[str, dict[str, int]]:
        """Object -> label -> 0/1: a label's listed objects are positive, the others negative."""
        return {
            o: {a: int(o in spec.positive) for a, spec in self.labels.items()} for o in self.objects
        }

    def frozen_folds(self) -> FrozenFolds:
        """The folds it ships (``frozen_folds/<name>.yaml``)."""
        file = FOLDS_DIR / f"{self.name}.yaml"
        if not file.is_file():
            raise DataError(f"{file}: missing; recipe {self.name} ships its frozen folds there")
        return FrozenFolds.read(file)

    def where(self) -> str:
        """Its upstream in a phrase: ``OWNER/NAME at COMMIT`` or ``doi:...``."""
        up = self.upstream
        if "repository" in up:
            return f"github.com/{up['repository']} at {up.get('commit', '?')}"
        return f"doi:{up['doi']}" if "doi" in up else up.get("release", "?")


RECIPES: Registry[Recipe] = Registry("public data set")
for _file in sorted(RECIPE_DIR.glob("*.yaml")):
    RECIPES.register(_file.stem)(lambda file=_file: Recipe.load(file))


def find(name: str) -> Recipe:
    """A registered recipe by name, or a recipe file of one's own (``*.yaml``)."""
    if name.endswith((".yaml", ".yml")):
        return Recipe.load(Path(name).expanduser())
    if name not in RECIPES:
        raise DataError(
            f"unknown public data set {name!r}; known: {', '.join(RECIPES.names())} "
            "(python -m tactile_exp.data public list), or a recipe file NAME.yaml"
        )
    return RECIPES.build(name)

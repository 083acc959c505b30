"""Per-adjective train/test splits (METHOD E1, E3; PHAC2_FORMAT §2).

Each rule is a function ``(dataset, adjective, seed, **params) -> Split`` in `SPLITS` (params
from the rule's YAML, checked by `check_split_params` before a job starts); `make_split` is the one
way to get a split. Every split leaves `check_split`, so no rule can hand out a split with
object leakage or a one-class side.
"""

from __future__ import annotations

import warnings

import h5py
import numpy as np

from tactile_exp.data.dataset import DataSet, select_labels
from tactile_exp.data.frozen import FrozenFolds
from tactile_exp.data.layout import (
    NEGATIVE_SPLIT_GROUP,
    POSITIVE_SPLIT_GROUP,
    DataError,
    Split,
    TrialName,
    published_test_split,
)
from tactile_exp.data.phac2 import PHAC2
from tactile_exp.registry import Registry

TRAIN_RATIO = 0.9  # the authors' 90/10 (the "90_10" in the file name)
MAX_FOLDS = 5  # ours: the largest K a data set's declared folds split takes
DECLARED = "declared"  # split=declared: the split the data set declares (`declared_split`)

SPLITS: Registry[Split] = Registry("split")  # rule(dataset, adjective, seed, **params) -> Split


def make_split(
    dataset: DataSet, adjective: str, rule: str = "published", seed: int = 0, **params: int
) -> Split:
    """One label's train/test split by a rule of `SPLITS` (E1, E3; ``folds``: ours)."""
    if adjective not in dataset.label_names:
        raise DataError(
            f"{dataset.path}: unknown adjective {adjective!r} (expected one of the data set's "
            f"labels: {', '.join(dataset.label_names)})"
        )
    return SPLITS[rule](dataset, adjective, seed, **params)


def object_counts(dataset: DataSet, label: str) -> tuple[int, int]:
    """(positive, negative) objects of ``label`` that have trials."""
    labels = dataset.labels()
    values = [labels[i][label] for i in dataset.object_ids()]
    return sum(values), len(values) - sum(values)


def _counts(dataset: DataSet, labels: list[str]) -> str:
    return ", ".join(
        f"{a} (+{p}/-{n} objects)" for a in labels for p, n in [object_counts(dataset, a)]
    )


def label_splits(
    dataset: DataSet,
    labels: tuple[str, ...],
    rule: str,
    seed: int = 0,
    min_objects: int | None = None,
    **params: int,
) -> dict[str, Split]:
    """Each label's split under ``rule``, for the labels that can be evaluated under it.

    ``min_objects`` K (``labels.min_objects``, ours) first leaves out every label with fewer
    than K positive or K negative objects; any other label that cannot be split is refused,
    all such labels in one `DataError` with their object counts and the K that drops them."""
    kept = [
        a for a in labels if min_objects is None or min(object_counts(dataset, a)) >= min_objects
    ]
    if not kept:
        raise DataError(
            f"{dataset.path}: labels.min_objects={min_objects} leaves no label: "
            f"{_counts(dataset, list(labels))}"
        )
    splits: dict[str, Split] = {}
    errors: dict[str, DataError] = {}
    for a in kept:
        try:
            splits[a] = make_split(dataset, a, rule, seed, **params)
        except DataError as err:
            errors[a] = err
    if not errors:
        return splits
    if not splits and all(repr(a) not in str(e) for a, e in errors.items()):
        raise next(iter(errors.values()))  # the rule refuses this data set, not its labels
    bad = list(errors)
    k = max(min(object_counts(dataset, a)) for a in bad) + 1
    also = [a for a in splits if min(object_counts(dataset, a)) < k]
    spared = [a for a in kept if a not in bad and a not in also]
    if spared:
        ways = f"labels.min_objects={k} drops them" + (f" (and {', '.join(also)})" if also else "")
        ways += f", or adjectives=[{','.join(spared)}]"
    else:
        most = max(min(object_counts(dataset, a)) for a in kept)
        ways = "dropping them leaves no label; " + (
            f"split.folds={most} or split=random"
            if rule == "folds" and most >= 2
            else "bring more objects, or another split"
        )
    raise DataError(
        f"{dataset.path}: {len(bad)} label(s) cannot be evaluated under split={rule}"
        f"{_need(rule, params)}: {_counts(dataset, bad)}; {ways}"
    )


def _need(rule: str, params: dict[str, int]) -> str:
    """What the rule needs of each class, as a parenthesis (empty for an unknown rule)."""
    if rule == "folds":
        return f" (each class needs split.folds={params.get('folds')} objects)"
    if rule == "random":
        return " (each class needs an object; a single one, two trials)"
    return ""


def check_split_params(rule: str, params: dict[str, object]) -> None:
    """A rule's parameters, before any data is read: ValueError naming the key otherwise."""
    allowed = {"folds": ("folds", "fold", "frozen")}.get(rule, ())
    extra = sorted(set(params) - set(allowed))
    if extra:
        raise ValueError(
            f"{extra[0]}: not a parameter of split={rule} (it takes {allowed or 'none'})"
        )
    if rule != "folds":
        return
    folds, fold = params.get("folds"), params.get("fold")
    if not isinstance(folds, int) or isinstance(folds, bool) or folds < 2:
        raise ValueError(f"folds: must be a whole number of folds >= 2, got {folds!r}")
    if not isinstance(fold, int) or isinstance(fold, bool) or not 0 <= fold < folds:
        raise ValueError(
            f"fold: must be a whole number in 0..{folds - 1} (split.folds-1), got {fold!r}"
        )


def check_split(split: Split, where: str = "") -> Split:
    """Reject leakage and one-class sides; `where` (file, rule) prefixes the error message.

    An object may sit on both sides only when it is the single object of its class (the
    authors split such an object by trial).
    """
    head = f"{where}: " if where else ""
    adj = split.adjective
    both = sorted(set(split.train) & set(split.test))
    if both:
        raise DataError(f"{head}split of {adj!r}: trial(s) {both[:5]} in both train and test")
    for part, names in (("train", split.train), ("test", split.test)):
        have = {split.labels[n] for n in names}
        for label, word in ((1, "positive"), (0, "negative")):
            if label not in have:
                raise DataError(
                    f"{head}split of {adj!r}: {part} has no {word} trial "
                    f"(expected at least one positive and one negative on each side)"
                )
    objects_of = {1: set(), 0: set()}
    for n, label in split.labels.items():
        objects_of[label].add(_object(n))
    for obj in sorted(split.objects("train") & split.objects("test")):
        label = next(split.labels[n] for n in split.labels if _object(n) == obj)
        if len(objects_of[label]) > 1:
            raise DataError(
                f"{head}split of {adj!r}: object {obj} in both train and test (expected no "
                "shared object unless it is the only object of its class)"
            )
    return split


def _object(name: str) -> int:
    return TrialName.parse(name).object_id  # type: ignore[union-attr]


def _trials_by_object(dataset: DataSet, adjective: str) -> dict[int, dict[int, list[str]]]:
    """label -> object id -> its trial names (sorted)."""
    labels = dataset.labels()
    out: dict[int, dict[int, list[str]]] = {1: {}, 0: {}}
    for t in dataset.trials:
        out[labels[t.object_id][adjective]].setdefault(t.object_id, []).append(t.name)
    return out


def _make(dataset: DataSet, adjective: str, train: list[str], test: list[str], rule: str) -> Split:
    labels = dataset.labels()
    split = Split(
        adjective=adjective,
        train=tuple(sorted(train)),
        test=tuple(sorted(test)),
        labels={n: labels[_object(n)][adjective] for n in [*train, *test]},
    )
    return check_split(split, f"{dataset.path} ({rule} split)")


@SPLITS.register("published")
def published(dataset: DataSet, adjective: str, seed: int = 0) -> Split:
    """The published split: from the file's split groups, else from the package's table.
    PHAC-2's own: another data set has no published split to follow."""
    if not isinstance(dataset, PHAC2):
        raise DataError(
            f"{dataset.path}: split=published is PHAC-2's published split and this data set is "
            "not PHAC-2; use split=random or split=folds"
        )
    if {POSITIVE_SPLIT_GROUP, NEGATIVE_SPLIT_GROUP} <= dataset.groups:
        with h5py.File(dataset.path, "r") as f:
            found = _read_split_groups(dataset, f, adjective)
        if found is not None:
            return found
    try:
        return _from_table(dataset, adjective)
    except DataError as e:
        warnings.warn(f"{e}; falling back to the random split with seed {seed}", stacklevel=3)
        return random_split(dataset, adjective, seed)


def _read_split_groups(dataset: PHAC2, f: h5py.File, adjective: str) -> Split | None:
    parts: dict[str, list[str]] = {"train": [], "test": []}
    trials = {t.name: t for t in dataset.trials}
    labels = dataset.labels()  # once: it copies the label table (per trial it was most of a check)
    for group, label in ((POSITIVE_SPLIT_GROUP, 1), (NEGATIVE_SPLIT_GROUP, 0)):
        for part in parts:
            key = f"/{group}/{adjective}/{part}"
            node = f.get(key)
            if not isinstance(node, h5py.Group):
                warnings.warn(f"{dataset.path}: {key} missing; using the table", stacklevel=4)
                return None
            for name in node:
                if name not in trials:
                    raise DataError(
                        f"{dataset.path}: {key}/{name} is not one of the file's trial groups"
                    )
                have = labels[trials[name].object_id][adjective]
                if have != label:
                    raise DataError(
                        f"{dataset.path}: {key} links {name}, whose {adjective} label is {have} "
                        f"(expected {label})"
                    )
                parts[part].append(name)
    return _make(dataset, adjective, parts["train"], parts["test"], "published")


def _from_table(dataset: PHAC2, adjective: str) -> Split:
    by_object = _trials_by_object(dataset, adjective)
    rows = [r for r in published_test_split() if r.adjective == adjective]
    test: list[str] = []
    for r in rows:
        trials = by_object[r.label].get(r.object_id)
        if trials is None:
            raise DataError(
                f"{dataset.path}: published test object {r.object_id} ({adjective}={r.label}) "
                "is not in the file"
            )
        test += [n for n in trials if r.trials is None or _trial_no(n) in r.trials]
    chosen = set(test)
    every = [n for objs in by_object.values() for names in objs.values() for n in names]
    train = [n for n in every if n not in chosen]
    return _make(dataset, adjective, train, test, "published")


def _trial_no(name: str) -> int:
    return TrialName.parse(name).trial  # type: ignore[union-attr]


@SPLITS.register("random")
def random_split(dataset: DataSet, adjective: str, seed: int = 0) -> Split:
    """The authors' rule with a seeded object order (§2): 90/10 by object, per class."""
    rng = np.random.default_rng([seed, dataset.label_names.index(adjective)])
    train: list[str] = []
    test: list[str] = []
    for _, objs in sorted(_trials_by_object(dataset, adjective).items(), reverse=True):
        ids = [int(i) for i in rng.permutation(sorted(objs))]
        if len(ids) == 1:
            trials = [str(n) for n in rng.permutation(objs[ids[0]])]
            cut = len(trials) - len(trials) // 2
            train += trials[:cut]
            test += trials[cut:]
            continue
        n_train = min(max(int(TRAIN_RATIO * len(ids)), 1), max(len(ids) - 1, 1))
        train += [n for i in ids[:n_train] for n in objs[i]]
        test += [n for i in ids[n_train:] for n in objs[i]]
    return _make(dataset, adjective, train, test, f"random seed={seed}")


@SPLITS.register("folds")
def folds_split(
    dataset: DataSet,
    adjective: str,
    seed: int = 0,
    folds: int = 5,
    fold: int = 0,
    frozen: str | None = None,
) -> Split:
    """Object-grouped, class-stratified K-fold (ours): fold ``fold`` of ``folds`` is
    the test side. Over ``fold = 0..folds-1`` of one seed every object is tested exactly once.

    Each class's objects are shuffled (seeded by ``seed`` and the adjective) and dealt to the
    folds in turn; the negatives continue the deal where the positives stopped, so the folds
    differ in size by at most one object. A data set with frozen folds (``frozen_folds``, e.g.
    an imported public data set) is not dealt: fold ``fold`` of its resample ``seed`` is tested,
    and ``frozen`` (the digest a job was configured with; None: whatever file it holds) must be
    its file's.
    """
    check_split_params("folds", {"folds": folds, "fold": fold})
    held: FrozenFolds | None = getattr(dataset, "frozen_folds", None)
    if held is not None or frozen is not None:
        return _frozen_split(dataset, adjective, seed, folds, fold, frozen, held)
    rng = np.random.default_rng([seed, dataset.label_names.index(adjective), 27])
    train: list[str] = []
    test: list[str] = []
    start = 0
    for label, objs in sorted(_trials_by_object(dataset, adjective).items(), reverse=True):
        if len(objs) < folds:
            word = "positive" if label == 1 else "negative"
            fewer = f"use split.folds<={len(objs)}, " if len(objs) >= 2 else ""
            raise DataError(
                f"{dataset.path} (folds split): {adjective!r} has {len(objs)} {word} object(s), "
                f"fewer than split.folds={folds}; every fold needs one ({fewer}leave it out of "
                "adjectives=, or use split=random)"
            )
        for k, i in enumerate(int(i) for i in rng.permutation(sorted(objs))):
            (test if (start + k) % folds == fold else train).extend(objs[i])
        start = (start + len(objs)) % folds
    return _make(dataset, adjective, train, test, f"folds seed={seed} fold={fold}/{folds}")


def _frozen_split(
    dataset: DataSet,
    adjective: str,
    seed: int,
    folds: int,
    fold: int,
    frozen: str | None,
    held: FrozenFolds | None,
) -> Split:
    where = f"{dataset.path} (frozen folds)"
    if held is None or (frozen is not None and held.digest != frozen):
        have = f"digest {held.digest}" if held is not None else "none"
        raise DataError(
            f"{where}: the job was configured for frozen folds {frozen}, the data set holds "
            f"{have}; its folds file changed since the job was configured: run it again"
        )
    tested = set(held.test_objects(adjective, seed, folds, fold, where))
    names = {dataset.object_name(i): i for i in dataset.object_ids()}
    unknown = sorted(tested - set(names))
    if unknown:
        raise DataError(f"{where}: {adjective} fold {fold} names unknown object(s) {unknown}")
    test_ids = {names[o] for o in tested}
    train = [t.name for t in dataset.trials if t.object_id not in test_ids]
    test = [t.name for t in dataset.trials if t.object_id in test_ids]
    return _make(dataset, adjective, train, test, f"frozen folds seed={seed} fold={fold}/{folds}")


def folds_for(counts: dict[str, tuple[int, int]]) -> tuple[int, str]:
    """(K, why) of a declared folds split: the largest K <= `MAX_FOLDS` for which every label
    (``counts``: label -> its positive and negative objects) has K objects of each class, and
    the label that limits it. DataError's text when no K >= 2 fits."""
    limiting = min(counts, key=lambda a: min(counts[a]))
    p, n = counts[limiting]
    k = min(MAX_FOLDS, p, n)
    word = "positive" if p <= n else "negative"
    if k == MAX_FOLDS:
        return k, f"every label has at least {MAX_FOLDS} positive and {MAX_FOLDS} negative objects"
    why = f"label {limiting} has {min(p, n)} {word} object{'s' if min(p, n) != 1 else ''}"
    if k < 2:
        raise DataError(
            f"no folds split fits: {why} (+{p}/-{n}), object-grouped folds need 2 of each class; "
            "labels.min_objects=2 drops such labels, or split=random"
        )
    return k, why


def declared_split(
    dataset: DataSet, adjectives: tuple[str, ...] | None, min_objects: int | None
) -> tuple[dict[str, object], str]:
    """The split node a data set declares (its ``declared_split``, e.g. a folder's
    ``dataset.yaml`` ``split:``; none: object-grouped folds) and what to print about it. A
    folds split without K takes `folds_for` the labels the job keeps."""
    node = dict(getattr(dataset, "declared_split", None) or {"name": "folds"})
    if node["name"] != "folds":
        return node, f"{node['name']} (declared by the data set)"
    held: FrozenFolds | None = getattr(dataset, "frozen_folds", None)
    if held is not None:
        node.setdefault("folds", held.folds)
    if "folds" in node:
        node.setdefault("fold", 0)
        return node, f"folds K={node['folds']} (declared by the data set)"
    labels = select_labels(dataset, adjectives)
    counts = {a: object_counts(dataset, a) for a in labels}
    kept = {a: c for a, c in counts.items() if min_objects is None or min(c) >= min_objects}
    if not kept:
        raise DataError(
            f"{dataset.path}: labels.min_objects={min_objects} leaves no label: "
            f"{_counts(dataset, list(labels))}"
        )
    try:
        k, why = folds_for(kept)
    except DataError as err:
        raise DataError(f"{dataset.path}: split=declared: {err}") from None
    return {"name": "folds", "folds": k, "fold": 0}, f"folds K={k} ({why})"


@SPLITS.register(DECLARED)
def declared(dataset: DataSet, adjective: str, seed: int = 0, fold: int = 0) -> Split:
    """The split the data set declares (`declared_split`) for its labels, fold ``fold`` of a
    folds split: what a job's ``split=declared`` resolves to before it runs, here for a
    notebook's `make_split`."""
    node, _ = declared_split(dataset, None, None)
    params = {k: v for k, v in node.items() if k != "name"}
    if node["name"] == "folds":
        params["fold"] = fold
    elif fold:
        raise DataError(f"{dataset.path}: declares split={node['name']}, one test side; fold=0")
    return SPLITS[str(node["name"])](dataset, adjective, seed, **params)


def divide_views(
    views: np.ndarray, n_train: int, n_test: int, where: str
) -> tuple[np.ndarray, np.ndarray]:
    """The photographs (in view order) of an object whose trials a split puts on both sides,
    divided in the proportion of its trials: first views to training, at least one per side."""
    if len(views) < 2:
        raise ValueError(
            f"visual split of {where} is split by trial ({n_train} train, {n_test} test) but "
            f"has {len(views)} photograph(s); at least 2 are needed to put views on both sides"
        )
    k = min(len(views) - 1, max(1, round(len(views) * n_train / (n_train + n_test))))
    return views[:k], views[k:]

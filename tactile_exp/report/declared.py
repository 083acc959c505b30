"""Comparisons the user declares (``--compare "model=haptic_cnn > model=linear"``), judged as the
paper's claims are, on every data set where both configurations ran.

On a data set: the paired difference of mean metric with its object-bootstrap interval,
Wilcoxon's signed-rank test over labels and the bootstrap's own test, Holm over every declared
comparison on every data set (one family), and the verdict from the three together
(``comparisons.judge``: ``>`` needs a win, ``>=`` an interval that rules out a loss of
``--margin``); then each label's difference with its paired interval at the Bonferroni level over
the labels (the paper's Fig. 5, for any pair). Across data sets: each data set's difference of
means, and Wilcoxon's test over the data sets (Demsar 2006), which needs six or more data sets
before any p can fall below 0.05.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tactile_exp import stats
from tactile_exp.report import comparisons
from tactile_exp.report.configurations import Spec, SpecError
from tactile_exp.report.heldout import Evidence
from tactile_exp.report.leaderboard import value
from tactile_exp.report.runs import Group

RELATIONS = (">=", ">")  # tried in this order: ">=" contains ">"


@dataclass(frozen=True)
class Declared:
    """``better > worse`` (better wins) or ``better >= worse`` (not worse by over the margin)."""

    text: str
    better: Spec
    relation: str
    worse: Spec

    @classmethod
    def parse(cls, text: str) -> Declared:
        for relation in RELATIONS:
            left, sep, right = text.partition(relation)
            if sep:
                return cls(text, Spec.parse(left), relation, Spec.parse(right.lstrip("=")))
        raise SpecError(
            f"--compare {text!r}: expected 'A > B' or 'A >= B' with A and B configurations "
            '(key=value settings, e.g. "model=haptic_cnn > model=linear")'
        )


@dataclass(frozen=True)
class Outcome:
    """One declared comparison on one data set."""

    declared: Declared
    dataset: str
    result: str  # supported / contradicted / mixed / not distinguishable / not compared / not run
    detail: str
    a: str = ""  # the configurations' names, where both ran
    b: str = ""
    comparison: stats.Comparison | None = None
    labels: dict[str, stats.Interval] = field(default_factory=dict)  # a - b per label
    level: float = 1 - stats.ALPHA  # the per-label intervals' level


@dataclass(frozen=True)
class Across:
    """One declared comparison over the data sets where both sides have a mean."""

    declared: Declared
    differences: dict[str, float]  # data set -> a - b of the means
    p: float  # Wilcoxon over the data sets (1 with none non-zero)

    def describe(self) -> str:
        d = np.array(list(self.differences.values()))
        n = len(d)
        return (
            f"{self.declared.better.text} higher on {int(np.sum(d > 0))} of {n} data sets, "
            f"lower on {int(np.sum(d < 0))}; mean difference {d.mean():+.3f}; Wilcoxon over data "
            f"sets p = {self.p:.3g}"
            + (" (fewer than 6 data sets: p cannot fall below 0.05)" if n < 6 else "")
        )


def outcomes(
    declared: list[Declared],
    datasets: dict[str, list[Group]],
    evidence: dict[str, Evidence],
    names: dict[str, str],
    margin: float = stats.MARGIN,
) -> list[Outcome]:
    """Each declared comparison on each data set where either side ran; Holm over the compared
    ones. A spec that names no configuration on any data set is a `SpecError`."""
    for d in declared:
        for spec in (d.better, d.worse):
            if not any(spec.pick(gs, names) for gs in datasets.values()):
                known = sorted({names[g.key] for gs in datasets.values() for g in gs})
                raise SpecError(
                    f"--compare {d.text!r}: {spec.text!r} names no configuration on any data set "
                    f"(configurations: {'; '.join(known)})"
                )
    done: list[Outcome] = []
    pending: list[tuple[int, stats.Comparison]] = []
    for d in declared:
        for dataset, groups in datasets.items():
            a, b = d.better.pick(groups, names), d.worse.pick(groups, names)
            if a is None and b is None:
                continue
            if a is None or b is None:
                absent = d.better.text if a is None else d.worse.text
                done.append(Outcome(d, dataset, "not run", f"{absent} did not run here"))
                continue
            ea, eb = evidence[a.key], evidence[b.key]
            if not (ea.ok and eb.ok):
                done.append(Outcome(d, dataset, "not compared", ea.missing or eb.missing))
                continue
            reason = stats.unpaired_reason(ea.evaluations, eb.evaluations)
            if reason is not None:
                done.append(Outcome(d, dataset, "not compared", f"not paired: {reason}"))
                continue
            cmp = stats.compare(names[a.key], ea.evaluations, names[b.key], eb.evaluations)
            labels, level = _labels(ea, eb)
            pending.append((len(done), cmp))
            done.append(Outcome(d, dataset, "", "", names[a.key], names[b.key], cmp, labels, level))
    for (i, _), cmp in zip(pending, stats.with_holm([c for _, c in pending]), strict=True):
        o = done[i]
        done[i] = Outcome(
            o.declared,
            o.dataset,
            comparisons.judge(o.declared.relation, cmp, margin),
            comparisons.describe(cmp, margin),
            o.a,
            o.b,
            cmp,
            o.labels,
            o.level,
        )
    return done


def _labels(a: Evidence, b: Evidence) -> tuple[dict[str, stats.Interval], float]:
    """Each label's difference a - b with its paired interval, Bonferroni over the labels."""
    labels = sorted(a.evaluations[0])
    level = 1 - stats.ALPHA / len(labels)
    return {
        j: stats.adjective_difference(a.evaluations, b.evaluations, j, level) for j in labels
    }, level


def across(
    declared: list[Declared],
    datasets: dict[str, list[Group]],
    evidence: dict[str, Evidence],
    names: dict[str, str],
) -> list[Across]:
    """Each declared comparison over the data sets where both sides ran (two or more)."""
    out = []
    for d in declared:
        differences = {}
        for dataset, groups in datasets.items():
            a, b = d.better.pick(groups, names), d.worse.pick(groups, names)
            if a is not None and b is not None:
                va, vb = value(a, evidence[a.key]), value(b, evidence[b.key])
                differences[dataset] = va.estimate - vb.estimate
        if len(differences) >= 2:
            p = stats.wilcoxon_p(np.array(list(differences.values())))
            out.append(Across(d, differences, p))
    return out


def rows(found: list[Outcome]) -> list[dict[str, str]]:
    """The outcomes, machine-readable; one line per label difference follows each compared one
    (``label`` set)."""
    out = []
    for o in found:
        cmp = o.comparison
        base = {"comparison": o.declared.text, "dataset": o.dataset, "a": o.a, "b": o.b}
        d = cmp.difference if cmp else None
        out.append(
            base
            | {
                "label": "",
                "result": o.result,
                "difference": "" if d is None else f"{d.estimate:.6f}",
                "ci_low": "" if d is None else f"{d.low:.6f}",
                "ci_high": "" if d is None else f"{d.high:.6f}",
                "level": f"{1 - stats.ALPHA:.4f}",
                "p_wilcoxon": "" if cmp is None else f"{cmp.p:.6g}",
                "p_bootstrap": "" if cmp is None else f"{cmp.p_bootstrap:.6g}",
                "p_holm": "" if cmp is None else f"{cmp.p_holm:.6g}",
                "detail": o.detail,
            }
        )
        for label, iv in o.labels.items():
            out.append(
                base
                | {
                    "label": label,
                    "result": _side(iv),
                    "difference": f"{iv.estimate:.6f}",
                    "ci_low": "" if iv.missing else f"{iv.low:.6f}",
                    "ci_high": "" if iv.missing else f"{iv.high:.6f}",
                    "level": f"{o.level:.4f}",
                    "p_wilcoxon": "",
                    "p_bootstrap": "",
                    "p_holm": "",
                    "detail": iv.missing,
                }
            )
    return out


def _side(iv: stats.Interval) -> str:
    if iv.missing:
        return "no interval"
    return "a higher" if iv.low > 0 else "b higher" if iv.high < 0 else "not distinguishable"


def markdown(found: list[Outcome], overall: list[Across]) -> str:
    lines = [
        "| comparison | data set | verdict | numbers |",
        "|---|---|---|---|",
        *(f"| {o.declared.text} | {o.dataset} | **{o.result}** | {o.detail} |" for o in found),
        "",
    ]
    for o in found:
        if not o.labels:
            continue
        lines += [
            f"**{o.declared.text}** on {o.dataset}, per label (`{o.a}` - `{o.b}`, "
            f"{o.level:.2%} paired intervals: Bonferroni over {len(o.labels)} labels):",
            "",
            "| label | difference [interval] | |",
            "|---|---|---|",
        ]
        for label, iv in o.labels.items():
            shown = (
                f"{iv.estimate:+.3f} (no interval: {iv.missing})"
                if iv.missing
                else f"{iv.estimate:+.3f} [{iv.low:+.3f}, {iv.high:+.3f}]"
            )
            lines.append(f"| {label} | {shown} | {_side(iv)} |")
        lines.append("")
    if overall:
        lines += ["Across data sets (each data set's difference of means):", ""]
        lines += [f"- **{x.declared.text}**: {x.describe()}" for x in overall]
        lines.append("")
    return "\n".join(lines) + "\n"

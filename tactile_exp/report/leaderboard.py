"""One data set's leaderboard: every configuration's mean metric with its object-bootstrap
interval, its rank, what its number rests on, and its paired difference from a baseline.

The baseline is the configuration ``--baseline`` names, else the best by mean. Each other
configuration is compared with it paired (the same test objects drawn for both, Wilcoxon over
labels; ``stats.compare``), Holm-corrected over the data set's comparisons, and its verdict
comes from ``stats.Comparison.verdict``: never from the point estimates alone.
"""

from __future__ import annotations

from dataclasses import dataclass

from scipy import stats as sps

from tactile_exp import stats
from tactile_exp.metrics import METRICS
from tactile_exp.report.configurations import Spec
from tactile_exp.report.heldout import FEW_OBJECTS, Evidence
from tactile_exp.report.runs import Group, label_order


@dataclass(frozen=True)
class Entry:
    """One configuration's line."""

    group: Group
    name: str
    value: stats.Interval  # mean over labels with its 95% interval (or why there is none)
    rank: float  # 1 = best mean; ties share their mean rank
    comparison: stats.Comparison | None = None  # this - baseline, Holm over the data set
    not_compared: str = ""  # why there is no comparison with the baseline ("" for it)


@dataclass(frozen=True)
class Board:
    dataset: str
    baseline: str  # the baseline configuration's name
    chosen: str  # how it was chosen
    entries: tuple[Entry, ...]  # best first


def value(group: Group, evidence: Evidence) -> stats.Interval:
    """The mean over labels with its interval; without scores the runs' own mean, saying why."""
    if evidence.ok:
        return evidence.interval()
    return stats.no_interval(float(group.aucs.mean()), evidence.missing)


def board(
    dataset: str,
    groups: list[Group],
    evidence: dict[str, Evidence],
    names: dict[str, str],
    baseline: Spec | None = None,
) -> Board:
    """The leaderboard of one data set's ``groups`` (configurations)."""
    values = {g.key: value(g, evidence[g.key]) for g in groups}
    ordered = sorted(groups, key=lambda g: (-values[g.key].estimate, names[g.key]))
    ranks = sps.rankdata([-values[g.key].estimate for g in ordered])
    if baseline is not None:
        base = baseline.pick(groups, names)
        chosen = f"`--baseline {baseline.text}`"
        if base is None:
            base = ordered[0]
            chosen = f"the best by mean (`--baseline {baseline.text}` did not run here)"
    else:
        base, chosen = ordered[0], "the best by mean"
    pending: list[tuple[Group, stats.Comparison]] = []
    why: dict[str, str] = {}
    eb = evidence[base.key]
    for g in ordered:
        if g is base:
            continue
        ea = evidence[g.key]
        if not (ea.ok and eb.ok):
            why[g.key] = ea.missing or eb.missing
            continue
        reason = stats.unpaired_reason(ea.evaluations, eb.evaluations)
        if reason is not None:
            why[g.key] = f"not paired with the baseline: {reason}"
            continue
        cmp = stats.compare(names[g.key], ea.evaluations, names[base.key], eb.evaluations)
        pending.append((g, cmp))
    adjusted = dict(
        zip(
            (g.key for g, _ in pending),
            stats.with_holm([c for _, c in pending]),
            strict=True,
        )
    )
    entries = tuple(
        Entry(
            group=g,
            name=names[g.key],
            value=values[g.key],
            rank=float(r),
            comparison=adjusted.get(g.key),
            not_compared=why.get(g.key, ""),
        )
        for g, r in zip(ordered, ranks, strict=True)
    )
    return Board(dataset, names[base.key], chosen, entries)


def _objects(evidence: Evidence) -> str:
    """Positive/negative test objects per label, as a range over labels (``3-5/4-9``)."""
    sizes = evidence.sizes()
    if not sizes:
        return ""
    spans = []
    for side in zip(*sizes.values(), strict=True):
        low, high = min(side), max(side)
        spans.append(f"{low}" if low == high else f"{low}-{high}")
    few = len(evidence.thin())
    return "/".join(spans) + (f" ({few} label(s) < {FEW_OBJECTS})" if few else "")


def _difference(entry: Entry, board: Board) -> tuple[str, str]:
    """The difference from the baseline with its interval, and the verdict."""
    if entry.name == board.baseline:
        return "baseline", ""
    cmp = entry.comparison
    if cmp is None:
        return "", f"not compared: {entry.not_compared}"
    d = cmp.difference
    return (
        f"{d.estimate:+.3f} [{d.low:+.3f}, {d.high:+.3f}]",
        f"{cmp.verdict} (Holm p = {cmp.p_holm:.3g})",
    )


def rows(board: Board, evidence: dict[str, Evidence], metric: str) -> list[dict[str, str]]:
    """The leaderboard, machine-readable: fractions at full precision."""
    key = METRICS.build(metric).key
    out = []
    for e in board.entries:
        cmp = e.comparison
        iv = e.value
        labels = label_order([e.group])
        out.append(
            {
                "dataset": board.dataset,
                "rank": f"{e.rank:g}",
                "configuration": e.name,
                f"mean_{key}": f"{iv.estimate:.6f}",
                "ci_low": "" if iv.missing else f"{iv.low:.6f}",
                "ci_high": "" if iv.missing else f"{iv.high:.6f}",
                "test_objects": _objects(evidence[e.group.key]),
                "labels": str(len(labels)),
                "baseline": board.baseline,
                "difference": "" if cmp is None else f"{cmp.difference.estimate:.6f}",
                "difference_ci_low": "" if cmp is None else f"{cmp.difference.low:.6f}",
                "difference_ci_high": "" if cmp is None else f"{cmp.difference.high:.6f}",
                "p_holm": "" if cmp is None else f"{cmp.p_holm:.6g}",
                "verdict": _difference(e, board)[1],
                "seeds": str(len(e.group.seeds)),
                "row_hash": e.group.row_hash,
                "run_ids": " ".join(r.run_id for r in e.group.sorted_runs),
            }
        )
    return out


def markdown(board: Board, evidence: dict[str, Evidence], metric: str) -> str:
    """The leaderboard for people: the metric in %, the difference in metric units."""
    label = METRICS.build(metric).label
    lines = [
        f"| rank | configuration | mean {label} % [95% CI] | test objects +/- | labels | "
        "difference from the baseline [95% CI] | verdict |",
        "|---|---|---|---|---|---|---|",
    ]
    for e in board.entries:
        iv = e.value
        mean = f"{iv.estimate * 100:.1f}"
        mean += (
            f" (no interval: {iv.missing})"
            if iv.missing
            else (f" [{iv.low * 100:.1f}, {iv.high * 100:.1f}]")
        )
        difference, verdict = _difference(e, board)
        n_labels = len(label_order([e.group]))
        lines.append(
            f"| {e.rank:g} | `{e.name}` | {mean} | {_objects(evidence[e.group.key])} | "
            f"{n_labels} | {difference} | {verdict} |"
        )
    return "\n".join(lines) + "\n"


def few_labels_note(n_labels: int) -> str:
    """Why no verdict can name a winner on this few labels ("" from 6 labels on): Wilcoxon's
    exact two-sided p over n labels is at least 2 / 2**n, which is 0.0625 at n = 5."""
    floor = 2 / 2**n_labels
    if floor < stats.ALPHA:
        return ""
    return (
        f"With {n_labels} label(s), Wilcoxon's test over labels cannot reach p < {stats.ALPHA} "
        f"(its smallest two-sided p is 2/2^{n_labels} = {floor:.3g}): no verdict here can name "
        "a winner, whatever the difference; the intervals still say how large it may be."
    )

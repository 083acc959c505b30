"""The report's comparisons: the paper's claims as paired verdicts, the ablation view of a
sweep, and which configurations enter Friedman's test (``tactile_exp.stats`` does the numbers).

A verdict comes from the Holm-corrected tests, the paired-bootstrap interval and the direction of
the signed ranks together (`stats.Comparison.verdict`), never from point estimates; configurations
not tested on the same objects are not compared paired, and the line says why. "As good as"
claims need the interval to rule out a loss beyond ``stats.MARGIN`` (non-inferiority): no
difference found is not agreement.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from tactile_exp import stats
from tactile_exp.report.heldout import Evidence
from tactile_exp.report.runs import HAPTIC, Group, row_group


@dataclass(frozen=True)
class Claim:
    better: str  # Table I row
    relation: str  # ">" (better beats worse) or ">=" (better is not worse by over the margin)
    worse: str
    says: str


CLAIMS = (
    Claim("I", ">", "A", "deep (ConvNet) beats hand-designed features"),
    Claim("I", ">", "G", "the ConvNet beats the LSTM"),
    Claim("I", ">", "H", "combining instances beats scoring each alone"),
    Claim("I", ">=", "J", "one trial per unit is as good as ten (instance combining)"),
    Claim("L", ">", "K", "eight views beat one"),
    Claim("M", ">", "I", "multimodal beats touch alone"),
    Claim("M", ">", "L", "multimodal beats sight alone"),
    Claim("N", ">", "I", "multimodal (10 trials) beats touch alone"),
    Claim("N", ">", "L", "multimodal (10 trials) beats sight alone"),
)
# Fig. 5's reading: (adjective, the modality the paper finds better on it).
BY_MODALITY = (
    ("thick", "visual"),
    ("thin", "visual"),
    ("squishy", "haptic"),
    ("absorbent", "haptic"),
)


@dataclass(frozen=True)
class ClaimLine:
    claim: str  # e.g. "I > A"
    says: str
    result: str  # supported / contradicted / mixed / not distinguishable / not run / ...
    detail: str  # the numbers, or why there are none


def _name(g: Group) -> str:
    return f"{g.row}" if g.row else g.method


def claims(
    groups: list[Group], evidence: dict[str, Evidence], margin: float = stats.MARGIN
) -> list[ClaimLine]:
    """Each of the paper's Table I claims on the runs at hand; Holm over those compared."""
    pending: list[tuple[Claim, stats.Comparison]] = []
    lines: dict[Claim, ClaimLine] = {}
    for claim in CLAIMS:
        text = f"{claim.better} {claim.relation} {claim.worse}"
        a, b = row_group(groups, claim.better), row_group(groups, claim.worse)
        absent = [r for r, g in ((claim.better, a), (claim.worse, b)) if g is None]
        if absent:
            lines[claim] = ClaimLine(
                text, claim.says, "not run", f"row {' and '.join(absent)} not run"
            )
            continue
        ea, eb = evidence[a.key], evidence[b.key]
        if not (ea.ok and eb.ok):
            why = ea.missing or eb.missing
            lines[claim] = ClaimLine(text, claim.says, "not compared", why)
            continue
        reason = stats.unpaired_reason(ea.evaluations, eb.evaluations)
        if reason is not None:
            lines[claim] = ClaimLine(text, claim.says, "not compared", f"not paired: {reason}")
            continue
        pending.append(
            (claim, stats.compare(claim.better, ea.evaluations, claim.worse, eb.evaluations))
        )
    for claim, cmp in zip(
        (c for c, _ in pending), stats.with_holm([c for _, c in pending]), strict=True
    ):
        text = f"{claim.better} {claim.relation} {claim.worse}"
        result = judge(claim.relation, cmp, margin)
        lines[claim] = ClaimLine(text, claim.says, result, describe(cmp, margin))
    return [lines[c] for c in CLAIMS]


def judge(relation: str, cmp: stats.Comparison, margin: float = stats.MARGIN) -> str:
    """A claim's result from its comparison: ``>`` needs ``a`` to win; ``>=`` (as good as)
    needs the interval's lower end above -margin (non-inferiority), a loss contradicts it."""
    verdict = cmp.verdict
    if verdict.startswith("mixed"):
        return "mixed"
    if verdict == f"{cmp.b} beats {cmp.a}":
        return "contradicted"
    if relation == ">":
        return "supported" if verdict == f"{cmp.a} beats {cmp.b}" else "not distinguishable"
    if cmp.non_inferior(margin):
        return f"supported (not worse by {margin:.3f} or more)"
    return f"not distinguishable (the interval allows a loss beyond {margin:.3f})"


def describe(cmp: stats.Comparison, margin: float = stats.MARGIN) -> str:
    """The numbers behind a verdict; "equivalent" only where TOST rules out +-margin."""
    d = cmp.difference
    verdict = cmp.verdict
    if verdict == "not distinguishable" and cmp.equivalent(margin):
        e = cmp.equivalence
        verdict = (
            f"equivalent within +-{margin:.3f} (TOST: 90% interval [{e.low:+.3f}, {e.high:+.3f}])"
        )
    return (
        f"{cmp.a} - {cmp.b} = {d.estimate:+.3f} [{d.low:+.3f}, {d.high:+.3f}] over "
        f"{cmp.n_adjectives} adjectives ({len(cmp.a_better)} higher, {len(cmp.b_better)} "
        f"lower); Wilcoxon p = {cmp.p:.3g}, bootstrap p = {cmp.p_bootstrap:.3g}, Holm p = "
        f"{cmp.p_holm:.3g}: {verdict}"
    )


def selection_family(groups: list[Group]) -> int:
    """How many (haptic, visual) row pairs Fig. 5's "best" rows are picked from (by test mean
    AUC, as ``runs.best`` picks them): the pairs its by-adjective family covers."""
    counts = []
    for modalities in (HAPTIC, ("visual",)):
        candidates = [g for g in groups if g.modality in modalities and g.model != "random"]
        counts.append(len([g for g in candidates if g.at_paper_settings] or candidates))
    return max(1, counts[0] * counts[1])


def by_modality(
    haptic: Group | None,
    visual: Group | None,
    evidence: dict[str, Evidence],
    candidates: int = 1,
) -> list[ClaimLine]:
    """Fig. 5's adjectives better by sight or by touch: per adjective, the paired-bootstrap
    interval of visual - haptic AUC (one adjective has no Wilcoxon test). The two rows were
    picked on the test objects out of ``candidates`` (haptic, visual) pairs
    (`selection_family`), so the interval's level is Bonferroni's over the adjectives and every
    candidate pair: whichever pair was picked, the family-wise error stays at ALPHA."""
    family = len(BY_MODALITY) * candidates
    level = 1 - stats.ALPHA / family
    out = []
    for adjective, side in BY_MODALITY:
        text = f"{adjective}: better by {'sight' if side == 'visual' else 'touch'}"
        if haptic is None or visual is None:
            out.append(ClaimLine(text, "Fig. 5", "not run", "needs a haptic and a visual row"))
            continue
        eh, ev = evidence[haptic.key], evidence[visual.key]
        if not (eh.ok and ev.ok):
            out.append(ClaimLine(text, "Fig. 5", "not run", eh.missing or ev.missing))
            continue
        if any(adjective not in e for e in (*eh.evaluations, *ev.evaluations)):
            why = f"{adjective} not among both rows' adjectives"
            out.append(ClaimLine(text, "Fig. 5", "not run", why))
            continue
        try:
            iv = stats.adjective_difference(ev.evaluations, eh.evaluations, adjective, level)
        except ValueError as err:
            out.append(ClaimLine(text, "Fig. 5", "not compared", str(err)))
            continue
        name = f"{_name(visual)} - {_name(haptic)} = {iv.estimate:+.3f}"
        if iv.missing:
            detail = f"{name} (no interval: {iv.missing})"
            out.append(ClaimLine(text, "Fig. 5", "not distinguishable", detail))
            continue
        winner = "visual" if iv.low > 0 else "haptic" if iv.high < 0 else None
        result = (
            "supported" if winner == side else "contradicted" if winner else "not distinguishable"
        )
        detail = (
            f"{name} [{iv.low:+.3f}, {iv.high:+.3f}] ({level:.2%} interval: Bonferroni over "
            f"{len(BY_MODALITY)} adjectives x {candidates} candidate row pair(s), the rows "
            "picked by test mean AUC)"
        )
        out.append(ClaimLine(text, "Fig. 5", result, detail))
    return out


@dataclass(frozen=True)
class Ablation:
    """Configurations of a sweep named by the axes that differ between them."""

    axes: dict[str, list[str]]  # axis -> its levels (numeric order where numeric)
    configs: dict[tuple[str, ...], Group]  # axis values (in `axes` order) -> group
    effects: list[tuple[str, stats.Comparison, int]]  # axis, comparison, combinations averaged
    unpaired: list[tuple[str, str, str]]  # axis, levels, why they were not compared

    def name(self, values: tuple[str, ...]) -> str:
        return " ".join(f"{a}={v}" for a, v in zip(self.axes, values, strict=True))


def _level_key(v: str) -> tuple[int, float | str]:
    try:
        return 0, float(v)
    except ValueError:
        return 1, v


IGNORED_AXES = ("seed", "split.fold", "hydra", "tracking", "data")


def ablation(groups: list[Group], evidence: dict[str, Evidence]) -> Ablation | None:
    """The configurations outside Table I's rows of one sweep on one data set (the pair with
    the most of them), named by the overrides that differ, with each axis's paired effect
    between each pair of its levels, averaged over the other axes' combinations (Holm over all
    of them)."""
    sweeps: dict[tuple[str, str], list[Group]] = {}
    for g in groups:
        if not g.row and evidence[g.key].ok:
            sweeps.setdefault((g.first_run.sweep_id, g.first_run.data), []).append(g)
    pool = max(sweeps.values(), key=len, default=[])
    if len(pool) < 2:
        return None
    keys = sorted({k for g in pool for k in g.overrides})
    keys = [k for k in keys if not any(k == i or k.startswith(f"{i}.") for i in IGNORED_AXES)]
    axes = {k: sorted({g.overrides.get(k, "") for g in pool}, key=_level_key) for k in keys}
    axes = {k: v for k, v in axes.items() if len(v) > 1}
    if not axes:
        return None
    configs = {tuple(g.overrides.get(k, "") for k in axes): g for g in pool}
    pending = []
    unpaired = []
    names = list(axes)
    for i, axis in enumerate(names):
        for low, high in itertools.combinations(axes[axis], 2):
            a_runs, b_runs, n, why = [], [], 0, "no combination of the other axes has both"
            for values, g in configs.items():
                if values[i] != high:
                    continue
                other = configs.get(values[:i] + (low,) + values[i + 1 :])
                if other is None:
                    continue
                ea, eb = evidence[g.key].evaluations, evidence[other.key].evaluations
                reason = stats.unpaired_reason(ea, eb)
                if reason is None:
                    a_runs += ea
                    b_runs += eb
                    n += 1
                else:
                    why = f"not paired: {reason}"
            if n:
                cmp = stats.compare(f"{axis}={high}", a_runs, f"{axis}={low}", b_runs)
                pending.append((axis, cmp, n))
            else:
                unpaired.append((axis, f"{axis}={high} vs {axis}={low}", why))
    adjusted = stats.with_holm([c for _, c, _ in pending])
    effects = [(axis, c, n) for (axis, _, n), c in zip(pending, adjusted, strict=True)]
    return Ablation(axes, configs, effects, unpaired)


def friedman_set(groups: list[Group], evidence: dict[str, Evidence]) -> list[Group]:
    """The largest set (>= 3) of configurations tested on the same objects and adjectives:
    Friedman's test ranks them adjective by adjective."""
    classes: dict[tuple, list[Group]] = {}
    for g in groups:
        ev = evidence[g.key]
        if ev.ok:
            signature = tuple(
                tuple(sorted((a, t.key) for a, t in e.items())) for e in ev.evaluations
            )
            classes.setdefault(signature, []).append(g)
    best = max(classes.values(), key=len, default=[])
    return best if len(best) >= 3 else []


def friedman(groups: list[Group], evidence: dict[str, Evidence]) -> stats.Friedman | None:
    chosen = friedman_set(groups, evidence)
    if not chosen:
        return None
    adjectives = sorted(evidence[chosen[0].key].evaluations[0])
    aucs = np.array(
        [
            [np.mean([e[a].value for e in evidence[g.key].evaluations]) for a in adjectives]
            for g in chosen
        ]
    )
    return stats.friedman([label(g) for g in chosen], aucs)


def label(g: Group) -> str:
    """A configuration's short name: its row letter (bracketed when not at the paper's
    settings) or its method, and what differs."""
    if g.row:
        return g.row if g.at_paper_settings else f"({g.row})"
    return g.method

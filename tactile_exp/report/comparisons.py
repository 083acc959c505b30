"""The report's comparisons: the paper's claims as paired verdicts, the ablation view of a
sweep, and which configurations enter Friedman's test (``tactile_exp.stats`` does the numbers).

A verdict comes from the Holm-corrected Wilcoxon test and the paired-bootstrap interval together
(`stats.Comparison.verdict`), never from point estimates; configurations not tested on the same
objects are not compared paired, and the line says why.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from tactile_exp import stats
from tactile_exp.report.heldout import Evidence
from tactile_exp.report.runs import Group, row_group


@dataclass(frozen=True)
class Claim:
    better: str  # Table I row
    relation: str  # ">" (better beats worse) or ">=" (worse does not beat better)
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
    result: str  # supported / contradicted / not distinguishable / consistent / not run / ...
    detail: str  # the numbers, or why there are none


def _name(g: Group) -> str:
    return f"{g.row}" if g.row else g.method


def claims(groups: list[Group], evidence: dict[str, Evidence]) -> list[ClaimLine]:
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
        verdict = cmp.verdict
        if claim.relation == ">":
            result = {
                f"{cmp.a} beats {cmp.b}": "supported",
                f"{cmp.b} beats {cmp.a}": "contradicted",
            }
        else:
            result = {
                f"{cmp.a} beats {cmp.b}": "consistent",
                f"{cmp.b} beats {cmp.a}": "contradicted",
            }
        default = (
            "not distinguishable" if claim.relation == ">" else "consistent (not distinguishable)"
        )
        lines[claim] = ClaimLine(text, claim.says, result.get(verdict, default), describe(cmp))
    return [lines[c] for c in CLAIMS]


def describe(cmp: stats.Comparison) -> str:
    d = cmp.difference
    return (
        f"{cmp.a} - {cmp.b} = {d.estimate:+.3f} [{d.low:+.3f}, {d.high:+.3f}] over "
        f"{cmp.n_adjectives} adjectives; Wilcoxon p = {cmp.p:.3g}, Holm p = {cmp.p_holm:.3g}: "
        f"{cmp.verdict}"
    )


def by_modality(
    haptic: Group | None, visual: Group | None, evidence: dict[str, Evidence]
) -> list[ClaimLine]:
    """Fig. 5's adjectives better by sight or by touch: per adjective, the paired-bootstrap
    interval of visual - haptic AUC at the Bonferroni level over these adjectives (one
    adjective has no Wilcoxon test)."""
    level = 1 - stats.ALPHA / len(BY_MODALITY)
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
        winner = "visual" if iv.low > 0 else "haptic" if iv.high < 0 else None
        result = (
            "supported" if winner == side else "contradicted" if winner else "not distinguishable"
        )
        detail = (
            f"{_name(visual)} - {_name(haptic)} = {iv.estimate:+.3f} [{iv.low:+.3f}, "
            f"{iv.high:+.3f}] ({level:.1%} interval)"
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


IGNORED_AXES = ("seed", "split.fold", "hydra", "tracking")


def ablation(groups: list[Group], evidence: dict[str, Evidence]) -> Ablation | None:
    """The configurations outside Table I's rows of one sweep (the one with the most of them),
    named by the overrides that differ, with each axis's paired effect between each pair of its
    levels, averaged over the other axes' combinations (Holm over all of them)."""
    sweeps: dict[str, list[Group]] = {}
    for g in groups:
        if not g.row and evidence[g.key].ok:
            sweeps.setdefault(g.first_run.sweep_id, []).append(g)
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

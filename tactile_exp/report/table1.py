"""Table I: one line per configuration, machine-readable (CSV) and for people (Markdown)."""

from __future__ import annotations

from tactile_exp.metrics import METRICS
from tactile_exp.report.configurations import dataset
from tactile_exp.report.heldout import FEW_OBJECTS, Evidence
from tactile_exp.report.runs import Group


def table1(
    groups: list[Group],
    evidence: dict[str, Evidence] | None = None,
    metric: str = "roc_auc",
    names: dict[str, str] | None = None,
) -> list[dict[str, str]]:
    """Table I's lines, machine-readable: AUC as fractions, full precision, full run ids; with
    ``names`` (`configurations.names`), each line's configuration and data set too.

    ``mean_auc`` is the mean over adjectives (then seeds); with ``split=folds`` it is each
    adjective's AUC over all objects' pooled out-of-fold scores when the scores are there, and
    ``per_fold_mean_auc`` the mean of the folds' own AUCs. The interval (95%, object bootstrap,
    ``tactile_exp.stats``) needs the scores; without them its cells are empty and
    ``intervals`` says why. Another ``metric`` than roc_auc names the columns by its key
    (``mean_f1``, ...; the groups and evidence must be of it) and leaves ``paper_auc`` empty:
    the paper's figures are ROC AUC."""
    key = METRICS.build(metric).key
    rows = []
    for g in groups:
        ev = (evidence or {}).get(g.key) or Evidence(missing="scores not read")
        aucs = g.aucs
        mean = aucs.mean()
        low = high = ""
        if ev.ok:
            iv = ev.interval()
            mean, low, high = iv.estimate, f"{iv.low:.6f}", f"{iv.high:.6f}"
        sizes = ev.sizes()
        rows.append(
            {
                "row": g.row,
                "at_paper_settings": str(g.at_paper_settings),
                "method": g.method,
                **(
                    {"configuration": names[g.key], "dataset": dataset(g, groups)}
                    if names is not None
                    else {}
                ),
                "differences": "; ".join(g.differences),
                "schedule": f"{g.schedule} ({g.schedule_epochs})" if g.schedule else "no epochs",
                "adjectives": str(g.n_adjectives),
                "split": g.split + (f" ({ev.folds_run} folds pooled)" if ev.folds_run else ""),
                "seeds": " ".join(str(s) for s in g.seeds),
                "n_seeds": str(len(g.seeds)),
                f"mean_{key}": f"{mean:.6f}",
                f"mean_{key}_ci_low": low,
                f"mean_{key}_ci_high": high,
                f"per_fold_mean_{key}": f"{aucs.mean():.6f}" if g.folds else "",
                f"std_{key}": f"{aucs.std(ddof=1):.6f}" if len(aucs) > 1 else "",
                "test_objects": _sizes(sizes),
                "few_objects": " ".join(ev.thin()),
                "intervals": "" if ev.ok else ev.missing,
                "paper_auc": f"{g.paper_auc / 100:.3f}"
                if g.paper_auc is not None and metric == "roc_auc"
                else "",
                "data": " ".join(sorted({r.data for r in g.sorted_runs})),
                "run_ids": " ".join(r.run_id for r in g.sorted_runs),
            }
        )
    return rows


def _sizes(sizes: dict[str, tuple[int, int]]) -> str:
    """Positive/negative test objects per adjective as a range, e.g. ``3-5/4-9``."""
    if not sizes:
        return ""
    pos = sorted(p for p, _ in sizes.values())
    neg = sorted(n for _, n in sizes.values())

    def span(v: list[int]) -> str:
        return f"{v[0]}" if v[0] == v[-1] else f"{v[0]}-{v[-1]}"

    return f"{span(pos)}/{span(neg)}"


def table1_markdown(rows: list[dict[str, str]], metric: str = "roc_auc") -> str:
    """Table I for people: AUC (or ``metric``) in % with its 95% interval, a row letter in
    brackets when not at the paper's settings, a warning mark where an adjective rests on few
    test objects."""
    shown = METRICS.build(metric)
    key = shown.key
    head = [
        "row",
        "method",
        "setting",
        "schedule",
        "adj.",
        "split",
        "n seeds",
        f"mean {shown.label} % [95% CI]",
        "per-fold mean %",
        "std over seeds",
        "test objects +/- per adj.",
        "paper (real PHAC-2)",
        "data",
        "run ids",
    ]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        paper_settings = r["at_paper_settings"] == "True"
        mean = f"{float(r[f'mean_{key}']) * 100:.1f}"
        if r[f"mean_{key}_ci_low"]:
            mean += (
                f" [{float(r[f'mean_{key}_ci_low']) * 100:.1f}, "
                f"{float(r[f'mean_{key}_ci_high']) * 100:.1f}]"
            )
        else:
            mean += " (no interval: no scores)"
        few = f" (< {FEW_OBJECTS} on: {r['few_objects']})" if r["few_objects"] else ""
        cells = [
            r["row"] if paper_settings or not r["row"] else f"({r['row']})",
            f"`{r['method']}`",
            "paper" if paper_settings else r["differences"] or "no paper row",
            r["schedule"],
            r["adjectives"],
            r["split"],
            r["n_seeds"],
            mean,
            f"{float(r[f'per_fold_mean_{key}']) * 100:.1f}" if r[f"per_fold_mean_{key}"] else "",
            f"{float(r[f'std_{key}']) * 100:.1f}" if r[f"std_{key}"] else "",
            (r["test_objects"] + few) if r["test_objects"] else "",
            f"{float(r['paper_auc']) * 100:.1f}" if r["paper_auc"] else "",
            r["data"],
            " ".join(f"`{i}`" for i in r["run_ids"].split()),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def table1_summary(rows: list[dict[str, str]], metric: str = "roc_auc") -> str:
    """Table I in the four columns a reader compares (row, method, mean with its 95% interval,
    the paper's figure; a row letter in brackets ran with other settings than the paper's);
    ``table1_markdown`` has the rest (settings, split, test objects, run ids)."""
    shown = METRICS.build(metric)
    key = shown.key
    lines = [
        f"| row | method | mean {shown.label} % [95% CI] | paper (real PHAC-2) |",
        "|---|---|---|---|",
    ]
    for r in rows:
        row = r["row"] if r["at_paper_settings"] == "True" or not r["row"] else f"({r['row']})"
        mean = f"{float(r[f'mean_{key}']) * 100:.1f}"
        if r[f"mean_{key}_ci_low"]:
            low, high = float(r[f"mean_{key}_ci_low"]), float(r[f"mean_{key}_ci_high"])
            mean += f" [{low * 100:.1f}, {high * 100:.1f}]"
        paper = f"{float(r['paper_auc']) * 100:.1f}" if r["paper_auc"] else ""
        lines.append(f"| {row} | `{r['method']}` | {mean} | {paper} |")
    return "\n".join(lines) + "\n"

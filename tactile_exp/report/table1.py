"""Table I: one line per configuration, machine-readable (CSV) and for people (Markdown)."""

from __future__ import annotations

from tactile_exp.report.runs import Group


def table1(groups: list[Group]) -> list[dict[str, str]]:
    """Table I's lines, machine-readable: AUC as fractions, full precision, full run ids."""
    rows = []
    for g in groups:
        aucs = g.aucs
        rows.append(
            {
                "row": g.row,
                "at_paper_settings": str(g.at_paper_settings),
                "method": g.method,
                "differences": "; ".join(g.differences),
                "schedule": f"{g.schedule} ({g.schedule_epochs})",
                "adjectives": str(g.n_adjectives),
                "split": g.split,
                "seeds": " ".join(str(s) for s in sorted(g.runs)),
                "mean_auc": f"{aucs.mean():.6f}",
                "std_auc": f"{aucs.std(ddof=1):.6f}" if len(aucs) > 1 else "",
                "paper_auc": f"{g.paper_auc / 100:.3f}" if g.paper_auc is not None else "",
                "data": " ".join(sorted({r.data for r in g.sorted_runs})),
                "run_ids": " ".join(r.run_id for r in g.sorted_runs),
            }
        )
    return rows


def table1_markdown(rows: list[dict[str, str]]) -> str:
    """Table I for people: AUC in %, a row letter in brackets when not at the paper's settings."""
    head = [
        "row",
        "method",
        "setting",
        "schedule",
        "adj.",
        "split",
        "seeds",
        "mean AUC %",
        "std",
        "paper (real PHAC-2)",
        "data",
        "run ids",
    ]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        paper_settings = r["at_paper_settings"] == "True"
        cells = [
            r["row"] if paper_settings or not r["row"] else f"({r['row']})",
            f"`{r['method']}`",
            "paper" if paper_settings else r["differences"] or "no paper row",
            r["schedule"],
            r["adjectives"],
            r["split"],
            r["seeds"],
            f"{float(r['mean_auc']) * 100:.1f}",
            f"{float(r['std_auc']) * 100:.1f}" if r["std_auc"] else "",
            f"{float(r['paper_auc']) * 100:.1f}" if r["paper_auc"] else "",
            r["data"],
            " ".join(f"`{i}`" for i in r["run_ids"].split()),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"

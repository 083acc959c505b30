"""``python -m tactile_exp.report``: Table I and a per-adjective figure from the tracked runs.

Reads every FINISHED parent run of the MLflow experiment, groups runs that differ only in seed
(by the Table I row when one was chosen), and writes ``table1.md``/``table1.csv`` (mean AUC over
runs, with the paper's figure on the real data beside it: the ``paper`` node of the row's
experiment file, logged with the run) and ``per_adjective.csv``/``.png``
(the paper's Fig. 5 view: per-adjective AUC of each method, averaged over seeds and splits).
"""

from __future__ import annotations

import argparse
import csv
import re
from collections import defaultdict
from pathlib import Path

import numpy as np

from tactile_exp.data.layout import ADJECTIVES
from tactile_exp.tracking import Tracker


def method_of(run_name: str, experiment: str | None) -> str:
    """Runs that differ only in seed describe one method."""
    if experiment and experiment != "None":
        return experiment
    return re.sub(r"-s\d+$", "", run_name)


def collect(tracker: Tracker) -> dict[str, list[dict[str, float]]]:
    """method -> one {metric: value} per FINISHED parent run (plus ``paper.auc`` when the run's
    experiment file gives the paper's figure)."""
    runs = tracker.client.search_runs(
        [tracker.experiment_id],
        filter_string="tags.run_level = 'parent' and attributes.status = 'FINISHED'",
        max_results=50000,
    )
    methods: dict[str, list[dict[str, float]]] = defaultdict(list)
    for run in runs:
        name = method_of(run.info.run_name, run.data.params.get("choice.experiment"))
        values = dict(run.data.metrics)
        if run.data.params.get("paper.auc") not in (None, "None"):
            values["paper.auc"] = float(run.data.params["paper.auc"])
        methods[name].append(values)
    return dict(sorted(methods.items()))


def table1(methods: dict[str, list[dict[str, float]]]) -> list[dict[str, str]]:
    rows = []
    for name, runs in methods.items():
        means = np.array([r["mean_auc"] for r in runs]) * 100
        row = re.match(r"table1_([a-z])_", name)
        paper = next((r["paper.auc"] for r in runs if "paper.auc" in r), None)
        rows.append(
            {
                "row": row.group(1).upper() if row else "",
                "method": name,
                "runs": str(len(runs)),
                "mean AUC %": f"{means.mean():.1f}",
                "std over runs": f"{means.std():.1f}" if len(runs) > 1 else "",
                "paper (real PHAC-2)": f"{paper:.1f}" if paper is not None else "",
            }
        )
    return rows


def per_adjective(methods: dict[str, list[dict[str, float]]]) -> dict[str, dict[str, float]]:
    """method -> adjective -> AUC averaged over that method's runs."""
    out = {}
    for name, runs in methods.items():
        out[name] = {
            a: float(np.mean([r[f"auc.{a}"] for r in runs if f"auc.{a}" in r]))
            for a in ADJECTIVES
            if any(f"auc.{a}" in r for r in runs)
        }
    return out


def write(methods: dict[str, list[dict[str, float]]], out: Path) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    rows = table1(methods)
    keys = list(rows[0]) if rows else ["method"]
    md = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    md += ["| " + " | ".join(r[k] for k in keys) + " |" for r in rows]
    (out / "table1.md").write_text("\n".join(md) + "\n")
    with open(out / "table1.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, keys)
        writer.writeheader()
        writer.writerows(rows)
    adj = per_adjective(methods)
    with open(out / "per_adjective.csv", "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["method", *ADJECTIVES])
        for name, aucs in adj.items():
            writer.writerow([name, *(f"{aucs[a]:.4f}" if a in aucs else "" for a in ADJECTIVES)])
    _figure(adj, out / "per_adjective.png")
    return [out / n for n in ("table1.md", "table1.csv", "per_adjective.csv", "per_adjective.png")]


def _figure(adj: dict[str, dict[str, float]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(12, 4.5 + 0.15 * len(adj)))
    width = 0.8 / max(1, len(adj))
    x = np.arange(len(ADJECTIVES))
    for i, (name, aucs) in enumerate(adj.items()):
        values = [aucs.get(a, np.nan) for a in ADJECTIVES]
        ax.bar(x + i * width, values, width, label=name)
    ax.axhline(0.5, color="k", lw=0.8, ls=":")
    ax.set_xticks(x + 0.4 - width / 2, ADJECTIVES, rotation=60, ha="right", fontsize=8)
    ax.set_ylabel("AUC")
    ax.set_ylim(0, 1)
    ax.legend(fontsize=7, ncol=3, loc="upper center", bbox_to_anchor=(0.5, -0.28))
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m tactile_exp.report", description=__doc__)
    parser.add_argument("--tracking-uri", default=None, help="default: as the jobs use")
    parser.add_argument("--experiment", default="tactile_exp", help="MLflow experiment name")
    parser.add_argument("--out", type=Path, default=Path("reports"), help="output folder")
    args = parser.parse_args(argv)
    methods = collect(Tracker(args.tracking_uri, args.experiment))
    if not methods:
        raise SystemExit(f"no FINISHED runs in MLflow experiment {args.experiment!r}")
    for path in write(methods, args.out):
        print(path)
    print((args.out / "table1.md").read_text())


if __name__ == "__main__":
    main()

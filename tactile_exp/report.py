"""``python -m tactile_exp.report``: Table I and Fig. 5 regenerated from the tracked runs.

Reads the FINISHED parent runs of one MLflow experiment (optionally of one sweep) and groups
them by ``row_hash``, the resolved config up to the seed: runs in a group differ only in seed
(and, with ``split=random``, in the split the seed draws). Each seed counts once (its latest
run). Writes into ``--out``:

- ``table1.md`` / ``table1.csv``: one line per group: its Table I row (from the ``paper`` node of
  the row's experiment file, logged with the run), whether it ran at the paper's settings (else
  what differs: schedule, adjectives, command-line overrides), mean AUC and its spread over
  seeds/splits, the paper's figure on the real data, the data file's identity and the run ids;
- ``per_adjective.csv``: per-adjective AUC of every group, averaged over its seeds;
- ``fig5_per_adjective.png``: the paper's Fig. 5 view, the best visual against the best haptic
  group, per adjective;
- ``index.md``, tying them together.

The folder is also logged as a ``report`` run of the same experiment, so it shows in ``mlflow ui``.
"""

from __future__ import annotations

import argparse
import csv
import re
import sys
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from tactile_exp.data.layout import ADJECTIVES
from tactile_exp.tracking import ExperimentNotFound, Tracker, git_commit

ENTRY_POINT = "python -m tactile_exp.report"
# Command-line overrides that leave a row's method as the paper has it: which data, which split,
# where results go, which GoogLeNet weights file. Anything else makes the group a variant.
NEUTRAL_OVERRIDES = (
    "experiment",
    "seed",
    "split",
    "data",
    "tracking",
    "device",
    "cache_dir",
    "modality.weights",
    "modality.layout",
    "sweep",
    "hydra",
)
HAPTIC = ("haptic", "haptic_features")
FIG5_SIZE = (12.0, 4.5)  # inches; at FIG5_DPI the PNG is 1200 x 450 pixels
FIG5_DPI = 100


@dataclass(frozen=True)
class Run:
    run_id: str
    seed: int
    start_time: int
    mean_auc: float
    aucs: dict[str, float]
    data: str  # the data file's identity
    sweep_id: str


@dataclass
class Group:
    """Runs of one config up to the seed: one line of Table I."""

    key: str
    method: str
    row: str  # the paper's Table I row the experiment file names, or ""
    paper_auc: float | None
    schedule: str
    schedule_epochs: str
    split: str
    modality: str
    model: str
    n_adjectives: int
    differences: tuple[str, ...]  # what differs from the paper's settings of the row
    runs: dict[int, Run] = field(default_factory=dict)  # seed -> its latest run

    @property
    def at_paper_settings(self) -> bool:
        return bool(self.row) and not self.differences

    @property
    def aucs(self) -> np.ndarray:
        return np.array([r.mean_auc for r in self.sorted_runs])

    @property
    def sorted_runs(self) -> list[Run]:
        return [self.runs[s] for s in sorted(self.runs)]

    def per_adjective(self) -> dict[str, float]:
        runs = self.sorted_runs
        return {
            a: float(np.mean([r.aucs[a] for r in runs if a in r.aucs]))
            for a in ADJECTIVES
            if any(a in r.aucs for r in runs)
        }


def _differences(params: dict[str, str], overrides: str, n_adjectives: int) -> tuple[str, ...]:
    out = []
    if params.get("choice.schedule", "paper") != "paper":
        out.append(f"schedule={params['choice.schedule']}")
    if n_adjectives != len(ADJECTIVES):
        out.append(f"{n_adjectives} adjectives")
    for item in overrides.split():
        key = item.lstrip("+~").split("=", 1)[0]
        neutral = any(key == k or key.startswith(f"{k}.") for k in NEUTRAL_OVERRIDES)
        if not neutral and key not in ("adjectives", "schedule"):
            out.append(item)
    return tuple(out)


def collect(tracker: Tracker, sweep_id: str | None = None) -> list[Group]:
    """Every group of FINISHED parent runs (of one sweep, if given), sorted by Table I row."""
    query = "tags.run_level = 'parent' and attributes.status = 'FINISHED'"
    if sweep_id:
        query += f" and tags.sweep_id = '{sweep_id}'"
    found = tracker.client.search_runs([tracker.experiment_id], query, max_results=50000)
    groups: dict[str, Group] = {}
    for run in found:
        params, tags, metrics = run.data.params, run.data.tags, run.data.metrics
        if "mean_auc" not in metrics:
            continue
        aucs = {k.removeprefix("auc."): v for k, v in metrics.items() if k.startswith("auc.")}
        key = tags.get("row_hash") or tags["config_hash"]  # runs logged before row_hash existed
        if key not in groups:
            experiment = params.get("choice.experiment", "None")
            paper = params.get("paper.auc", "None")
            groups[key] = Group(
                key=key,
                method=experiment
                if experiment != "None"
                else re.sub(r"-s\d+$", "", run.info.run_name),
                row=params.get("paper.row", ""),
                paper_auc=None if paper == "None" else float(paper),
                schedule=params.get("choice.schedule", ""),
                schedule_epochs=f"{params.get('schedule.epochs')}+"
                f"{params.get('schedule.finetune_epochs')} epochs",
                split=params.get("split.name", ""),
                modality=params.get("modality.name", ""),
                model=params.get("model.name", ""),
                n_adjectives=len(aucs),
                differences=_differences(params, tags.get("overrides", ""), len(aucs)),
            )
        entry = Run(
            run_id=run.info.run_id,
            seed=int(params["seed"]),
            start_time=run.info.start_time,
            mean_auc=metrics["mean_auc"],
            aucs=aucs,
            data=tags.get("data.identity", ""),
            sweep_id=tags.get("sweep_id", ""),
        )
        kept = groups[key].runs.get(entry.seed)
        if kept is None or entry.start_time > kept.start_time:
            groups[key].runs[entry.seed] = entry
    return sorted(groups.values(), key=lambda g: (g.row or "~", g.method, g.key))


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


def best(groups: list[Group], modalities: tuple[str, ...]) -> Group | None:
    """The group of these modalities with the highest mean AUC, preferring the paper's settings
    (a 2-epoch preset must not stand for a modality when the full row exists)."""
    candidates = [g for g in groups if g.modality in modalities and g.model != "random"]
    preferred = [g for g in candidates if g.at_paper_settings] or candidates
    return max(preferred, key=lambda g: g.aucs.mean(), default=None)


def fig5(visual: Group | None, haptic: Group | None, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=FIG5_SIZE)
    x = np.arange(len(ADJECTIVES))
    shown = [(g, c) for g, c in ((haptic, "tab:red"), (visual, "tab:blue")) if g is not None]
    for i, (g, colour) in enumerate(shown):
        aucs = g.per_adjective()
        label = f"{g.row + ' ' if g.row else ''}{g.method} ({len(g.runs)} seed(s)/split(s))"
        values = [aucs.get(a, np.nan) for a in ADJECTIVES]
        ax.bar(x + (i - (len(shown) - 1) / 2) * 0.4, values, 0.4, color=colour, label=label)
    ax.axhline(0.5, color="k", lw=0.8, ls=":")
    ax.set_xticks(x, ADJECTIVES, rotation=60, ha="right", fontsize=8)
    ax.set_ylabel("AUC")
    ax.set_ylim(0, 1)
    ax.set_title("Per-adjective AUC: best haptic vs best visual model", fontsize=10)
    ax.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=FIG5_DPI)
    plt.close(fig)


def write(groups: list[Group], out: Path, source: str) -> list[Path]:
    """Every report file into ``out``; returns their paths, ``index.md`` last."""
    out.mkdir(parents=True, exist_ok=True)
    rows = table1(groups)
    (out / "table1.md").write_text(table1_markdown(rows))
    with open(out / "table1.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    with open(out / "per_adjective.csv", "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["row", "method", "row_hash", "seeds", *ADJECTIVES])
        for g in groups:
            aucs = g.per_adjective()
            cells = [f"{aucs[a]:.6f}" if a in aucs else "" for a in ADJECTIVES]
            writer.writerow([g.row, g.method, g.key, len(g.runs), *cells])
    paths = [out / "table1.md", out / "table1.csv", out / "per_adjective.csv"]
    visual, haptic = best(groups, ("visual",)), best(groups, HAPTIC)
    if visual or haptic:
        fig5(visual, haptic, out / "fig5_per_adjective.png")
        paths.append(out / "fig5_per_adjective.png")
    (out / "index.md").write_text(_index(groups, rows, source, visual, haptic))
    return [*paths, out / "index.md"]


def _index(
    groups: list[Group],
    rows: list[dict[str, str]],
    source: str,
    visual: Group | None,
    haptic: Group | None,
) -> str:
    lines = [
        "# Gao et al. (ICRA 2016), regenerated from tracked runs",
        "",
        f"{source}; {len(groups)} configurations, {_n_runs(groups)} runs (each seed once). "
        f"Written {datetime.now(UTC):%Y-%m-%d %H:%M} UTC by `{ENTRY_POINT}`"
        + (f" at commit `{commit}`." if (commit := _commit()) else "."),
        "",
        "## Table I: mean AUC over the 24 adjectives",
        "",
        "One line per configuration up to the seed; `std` is the spread of the mean AUC over its",
        "seeds (splits, with `split=random`). A row letter in brackets ran with other settings",
        "than the paper's (the `setting` column says which). The paper's figures are on the real",
        "PHAC-2 data; on the embedded synthetic data set they are a reference, not a target.",
        "Machine-readable: [table1.csv](table1.csv) (AUC as fractions, full precision).",
        "",
        table1_markdown(rows),
    ]
    if visual or haptic:
        names = " vs ".join(
            f"`{g.method}` (mean {g.aucs.mean():.3f})" for g in (haptic, visual) if g
        )
        lines += [
            "## Fig. 5: per-adjective AUC, best haptic vs best visual",
            "",
            f"{names}, each averaged over its seeds/splits; every configuration's per-adjective",
            "AUC is in [per_adjective.csv](per_adjective.csv).",
            "",
            "![Fig. 5](fig5_per_adjective.png)",
            "",
        ]
    return "\n".join(lines)


def _commit() -> str | None:
    return git_commit(Path(__file__).resolve().parents[1])


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog=ENTRY_POINT, description=__doc__.split("\n\n")[0])
    parser.add_argument("--tracking-uri", default=None, help="default: as the jobs use")
    parser.add_argument("--experiment", default="tactile_exp", help="MLflow experiment name")
    parser.add_argument(
        "--sweep-id", default=None, help="only runs of this sweep (the tag sweep_id: its folder)"
    )
    parser.add_argument("--out", type=Path, default=Path("reports"), help="output folder")
    args = parser.parse_args(argv)
    try:
        tracker = Tracker(args.tracking_uri, args.experiment, entry_point=ENTRY_POINT, create=False)
    except ExperimentNotFound as err:
        sys.exit(f"error: {err}")
    groups = collect(tracker, args.sweep_id)
    if not groups:
        where = f" with sweep_id {args.sweep_id!r}" if args.sweep_id else ""
        sys.exit(
            f"error: no FINISHED job runs in MLflow experiment {args.experiment!r}{where} "
            f"({tracker.uri})"
        )
    source = f"MLflow experiment `{args.experiment}`" + (
        f", sweep `{args.sweep_id}`" if args.sweep_id else ""
    )
    paths = write(groups, args.out, source)
    params = {"experiment": args.experiment, "sweep_id": args.sweep_id or "", "out": str(args.out)}
    with tracker.run("report", params, {"run_level": "report"}) as run_id:
        tracker.log_metrics(run_id, {"n_groups": len(groups), "n_runs": _n_runs(groups)})
        for path in paths:
            tracker.log_file(run_id, path, "report")
    for path in paths:
        print(path)
    print(f"logged as MLflow run {run_id} (report) in {tracker.uri}")
    print((args.out / "table1.md").read_text())


def _n_runs(groups: list[Group]) -> int:
    return sum(len(g.runs) for g in groups)


if __name__ == "__main__":
    main()

"""``python -m tactile_exp.report``: Table I, Fig. 5, Fig. 6 and Table III from the tracked runs.

Reads the FINISHED job runs of one MLflow experiment (optionally of one sweep), groups them into
Table I's lines (``runs``) and writes into ``--out``:

- ``table1.md`` / ``table1.csv``: one line per configuration up to the seed: its Table I row,
  whether it ran at the paper's settings (else what differs), mean AUC and its spread over
  seeds/splits, the paper's figure, the data file's identity and the run ids;
- ``per_adjective.csv``: per-adjective AUC of every configuration, averaged over its seeds;
- ``fig5_per_adjective.png``: the best haptic against the best visual configuration per adjective;
- ``fig6_<adjective>.png``: conv3 activation maps of row I's stored haptic ConvNet (else H's,
  J's) on test trials of chosen adjectives (``activations``);
- ``table3.md`` / ``table3.csv``: ground truth and the predicted adjectives of rows I, L and M for
  three test objects (``table3``);
- ``index.md``, tying them together.

The folder is also logged as a ``report`` run of the same experiment, so it shows in ``mlflow ui``.
``--runs-table RUN_ID`` prints one job's runs as ``mlflow ui`` lists them, in Markdown, instead.
"""

from __future__ import annotations

import argparse
import csv
import sys
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

from tactile_exp.data.layout import ADJECTIVES
from tactile_exp.report import table3 as t3
from tactile_exp.report.activations import N_TRIALS, conv3_maps
from tactile_exp.report.figures import fig5, fig6
from tactile_exp.report.runs import HAPTIC, Group, best, collect, row_group, skipped_cells
from tactile_exp.report.runs_table import runs_table
from tactile_exp.report.scores import THRESHOLD, ReportError
from tactile_exp.report.table1 import table1, table1_markdown
from tactile_exp.store import ArtifactError
from tactile_exp.tracking import ExperimentNotFound, Tracker, git_commit

ENTRY_POINT = "python -m tactile_exp.report"
FIG6_ADJECTIVES = ("metallic", "compressible")  # the paper's Fig. 6
FIG6_ROWS = ("I", "H", "J")  # the jobs whose ConvNet Fig. 6 shows, first run first


@dataclass(frozen=True)
class Choices:
    """What Fig. 6 and Table III show (command-line options)."""

    fig6_adjectives: tuple[str, ...] = FIG6_ADJECTIVES
    fig6_trials: tuple[str, ...] = ()  # default: N_TRIALS picked per adjective
    fig6_n_trials: int = N_TRIALS
    fig6_run: str | None = None  # default: row I's job (else H's, J's)
    table3_objects: tuple[int, ...] = ()  # default: the best-covered common test objects


def write(
    *,
    groups: list[Group],
    out: Path,
    source: str,
    tracker: Tracker,
    choices: Choices,
    skipped: tuple[str, ...] = (),
) -> list[Path]:
    """Every report file into ``out``; returns their paths, ``index.md`` last. ``skipped``: the
    sweep's cells that did not run (invalid config), listed at the end of ``index.md``."""
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
    fig6_paths, fig6_text = _fig6(groups, out, tracker, choices)
    table3_lines = _table3(groups, tracker, choices)
    paths += fig6_paths + t3.write_table3(table3_lines, out)
    index = _index(groups, rows, source, visual, haptic)
    index += fig6_text + _table3_text(table3_lines)
    if skipped:
        index += "\n## Not run: invalid config\n\nCells of this sweep listed invalid before its "
        index += "first job and skipped (`sweep.on_invalid=skip`):\n\n"
        index += "".join(f"- {line}\n" for line in skipped)
    (out / "index.md").write_text(index)
    return [*paths, out / "index.md"]


def _fig6(
    groups: list[Group], out: Path, tracker: Tracker, choices: Choices
) -> tuple[list[Path], str]:
    """Fig. 6's PNGs (one per adjective) and its index section; a job that cannot be shown is
    said so in the section (the rest of the report stands without it)."""
    lines = ["## Fig. 6: conv3 activations of the haptic ConvNet", ""]
    job_id = choices.fig6_run
    group = next((g for r in FIG6_ROWS if (g := row_group(groups, r))), None)
    if job_id is None and group is None:
        return [], "\n".join([*lines, "Not drawn: none of rows I, H, J was run.", "", ""])
    job_id = job_id or group.first_run.run_id
    try:
        data = conv3_maps(
            tracker=tracker,
            job_id=job_id,
            adjectives=choices.fig6_adjectives,
            trials=choices.fig6_trials,
            n_trials=choices.fig6_n_trials,
        )
    except (ReportError, ArtifactError) as err:
        if choices.fig6_run or choices.fig6_trials:
            raise ReportError(f"Fig. 6: {err}") from None  # what was asked for cannot be shown
        print(f"warning: Fig. 6 not drawn: {err}", file=sys.stderr)
        return [], "\n".join([*lines, f"Not drawn: {err}", "", ""])
    name = group.method if group and not choices.fig6_run else f"run {job_id}"
    lines += [
        f"The stored ConvNet of `{name}` (job `{job_id}`), loaded from its child runs, not",
        "retrained, on test trials rebuilt with the preprocessing each child run stored. Each",
        "panel is one test trial's first instance (finger_0, offset 0); its title gives the",
        f"trial's label and the job's score for it (predicted when > {THRESHOLD:g}). Rows are",
        "conv3 channels grouped by input signal (EP-major: the four EPs are channel blocks,",
        "split by red lines; each EP is resampled to its own 150 steps, so time runs along each",
        "EP at once). Darker = higher activation.",
        "",
    ]
    paths = []
    for adjective in choices.fig6_adjectives:
        maps = [m for m in data.maps if m.adjective == adjective]
        if not maps:
            lines += [f"- {adjective}: not among the job's adjectives.", ""]
            continue
        path = out / f"fig6_{adjective}.png"
        title = f"conv3 activations for '{adjective}': {name} (job {job_id[:8]})"
        fig6(maps, data.signals, title, path)
        paths.append(path)
        lines += [f"![Fig. 6: {adjective}]({path.name})", ""]
    return paths, "\n".join(lines) + "\n"


def _table3(groups: list[Group], tracker: Tracker, choices: Choices) -> list[dict[str, str]]:
    rows = t3.read_rows(tracker, groups)
    if not choices.table3_objects:
        return t3.table3(rows, t3.choose_objects(rows))
    common = t3.choose_objects(rows, n=None)
    absent = [o for o in choices.table3_objects if o not in common]
    if absent:
        raise ReportError(
            f"objects {absent} are not test objects of every run row of Table III; those are "
            f"{sorted(common)}"
        )
    return t3.table3(rows, list(choices.table3_objects))


def _table3_text(lines: list[dict[str, str]]) -> str:
    return "\n".join(
        [
            "## Table III: predicted adjectives of three test objects",
            "",
            "Ground truth beside the adjectives rows I (haptic), L (visual) and M (multimodal)",
            "predict, from each job's held-out `scores.csv` (lowest seed): an adjective is",
            f"predicted when the mean score of the object's test units is > {THRESHOLD:g}. Each",
            "adjective has its own split, so an object is shown on the adjectives it is a test",
            "object of in every row; `agree` counts those the prediction gets right.",
            "Machine-readable: [table3.csv](table3.csv).",
            "",
            t3.table3_markdown(lines) if lines else "No test object common to the rows run.\n",
        ]
    )


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
    return "\n".join(lines) + "\n"


def _commit() -> str | None:
    return git_commit(Path(__file__).resolve().parents[2])


def _n_runs(groups: list[Group]) -> int:
    return sum(len(g.runs) for g in groups)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog=ENTRY_POINT, description=__doc__.split("\n\n")[0])
    parser.add_argument("--tracking-uri", default=None, help="default: as the jobs use")
    parser.add_argument("--experiment", default="tactile_exp", help="MLflow experiment name")
    parser.add_argument(
        "--sweep-id",
        default=None,
        help="only runs of this sweep (the tag sweep_id: its folder, multirun/<date>/<time>)",
    )
    parser.add_argument("--out", type=Path, default=Path("reports"), help="output folder")
    parser.add_argument(
        "--fig6-adjective",
        action="append",
        choices=ADJECTIVES,
        metavar="ADJ",
        help=f"Fig. 6 for this adjective (repeat; default: {' '.join(FIG6_ADJECTIVES)})",
    )
    parser.add_argument(
        "--fig6-trial",
        action="append",
        default=[],
        metavar="TRIAL",
        help="Fig. 6 on this test trial, e.g. aluminum_bar_701_03 (repeat; default: the "
        "best and the worst scored positive test trials of each adjective)",
    )
    parser.add_argument(
        "--fig6-trials", type=int, default=N_TRIALS, help="trials per adjective when picked"
    )
    parser.add_argument(
        "--fig6-run", default=None, help="the haptic_cnn job (run id) to show; default: row I's"
    )
    parser.add_argument(
        "--table3-object",
        action="append",
        type=int,
        default=[],
        metavar="ID",
        help="Table III for this object id (repeat; default: the three test objects common "
        "to rows I, L, M tested on the most adjectives)",
    )
    parser.add_argument(
        "--runs-table",
        metavar="RUN_ID",
        help="print this job's runs as mlflow ui lists them (Markdown) and exit",
    )
    args = parser.parse_args(argv)
    if args.fig6_trials < 1:
        parser.error("--fig6-trials must be >= 1")
    try:
        tracker = Tracker(args.tracking_uri, args.experiment, entry_point=ENTRY_POINT, create=False)
    except ExperimentNotFound as err:
        sys.exit(f"error: {err}")
    if args.runs_table:
        print(runs_table(tracker=tracker, job_id=args.runs_table), end="")
        return
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
    choices = Choices(
        fig6_adjectives=tuple(args.fig6_adjective or FIG6_ADJECTIVES),
        fig6_trials=tuple(args.fig6_trial),
        fig6_n_trials=args.fig6_trials,
        fig6_run=args.fig6_run,
        table3_objects=tuple(args.table3_object),
    )
    try:
        skipped = tuple(skipped_cells(tracker, args.sweep_id)) if args.sweep_id else ()
        paths = write(
            groups=groups,
            out=args.out,
            source=source,
            tracker=tracker,
            choices=choices,
            skipped=skipped,
        )
    except (ReportError, ArtifactError) as err:
        sys.exit(f"error: {err}")
    params = {"experiment": args.experiment, "sweep_id": args.sweep_id or "", "out": str(args.out)}
    with tracker.run("report", params, {"run_level": "report"}) as run_id:
        tracker.log_metrics(run_id, {"n_groups": len(groups), "n_runs": _n_runs(groups)})
        for path in paths:
            tracker.log_file(run_id, path, "report")
    for path in paths:
        print(path)
    print(f"logged as MLflow run {run_id} (report) in {tracker.uri}")
    print((args.out / "table1.md").read_text())

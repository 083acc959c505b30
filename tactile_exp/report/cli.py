"""``python -m tactile_exp.report``: Table I, Fig. 5, Fig. 6 and Table III from the tracked runs.

Reads the FINISHED job runs of one MLflow experiment (optionally of one sweep), groups them into
Table I's lines (``runs``) and writes into ``--out``:

- ``table1.md`` / ``table1.csv``: one line per configuration up to the seed (and fold): its
  Table I row, whether it ran at the paper's settings (else what differs), mean AUC with its 95%
  object-bootstrap interval (``split=folds``: pooled out of fold, and the per-fold mean), its
  spread over seeds/splits, how many test objects each AUC rests on, the paper's figure, the data
  file's identity and the run ids; ``table1_summary.md`` the same lines in four columns (row,
  method, mean AUC [95% CI], the paper's figure);
- ``per_adjective.csv``: per-adjective AUC of every configuration, averaged over its seeds;
  ``per_adjective_intervals.csv`` the same with intervals and test-object counts;
- ``fig5_per_adjective.png``: the best haptic against the best visual configuration per
  adjective, with error bars;
- ``claims.md`` / ``claims.csv``: the paper's claims as paired verdicts on the runs at hand
  (``comparisons``, ``tactile_exp.stats``); ``cd_diagram.png``: Friedman's test and Nemenyi's
  critical difference; ``ablation.md`` / ``ablation_<axis>.png``: the ablation view of a sweep;
- ``fig6_<adjective>.png``: conv3 activation maps of row I's stored haptic ConvNet (else H's,
  J's) on test trials of chosen adjectives (``activations``);
- ``table3.md`` / ``table3.csv``: ground truth and the predicted adjectives of rows I, L and M for
  three test objects (``table3``);
- ``index.md``, tying them together.

The folder is also logged as a ``report`` run of the same experiment, so it shows in ``mlflow ui``.
``--runs-table RUN_ID`` prints one job's runs as ``mlflow ui`` lists them, in Markdown, instead.
``--metric NAME`` (``tactile_exp.metrics``; default ``roc_auc``) puts another logged metric
where AUC stands: Table I, Fig. 5, the per-adjective files, the claims, Friedman's test and the
ablation view, its intervals recomputed on the resampled test objects.
"""

from __future__ import annotations

import argparse
import csv
import sys
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

from tactile_exp import stats
from tactile_exp.artifacts import ArtifactError
from tactile_exp.data.dataset import PHAC2_LAYOUT
from tactile_exp.metrics import METRICS, THRESHOLD
from tactile_exp.report import (
    benchmark,
    comparisons,
    configurations,
    declared,
    heldout,
    leaderboard,
    results,
)
from tactile_exp.report import table3 as t3
from tactile_exp.report.activations import N_TRIALS, conv3_maps
from tactile_exp.report.configurations import Spec, SpecError
from tactile_exp.report.figures import cd_diagram, differences, fig5, fig6, numeric_axis
from tactile_exp.report.labels import label_notes
from tactile_exp.report.runs import (
    HAPTIC,
    Group,
    best,
    collect,
    label_order,
    row_group,
    skipped_cells,
)
from tactile_exp.report.runs_table import runs_table
from tactile_exp.report.scores import ReportError
from tactile_exp.report.table1 import table1, table1_markdown, table1_summary
from tactile_exp.tracking import ExperimentNotFound, Tracker, canonical_column, git_commit

ENTRY_POINT = "python -m tactile_exp.report"
PRESETS = ("auto", "gao2016", "none")  # auto: the paper's sections when its rows ran on PHAC-2
PHAC2_SOURCES = ("synthetic", "phac2")  # data sources of PHAC-2's layout (runs without the tag)
FIG6_ADJECTIVES = ("metallic", "compressible")  # the paper's Fig. 6
FIG6_ROWS = ("I", "H", "J")  # the jobs whose ConvNet Fig. 6 shows, first run first


@dataclass(frozen=True)
class Choices:
    """What Fig. 6 and Table III show (command-line options)."""

    fig6_adjectives: tuple[str, ...] = ()  # default: FIG6_ADJECTIVES, drawn where run
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
    metric: str = "roc_auc",
    margin: float = stats.MARGIN,
    compare: tuple[declared.Declared, ...] = (),
    baseline: Spec | None = None,
    preset: str = "auto",
    known: dict[str, heldout.Evidence] | None = None,
) -> list[Path]:
    """Every report file into ``out``; returns their paths, ``index.md`` last. ``skipped``: the
    sweep's cells that did not run (invalid config), listed at the end of ``index.md``.
    ``metric``: what the numbers are (``groups`` must be collected for it). ``margin``: the
    loss (in AUC) an "as good as" comparison may rule out (``stats.MARGIN`` unless given).
    ``compare``: the declared comparisons; ``baseline``: what each leaderboard compares with
    (default: its best by mean). ``preset``: the paper's sections (`PRESETS`). ``known``: the
    evidence of groups that are not tracked runs (``--import-results``)."""
    out.mkdir(parents=True, exist_ok=True)
    known = known or {}
    evidence = {g.key: known.get(g.key) or heldout.load(tracker, g, metric) for g in groups}
    names = configurations.names(groups)
    datasets = configurations.by_dataset(groups)
    # Fig. 6 or Table III asked for by an option: the paper's sections.
    paper = paper_groups(groups, "gao2016" if preset == "auto" and choices != Choices() else preset)
    rows = table1(groups, evidence, metric, names)
    (out / "table1.md").write_text(table1_markdown(rows, metric))
    (out / "table1_summary.md").write_text(table1_summary(rows, metric))
    _write_csv(out / "table1.csv", rows)
    with open(out / "per_adjective.csv", "w", newline="") as f:
        writer = csv.writer(f)
        labels = label_order(groups)
        writer.writerow(["row", "configuration", "method", "row_hash", "n_seeds", *labels])
        for g in groups:
            aucs = _per_adjective(g, evidence[g.key])
            cells = [f"{aucs[a]:.6f}" if a in aucs else "" for a in labels]
            writer.writerow([g.row, _configuration(g), g.method, g.row_hash, len(g.seeds), *cells])
    _write_csv(out / "per_adjective_intervals.csv", _interval_rows(groups, evidence, metric))
    paths = [
        out / "table1.md",
        out / "table1_summary.md",
        out / "table1.csv",
        out / "per_adjective.csv",
        out / "per_adjective_intervals.csv",
    ]
    boards = [
        leaderboard.board(name, members, evidence, names, baseline)
        for name, members in datasets.items()
    ]
    board_text, board_paths = _leaderboards(boards, evidence, out, metric, tracker)
    declared_text, declared_paths = _declared(
        list(compare), datasets, evidence, names, out, margin, metric
    )
    bench_text, bench_paths = _benchmark(boards, out, metric)
    paths += board_paths + declared_paths + bench_paths
    index = _title(groups, datasets, paper, source, names) + _metric_text(metric)
    if paper:
        index += _paper(paper, evidence, out, tracker, choices, metric, margin, paths)
    index += board_text + declared_text + bench_text
    ablation_text, ablation_paths = _ablation(groups, evidence, out, metric)
    paths += ablation_paths
    index += ablation_text
    index += label_notes([g for g in groups if g.key not in known], tracker)
    if skipped:
        index += "\n## Not run: invalid config\n\nCells of this sweep listed invalid before its "
        index += "first job and skipped (`sweep.on_invalid=skip`):\n\n"
        index += "".join(f"- {line}\n" for line in skipped)
    (out / "index.md").write_text(index)
    return [*paths, out / "index.md"]


def paper_groups(groups: list[Group], preset: str) -> list[Group]:
    """The groups the paper's sections (Table I's rows, Fig. 5, the claims, Fig. 6, Table III)
    are about: with ``auto``, the groups on PHAC-2-layout data when one of them is a Table I
    row, else none; ``gao2016`` all groups on PHAC-2-layout data (all groups if none is);
    ``none`` none."""
    if preset == "none":
        return []
    phac2 = [g for g in groups if on_phac2(g)]
    if preset == "gao2016":
        return phac2 or groups
    return phac2 if any(g.row for g in phac2) else []


def on_phac2(g: Group) -> bool:
    """Whether the group ran on PHAC-2's layout (the real file or its synthetic twin): the
    ``data.layout`` tag jobs log; for runs logged without it, the data source's name."""
    layout = g.layout
    if layout is not None:
        return layout == PHAC2_LAYOUT
    return g.params.get("data.name", "phac2") in PHAC2_SOURCES


# The report's tables MLflow shows as tables too (its Evaluation/Artifacts views), not only files.
TABLES = ("leaderboard", "benchmark", "comparisons")


def _read_csv(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def _write_csv(path: Path, rows: list[dict[str, str]]) -> None:
    with open(path, "w", newline="") as f:
        if rows:
            writer = csv.DictWriter(f, list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)


def _configuration(g: Group) -> str:
    """The method and what differs: tells apart configurations that share a method name."""
    return f"{g.method} [{'; '.join(g.differences)}]" if g.differences else g.method


def _per_adjective(g: Group, ev: heldout.Evidence) -> dict[str, float]:
    """Pooled out-of-fold AUC per adjective where the scores are there, else the runs' own."""
    if ev.ok and g.folds:
        return {a: iv.estimate for a, iv in ev.per_adjective().items()}
    return g.per_adjective()


def _interval_rows(groups: list[Group], evidence: dict[str, heldout.Evidence], metric: str):
    key = METRICS.build(metric).key
    rows = []
    for g in groups:
        ev = evidence[g.key]
        if not ev.ok:
            continue
        sizes = ev.sizes()
        for a, iv in ev.per_adjective().items():
            n_pos, n_neg = sizes[a]
            rows.append(
                {
                    "row": g.row,
                    "configuration": _configuration(g),
                    "row_hash": g.row_hash,
                    "adjective": a,
                    key: f"{iv.estimate:.6f}",
                    "ci_low": "" if iv.missing else f"{iv.low:.6f}",
                    "ci_high": "" if iv.missing else f"{iv.high:.6f}",
                    "positive_objects": str(n_pos),
                    "negative_objects": str(n_neg),
                    "few_objects": str(min(n_pos, n_neg) < heldout.FEW_OBJECTS),
                }
            )
    return rows


def _fig5_title(haptic: Group | None, visual: Group | None, metric: str) -> str:
    label = METRICS.build(metric).label
    if haptic and visual:
        return f"Per-adjective {label}: best haptic vs best visual configuration"
    kind = "haptic" if haptic else "visual"
    other = "visual" if haptic else "haptic"
    return f"Per-adjective {label} of the best {kind} configuration (no {other} row was run)"


def _claims(
    groups: list[Group],
    evidence: dict[str, heldout.Evidence],
    haptic: Group | None,
    visual: Group | None,
    out: Path,
    margin: float,
) -> tuple[str, list[Path]]:
    candidates = comparisons.selection_family(groups)
    lines = comparisons.claims(groups, evidence, margin)
    lines += comparisons.by_modality(haptic, visual, evidence, candidates)
    rows = [vars(c) for c in lines]
    _write_csv(out / "claims.csv", rows)
    text = [
        "## The paper's claims, on these runs",
        "",
        "Each claim compares two Table I rows paired (the same test objects): the difference of",
        "mean AUC with its 95% paired-bootstrap interval, a Wilcoxon signed-rank test over the",
        "per-adjective differences and the bootstrap's own test, Holm-corrected over the claims",
        "compared (on the larger of the two p-values). A claim is `supported` only when the",
        "corrected test, the interval and the direction of the signed ranks agree on the winner,",
        "`contradicted` when they agree on the other, `mixed` when the interval and the ranks",
        "point opposite ways, else `not distinguishable`; never from the point estimates alone.",
        f"`I >= J` is `supported` only when the interval rules out a loss of {margin} or",
        "more (non-inferiority). The by-adjective lines (Fig. 5) compare the best visual and the",
        "best haptic configuration, picked by test mean AUC, on one adjective (interval only, at",
        "the Bonferroni level over the adjectives and every candidate pair of rows).",
        "Machine-readable: [claims.csv](claims.csv).",
        "",
        "| claim | what the paper says | verdict here | numbers |",
        "|---|---|---|---|",
        *(f"| {c.claim} | {c.says} | **{c.result}** | {c.detail} |" for c in lines),
        "",
    ]
    (out / "claims.md").write_text("\n".join(text) + "\n")
    return "\n".join(text) + "\n", [out / "claims.md", out / "claims.csv"]


def _friedman(
    groups: list[Group], evidence: dict[str, heldout.Evidence], out: Path
) -> tuple[str, list[Path]]:
    head = ["## All configurations: Friedman's test and the critical-difference diagram", ""]
    result = comparisons.friedman(groups, evidence)
    if result is None:
        why = "fewer than 3 configurations tested on the same objects with scores"
        return "\n".join([*head, f"Not drawn: {why}.", "", ""]), []
    cd_diagram(result, out / "cd_diagram.png")
    ranks = ", ".join(
        f"{n} {r:.2f}"
        for n, r in sorted(zip(result.names, result.mean_ranks, strict=True), key=lambda x: x[1])
    )
    text = [
        *head,
        f"{len(result.names)} configurations tested on the same objects, ranked on each of "
        f"{result.n_adjectives} adjectives (1 = best AUC): Friedman chi2 = {result.statistic:.2f},"
        f" p = {result.p:.3g}; Iman-Davenport F = {result.f_statistic:.2f}, p = "
        f"{result.f_p:.3g}. Mean ranks: {ranks}. Nemenyi's critical difference at 0.05 is "
        f"{result.critical_difference:.2f}: configurations joined by a red bar are not",
        "distinguishable (scipy's Friedman test; the diagram is drawn with matplotlib).",
        "",
        "![critical-difference diagram](cd_diagram.png)",
        "",
        "",
    ]
    return "\n".join(text), [out / "cd_diagram.png"]


def _ablation(
    groups: list[Group], evidence: dict[str, heldout.Evidence], out: Path, metric: str
) -> tuple[str, list[Path]]:
    view = comparisons.ablation(groups, evidence)
    if view is None:
        return "", []
    lines = [
        "## The ablation view",
        "",
        "The configurations of one sweep on one data set (the paper's rows aside), named by the",
        "swept settings that differ. For each axis, every pair of its levels compared paired,",
        "averaged over the other axes' combinations (Holm over all these comparisons).",
        "",
        "| configuration | mean AUC [95% CI] | seeds |",
        "|---|---|---|",
    ]
    for values, g in sorted(view.configs.items()):
        lines.append(f"| {view.name(values)} | {evidence[g.key].interval()} | {len(g.seeds)} |")
    same = _identical_axes(view, evidence)
    lines += ["", "| axis | comparison | combinations | difference and test |", "|---|---|---|---|"]
    for axis, cmp, n in view.effects:
        result = IDENTICAL if axis in same else comparisons.describe(cmp)
        lines.append(f"| {axis} | {cmp.a} vs {cmp.b} | {n} | {result} |")
    for axis, levels, why in view.unpaired:
        lines.append(f"| {axis} | {levels} | 0 | not compared: {why} |")
    for axis in same:
        lines += ["", f"**`{axis}` changed no score here**: {_identical_note(axis)}"]
    paths = []
    for i, axis in enumerate(view.axes):
        try:
            [float(v) for v in view.axes[axis]]
        except ValueError:
            continue
        series: dict[str, list[tuple[float, stats.Interval]]] = {}
        for values, g in view.configs.items():
            rest = " ".join(
                f"{a}={v}" for j, (a, v) in enumerate(zip(view.axes, values, strict=True)) if j != i
            )
            series.setdefault(rest, []).append((float(values[i]), evidence[g.key].interval()))
        path = out / f"ablation_{axis.replace('/', '_')}.png"
        numeric_axis(axis, series, path, metric)
        paths.append(path)
        lines += ["", f"![mean AUC against {axis}]({path.name})"]
    text = "\n".join(lines) + "\n\n"
    (out / "ablation.md").write_text(text)
    return text, [out / "ablation.md", *paths]


IDENTICAL = "identical scores at every level: not compared (below)"


def _identical_axes(view: comparisons.Ablation, evidence: dict[str, heldout.Evidence]) -> list[str]:
    """The axes whose levels gave every adjective the same value in each combination of the
    other axes: they changed no score, and a comparison of them is 0 by construction."""
    out = []
    for i, axis in enumerate(view.axes):
        by_rest: dict[tuple[str, ...], list[dict[str, float]]] = {}
        for values, g in view.configs.items():
            rest = values[:i] + values[i + 1 :]
            by_rest.setdefault(rest, []).append(_per_adjective(g, evidence[g.key]))
        compared = [v for v in by_rest.values() if len(v) > 1]
        if compared and all(all(x == v[0] for x in v[1:]) for v in compared):
            out.append(axis)
    return out


def _identical_note(axis: str) -> str:
    note = (
        "each of its levels gave every adjective the same value in every combination of the "
        "other axes, so the comparison above is 0 by construction, not evidence that the levels "
        "are equivalent in general."
    )
    if axis == "loss":
        note += (
            " With `combine_instances=concat` the scores come from the classification layer "
            "retrained on combined units (T4), and on separable units its hinge stage leaves the "
            "logistic stage's layer unchanged (the jobs' FinetuneWarning): `loss=hinge` then "
            "scores as `loss=logistic` does (conf/loss/hinge.yaml)."
        )
    return note


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
    adjectives = choices.fig6_adjectives or FIG6_ADJECTIVES
    try:
        data = conv3_maps(
            tracker=tracker,
            job_id=job_id,
            adjectives=adjectives,
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
    absent = [a for a in adjectives if not any(m.adjective == a for m in data.maps)]
    if absent and choices.fig6_adjectives:  # asked for by name: an error, not a note
        raise ReportError(
            f"--fig6-adjective {', '.join(absent)}: no finished model in job {job_id}"
        )
    if absent:
        lines += [f"Not drawn for {', '.join(absent)}: the job did not run them.", ""]
    for adjective in adjectives:
        maps = [m for m in data.maps if m.adjective == adjective]
        if not maps:
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


def _title(
    groups: list[Group],
    datasets: dict[str, list[Group]],
    paper: list[Group],
    source: str,
    names: dict[str, str],
) -> str:
    """The report's title names what it compares; the paper's when its rows were run."""
    n_configs = len(set(names.values()))
    if paper:
        title = "Gao et al. (ICRA 2016), regenerated from tracked runs"
    elif len(datasets) == 1:
        title = f"{_count(n_configs, 'configuration')} on {next(iter(datasets))}"
    else:
        title = f"{_count(n_configs, 'configuration')} on {len(datasets)} data sets"
    return "\n".join(
        [
            f"# {title}",
            "",
            f"{source}; {_count(n_configs, 'configuration')} on "
            f"{_count(len(datasets), 'data set')} ({', '.join(datasets)}), "
            f"{_count(_n_runs(groups), 'run')} (each seed and fold once). Written "
            f"{datetime.now(UTC):%Y-%m-%d %H:%M} UTC by `{ENTRY_POINT}`"
            + (f" at commit `{commit}`." if (commit := _commit()) else "."),
            "",
            "",
        ]
    )


def _leaderboards(
    boards: list[leaderboard.Board],
    evidence: dict[str, heldout.Evidence],
    out: Path,
    metric: str,
    tracker: Tracker,
) -> tuple[str, list[Path]]:
    """``leaderboard.md`` / ``.csv``, one board per data set, each with a runs-table link."""
    label = METRICS.build(metric).label
    text = [
        "## Leaderboard" + ("s" if len(boards) > 1 else ""),
        "",
        f"Per data set, every configuration's mean {label} over the labels it ran, with a 95%",
        "bootstrap interval over test objects (an object's units together, positives and",
        "negatives apart; with `split=folds` over the pooled out-of-fold scores), its rank (1 =",
        "best mean), the positive/negative test objects each label rests on (range over labels),",
        "and its difference from the baseline, paired on the same test objects (95% paired",
        "bootstrap interval; Wilcoxon over labels and the bootstrap's test, Holm over the data",
        "set's comparisons). A configuration is named by the settings that differ between the",
        "report's configurations; every setting, split, seed and run id is in",
        "[table1.md](table1.md) ([table1.csv](table1.csv)). Machine-readable:",
        "[leaderboard.csv](leaderboard.csv).",
        "",
    ]
    rows = []
    for b in boards:
        identity = b.entries[0].group.first_run.data
        columns = [canonical_column("metrics", f"mean_{METRICS.build(metric).key}")]
        columns += [canonical_column("params", "choice.model")]
        where = f"tags.`data.identity` = '{identity}'" if identity else ""
        link = tracker.runs_view(columns, order_by=columns[0], where=where)
        text += [
            f"### {b.dataset}",
            "",
            f"Baseline: `{b.baseline}` ({b.chosen}). In `mlflow ui`: [its runs]({link}).",
            "",
            leaderboard.markdown(b, evidence, metric),
        ]
        n_labels = min(len(label_order([e.group])) for e in b.entries)
        if note := leaderboard.few_labels_note(n_labels):
            text += [note, ""]
        rows += leaderboard.rows(b, evidence, metric)
    body = "\n".join(text) + "\n"
    (out / "leaderboard.md").write_text(body)
    _write_csv(out / "leaderboard.csv", rows)
    return body, [out / "leaderboard.md", out / "leaderboard.csv"]


def _declared(
    compare: list[declared.Declared],
    datasets: dict[str, list[Group]],
    evidence: dict[str, heldout.Evidence],
    names: dict[str, str],
    out: Path,
    margin: float,
    metric: str,
) -> tuple[str, list[Path]]:
    """``comparisons.md`` / ``.csv`` and each compared pair's per-label figure."""
    if not compare:
        return "", []
    found = declared.outcomes(compare, datasets, evidence, names, margin)
    overall = declared.across(compare, datasets, evidence, names)
    text = [
        "## Declared comparisons",
        "",
        "Each `--compare` on every data set where both configurations ran: the difference of",
        "mean metric with its 95% paired-bootstrap interval, Wilcoxon's signed-rank test over the",
        "labels and the bootstrap's test, Holm-corrected over every declared comparison on every",
        "data set (on the larger of the two p-values). `A > B` is `supported` only when the",
        "corrected test, the interval and the direction of the signed ranks agree that A wins,",
        "`contradicted` when they agree B does, `mixed` when the interval and the ranks point",
        "opposite ways, else `not distinguishable`. `A >= B` is `supported` only when the",
        f"interval rules out a loss of {margin} or more (`--margin`). Machine-readable, with each",
        "label's difference: [comparisons.csv](comparisons.csv).",
        "",
        declared.markdown(found, overall),
    ]
    compared = [o.comparison.n_adjectives for o in found if o.comparison is not None]
    if compared and (note := leaderboard.few_labels_note(min(compared))):
        text += [note, ""]
    paths = []
    for i, o in enumerate(found, 1):
        if o.labels:
            path = out / f"comparison_{i}.png"
            title = f"{o.a}\nminus {o.b}\non {o.dataset} ({o.level:.2%} paired intervals)"
            differences(o.labels, title, path, metric)
            paths.append(path)
            text += [f"![{o.declared.text} on {o.dataset}]({path.name})", ""]
    body = "\n".join(text) + "\n"
    (out / "comparisons.md").write_text(body)
    _write_csv(out / "comparisons.csv", declared.rows(found))
    return body, [out / "comparisons.md", out / "comparisons.csv", *paths]


def _benchmark(boards: list[leaderboard.Board], out: Path, metric: str) -> tuple[str, list[Path]]:
    """With two or more data sets: ``benchmark.md`` / ``.csv`` and the CD diagram over them."""
    if len(boards) < 2:
        return "", []
    bench = benchmark.benchmark(boards)
    body = "## Across data sets\n\n" + benchmark.markdown(bench, metric)
    (out / "benchmark.md").write_text(body)
    _write_csv(out / "benchmark.csv", benchmark.rows(bench, metric))
    paths = [out / "benchmark.md", out / "benchmark.csv"]
    if bench.friedman is not None:
        cd_diagram(bench.friedman, out / "benchmark_cd.png", blocks="data sets")
        paths.append(out / "benchmark_cd.png")
    return body, paths


def _paper(
    groups: list[Group],
    evidence: dict[str, heldout.Evidence],
    out: Path,
    tracker: Tracker,
    choices: Choices,
    metric: str,
    margin: float,
    paths: list[Path],
) -> str:
    """The paper's sections on its rows (the ``gao2016`` preset): Table I, Fig. 5, the claims,
    Friedman's test over adjectives, Fig. 6 and Table III; their files are added to ``paths``."""
    rows = table1(groups, evidence, metric)
    visual, haptic = best(groups, ("visual",)), best(groups, HAPTIC)
    if visual or haptic:
        shown = [
            (kind, g, evidence[g.key].per_adjective() if evidence[g.key].ok else {})
            for kind, g in (("best haptic", haptic), ("best visual", visual))
            if g is not None
        ]
        fig5(shown, _fig5_title(haptic, visual, metric), out / "fig5_per_adjective.png", metric)
        paths.append(out / "fig5_per_adjective.png")
    claim_text, claim_paths = _claims(groups, evidence, haptic, visual, out, margin)
    friedman_text, friedman_paths = _friedman(groups, evidence, out)
    fig6_paths, fig6_text = _fig6(groups, out, tracker, choices)
    table3_lines = _table3(groups, tracker, choices)
    paths += claim_paths + friedman_paths + fig6_paths + t3.write_table3(table3_lines, out)
    text = _table1_text(groups, rows, visual, haptic, evidence, metric)
    return text + claim_text + friedman_text + fig6_text + _table3_text(table3_lines)


def _table1_text(
    groups: list[Group],
    rows: list[dict[str, str]],
    visual: Group | None,
    haptic: Group | None,
    evidence: dict[str, heldout.Evidence],
    metric: str,
) -> str:
    shown = METRICS.build(metric)
    counts = sorted({g.n_adjectives for g in groups})
    over = (
        f"over the {counts[0]} adjectives run"
        if len(counts) == 1
        else "over each configuration's adjectives (column `adj.`)"
    )
    if len(counts) == 1 and counts[0] < max(g.n_labels for g in groups):
        over += f" ({', '.join(label_order(groups))})"
    missing = [g for g in groups if not evidence[g.key].ok]
    lines = [
        f"## Table I: mean {shown.label} {over}",
        "",
        "One line per configuration up to the seed (and fold); `n seeds` counts its seeds",
        "(splits, with `split=random`), `std over seeds` is the spread of their mean AUC. The",
        "bracket is a 95% confidence interval of the mean over adjectives from a bootstrap of",
        "the test objects (an object's units together, positives and negatives separately, all",
        "adjectives at once; averaged over seeds): it is about which objects happened to be",
        "tested. With `split=folds` every object is tested once per seed and the AUC is over",
        "all objects' pooled out-of-fold scores; `per-fold mean` is the mean of the folds' own",
        "AUCs, for reference. `test objects +/-` gives the positive/negative test objects each",
        f"adjective's AUC rests on (range over adjectives); fewer than {heldout.FEW_OBJECTS} of a",
        "class make an AUC that moves in steps of a third or more per object: such an",
        "adjective's number cannot carry a conclusion alone (listed in brackets). A row letter",
        "in brackets ran with other settings than the paper's (`setting` says which). The",
        "paper's figures are on the real PHAC-2 data; on the embedded synthetic data set they",
        "are a reference, not a target. Machine-readable: [table1.csv](table1.csv).",
        "",
    ]
    if missing:
        lines += [
            f"No interval for {len(missing)} configuration(s): "
            + "; ".join(f"`{g.method}`: {evidence[g.key].missing}" for g in missing),
            "",
        ]
    lines.append(table1_markdown(rows, metric))
    if visual or haptic:
        names = " vs ".join(
            f"`{g.method}` (mean {g.aucs.mean():.3f})" for g in (haptic, visual) if g
        )
        lines += [
            f"## Fig. 5: {_fig5_title(haptic, visual, metric)}",
            "",
            f"{names}, each averaged over its seeds/splits (pooled out of fold with",
            "`split=folds`); error bars are 95% object-bootstrap intervals per adjective; only",
            "the adjectives run are drawn. Every configuration's per-adjective AUC is in",
            "[per_adjective.csv](per_adjective.csv), with intervals and test-object counts in",
            "[per_adjective_intervals.csv](per_adjective_intervals.csv).",
            "",
            "![Fig. 5](fig5_per_adjective.png)",
            "",
        ]
    return "\n".join(lines) + "\n"


def _metric_text(metric: str) -> str:
    """What the numbers are when they are not ROC AUC (the prose below speaks of AUC)."""
    if metric == "roc_auc":
        return ""
    shown = METRICS.build(metric)
    lines = [
        f"**Metric: {shown.label}** (`--metric {metric}`, logged as `{shown.key}`). Every AUC",
        "below (the leaderboards, the comparisons, Table I, Fig. 5, the per-adjective files, the",
        f"claims, Friedman's test, the ablation view) is the {shown.label} of the test units; its",
        f"intervals come from the same object bootstrap, {shown.label} recomputed on each",
        "replicate's resampled objects. Table I's paper column is empty: the paper's figures are",
        f"ROC AUC. Jobs that did not log `mean_{shown.key}` are not listed.",
        "",
        "",
    ]
    return "\n".join(lines)


def _commit() -> str | None:
    return git_commit(Path(__file__).resolve().parents[2])


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}{'' if n == 1 else 's'}"


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
        "--metric",
        default="roc_auc",
        help="what the tables, figures and comparisons show: a metric the jobs logged "
        "(conf/config.yaml metrics; default: roc_auc, logged as auc)",
    )
    parser.add_argument(
        "--margin",
        type=float,
        default=stats.MARGIN,
        help="stats.margin: the AUC loss an 'as good as' claim (I >= J) must rule out, and the "
        f"equivalence bound (ours, not the paper's; default: {stats.MARGIN})",
    )
    parser.add_argument(
        "--compare",
        action="append",
        default=[],
        metavar="'A > B'",
        help="a declared comparison of two configurations by their settings, e.g. "
        '"model=haptic_cnn > model=linear" (A beats B) or "combine=1 >= combine=10" (A is '
        "not worse by --margin or more); repeat for several (Holm over all of them)",
    )
    parser.add_argument(
        "--baseline",
        metavar="SPEC",
        help="the configuration each leaderboard compares every other with, by its settings "
        "(e.g. model=linear; default: each data set's best by mean)",
    )
    parser.add_argument(
        "--preset",
        choices=PRESETS,
        default="auto",
        help="the paper's sections (Table I's rows, Fig. 5, its claims, Fig. 6, Table III): auto "
        "(when its rows ran on PHAC-2-layout data), gao2016 (always), none (never)",
    )
    parser.add_argument(
        "--export-results",
        type=Path,
        metavar="DIR",
        help="also write every configuration's held-out scores as DIR/<configuration>/<data "
        "set>/fold<k>.csv (label, object, unit, truth, score), to compare elsewhere",
    )
    parser.add_argument(
        "--import-results",
        type=Path,
        action="append",
        default=[],
        metavar="DIR",
        help="results of methods run elsewhere, in --export-results' layout, as configurations "
        "of the report (repeat for several folders)",
    )
    parser.add_argument(
        "--runs-table",
        metavar="RUN_ID",
        help="print this job's runs as mlflow ui lists them (Markdown) and exit",
    )
    args = parser.parse_args(argv)
    if args.fig6_trials < 1:
        parser.error("--fig6-trials must be >= 1")
    if not 0 < args.margin < 1:
        parser.error(f"--margin: an AUC difference in (0, 1), got {args.margin}")
    if args.metric not in METRICS:
        parser.error(f"--metric: unknown {args.metric!r}; known: {', '.join(METRICS.names())}")
    try:
        compare = tuple(declared.Declared.parse(text) for text in args.compare)
        baseline = Spec.parse(args.baseline) if args.baseline else None
    except SpecError as err:
        parser.error(str(err))
    try:
        tracker = Tracker.open(args.tracking_uri, args.experiment, entry_point=ENTRY_POINT)
    except ExperimentNotFound as err:
        sys.exit(f"error: {err}")
    if args.runs_table:
        print(runs_table(tracker=tracker, job_id=args.runs_table, metric=args.metric), end="")
        return
    groups = collect(tracker, args.sweep_id, args.metric)
    try:
        imported = [found for root in args.import_results for found in results.load(root)]
    except ReportError as err:
        sys.exit(f"error: {err}")
    if imported and args.metric != "roc_auc":
        parser.error("--import-results: imported scores are compared on roc_auc only")
    groups += [g for g, _ in imported]
    if not groups:
        where = f" with sweep_id {args.sweep_id!r}" if args.sweep_id else ""
        logged = f" that logged mean_{METRICS.build(args.metric).key}"
        sys.exit(
            f"error: no FINISHED job runs{logged if args.metric != 'roc_auc' else ''} in MLflow "
            f"experiment {args.experiment!r}{where} ({tracker.uri})"
        )
    source = f"MLflow experiment `{args.experiment}`" + (
        f", sweep `{args.sweep_id}`" if args.sweep_id else ""
    )
    choices = Choices(
        fig6_adjectives=tuple(args.fig6_adjective or ()),
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
            metric=args.metric,
            margin=args.margin,
            compare=compare,
            baseline=baseline,
            preset=args.preset,
            known={g.key: e for g, e in imported},
        )
        if args.export_results:
            tracked = [g for g in groups if g.key not in {i.key for i, _ in imported}]
            names = configurations.names(groups)
            exported = results.export(tracker, tracked, names, args.export_results)
            print(f"exported {len(exported)} result files into {args.export_results}")
    except (ReportError, ArtifactError, SpecError) as err:
        sys.exit(f"error: {err}")
    params = {
        "experiment": args.experiment,
        "sweep_id": args.sweep_id or "",
        "out": str(args.out),
        "metric": args.metric,
        "margin": str(args.margin),
        "compare": " ; ".join(args.compare)[:5000],
        "baseline": args.baseline or "",
        "preset": args.preset,
    }
    with tracker.run("report", params, {"run_level": "report"}) as run_id:
        tracker.log_metrics(run_id, {"n_groups": len(groups), "n_runs": _n_runs(groups)})
        for path in paths:
            tracker.log_file(run_id, path, "report")
            if path.suffix == ".csv" and path.stem in TABLES:
                tracker.log_table(run_id, _read_csv(path), f"tables/{path.stem}.json")
    for path in paths:
        print(path)
    print(f"logged as MLflow run {run_id} (report) in {tracker.uri}")
    if (args.out / "table1_summary.md").exists() and paper_groups(groups, args.preset):
        print(f"Table I (every column: {args.out / 'table1.md'}):")
        print((args.out / "table1_summary.md").read_text())
    print(f"Leaderboard (every column: {args.out / 'leaderboard.csv'}):")
    print((args.out / "leaderboard.md").read_text())

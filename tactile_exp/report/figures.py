"""The report's figures as PNGs of fixed pixel size: Fig. 5 (per-adjective AUC), Fig. 6
(conv3 activation maps), the critical-difference diagram and the ablation's numeric-axis plot
(drawn with matplotlib: ``autorank`` would add pandas-era pins for one figure)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tactile_exp.data.layout import EPS
from tactile_exp.metrics import METRICS
from tactile_exp.report.activations import Conv3Map
from tactile_exp.report.runs import Group, label_order
from tactile_exp.report.scores import ReportError
from tactile_exp.stats import Friedman, Interval

DPI = 100
FIG5_SIZE = (12.0, 4.5)  # inches: 1200 x 450 pixels
# Fig. 6: a margin for the signal names plus one panel per trial, all 8 inches high
# (2 trials: 900 x 800 pixels).
FIG6_MARGIN, FIG6_PANEL, FIG6_HEIGHT = 2.0, 3.5, 8.0


def fig6_size(n_panels: int) -> tuple[int, int]:
    """Fig. 6's PNG size in pixels for ``n_panels`` trials."""
    return round((FIG6_MARGIN + FIG6_PANEL * n_panels) * DPI), round(FIG6_HEIGHT * DPI)


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def fig5(
    shown: list[tuple[str, Group, dict[str, Interval]]],
    title: str,
    path: Path,
    metric: str = "roc_auc",
) -> None:
    """Per-adjective AUC (or ``metric``) of the given groups (kind, group, intervals) side by
    side, with 95% object-bootstrap error bars where the scores allow; adjectives a group did not
    run are left empty and named on the axis as not run. Chance is drawn for ROC AUC only (for
    the others it depends on each adjective's share of positives)."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=FIG5_SIZE)
    run = fig5_adjectives([g for _, g, _ in shown])
    x = np.arange(len(run))
    width = 0.8 / max(len(shown), 1)
    for i, ((kind, g, intervals), colour) in enumerate(
        zip(shown, ("tab:red", "tab:blue", "tab:green"), strict=False)
    ):
        aucs = {a: iv.estimate for a, iv in intervals.items()} or g.per_adjective()
        values = np.array([aucs.get(a, np.nan) for a in run])
        label = f"{kind}: {g.row + ' ' if g.row else ''}{g.method} ({len(g.seeds)} seed(s))"
        offset = x + (i - (len(shown) - 1) / 2) * width
        if intervals:
            label += ", 95% interval"
        ax.bar(offset, values, width, color=colour, label=label)
        if intervals:
            low = np.array([intervals[a].low if a in intervals else np.nan for a in run])
            high = np.array([intervals[a].high if a in intervals else np.nan for a in run])
            _interval_bars(ax, offset, low, high)
    if metric == "roc_auc":
        ax.axhline(0.5, color="k", lw=0.8, ls=":", label="chance (AUC 0.5)")
    ax.set_xticks(x, run, rotation=60, ha="right", fontsize=8)
    ax.set_xlabel("haptic adjective (only those run)")
    ax.set_ylabel(f"{_label(metric)} on held-out objects")
    ax.set_ylim(0, 1.3)
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=7, loc="upper left", ncol=3)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def _interval_bars(
    ax, x: np.ndarray, low: np.ndarray, high: np.ndarray, colour: str = "k", caps: float = 2
) -> None:
    """Intervals drawn from their own ends: a bootstrap interval need not contain the point
    estimate (a percentile interval of a skewed statistic can lie wholly on one side)."""
    middle, half = (low + high) / 2, (high - low) / 2
    ax.errorbar(x, middle, yerr=half, fmt="none", ecolor=colour, capsize=caps, lw=0.8)


def fig5_adjectives(groups: list[Group]) -> list[str]:
    """The adjectives Fig. 5 draws: those any shown group ran (a missing one is no bar, not 0)."""
    return label_order(groups)


def cd_diagram(result: Friedman, path: Path, blocks: str = "adjectives") -> None:
    """Demsar's critical-difference diagram: mean ranks on one axis (1 = best, on the left),
    bars joining configurations whose ranks differ by less than Nemenyi's CD; ``blocks`` names
    what each configuration was ranked on (adjectives, data sets)."""
    plt = _pyplot()
    order = np.argsort(result.mean_ranks)
    k = len(order)
    short = cd_labels(result.names)
    legend = [f"{s} = {n}" for s, n in zip(short, result.names, strict=True) if s != n]
    fig, ax = plt.subplots(figsize=(8.0, 1.9 + 0.3 * k + 0.16 * len(legend)))
    ax.set_xlim(0.5, k + 0.5)
    ax.set_ylim(-k * 0.35 - 0.5, 1.2)
    ax.axhline(0, color="k", lw=1)
    for r in range(1, k + 1):
        ax.plot([r, r], [0, 0.1], color="k", lw=1)
        ax.text(r, 0.2, str(r), ha="center", fontsize=8)
    for j, i in enumerate(order):
        rank = result.mean_ranks[i]
        y = -0.35 * (j + 1)
        left = j < (k + 1) // 2
        end = 0.5 if left else k + 0.5
        ax.plot([rank, rank, end], [0, y, y], color="k", lw=0.8)
        ax.text(
            end,
            y + 0.05,
            f"{short[i]} ({rank:.2f})",
            fontsize=8,
            ha="left" if left else "right",
            va="bottom",
        )
    cliques = []
    for a in range(k):
        b = a
        while b + 1 < k and result.mean_ranks[order[b + 1]] - result.mean_ranks[order[a]] < (
            result.critical_difference
        ):
            b += 1
        if b > a and not any(a >= s and b <= e for s, e in cliques):
            cliques.append((a, b))
    for n, (a, b) in enumerate(cliques):
        y = -0.12 - 0.08 * n
        ax.plot(
            [result.mean_ranks[order[a]] - 0.03, result.mean_ranks[order[b]] + 0.03],
            [y, y],
            color="tab:red",
            lw=3,
        )
    ax.plot([1, 1 + result.critical_difference], [0.8, 0.8], color="k", lw=1.5)
    ax.text(
        1 + result.critical_difference / 2,
        0.9,
        f"CD = {result.critical_difference:.2f}",
        ha="center",
        fontsize=8,
    )
    ax.set_title(
        f"Mean rank over {result.n_adjectives} {blocks} (Friedman p = {result.p:.3g}); red bars: "
        "not distinguishable (Nemenyi, 0.05)",
        fontsize=9,
    )
    ax.text((k + 1) / 2, 0.45, f"mean rank over {blocks} (1 = best)", ha="center", fontsize=8)
    if legend:
        ax.text(
            0.5,
            -k * 0.35 - 0.6,
            "\n".join(legend),
            ha="left",
            va="top",
            fontsize=7,
            family="monospace",
        )
        ax.set_ylim(-k * 0.35 - 0.7 - 0.16 * len(legend), 1.2)
    ax.axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def differences(intervals: dict[str, Interval], title: str, path: Path, metric: str) -> None:
    """One pair's per-label differences (a - b) with their paired intervals: the paper's Fig. 5
    for any two configurations; a label without an interval is drawn as its point alone."""
    plt = _pyplot()
    labels = list(intervals)
    fig, ax = plt.subplots(figsize=(max(6.0, 0.35 * len(labels) + 1.5), 4.2))
    x = np.arange(len(labels))
    estimates = np.array([intervals[j].estimate for j in labels])
    colours = [
        "tab:red" if iv.low > 0 else "tab:blue" if iv.high < 0 else "0.4"
        for iv in intervals.values()
    ]
    ax.scatter(x, estimates, c=colours, s=14, zorder=3)
    low = np.array([iv.low for iv in intervals.values()])
    high = np.array([iv.high for iv in intervals.values()])
    _interval_bars(ax, x, low, high)
    ax.axhline(0, color="k", lw=0.8, ls=":")
    ax.set_xticks(x, labels, rotation=60, ha="right", fontsize=8)
    ax.set_ylabel(f"difference of {_label(metric)}")
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def line_labels(lines: dict[str, list[tuple[float, Interval]]]) -> dict[str, str]:
    """Each line's legend label; a line whose points equal an earlier one's (in name order) is
    labelled identical to it (drawn apart by its marker and a small shift, not hidden under it)."""
    first: dict[tuple, str] = {}
    out = {}
    for name, points in sorted(lines.items()):
        key = tuple(sorted((x, iv.estimate) for x, iv in points))
        shown = name or "(all)"
        out[name] = f"{shown} (identical to {first[key]})" if key in first else shown
        first.setdefault(key, shown)
    return out


def cd_labels(names: list[str], longest: int = 4) -> list[str]:
    """Short labels for the CD diagram: a row letter as it is, a longer name (an ablation's
    configuration) as c1, c2, ... in the given order, mapped to its full name in a legend."""
    out, n = [], 0
    for name in names:
        if len(name) <= longest:
            out.append(name)
        else:
            n += 1
            out.append(f"c{n}")
    return out


def _label(metric: str) -> str:
    return "ROC AUC" if metric == "roc_auc" else METRICS.build(metric).label


def numeric_axis(
    axis: str,
    lines: dict[str, list[tuple[float, Interval]]],
    path: Path,
    metric: str = "roc_auc",
) -> None:
    """Mean AUC (or ``metric``; 95% interval) against a numeric swept axis, one line per
    combination of the other axes."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.0, 4.0))
    labels = line_labels(lines)
    markers, styles = "osD^v<>", ("-", "--", ":", "-.")
    for n, (name, points) in enumerate(sorted(lines.items())):
        points = sorted(points, key=lambda p: p[0])
        xs = np.array([p[0] for p in points])
        ys = np.array([p[1].estimate for p in points])
        label = labels[name]
        # Lines that coincide stay visible: each its own marker and dash, shifted a little.
        shift = 0.012 * n * (xs.max() - xs.min() or 1.0)
        (line,) = ax.plot(
            xs + shift,
            ys,
            marker=markers[n % len(markers)],
            ls=styles[n % len(styles)],
            mfc="none" if n % 2 else None,
            label=label,
        )
        low = np.array([p[1].low for p in points])
        high = np.array([p[1].high for p in points])
        _interval_bars(ax, xs + shift, low, high, line.get_color(), caps=3)
    if metric == "roc_auc":
        ax.axhline(0.5, color="k", lw=0.8, ls=":", label="chance")
    ax.set_xlabel(axis)
    ax.set_ylabel(f"mean {_label(metric)} over adjectives (95% interval)")
    ax.set_title(f"Mean {_label(metric)} against {axis}", fontsize=10)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def fig6(maps: list[Conv3Map], signals: list[str], title: str, path: Path) -> None:
    """One adjective's conv3 maps side by side (channel x time, darker = higher, one grey scale
    for the figure), rows labelled by input signal, EP blocks split by red lines."""
    plt = _pyplot()
    from matplotlib.ticker import MaxNLocator

    channels = maps[0].activations.shape[0]
    if channels % len(signals):
        raise ReportError(
            f"conv3 has {channels} channels, not a multiple of {len(signals)} signals"
        )
    width = channels // len(signals)  # conv3 filters per signal group
    vmax = max(float(m.activations.max()) for m in maps) or 1.0
    width_px, height_px = fig6_size(len(maps))
    fig, axes = plt.subplots(1, len(maps), figsize=(width_px / DPI, height_px / DPI), sharey=True)
    axes = np.atleast_1d(axes)
    left = FIG6_MARGIN / (width_px / DPI)
    fig.subplots_adjust(left=left, right=0.91, top=0.88, bottom=0.08, wspace=0.08)
    for ax, m in zip(axes, maps, strict=True):
        image = ax.imshow(
            m.activations, aspect="auto", cmap="Greys", vmin=0, vmax=vmax, interpolation="nearest"
        )
        per_ep = channels // len(EPS)
        for e in range(1, len(EPS)):
            ax.axhline(e * per_ep - 0.5, color="tab:red", lw=0.8)
        u = m.unit
        verdict = "correct" if u.predicted == bool(u.label) else "wrong"
        ax.set_title(
            f"{u.unit}\n{'positive' if u.label else 'negative'}, score {u.score:+.2f}: {verdict}",
            fontsize=8,
        )
        ax.set_xlabel("conv3 time step\n(each EP resampled to its own length)", fontsize=7)
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.tick_params(axis="x", labelsize=7)
    axes[0].set_yticks(np.arange(len(signals)) * width + (width - 1) / 2, signals, fontsize=5.5)
    axes[0].set_ylabel(f"conv3 channel ({width} filters per input signal)", fontsize=8)
    colorbar = fig.colorbar(image, cax=fig.add_axes((0.93, 0.3, 0.015, 0.4)))
    colorbar.ax.tick_params(labelsize=7)
    colorbar.set_label("conv3 activation (after ReLU)", fontsize=7)
    fig.suptitle(title, fontsize=9)
    fig.savefig(path, dpi=DPI)
    plt.close(fig)

"""The report's figures as PNGs of fixed pixel size: Fig. 5 (per-adjective AUC) and Fig. 6
(conv3 activation maps)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tactile_exp.data.layout import ADJECTIVES, EPS
from tactile_exp.report.activations import Conv3Map
from tactile_exp.report.runs import Group
from tactile_exp.report.scores import ReportError

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


def fig5(visual: Group | None, haptic: Group | None, path: Path) -> None:
    """The best haptic and the best visual group's AUC per adjective, side by side."""
    plt = _pyplot()
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
    fig.suptitle(title, fontsize=9)
    fig.savefig(path, dpi=DPI)
    plt.close(fig)

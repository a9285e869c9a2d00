"""Figures of the paper redrawn from our own constituent functions (headless, Agg).

:func:`plot_constituents` redraws Figure 1.1 (the eight-segment curve f_cc of eq. 1) and the four
panels of Figure 1.2 (eqs 5-7, 2 and 9, 3 and 10-11, 4 and 12) into one image.
"""

from __future__ import annotations

import io
import logging
from collections.abc import Callable
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from surfgen.generator.files import write_atomic
from surfgen.generator.formula import constituents as cf

log = logging.getLogger(__name__)

SAMPLES = 6001  # dense enough that a jump is the only step larger than JUMP between samples
JUMP = 0.2  # |dy| between neighbours above which the curve is broken rather than joined


def break_jumps(x: np.ndarray, y: np.ndarray, jump: float = JUMP) -> tuple[np.ndarray, np.ndarray]:
    """Insert a NaN between neighbours whose values differ by more than ``jump``.

    Matplotlib leaves a gap at a NaN, so a discontinuous function is drawn without the vertical
    connector a plain line plot would add. Returns new arrays of length ``len(x) + jumps``.
    """
    at = np.flatnonzero(np.abs(np.diff(y)) > jump) + 1
    return np.insert(x, at, np.nan), np.insert(y, at, np.nan)


def _curve(
    ax: Axes, x: np.ndarray, y: np.ndarray, label: str, offset: float = 0.0, **style
) -> None:
    bx, by = break_jumps(x, y)
    ax.plot(bx, by + offset, label=label, **style)


def _pulses(ax: Axes, x: np.ndarray, y: np.ndarray, label: str, offset: float, color: str) -> None:
    """A pulse train: the broken curve plus a light fill down to its baseline (no edges drawn)."""
    _curve(ax, x, y, label, offset, color=color, lw=2)
    ax.fill_between(x, offset, y + offset, color=color, alpha=0.15, lw=0)


def _plot_fcc8(ax: Axes) -> None:
    x = np.linspace(0.0, 11.0, SAMPLES)
    _curve(ax, x, cf.fcc8(x), "eq. (1) $f_{cc}$, eight segments", color="C0", lw=2)
    # The selector convention: each segment is [a, b): filled dot at a, open circle at b.
    labels = ["segment start a (value taken)", "segment end b (excluded)"]
    for a, b, slope, intercept in cf.FIGURE_1_1_SEGMENTS:
        start, end = labels or (None, None)  # label the first segment's markers only
        labels = []
        ax.plot([a], [slope * a + intercept], "o", color="C0", ms=5, label=start)
        ax.plot([b], [slope * b + intercept], "o", mfc="white", color="C0", ms=5, label=end)
    ax.set_title("Figure 1.1: a curve of eight piecewise segments, eq. (1) (0 outside [1, 10.5))")
    ax.set_xlim(0.0, 11.0)
    ax.set_ylim(-0.8, 8.8)


def _plot_rect(ax: Axes, x: np.ndarray) -> None:
    _pulses(ax, x, cf.rect1(x, 0.3), "eq. (5) rect1, t = 0.3", 0.0, "C0")
    _pulses(ax, x, cf.rect2(x, 2.0, 0.5), "eq. (6) rect2, r = 2, t = 0.5 (drawn +1.5)", 1.5, "C1")
    _pulses(ax, x, cf.rect3(x, 0.25), "eq. (7) rect3, t = 0.25 (drawn -0.5)", -0.5, "C2")
    ax.set_title("Figure 1.2 (a): rectangular pulses, eqs (5), (6), (7)")
    ax.set_ylim(-1.8, 3.6)


def _plot_pair(
    ax: Axes,
    x: np.ndarray,
    series: Callable[[np.ndarray], np.ndarray],
    series_label: str,
    others: list[tuple[Callable[[np.ndarray], np.ndarray], str]],
    title: str,
) -> None:
    """A paper's trigonometric form(s) drawn wide and light, the series form thin on top."""
    for k, (f, label) in enumerate(others):
        _curve(ax, x, f(x), label, color=f"C{k + 1}", lw=4 if k == 0 else 1.5, alpha=0.55)
    _curve(ax, x, series(x), series_label, color="C0", lw=1.5)
    ax.axvspan(-3.0, 2.0, color="0.92", zorder=0, label="domain of the series form, p = 2")
    ax.set_title(title)


def _draw(fig: Figure) -> None:
    grid = fig.add_gridspec(
        3,
        2,
        height_ratios=[1.1, 1, 1],
        hspace=0.3,
        wspace=0.16,
        left=0.05,
        right=0.985,
        bottom=0.035,
        top=0.97,
    )  # fixed margins: bbox_inches="tight" would draw the whole figure twice
    _plot_fcc8(fig.add_subplot(grid[0, :]))
    x = np.linspace(-5.0, 5.0, SAMPLES)
    panels = [fig.add_subplot(grid[1 + k // 2, k % 2]) for k in range(4)]
    _plot_rect(panels[0], x)
    _plot_pair(
        panels[1],
        x,
        lambda u: cf.saw1(u, 1.0, 2),
        "eq. (2) saw1, r = 1, p = 2",
        [(lambda u: cf.saw2(u, 1.0), "eq. (9) saw2, r = 1")],
        "Figure 1.2 (b): saw-tooth, eqs (2) and (9)",
    )
    _plot_pair(
        panels[2],
        x,
        lambda u: cf.tri1(u, 1.0, 2),
        "eq. (3) tri1, r = 1, p = 2",
        [
            (lambda u: cf.tri3(u, 1.0), "eq. (11) tri3, r = 1"),
            (lambda u: cf.tri2(u, 1.0), "eq. (10) tri2, r = 1"),
        ],
        "Figure 1.2 (c): triangular pulses, eqs (3), (10), (11)",
    )
    _plot_pair(
        panels[3],
        x,
        lambda u: cf.stair1(u, 1.0, 0.5, 2),
        "eq. (4) stair1, r = 1, h = 0.5, p = 2",
        [(lambda u: cf.stair2(u, 1.0, 0.5), "eq. (12) stair2, r = 1, h = 0.5")],
        "Figure 1.2 (d): staircase, eqs (4) and (12)",
    )
    for ax in [*panels, fig.axes[0]]:
        ax.grid(True, lw=0.4, alpha=0.5)
        ax.legend(fontsize=7.5, loc="upper left", framealpha=0.9)
    for ax in panels:
        ax.set_xlim(-5.0, 5.0)
    panels[1].set_ylim(-0.15, 1.55)
    panels[2].set_ylim(-0.15, 1.75)
    panels[3].set_ylim(-3.2, 3.6)


def plot_constituents(path: Path) -> Path:
    """Draw Figure 1.1 above the 2x2 panels of Figure 1.2 into ``path`` (format from suffix).

    The file is written to a temporary name in the same folder and renamed into place.
    Returns ``path``.
    """
    path = Path(path)
    fig = Figure(figsize=(12.0, 13.0), dpi=100, layout=None)
    FigureCanvasAgg(fig)
    _draw(fig)
    fmt = path.suffix.lstrip(".").lower() or "png"
    buffer = io.BytesIO()
    fig.savefig(buffer, format=fmt)
    write_atomic(path, buffer.getvalue())
    log.info("wrote %s", path)
    return path
